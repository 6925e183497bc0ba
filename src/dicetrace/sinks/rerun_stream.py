"""Rerun streaming sinks: send a recording to a viewer (``--spawn``), a gRPC server (``--connect``) or serve it (``--serve``).

The sinks of rerun's own example scripts (``rr.script_add_args``): the same
``log(rec)`` function and default blueprint as the ``.rrd`` file
(:func:`dicetrace.sinks.rerun.roll_logger`), sent through
``RecordingStream.connect_grpc``, a viewer started here, or a gRPC server
(``rerun.GrpcServerSink``) plus Rerun's web viewer over HTTP.

Servers listen on :data:`DEFAULT_BIND` (127.0.0.1: this machine only) unless
asked for another address: the gRPC server is the SDK's, bound there; the web
viewer is rerun-notebook's build of Rerun's viewer, served by
:class:`dicetrace.sinks.rerun_web.WebViewerServer` on the same address (the SDK's
own web server listens on every interface and has no bind option in 0.41).

Every wait is bounded and every failure is one line (:class:`StreamError`):
a ``--connect`` target must answer an HTTP/2 handshake within
:data:`PROBE_TIMEOUT_S` before anything is computed (a refused port, a peer
that accepts and never answers and one that answers garbage are all refused
there), the final flush has :data:`FLUSH_TIMEOUT_S`, and a spawned viewer that
exits or does not listen within :data:`SPAWN_TIMEOUT_S` is reported with its
own error line.  The SDK's Rust log lines are silenced (:func:`quiet_sdk_logs`).
"""

from __future__ import annotations

import ipaddress
import os
import shutil
import socket
import ssl
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
from dataclasses import dataclass
from pathlib import Path

from dicetrace.sinks.rerun_web import WebViewerError, WebViewerServer

#: The SDK's default gRPC address (``rerun+http://127.0.0.1:9876/proxy``).
DEFAULT_PORT = 9876
DEFAULT_URL = f"rerun+http://127.0.0.1:{DEFAULT_PORT}/proxy"
DEFAULT_WEB_PORT = 9090
#: Where ``--serve`` and ``--spawn`` listen unless ``--bind`` says otherwise: this machine only.
DEFAULT_BIND = "127.0.0.1"
SCHEMES = ("rerun", "rerun+http", "rerun+https")

#: Longest wait for the target to open a connection and answer the HTTP/2 handshake, s.
PROBE_TIMEOUT_S = 2.0
#: Longest wait for the recording to reach the target, s.
FLUSH_TIMEOUT_S = 60.0
#: Longest wait for a disconnect when nothing was sent (a server shutting down), and the least one ever gets, s.
CLOSE_TIMEOUT_S = 10.0
CLOSE_MIN_S = 2.0
#: Longest wait for a spawned viewer to start listening, s.
SPAWN_TIMEOUT_S = 20.0
#: How long a viewer started here is watched after the recording reached it (it may fail to open its window), s.
VIEWER_WATCH_S = 1.0
#: Longest wait for a display server (X11 or Wayland socket) to accept a connection, s.
DISPLAY_TIMEOUT_S = 1.0

#: The client preface of HTTP/2 (RFC 9113 §3.4) and an empty SETTINGS frame: what a gRPC client sends first.
H2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
H2_SETTINGS = 4


class StreamError(ValueError):
    """A streaming sink could not be reached or fed (reported as one line, exit 2)."""


def quiet_sdk_logs() -> None:
    """Silence the Rust log lines of the rerun SDK (``RUST_LOG=off``) unless the user set ``RUST_LOG``.

    Call before rerun is imported: its logger reads the variable once.  Failures are
    reported by dicetrace itself, one line each.
    """
    os.environ.setdefault("RUST_LOG", "off")


@dataclass(frozen=True)
class Target:
    url: str
    host: str
    port: int
    tls: bool = False


def url_host(host: str) -> str:
    """``host`` as it goes into a URL (an IPv6 address in brackets)."""
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


