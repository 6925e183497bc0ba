"""IC spaces of full starting states: each throw its own velocity, angular momentum, orientation and height.

A slice's IC is 6 numbers, thrown from the preset's start (face 3 down, at
``z0_cm``).  A hand throw is more: the die leaves the hand turned anyhow, at
some height.  Two spaces hold such throws, and a scan runs both the same way
(``simulate_batch(ics, orientations=, heights_cm=)``, one chunk at a time,
resumable, on Dask like any scan); their rows carry the pose columns
``qx, qy, qz, qw, z0_cm``:

:class:`HandThrows`
    ``n`` throws drawn from a hand-throw model (:class:`dicetrace.throws.HandThrow`:
    ``casual``, ``gentle``, ``vigorous``), reproducibly from ``seed``, in
    blocks of ``POSE_BLOCK`` throws: block b is ``model.sample(POSE_BLOCK,
    config, [seed, b])``, so any range of throws is drawn again, bit for bit,
    whatever the chunking (the same scheme as a random
    :class:`~dicetrace.ics.Sample`).  These are not the throws ``dicetrace
    throw --seed`` draws for the same seed (it draws all n from one stream);
    scan its table (:class:`ThrowTable`) to run those.
:class:`ThrowTable`
    The rows of a throw table: a Parquet file with the columns ``vx, vy, vz,
    Lx, Ly, Lz, qx, qy, qz, qw, z0_cm`` (what ``dicetrace throw`` writes, or any
    rolls table with a pose) or a CSV file with the same header.  The
    definition holds the file's path and SHA-256: a resume reads the same
    throws, and a file changed since is refused (Dask workers read the file
    at that path: on a cluster of several machines it must lie on a shared
    file system).  L is in the convention the
    Parquet file's dicetrace metadata names, a CSV's in the scan preset's.

``ic_id`` numbers the throws 0..n-1 (a table's rows in their order).  A
throw's pose is stored as it was given (the quaternion, before it is made a
matrix): ``dicetrace record --rolls SCAN --ic-id N`` turns it into the same
matrix and replays the row bit for bit.
"""

from __future__ import annotations

import csv
import functools
import hashlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from dicetrace.ics import IcBlock, _check_range as _range
from dicetrace.params import L_CONVENTIONS, ConfigError, _show
from dicetrace.throws import THROWS, HandThrow
from dicetrace.windows import _is_count as _count

#: Throws drawn per block of a :class:`HandThrows` space (each block from its own seed ``[seed, block]``).
POSE_BLOCK = 4096
#: The columns of a throw table: the IC, the orientation quaternion (x, y, z, w; world from body) and the start
#: height of the centre of mass.
THROW_COLUMNS = ("vx", "vy", "vz", "Lx", "Ly", "Lz", "qx", "qy", "qz", "qw", "z0_cm")
#: The space kinds this module defines (a definition dict's ``space.kind``).
POSED_KINDS = ("throws", "throw-table")


@dataclass
class PosedBlock(IcBlock):
    """A contiguous range of a posed space's throws: an :class:`~dicetrace.ics.IcBlock` (``index`` all -1 and
    ``coords`` all NaN: no grid, no slice) with each throw's ``orientations`` (m, 4), quaternions x, y, z, w, and
    ``heights_cm`` (m,)."""

    orientations: np.ndarray = None
    heights_cm: np.ndarray = None


def _block(start: int, ics, orientations, heights) -> PosedBlock:
    m = len(ics)
    return PosedBlock(np.arange(start, start + m, dtype=np.int64), np.full((m, 3), -1, dtype=np.int32),
                      np.full((m, 3), np.nan), np.ascontiguousarray(ics, dtype=np.float64),
                      np.ascontiguousarray(orientations, dtype=np.float64),
                      np.ascontiguousarray(heights, dtype=np.float64))


