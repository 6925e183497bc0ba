"""Writing output files safely: one place that knows what an output path is.

:func:`destination` checks an output path *before* any work and says what it
is: a regular file (new or existing: written under a temporary name beside
it and renamed when complete, so an existing file is replaced only by a
whole new one and nothing half-written is ever left), a character device or
a FIFO (written directly: never replaced by a regular file), or ``-``
(standard output).  Symbolic links are followed to their target, which is
what gets written (the link stays).  Folders, block devices, sockets and
paths that cannot be created are refused up front with an
:class:`OutputError` naming the path as given.

:class:`Staging` writes several outputs and commits them together: every
file is complete before any is renamed into place.  Any OS error while
writing (a full disk, a reader that went away) becomes an
:class:`OutputError` naming the path; temporary files are removed.

Every wait is bounded: a FIFO without a reader, or whose reader stops
reading, fails after :data:`STREAM_WAIT_S` seconds, and the message says so.
"""

from __future__ import annotations

import contextlib
import errno
import os
import select
import shutil
import stat
import sys
import tempfile
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

#: The path that means standard output.
STDOUT = "-"
#: Longest wait for a FIFO's reader to open it or to take more bytes, s.
STREAM_WAIT_S = 60.0
_COPY_BLOCK = 1 << 16


class OutputError(OSError, ValueError):
    """An output that cannot be written; the message names the path as the user gave it.

    Both an ``OSError`` (it is one) and a ``ValueError`` (a bad argument when
    raised before any work).
    """

    def __str__(self) -> str:  # OSError's str() would show "[Errno ...]" for 2-argument forms
        return str(self.args[0]) if self.args else ""


def temp_path_beside(path: Path) -> Path:
    """A fresh hidden temporary path in ``path``'s folder (same file system: rename is atomic).

    Unlike ``tempfile.mkstemp`` the file is not created here, so whoever
    writes it gets the usual permissions (umask), not 0600.
    """
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:12]}.tmp")


def remove_quietly(path: Path) -> None:
    try:
        Path(path).unlink()
    except FileNotFoundError:
        pass


def _reason(e: BaseException) -> str:
    """The OS's words for an error (``No space left on device``), not the library's wrapping."""
    if isinstance(e, OutputError):
        return str(e)
    code = getattr(e, "errno", None)
    if code:
        return os.strerror(code)
    return " ".join(str(e).split()) or type(e).__name__


def human_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} EiB"  # pragma: no cover


def free_bytes(folder: Path) -> int | None:
    """Bytes available to this user on ``folder``'s file system (None if unknown)."""
    try:
        st = os.statvfs(folder)
    except OSError:
        return None
    return st.f_bavail * st.f_frsize


def _nearest_existing(path: Path) -> Path:
    p = path
    while not os.path.lexists(p) and p != p.parent:
        p = p.parent
    return p


def _require_folder(path: Path, unusable: str, not_folder: str) -> None:
    """Fail unless the existing ``path`` is a folder: ``unusable: <the OS's reason>`` when it cannot be
    examined (a symlink loop, no permission), ``not_folder`` when it is something else."""
    try:
        st = os.stat(path)
    except OSError as e:
        raise OutputError(f"{unusable}: {_reason(e)}") from None
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(not_folder)


def _check_free_space(folder: Path, expected_bytes: int | None, what: str, given: str) -> None:
    """Fail when the file system of ``folder`` (or of its nearest existing parent) has less room than
    ``expected_bytes`` (no check without it, or where the free space is unknown)."""
    if not expected_bytes:
        return
    free = free_bytes(_nearest_existing(folder))
    if free is not None and expected_bytes > free:
        raise OutputError(
            f"{what} {given!r}: needs about {human_bytes(expected_bytes)}, only {human_bytes(free)} free there"
        )