def parse_bind(text: str | None) -> str:
    """The address for ``--bind``: an IPv4 or IPv6 address (``127.0.0.1``, ``0.0.0.0`` for every interface, ``::1``).

    Raises :class:`ValueError` naming what is wrong.
    """
    if text is None:
        return DEFAULT_BIND
    raw = text.strip()
    if raw == "localhost":
        return DEFAULT_BIND
    try:
        return str(ipaddress.ip_address(raw.strip("[]")))
    except ValueError:
        raise ValueError(f"{text!r} is not an IP address (e.g. 127.0.0.1, this machine only; 0.0.0.0, every "
                         "interface)") from None


def is_loopback(host: str) -> bool:
    return ipaddress.ip_address(host.strip("[]")).is_loopback


def parse_url(text: str | None) -> Target:
    """A gRPC address: a port (``9876``), or a URL ``rerun+http://HOST:PORT/proxy`` (``rerun+https://``, or its
    alias ``rerun://``: TLS).

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
    tls = u.scheme in ("rerun", "rerun+https")  # rerun:// is Rerun's alias of rerun+https://
    if port is None:
        port = 443 if tls else DEFAULT_PORT
    return Target(text, u.hostname, port, tls=tls)


def reachable(host: str, port: int, timeout_s: float = PROBE_TIMEOUT_S) -> bool:
    """Whether a TCP connection to host:port opens within ``timeout_s``."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False


def _recv_exactly(sock, n: int, deadline: float) -> bytes:
    data = b""
    while len(data) < n:
        sock.settimeout(max(0.01, deadline - time.monotonic()))
        chunk = sock.recv(n - len(data))
        if not chunk:
            raise ConnectionError("the connection was closed")
        data += chunk
    return data


def probe_grpc(target: Target, timeout_s: float = PROBE_TIMEOUT_S) -> str | None:
    """Why ``target`` is not a gRPC server (None when it is one): an HTTP/2 handshake within ``timeout_s``.

    A gRPC server answers the client preface with a SETTINGS frame (RFC 9113 §3.4):
    a closed port, a peer that accepts and stays silent and one that answers
    anything else are all told apart here, before any work, in bounded time.
    """
    deadline = time.monotonic() + timeout_s
    try:
        raw = socket.create_connection((target.host, target.port), timeout=timeout_s)
    except socket.timeout:
        return f"no connection within {timeout_s:g} s"
    except ConnectionRefusedError:
        return "the connection was refused"
    except OSError as e:
        return e.strerror or str(e) or type(e).__name__
    try:
        with raw:
            sock = raw
            if target.tls:
                ctx = ssl.create_default_context()
                ctx.set_alpn_protocols(["h2"])
                raw.settimeout(max(0.01, deadline - time.monotonic()))
                sock = ctx.wrap_socket(raw, server_hostname=target.host)
            sock.settimeout(max(0.01, deadline - time.monotonic()))
            sock.sendall(H2_PREFACE)
            head = _recv_exactly(sock, 9, deadline)
    except socket.timeout:
        return f"it accepted the connection but did not answer within {timeout_s:g} s"
    except ssl.SSLError as e:
        return f"TLS failed ({e.reason or e})"
    except OSError as e:
        return e.strerror or str(e) or type(e).__name__
    if head[3] != H2_SETTINGS:
        return "it answered, but not as an HTTP/2 (gRPC) server"
    return None


