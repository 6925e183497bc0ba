"""Rerun streaming sinks: send a recording to a viewer (``--spawn``), a gRPC server (``--connect``) or serve it (``--serve``).

The sinks of rerun's own example scripts (``rr.script_add_args``): the same
``log(rec)`` function and default blueprint as the ``.rrd`` file
(:func:`dicetrace.sinks.rerun.roll_logger`), sent through
``RecordingStream.connect_grpc`` / ``rerun.spawn`` / ``serve_grpc`` +
``serve_web_viewer`` instead of a binary stream.  Every wait is bounded:
the target is probed (TCP, :data:`PROBE_TIMEOUT_S`) before anything is
computed, and the final flush has :data:`FLUSH_TIMEOUT_S`.
"""

from __future__ import annotations

import socket
import sys
import time
import urllib.parse
from dataclasses import dataclass
from pathlib import Path

#: The SDK's default gRPC address (``rerun+http://127.0.0.1:9876/proxy``).
DEFAULT_PORT = 9876
DEFAULT_URL = f"rerun+http://127.0.0.1:{DEFAULT_PORT}/proxy"
DEFAULT_WEB_PORT = 9090
SCHEMES = ("rerun", "rerun+http", "rerun+https")

#: Longest wait for a TCP connection to the target when probing it, s.
PROBE_TIMEOUT_S = 2.0
#: Longest wait for the recording to reach the target, s.
FLUSH_TIMEOUT_S = 60.0
#: Longest wait for a spawned viewer to start listening, s.
SPAWN_TIMEOUT_S = 20.0


class StreamError(ValueError):
    """A streaming sink could not be reached or fed (reported as one line, exit 2)."""


@dataclass(frozen=True)
class Target:
    url: str
    host: str
    port: int


def parse_url(text: str | None) -> Target:
    """A gRPC address: a port (``9876``), or a URL ``rerun+http://HOST:PORT/proxy`` (``rerun://``, ``rerun+https://``).

    Raises :class:`ValueError` naming what is wrong.
    """
    if text is None or text == "":
        text = DEFAULT_URL
    text = text.strip()
    if text.isdigit():
        port = int(text)
        if not 0 < port < 65536:
            raise ValueError(f"port {port} is out of range 1..65535")
        return Target(f"rerun+http://127.0.0.1:{port}/proxy", "127.0.0.1", port)
    u = urllib.parse.urlsplit(text)
    if u.scheme not in SCHEMES:
        raise ValueError(f"{text!r} is neither a port nor a URL of scheme {', '.join(s + '://' for s in SCHEMES)}")
    if u.path.rstrip("/") != "/proxy":
        raise ValueError(f"{text!r}: the URL's path must be /proxy (e.g. {DEFAULT_URL})")
    try:
        port = u.port
    except ValueError as e:
        raise ValueError(f"{text!r}: {e}") from None
    if not u.hostname:
        raise ValueError(f"{text!r} has no host")
    if port is None:
        port = 443 if u.scheme == "rerun+https" else DEFAULT_PORT
    return Target(text, u.hostname, port)


def reachable(host: str, port: int, timeout_s: float = PROBE_TIMEOUT_S) -> bool:
    """Whether a TCP connection to host:port opens within ``timeout_s``."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False


def port_free(port: int, host: str = "0.0.0.0") -> bool:
    """Whether ``port`` can be bound (for ``--serve``)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((host, port))
            return True
        except OSError:
            return False


def check_connect(url: str | None) -> Target:
    """The parsed ``--url`` of ``--connect``, refused (StreamError) when nothing listens there."""
    target = parse_url(url)
    if not reachable(target.host, target.port):
        raise StreamError(
            f"--connect {target.url}: no Rerun viewer or gRPC server answers there within {PROBE_TIMEOUT_S:g} s "
            "(start one with `rerun`, or use --spawn or --serve)"
        )
    return target