def _check_creatable_folder(folder: Path, what: str, given: str) -> None:
    """Fail unless ``folder`` is, or can be made, a folder we can create files in (nothing is left behind)."""
    base = _nearest_existing(folder)
    _require_folder(base, f"{what} {given!r}: cannot use folder {str(base)!r}",
                    f"{what} {given!r}: {str(base)!r} is not a folder")
    probe = base / f".dicetrace-probe.{os.getpid()}-{uuid.uuid4().hex[:12]}"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        os.close(fd)
    except OSError as e:
        if base == folder:
            raise OutputError(f"{what} {given!r}: cannot write into folder {str(base)!r}: {_reason(e)}") from None
        raise OutputError(f"{what} {given!r}: cannot create it in folder {str(base)!r}: {_reason(e)}") from None
    finally:
        with contextlib.suppress(OSError):
            os.unlink(probe)


@dataclass(frozen=True)
class Destination:
    """A checked output path (see :func:`destination`).

    ``kind`` is ``"file"`` (a regular file, new or replaced atomically),
    ``"stream"`` (a character device or a FIFO, written directly) or
    ``"stdout"``.  ``target`` is where the bytes go (symbolic links followed;
    None for standard output); ``given`` is the path as given, for messages.
    """

    given: str
    target: Path | None
    kind: str
    what: str = "output"

    @property
    def label(self) -> str:
        return "standard output" if self.kind == "stdout" else f"{self.what} {self.given!r}"

    def __fspath__(self) -> str:
        return STDOUT if self.target is None else str(self.target)


def _stdout_open() -> bool:
    if sys.stdout is None:
        return False
    try:
        fd = sys.stdout.fileno()
    except (OSError, ValueError, AttributeError):
        return not getattr(sys.stdout, "closed", False)  # an in-memory stream (tests): open unless closed
    try:
        os.fstat(fd)
    except OSError:
        return False
    return True


def destination(
    path,
    *,
    what: str = "output",
    suffix: str | None = None,
    allow_stdout: bool = True,
    expected_bytes: int | None = None,
) -> Destination:
    """Check an output path before any work; return its :class:`Destination` or raise :class:`OutputError`.

    ``suffix`` (e.g. ``".rrd"``): a regular file must end in it (the given
    name or the link's target).  ``expected_bytes``: refuse a regular file
    when its file system has less room than that.  Nothing is created (a
    probe file is made and removed to test that the folder is writable).
    """
    if isinstance(path, Destination):
        return path
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{what} must be a path (str or os.PathLike), not {type(path).__name__}")
    given = os.fspath(path)
    if isinstance(given, bytes):
        given = os.fsdecode(given)
    if given == "":
        raise OutputError(f"{what} is empty: give a file name")
    if given == STDOUT:
        if not allow_stdout:
            raise OutputError(f"{what} '-' (standard output) is not possible here: give a file name")
        if not _stdout_open():
            raise OutputError(f"{what} '-': standard output is closed")
        return Destination(given, None, "stdout", what)
    p = Path(given)
    target = Path(os.path.realpath(p)) if p.is_symlink() else p
    try:
        st = os.stat(target)
    except (FileNotFoundError, NotADirectoryError):  # a missing path, or a component that is a file (named below)
        st = None
    except OSError as e:  # a symlink loop, no permission
        raise OutputError(f"{what} {given!r}: {_reason(e)}") from None
    if st is not None:
        mode = st.st_mode
        if stat.S_ISDIR(mode):
            raise OutputError(f"{what} {given!r} is a folder, expected a file")
        if stat.S_ISCHR(mode) or stat.S_ISFIFO(mode):
            if not os.access(target, os.W_OK):
                raise OutputError(f"{what} {given!r}: no permission to write")
            return Destination(given, target, "stream", what)
        if not stat.S_ISREG(mode):
            kind = "block device" if stat.S_ISBLK(mode) else "socket" if stat.S_ISSOCK(mode) else "special file"
            raise OutputError(f"{what} {given!r} is a {kind}: dicetrace writes regular files, character devices and FIFOs")
        if not os.access(target, os.W_OK):
            raise OutputError(f"{what} {given!r} exists and is not writable")
    if suffix is not None and not (p.name.endswith(suffix) or target.name.endswith(suffix)):
        raise OutputError(f"{what} {given!r} must end in {suffix}")
    _check_creatable_folder(target.parent if str(target.parent) else Path("."), what, given)
    _check_free_space(target.parent, expected_bytes, what, given)
    return Destination(given, target, "file", what)