@dataclass(frozen=True)
class HandThrows:
    """``n`` hand throws of the model ``model`` (a :class:`~dicetrace.throws.HandThrow` or its name), seeded by
    ``seed``: see the module docstring.  The draws need the die (its inertia turns the spin into L, its shape
    keeps it above the table): :meth:`block` takes the scan's configuration."""

    model: HandThrow
    n: int
    seed: int = 0
    kind: str = field(default="throws", init=False)

    def __post_init__(self) -> None:
        model = self.model
        if isinstance(model, str):
            if model not in THROWS:
                raise ConfigError("throw", f"unknown throw model {model!r} (choose from {', '.join(THROWS)})")
            model = THROWS[model]
        if not isinstance(model, HandThrow):
            raise TypeError(f"model must be a dicetrace.throws.HandThrow or its name, not {type(model).__name__}")
        object.__setattr__(self, "model", model)
        if not _count(self.n) or self.n < 1:
            raise ConfigError("n", f"the number of throws n must be an integer >= 1, got {_show(self.n)}")
        object.__setattr__(self, "n", int(self.n))
        if not _count(self.seed) or not 0 <= self.seed < 2**63:
            raise ConfigError("seed", f"the throws' seed must be an integer in [0, 2**63), got {_show(self.seed)}")
        object.__setattr__(self, "seed", int(self.seed))

    ndim = 0
    slice = None

    @property
    def size(self) -> int:
        return self.n

    def l_convention(self, config) -> str:
        """The L convention of the ICs :meth:`block` gives: the preset's (the model draws them in it)."""
        return config.preset.l_convention

    def block(self, start: int, stop: int, config) -> PosedBlock:
        start, stop = _range(start, stop, self.n)
        parts = []
        for b in range(start // POSE_BLOCK, -(-stop // POSE_BLOCK)):
            t = _drawn(self.model, self.seed, b, config)
            lo, hi = max(start, b * POSE_BLOCK) - b * POSE_BLOCK, min(stop, (b + 1) * POSE_BLOCK) - b * POSE_BLOCK
            parts.append((t.ics[lo:hi], t.orientations[lo:hi], t.heights_cm[lo:hi]))
        if not parts:
            return _block(start, np.zeros((0, 6)), np.zeros((0, 4)), np.zeros(0))
        return _block(start, *(np.concatenate(p) for p in zip(*parts)))

    def check(self, config) -> None:
        """Nothing to check: every throw the model draws starts above the table."""

    def to_dict(self) -> dict:
        return {"kind": "throws", "model": asdict(self.model), "n": self.n, "seed": self.seed, "block": POSE_BLOCK}

    @classmethod
    def from_dict(cls, d: dict) -> "HandThrows":
        if d.get("block", POSE_BLOCK) != POSE_BLOCK:
            raise ValueError(f"a throws space drawn in blocks of {d.get('block')!r}, this version draws {POSE_BLOCK}")
        m = dict(d["model"])
        model = HandThrow(**{k: tuple(v) if isinstance(v, list) else v for k, v in m.items()})
        return cls(model, d["n"], d.get("seed", 0))


@functools.lru_cache(maxsize=8)
def _drawn(model: HandThrow, seed: int, b: int, config):
    """Block ``b`` of the throws of ``model`` with seed ``seed``, of the die of ``config`` (its body and L convention:
    a chunk of 8192 draws two blocks, and a chunk's check draws them again: the last few are kept)."""
    return model.sample(POSE_BLOCK, config, [seed, b])


@dataclass(frozen=True)
class ThrowTable:
    """The throws of a table file (see the module docstring): ``path`` (absolute), its ``sha256``, its rows ``n``
    and the ``l_convention`` of its L.  :func:`read_throw_table` makes one from a file (reading and checking
    it); :meth:`block` reads the file once per process, and refuses it if it has changed."""

    path: str
    sha256: str
    n: int
    l_convention: str = "physical"
    kind: str = field(default="throw-table", init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.path, str) or not self.path:
            raise ValueError(f"path must be a file's path, got {self.path!r}")
        if not _count(self.n) or self.n < 1:
            raise ValueError(f"a throw table needs at least one row, got n = {self.n!r}")
        object.__setattr__(self, "n", int(self.n))
        if self.l_convention not in L_CONVENTIONS:
            raise ValueError(f"l_convention must be 'program' or 'physical', got {self.l_convention!r}")

    ndim = 0
    slice = None

    @property
    def size(self) -> int:
        return self.n

    def block(self, start: int, stop: int, config=None) -> PosedBlock:
        start, stop = _range(start, stop, self.n)
        cols = _table_columns(self.path, self.sha256)
        return _block(start, cols[start:stop, :6], cols[start:stop, 6:10], cols[start:stop, 10])

    def check(self, config) -> None:
        """ValueError naming the first row whose die would start below the table (its lowest corner, turned by its
        orientation, below height 0) with ``config``'s die."""
        from dicetrace.ic_arrays import validate_orientations

        cols = _table_columns(self.path, self.sha256)
        offsets = config.initial_offsets()
        for a in range(0, self.n, 1 << 16):
            b = min(self.n, a + (1 << 16))
            rots = validate_orientations(cols[a:b, 6:10], b - a)
            lowest = cols[a:b, 10] + np.einsum("kj,nj->nk", offsets, rots[:, 2, :]).min(axis=1)
            bad = np.flatnonzero(lowest < 0.0)
            if len(bad):
                i = a + int(bad[0])
                raise ValueError(f"row {i} starts below the table with this die: its lowest corner is at "
                                 f"{lowest[bad[0]]:.6g} cm (z0_cm {cols[i, 10]:.6g}); raise its z0_cm")

    def to_dict(self) -> dict:
        return {"kind": "throw-table", "path": self.path, "sha256": self.sha256, "n": self.n,
                "l_convention": self.l_convention}

    @classmethod
    def from_dict(cls, d: dict) -> "ThrowTable":
        return cls(d["path"], d["sha256"], d["n"], d.get("l_convention", "physical"))


ThrowSpace = HandThrows | ThrowTable


def space_l_convention(space, config) -> str:
    """The L convention of the ICs a posed space gives."""
    return space.l_convention(config) if isinstance(space, HandThrows) else space.l_convention


def posed_from_dict(d: dict):
    """Inverse of ``HandThrows/ThrowTable.to_dict``."""
    kind = d.get("kind")
    if kind == "throws":
        return HandThrows.from_dict(d)
    if kind == "throw-table":
        return ThrowTable.from_dict(d)
    raise ValueError(f"unknown posed space kind {kind!r}")


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _read_columns(path: Path) -> tuple[np.ndarray, str | None]:
    """The throw columns of a table file (n, 11) and the L convention its metadata names (None: it names none).
    ValueError naming what is wrong."""
    with open(path, "rb") as f:
        parquet = f.read(4) == b"PAR1"
    if parquet:
        import pyarrow as pa
        import pyarrow.parquet as pq

        try:
            schema = pq.read_schema(path)
            missing = [c for c in THROW_COLUMNS if c not in schema.names]
            if missing:
                raise ValueError(f"it has no column{'s' if len(missing) > 1 else ''} {', '.join(missing)} (a throw "
                                 f"table has {', '.join(THROW_COLUMNS)}: dicetrace throw writes one)")
            table = pq.read_table(path, columns=list(THROW_COLUMNS))
        except (pa.ArrowException, OSError) as e:
            raise ValueError(f"it is not a readable Parquet file ({' '.join(str(e).split())[:160]})") from None
        conv = None
        from dicetrace.tables import METADATA_KEY

        import json

        raw = (schema.metadata or {}).get(METADATA_KEY)
        if raw is not None:
            try:
                conv = json.loads(raw).get("l_convention")
            except (ValueError, AttributeError):
                conv = None
        try:
            cols = np.stack([table.column(c).to_numpy(zero_copy_only=False).astype(np.float64)
                             for c in THROW_COLUMNS], axis=1)
        except (pa.ArrowException, TypeError, ValueError) as e:
            raise ValueError(f"its throw columns are not numbers ({' '.join(str(e).split())[:120]})") from None
        return cols, conv if conv in L_CONVENTIONS else None
    try:
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            header = reader.fieldnames or []
            missing = [c for c in THROW_COLUMNS if c not in header]
            if missing:
                raise ValueError(f"it is neither Parquet nor a CSV file with the columns {', '.join(THROW_COLUMNS)} "
                                 f"(missing: {', '.join(missing)})")
            rows = [[float(r[c]) for c in THROW_COLUMNS] for r in reader]
    except UnicodeDecodeError:
        raise ValueError(f"it is neither Parquet nor a CSV file with the columns {', '.join(THROW_COLUMNS)}") from None
    except (TypeError, ValueError) as e:
        if "columns" in str(e) or "missing" in str(e):
            raise
        raise ValueError("a row has a value that is not a number") from None
    return np.array(rows, dtype=np.float64).reshape(-1, len(THROW_COLUMNS)), None


def _checked(cols: np.ndarray) -> np.ndarray:
    if len(cols) == 0:
        raise ValueError("it has no rows")
    bad = np.flatnonzero(~np.isfinite(cols).all(axis=1))
    if len(bad):
        i = int(bad[0])
        names = ", ".join(c for c, ok in zip(THROW_COLUMNS, np.isfinite(cols[i])) if not ok)
        raise ValueError(f"row {i} has a value that is not a finite number ({names})")
    norm = np.linalg.norm(cols[:, 6:10], axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > 1e-6)
    if len(bad):
        i = int(bad[0])
        raise ValueError(f"row {i}'s orientation qx, qy, qz, qw has norm {norm[i]:.9g}, not 1 (a unit quaternion)")
    return np.ascontiguousarray(cols)


def _table_columns(path: str, sha256: str) -> np.ndarray:
    """The checked throw columns of the file ``path``, read once per process while the file stays as it was (its
    size and modification time); ValueError if its content is not the one of SHA-256 ``sha256`` any more."""
    try:
        st = Path(path).stat()
    except OSError as e:
        raise ValueError(f"cannot read the throw table {path!r}: {e.strerror or e}") from None
    return _columns_of(path, sha256, st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=2)
def _columns_of(path: str, sha256: str, size: int, mtime_ns: int) -> np.ndarray:
    p = Path(path)
    try:
        digest = _sha256(p)
    except OSError as e:
        raise ValueError(f"cannot read the throw table {path!r}: {e.strerror or e}") from None
    if digest != sha256:
        raise ValueError(f"the throw table {path!r} has changed since the scan began (its SHA-256 is "
                         f"{digest[:12]}…, the scan's {sha256[:12]}…): restore it, or scan it into another folder")
    cols, _ = _read_columns(p)
    cols = _checked(cols)
    cols.setflags(write=False)
    return cols


def read_throw_table(path, default_l_convention: str) -> ThrowTable:
    """A :class:`ThrowTable` of the file ``path`` (read and checked now: every value finite, every quaternion a
    unit one), its L in the convention its dicetrace metadata names, else ``default_l_convention`` (a CSV's:
    the scan preset's).  ValueError naming what is wrong."""
    p = Path(path).absolute()
    if not p.is_file():
        raise ValueError("is not a file")
    try:
        digest = _sha256(p)
        cols, conv = _read_columns(p)
    except OSError as e:
        raise ValueError(f"cannot be read: {e.strerror or e}") from None
    cols = _checked(cols)
    return ThrowTable(str(p), digest, len(cols), conv or default_l_convention)