def check_serve(grpc_port: int, web_port: int) -> None:
    """Refuse (StreamError) ``--serve`` ports that are taken."""
    for what, port in (("gRPC", grpc_port), ("web viewer", web_port)):
        if not port_free(port):
            raise StreamError(f"--serve: the {what} port {port} is already in use")


def viewer_executable() -> str | None:
    """The ``rerun`` CLI beside this interpreter (a venv not on PATH), else None (the SDK searches PATH)."""
    p = Path(sys.executable).parent / "rerun"
    return str(p) if p.exists() else None


def web_viewer_url(web_port: int, grpc_url: str) -> str:
    return f"http://127.0.0.1:{web_port}/?url={urllib.parse.quote(grpc_url, safe='')}"


class Stream:
    """One live recording stream to a sink; :meth:`send` logs and flushes, :meth:`close` disconnects."""

    def __init__(self, blueprint, *, application_id: str = "dicetrace") -> None:
        import rerun as rr

        self.rr = rr
        self.blueprint = blueprint
        self.rec = rr.RecordingStream(application_id)
        self.web_url: str | None = None
        self.grpc_url: str | None = None

    def connect(self, target: Target) -> None:
        self.grpc_url = target.url
        self.rec.connect_grpc(target.url, default_blueprint=self.blueprint)

    def spawn(self, port: int = DEFAULT_PORT) -> None:
        """Start a viewer (or reuse one already listening on ``port``) and connect to it."""
        from rerun.sinks import spawn

        try:
            spawn(port=port, connect=True, recording=self.rec, executable_path=viewer_executable(),
                  default_blueprint=self.blueprint)
        except Exception as e:  # the SDK raises RuntimeError (no executable, ...)
            raise StreamError(f"--spawn: could not start the Rerun viewer: {e}") from None
        self.grpc_url = f"rerun+http://127.0.0.1:{port}/proxy"
        deadline = time.monotonic() + SPAWN_TIMEOUT_S
        while not reachable("127.0.0.1", port, 0.5):
            if time.monotonic() > deadline:
                raise StreamError(f"--spawn: the Rerun viewer did not start listening on port {port} within "
                                  f"{SPAWN_TIMEOUT_S:g} s (is there a display?)")
            time.sleep(0.2)

    def serve(self, grpc_port: int = DEFAULT_PORT, web_port: int = DEFAULT_WEB_PORT) -> str:
        """Serve the recording over gRPC and the web viewer over HTTP; returns the web viewer's URL."""
        try:
            self.grpc_url = self.rec.serve_grpc(grpc_port=grpc_port, default_blueprint=self.blueprint)
            self.rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=self.grpc_url)
        except Exception as e:
            raise StreamError(f"--serve: {e}") from None
        self.web_url = web_viewer_url(web_port, self.grpc_url)
        return self.web_url

    def send(self, log, timeout_s: float = FLUSH_TIMEOUT_S) -> None:
        """``log(self.rec)`` and wait (at most ``timeout_s``) until it has reached the sink."""
        log(self.rec)
        try:
            self.rec.flush(timeout_sec=timeout_s)
        except Exception as e:  # RuntimeError: the connection failed or timed out
            raise StreamError(f"could not send the recording to {self.grpc_url}: {e}") from None

    def close(self) -> None:
        try:
            self.rec.disconnect()
        except Exception:  # pragma: no cover - nothing more to report
            pass


def wait_serving(seconds: float | None, *, sleep=time.sleep) -> str:
    """Keep serving for ``seconds`` (None: until Ctrl-C); returns why it stopped ("time" or "interrupted")."""
    deadline = None if seconds is None else time.monotonic() + seconds
    try:
        while deadline is None or time.monotonic() < deadline:
            sleep(0.2 if deadline is None else max(0.0, min(0.2, deadline - time.monotonic())))
    except KeyboardInterrupt:
        return "interrupted"
    return "time"