def output_folder(path, *, what: str = "output folder", expected_bytes: int | None = None) -> Path:
    """Check an output folder before any work: an existing folder, or one that can be made; nothing is created."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{what} must be a path (str or os.PathLike), not {type(path).__name__}")
    given = os.fsdecode(os.fspath(path))
    if given in ("", STDOUT):
        raise OutputError(f"{what} {given!r}: give a folder")
    p = Path(given)
    if os.path.lexists(p):
        _require_folder(p, f"{what} {given!r}", f"{what} {given!r} exists and is not a folder")
    _check_creatable_folder(p, what, given)
    _check_free_space(p, expected_bytes, what, given)
    return p


def make_folders(folder: Path) -> list[Path]:
    """``mkdir -p folder``; return the folders this call created, outermost first (for :func:`remove_folders`).

    A folder that another process made at the same moment is not counted: it is not ours to remove.
    """
    missing = []
    p = Path(folder)
    while not os.path.lexists(p) and p != p.parent:
        missing.append(p)
        p = p.parent
    made = []
    for d in reversed(missing):
        try:
            d.mkdir()
        except FileExistsError:
            if not d.is_dir():
                raise
        else:
            made.append(d)
    return made


def remove_folders(created: list[Path]) -> None:
    """Remove folders :func:`make_folders` created, innermost first, where still empty."""
    for d in reversed(created):
        try:
            d.rmdir()
        except OSError:
            break


# -- writing ---------------------------------------------------------------------------------


def _open_stream(dest: Destination):
    """A raw non-blocking fd on a FIFO (waiting at most STREAM_WAIT_S for a reader) or a device."""
    path = dest.target
    if stat.S_ISFIFO(os.stat(path).st_mode):
        deadline = time.monotonic() + STREAM_WAIT_S
        while True:
            try:
                return os.open(path, os.O_WRONLY | os.O_NONBLOCK)
            except OSError as e:
                if e.errno != errno.ENXIO:  # ENXIO: no reader yet
                    raise
            if time.monotonic() > deadline:
                raise OutputError(f"{dest.label}: no process opened the FIFO for reading within {STREAM_WAIT_S:g} s")
            time.sleep(0.02)
    return os.open(path, os.O_WRONLY | os.O_NONBLOCK)


def _write_all(fd: int, data, dest: Destination) -> None:
    view = memoryview(data)
    while view:
        try:
            n = os.write(fd, view[: 1 << 20])
        except BlockingIOError:
            _, ready, _ = select.select([], [fd], [], STREAM_WAIT_S)
            if not ready:
                raise OutputError(f"{dest.label}: the reader took no data for {STREAM_WAIT_S:g} s") from None
            continue
        view = view[n:]


def _copy_file_to(src: Path, dest: Destination) -> None:
    """Copy a finished temporary file to a stream or to standard output."""
    if dest.kind == "stdout":
        out = sys.stdout.buffer if hasattr(sys.stdout, "buffer") else None
        with open(src, "rb") as f:
            if out is None:  # a text-only stream (tests)
                sys.stdout.write(f.read().decode("utf-8", errors="replace"))
            else:
                shutil.copyfileobj(f, out, _COPY_BLOCK)
        sys.stdout.flush()
        return
    fd = _open_stream(dest)
    try:
        with open(src, "rb") as f:
            while block := f.read(_COPY_BLOCK):
                _write_all(fd, block, dest)
    finally:
        os.close(fd)


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _usual_mode(path: Path) -> None:
    mask = os.umask(0)
    os.umask(mask)
    with contextlib.suppress(OSError):
        os.chmod(path, 0o666 & ~mask)


class Staging:
    """Temporary files for one or more outputs, put in place together by :meth:`commit`.

    ``path(dest)`` gives the temporary path to write ``dest``'s content to
    (beside a regular file; in a private temporary folder for streams and
    standard output).  ``commit()`` renames every regular file into place
    (after they are all complete and synced) and copies the others;
    ``discard()`` (or leaving the ``with`` block on an error) removes every
    temporary file and any folder made for them.  OS errors become
    :class:`OutputError` naming the output.
    """

    def __init__(self) -> None:
        self._items: list[tuple[Destination, Path]] = []
        self._created: list[Path] = []
        self._private: Path | None = None

    def path(self, dest, **check) -> Path:
        dest = destination(dest, **check)
        if dest.kind == "file":
            try:
                self._created += make_folders(dest.target.parent)
            except OSError as e:
                raise OutputError(f"{dest.label}: cannot create folder {str(dest.target.parent)!r}: {_reason(e)}") from None
            tmp = temp_path_beside(dest.target)
        else:
            if self._private is None:
                self._private = Path(tempfile.mkdtemp(prefix="dicetrace-"))
            tmp = self._private / f"{len(self._items)}{Path(dest.given).suffix}"
        self._items.append((dest, tmp))
        return tmp

    def commit(self) -> None:
        ok = False
        try:
            for dest, tmp in self._items:
                if dest.kind == "file":
                    self._guard(dest, _fsync, tmp)
            for dest, tmp in self._items:
                if dest.kind == "file":
                    self._guard(dest, os.replace, tmp, dest.target)
                    _usual_mode(dest.target)
                else:
                    self._guard(dest, _copy_file_to, tmp, dest)
            ok = True
        finally:
            self._cleanup(keep_folders=ok)  # on failure: the folders made for the outputs go too, where empty

    def discard(self) -> None:
        self._cleanup(keep_folders=False)

    @staticmethod
    def _guard(dest: Destination, fn, *args) -> None:
        try:
            fn(*args)
        except OutputError:
            raise
        except OSError as e:
            raise OutputError(f"cannot write {dest.label}: {_reason(e)}") from None

    def fail(self, dest: Destination, e: BaseException) -> OutputError:
        """The :class:`OutputError` for an error while writing ``dest``'s temporary file."""
        return e if isinstance(e, OutputError) else OutputError(f"cannot write {dest.label}: {_reason(e)}")

    def _cleanup(self, keep_folders: bool) -> None:
        for dest, tmp in self._items:
            with contextlib.suppress(OSError):
                remove_quietly(tmp)
        self._items = []
        if self._private is not None:
            shutil.rmtree(self._private, ignore_errors=True)
            self._private = None
        if not keep_folders:
            remove_folders(self._created)
        self._created = []

    def __enter__(self) -> "Staging":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()