def port_free(port: int, host: str = DEFAULT_BIND) -> bool:
    """Whether ``port`` can be bound on ``host`` (for ``--serve``)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        try:
            s.bind((host.strip("[]"), port))
            return True
        except OSError:
            return False


def check_connect(url: str | None) -> Target:
    """The parsed ``--url`` of ``--connect``, refused (StreamError) unless a gRPC server answers there."""
    target = parse_url(url)
    why = probe_grpc(target)
    if why is not None:
        raise StreamError(
            f"--connect {target.url}: no Rerun viewer or gRPC server answers there ({why}; start one with `rerun`, "
            "or use --spawn or --serve)"
        )
    return target


def check_serve(grpc_port: int, web_port: int, host: str = DEFAULT_BIND) -> None:
    """Refuse (StreamError) ``--serve`` ports that are taken on ``host``, or the same port twice."""
    if grpc_port == web_port:
        raise StreamError(f"--serve: --port and --web-port are both {grpc_port}: give them different ports")
    for what, port in (("gRPC", grpc_port), ("web viewer", web_port)):
        if not port_free(port, host):
            raise StreamError(f"--serve: the {what} port {port} is already in use on {host}")


def viewer_executable() -> str | None:
    """The ``rerun`` CLI beside this interpreter (a venv not on PATH), else the one on PATH, else None."""
    p = Path(sys.executable).parent / "rerun"
    return str(p) if p.exists() else shutil.which("rerun")


def display_problem(env=None) -> str | None:
    """Why no window can be opened here (None when a display server accepts a connection).

    X11 (``DISPLAY``: its socket or TCP port) or Wayland (``WAYLAND_DISPLAY``: its socket),
    each given :data:`DISPLAY_TIMEOUT_S`; on other systems than Linux, None.
    """
    env = os.environ if env is None else env
    if not sys.platform.startswith("linux"):
        return None
    wayland, x11 = env.get("WAYLAND_DISPLAY"), env.get("DISPLAY")
    if not wayland and not x11:
        return "DISPLAY and WAYLAND_DISPLAY are unset"
    tried = []
    if wayland:
        path = wayland if wayland.startswith("/") else os.path.join(env.get("XDG_RUNTIME_DIR") or "/nonexistent", wayland)
        if _unix_connects(path):
            return None
        tried.append(f"no Wayland compositor at WAYLAND_DISPLAY={wayland}")
    if x11:
        host, _, rest = x11.rpartition(":")
        number = rest.split(".")[0]
        ok = False
        if number.isdigit():
            if host in ("", "unix"):
                ok = _unix_connects(f"/tmp/.X11-unix/X{number}") or _unix_connects(f"\0/tmp/.X11-unix/X{number}")
            else:
                try:
                    with socket.create_connection((host.strip("[]"), 6000 + int(number)), timeout=DISPLAY_TIMEOUT_S):
                        ok = True
                except OSError:
                    ok = False
        if ok:
            return None
        tried.append(f"no X server answers at DISPLAY={x11}")
    return ", ".join(tried)


def _unix_connects(path: str) -> bool:
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.settimeout(DISPLAY_TIMEOUT_S)
            s.connect(path)
            return True
    except OSError:
        return False


def web_viewer_url(host: str, web_port: int, grpc_url: str) -> str:
    return f"http://{url_host(host)}:{web_port}/?url={urllib.parse.quote(grpc_url, safe='')}"


class Stream:
    """One live recording stream to a sink; :meth:`send` logs and flushes, :meth:`close` disconnects."""

    def __init__(self, blueprint, *, application_id: str = "dicetrace") -> None:
        quiet_sdk_logs()
        import rerun as rr  # here, not at the top: heavy at import, and only once its log level is set (above)

        self.rr = rr
        self.blueprint = blueprint
        self.rec = rr.RecordingStream(application_id)
        self.web_url: str | None = None
        self.grpc_url: str | None = None
        self.web: WebViewerServer | None = None
        self.viewer: subprocess.Popen | None = None
        self.deadline: float | None = None  # when the recording must have reached the sink (set by send)
        self.closed = False

    def connect(self, target: Target) -> None:
        self.grpc_url = target.url
        self.rec.connect_grpc(target.url, default_blueprint=self.blueprint)

    def spawn(self, port: int = DEFAULT_PORT, host: str = DEFAULT_BIND) -> None:
        """Start a viewer listening on ``host:port`` (or reuse one already listening there) and connect to it.

        The viewer is started here (as the SDK's ``spawn`` does, plus ``--bind``), detached, its
        output kept aside: if it exits before it listens, its own error line is reported.
        """
        where = check_spawn(port, host)
        self.grpc_url = f"rerun+http://{url_host(where)}:{port}/proxy"
        if not reachable(where, port, 0.5):
            self.viewer = start_viewer(port, host)
        self.rec.connect_grpc(self.grpc_url, default_blueprint=self.blueprint)

    def serve(self, grpc_port: int = DEFAULT_PORT, web_port: int = DEFAULT_WEB_PORT, host: str = DEFAULT_BIND) -> str:
        """Serve the recording over gRPC and the web viewer over HTTP, both on ``host``; returns the web viewer's URL."""
        cors = [] if is_loopback(host) else [f"http://*:{web_port}" if ipaddress.ip_address(host).is_unspecified
                                              else f"http://{url_host(host)}:{web_port}"]
        try:
            sink = self.rr.GrpcServerSink(bind_ip=url_host(host), port=grpc_port, cors_allow_origin=cors)
            self.rec.set_sinks(sink)
            # the web viewer lays out a recording opened by URL by its own heuristics unless the blueprint is active
            self.rec.send_blueprint(self.blueprint, make_active=True, make_default=True)
        except Exception as e:  # RuntimeError from the SDK
            raise StreamError(f"--serve: {e}") from None
        self.grpc_url = f"rerun+http://{url_host(host)}:{grpc_port}/proxy"
        try:
            self.web = WebViewerServer(host, web_port, self.grpc_url)
        except WebViewerError as e:
            raise StreamError(f"--serve: {e}") from None
        self.web_url = web_viewer_url(host, web_port, self.grpc_url)
        return self.web_url

    def send(self, log, timeout_s: float | None = None) -> None:
        """``log(self.rec)`` and wait until it has reached the sink: at most ``timeout_s`` (default
        :data:`FLUSH_TIMEOUT_S`) for the flush and the hand-over together (see :meth:`close`)."""
        timeout_s = FLUSH_TIMEOUT_S if timeout_s is None else timeout_s
        self.deadline = time.monotonic() + timeout_s
        log(self.rec)
        try:
            self.rec.flush(timeout_sec=timeout_s)
        except Exception as e:  # RuntimeError: the connection failed or timed out
            raise StreamError(f"could not send the recording to {self.grpc_url}: {e}") from None
        if self.viewer is not None:  # a viewer listens before it opens its window: did that fail?
            try:
                self.viewer.wait(timeout=VIEWER_WATCH_S)
            except subprocess.TimeoutExpired:
                return
            raise StreamError(f"--spawn: the Rerun viewer exited ({viewer_error(self.viewer)})")

    def close(self) -> None:
        """Stop the web viewer and hand the rest of the recording over (``disconnect``), bounded.

        The SDK's flush returns once the data is queued, and its disconnect waits, with no bound,
        for a peer to take it: a peer that answered the handshake and then takes nothing would hold
        the command (and, at exit, the SDK's shutdown hook) forever.  The disconnect runs in a
        thread given what is left of :meth:`send`'s time (:data:`CLOSE_TIMEOUT_S` if nothing was
        sent); past it the connection is abandoned (the SDK's shutdown hook too, so the process can
        end) and :class:`StreamError` says so.  A second call returns at once.
        """
        if self.closed:
            return
        self.closed = True
        if self.web is not None:
            self.web.close()
        wait = CLOSE_TIMEOUT_S if self.deadline is None else max(CLOSE_MIN_S, self.deadline - time.monotonic())

        def disconnect():
            try:
                self.rec.disconnect()
            except Exception:  # pragma: no cover - nothing more to report
                pass

        worker = threading.Thread(target=disconnect, name="dicetrace-disconnect", daemon=True)
        worker.start()
        worker.join(wait)
        if worker.is_alive():
            self.rr.unregister_shutdown()  # its flush at exit would wait for the same peer
            raise StreamError(f"could not send the recording to {self.grpc_url}: it took no data for "
                              f"{FLUSH_TIMEOUT_S if self.deadline is not None else wait:g} s (the connection was "
                              "given up)")


def check_spawn(port: int, host: str = DEFAULT_BIND) -> str:
    """Refuse (StreamError) a ``--spawn`` that cannot work, before any work; returns the address to connect to.

    A viewer already listening on ``port`` is reused (the SDK's rule), but only if it answers as
    a gRPC server; otherwise a display and the ``rerun`` executable are needed to start one.
    """
    where = "127.0.0.1" if ipaddress.ip_address(host).is_unspecified else host
    if reachable(where, port, 0.5):
        why = probe_grpc(Target(f"rerun+http://{url_host(where)}:{port}/proxy", where, port))
        if why is not None:
            raise StreamError(f"--spawn: port {port} is taken by something that is not a Rerun viewer ({why}): "
                              "give another --port")
        return where
    if viewer_executable() is None:
        raise StreamError("--spawn: the Rerun viewer (the `rerun` command of rerun-sdk) was not found")
    problem = display_problem()
    if problem is not None:
        raise StreamError(f"--spawn needs a display to open the viewer on ({problem}): use --serve (web viewer) or "
                          "--out FILE.rrd")
    if not port_free(port, host):
        raise StreamError(f"--spawn: port {port} is already in use on {host}")
    return where


def start_viewer(port: int, host: str) -> subprocess.Popen:
    """Start Rerun's viewer listening on ``host:port``, detached; return once it listens (StreamError otherwise)."""
    exe = viewer_executable()
    err = tempfile.TemporaryFile()
    env = {**os.environ, "RERUN_APP_ONLY": "true"}  # as the SDK's spawn: no analytics opt-in prompt
    try:
        proc = subprocess.Popen(
            [exe, "--port", str(port), "--bind", host, "--memory-limit", "75%", "--server-memory-limit", "1GiB",
             "--expect-data-soon"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err, env=env, start_new_session=True,
        )
    except OSError as e:
        err.close()
        raise StreamError(f"--spawn: could not start the Rerun viewer {exe}: {e.strerror or e}") from None
    proc.error_file = err  # read if it exits early; the file goes away with both processes
    where = "127.0.0.1" if ipaddress.ip_address(host).is_unspecified else host
    deadline = time.monotonic() + SPAWN_TIMEOUT_S
    while not reachable(where, port, 0.5):
        if proc.poll() is not None:
            raise StreamError(f"--spawn: the Rerun viewer exited ({viewer_error(proc)})")
        if time.monotonic() > deadline:
            proc.kill()
            raise StreamError(f"--spawn: the Rerun viewer did not start listening on port {port} within "
                              f"{SPAWN_TIMEOUT_S:g} s")
        time.sleep(0.1)
    return proc


def viewer_error(proc: subprocess.Popen) -> str:
    """The last line of an exited viewer's error output (its ``Error: ...`` line), or its exit status."""
    lines = []
    f = getattr(proc, "error_file", None)
    if f is not None:
        try:
            f.seek(0)
            lines = [ln.strip() for ln in f.read().decode("utf-8", "replace").splitlines() if ln.strip()]
        except OSError:
            lines = []
    errors = [ln for ln in lines if ln.startswith("Error")] or lines
    return (errors[-1] if errors else f"exit status {proc.returncode}")[:300]


def wait_serving(seconds: float | None, *, sleep=time.sleep) -> str:
    """Keep serving for ``seconds`` (None: until Ctrl-C); returns why it stopped ("time" or "interrupted")."""
    deadline = None if seconds is None else time.monotonic() + seconds
    try:
        while deadline is None or time.monotonic() < deadline:
            sleep(0.2 if deadline is None else max(0.0, min(0.2, deadline - time.monotonic())))
    except KeyboardInterrupt:
        return "interrupted"
    return "time"