@contextlib.contextmanager
def staged(dest, **check):
    """Yield a temporary path for one output; put it in place on success only (see :class:`Staging`).

    An OS error raised inside the block (say, a full disk) becomes an
    :class:`OutputError` naming the output.
    """
    st = Staging()
    tmp = st.path(dest, **check)
    d = st._items[-1][0]
    try:
        yield tmp
    except OSError as e:
        st.discard()
        raise st.fail(d, e) from None
    except BaseException:
        st.discard()
        raise
    st.commit()


def write_bytes(dest, data: bytes, **check) -> Destination:
    """Write ``data`` to an output: atomically to a regular file, directly to a stream or standard output."""
    dest = destination(dest, **check)
    if dest.kind == "file":
        with staged(dest) as tmp:
            with open(tmp, "wb") as f:
                f.write(data)
        return dest
    try:
        if dest.kind == "stdout":
            out = sys.stdout.buffer if hasattr(sys.stdout, "buffer") else None
            if out is None:
                sys.stdout.write(data.decode("utf-8", errors="replace"))
            else:
                out.write(data)
            sys.stdout.flush()
        else:
            fd = _open_stream(dest)
            try:
                _write_all(fd, data, dest)
            finally:
                os.close(fd)
    except OutputError:
        raise
    except OSError as e:
        raise OutputError(f"cannot write {dest.label}: {_reason(e)}") from None
    return dest
