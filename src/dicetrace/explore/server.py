"""Serving the explorer: uvicorn on a socket bound to 127.0.0.1, in the foreground or on a background thread (:class:`Explorer`).

``Explorer`` is the notebook face: it starts the server on a free port in a
thread, and displays as an IFrame of the page (``_repr_html_``), so
``dicetrace.explore.Explorer(window="red-sea")`` as a cell's last line
shows the explorer inside Jupyter; ``Explorer.widget()`` is the same page as
an anywidget whose picked throws and view come back to Python.  ``stop()``
(or leaving a ``with`` block) shuts it down and frees the port.
"""

from __future__ import annotations

import asyncio
import html
import ipaddress
import logging
import math
import socket
import sys
import threading
import time
import traceback
from pathlib import Path

import numpy as np

from dicetrace.devices import resolve_device
from dicetrace.explore.view import View, view_from_query
from dicetrace.extras import require

#: The address the explorer listens on unless told otherwise.
DEFAULT_HOST = "127.0.0.1"
#: Longest wait for the server to come up, s.
START_TIMEOUT_S = 30.0


def check_port(port, name: str = "port") -> int:
    """``port`` as an int in 0..65535 (0: a free one), or ValueError naming ``name``."""
    if isinstance(port, bool) or not isinstance(port, (int, np.integer)):
        raise ValueError(f"{name} must be a whole number in 0..65535 (0: a free one), got {port!r}")
    if not 0 <= port <= 65535:
        raise ValueError(f"{name} must be in 0..65535 (0: a free one), got {port!r}")
    return int(port)


def check_host(host, name: str = "host") -> str:
    """``host`` as an address this machine can listen on (an IP address, or a name that resolves), or ValueError naming ``name``."""
    if not isinstance(host, str) or not host.strip() or host != host.strip():
        raise ValueError(f"{name} must be an address to listen on, such as 127.0.0.1, got {host!r}")
    try:
        ipaddress.ip_address(host)
        return host
    except ValueError:
        pass
    try:
        socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError) as e:
        raise ValueError(f"{name} {host!r} does not resolve to an address: {getattr(e, 'strerror', None) or e}") from None
    return host


def check_threads(threads, name: str = "threads"):
    """``threads`` as None or an int >= 1, or ValueError naming ``name``."""
    if threads is None:
        return None
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
        raise ValueError(f"{name} must be a whole number >= 1, got {threads!r}")
    return int(threads)


def check_budget(budget, name: str = "map_budget_s"):
    """``budget`` as None or a finite number of seconds > 0, or ValueError naming ``name``."""
    if budget is None:
        return None
    if isinstance(budget, bool) or not isinstance(budget, (int, float, np.integer, np.floating)) \
            or not math.isfinite(budget) or budget <= 0:
        raise ValueError(f"{name} must be a number of seconds > 0, got {budget!r}")
    return float(budget)


def bind_socket(host: str = DEFAULT_HOST, port: int = 0) -> socket.socket:
    """A listening TCP socket on (host, port); port 0 picks a free one."""
    fam = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(fam, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError:
        sock.close()
        raise
    sock.listen(128)
    sock.set_inheritable(True)
    return sock


#: Longest the server waits, once told to stop, for requests in progress (a throw being simulated) before it cancels them, s.
GRACEFUL_S = 1.0
#: Most connections open at once (fewer where the process may open fewer files: :func:`connection_limit`).  A
#: browser opens about 6 per server; a connection beyond the limit closes the oldest one that is not in a request
#: (a slow client's, an idle keep-alive one), or is answered 503 and closed when every one is in a request.
MAX_CONNECTIONS = 256
#: File descriptors kept for everything but connections (the listening socket, numba's cache, saved scans, pipes).
FD_RESERVE = 64
#: Seconds a connection may take to send a request's headers (from its opening, or from the end of its previous
#: response): a client that sends them slowly, or never, is closed after that.
HEADER_TIMEOUT_S = 10.0
#: Bytes of a request's headers held while they arrive (h11's bound; a longer request line or headers: a 400).
MAX_HEADER_BYTES = 16 * 1024
#: Seconds between two lines on standard error about one kind of trouble of the event loop (out of file descriptors).
LOOP_ERROR_EVERY_S = 10.0


def connection_limit() -> int:
    """Connections open at once: :data:`MAX_CONNECTIONS`, or fewer where the process's limit of open files
    (``ulimit -n``) leaves less room: half of what :data:`FD_RESERVE` leaves (a connection may hold a file it
    sends, Rerun's viewer, and connections just accepted come in bursts: :func:`accept_burst`), at least 8."""
    try:
        import resource
    except ImportError:  # pragma: no cover - not on POSIX
        return MAX_CONNECTIONS
    soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    if soft == resource.RLIM_INFINITY:
        return MAX_CONNECTIONS
    return max(8, min(MAX_CONNECTIONS, (soft - FD_RESERVE) // 2))


def accept_burst(limit: int) -> int:
    """The listening socket's backlog for a server of ``limit`` connections: at most a quarter of them, and 64.

    asyncio accepts up to the backlog's number of connections each time the socket is ready, before any of them
    reaches the protocol that counts them, so the file descriptors open stay below ``limit`` plus about two such
    bursts (:func:`connection_limit` leaves that room).
    """
    return max(4, min(64, limit // 4))


def guarded_protocol(limit: int, header_timeout_s: float):
    """uvicorn's h11 protocol with two bounds uvicorn itself lacks: at most ``limit`` connections open (its
    ``limit_concurrency`` answers 503 to requests beyond it, but accepts every connection: a flood of clients that
    never send a whole request would hold every file descriptor), and ``header_timeout_s`` to send a request's
    headers (its keep-alive timeout starts only after a response)."""
    from uvicorn.protocols.http.h11_impl import H11Protocol  # the server stack: imported only when serving

    open_: dict = {}  # the connections of this server, oldest first

    class GuardedH11Protocol(H11Protocol):
        _header_timer = None

        def connection_made(self, transport) -> None:
            super().connection_made(transport)
            live = [c for c in open_ if not c.transport.is_closing()]
            if len(live) >= limit:
                idle = next((c for c in live if not c.in_request()), None)
                if idle is None:  # every connection is in a request: this one is refused
                    body = b'{"error": "the explorer has as many connections open as it may: try again in a moment", "param": null}'
                    transport.write(b"HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\n"
                                    b"content-length: " + str(len(body)).encode() + b"\r\nconnection: close\r\n\r\n" + body)
                    transport.close()
                    return
                idle.transport.close()  # the oldest one not in a request makes room
            open_[self] = None
            self._arm_header_timer()

        def connection_lost(self, exc) -> None:
            open_.pop(self, None)
            if self._header_timer is not None:
                self._header_timer.cancel()
                self._header_timer = None
            super().connection_lost(exc)

        def on_response_complete(self) -> None:
            super().on_response_complete()
            self._arm_header_timer()  # the next request's headers are due within the same time

        def in_request(self) -> bool:
            """Whether a request's headers have arrived and its response is not complete."""
            return self.cycle is not None and not self.cycle.response_complete

        def _arm_header_timer(self) -> None:
            if self._header_timer is not None:
                self._header_timer.cancel()
            self._header_timer = self.loop.call_later(header_timeout_s, self._headers_late)

        def _headers_late(self) -> None:
            self._header_timer = None
            if not self.in_request() and not self.transport.is_closing():
                self.transport.close()

    return GuardedH11Protocol


class _OneLineLogs(logging.Filter):
    """uvicorn's error log without tracebacks: a request cancelled because the server stops is not logged (its
    client is being disconnected), any other error is one line (its message, the exception and where it rose)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if not record.exc_info:
            return True
        exc = record.exc_info[1]
        if isinstance(exc, asyncio.CancelledError):
            return False
        tb = traceback.extract_tb(exc.__traceback__) if exc is not None else []
        where = f" (at {Path(tb[-1].filename).name}:{tb[-1].lineno})" if tb else ""
        record.msg = f"{record.getMessage().strip()}: {type(exc).__name__}: {exc}{where}"
        record.args, record.exc_info, record.exc_text = (), None, None
        return True


_ONE_LINE = _OneLineLogs()


def _loop_errors(stream=None):
    """An event loop's exception handler printing one line per kind of trouble at most every
    :data:`LOOP_ERROR_EVERY_S` (asyncio's own prints a traceback each time: a thousand a second when the process
    is out of file descriptors and the listening socket has connections waiting)."""
    last: dict = {}

    def handler(loop, context) -> None:
        exc = context.get("exception")
        kind = (context.get("message"), type(exc).__name__, getattr(exc, "errno", None))
        now = time.monotonic()
        if now - last.get(kind, -math.inf) < LOOP_ERROR_EVERY_S:
            return
        last[kind] = now
        text = context.get("message") or "event loop error"
        if exc is not None:
            text += f": {type(exc).__name__}: {exc}"
        print(f"dicetrace explore: {text} (said at most every {LOOP_ERROR_EVERY_S:g} s)", file=stream or sys.stderr,
              flush=True)

    return handler


def make_server(app, sock: socket.socket, *, max_connections: int | None = None,
                header_timeout_s: float | None = None):
    """A uvicorn server of ``app`` that, told to stop (Ctrl-C, ``should_exit``), first cancels every map, throw and
    save in the making, so the requests waiting for them answer at once, and cancels what is still running after
    ``GRACEFUL_S``; with at most ``max_connections`` connections (default :func:`connection_limit`), each given
    ``header_timeout_s`` (default :data:`HEADER_TIMEOUT_S`) for a request's headers (:func:`guarded_protocol`);
    no tracebacks on standard error (:class:`_OneLineLogs`, :func:`_loop_errors`)."""
    import uvicorn  # the server stack: imported only when serving

    class Server(uvicorn.Server):
        async def startup(self, sockets=None):
            asyncio.get_running_loop().set_exception_handler(_loop_errors())
            await super().startup(sockets)

        async def shutdown(self, sockets=None):
            worker = getattr(getattr(app, "state", None), "worker", None)
            if worker is not None:
                worker.cancel_all()
            await super().shutdown(sockets)

    limit = connection_limit() if max_connections is None else int(max_connections)
    # backlog: the listening socket's queue, and how many connections asyncio accepts in one go before any of them
    # is counted (uvicorn's default, 2048, would take every file descriptor in one burst)
    config = uvicorn.Config(app, log_level="warning", lifespan="on", access_log=False,
                            timeout_graceful_shutdown=GRACEFUL_S, http=guarded_protocol(limit, HEADER_TIMEOUT_S if header_timeout_s is None else header_timeout_s),
                            h11_max_incomplete_event_size=MAX_HEADER_BYTES, backlog=accept_burst(limit))
    server = Server(config)
    server.max_connections = limit
    uvicorn_log = logging.getLogger("uvicorn.error")
    if _ONE_LINE not in uvicorn_log.filters:
        uvicorn_log.addFilter(_ONE_LINE)
    return server


def make_view(slice: str = "seed", window="red-sea", *, res=None, preset: str = "seed", integrator=None,
              gamma=None, dt=None, z=None, die=None, load=None) -> View:
    """A :class:`View` from keyword options as the command line gives them (ViewError naming a bad one); ``die``
    and ``load`` as ``--die X,Y,Z`` and ``--load W@X,Y,Z`` give them."""
    q = {"slice": slice, "preset": preset}
    q["window"] = window if isinstance(window, str) else ",".join(repr(float(v)) for pair in window for v in pair)
    for name, v in (("res", res), ("integrator", integrator), ("gamma", gamma), ("dt", dt), ("z", z), ("die", die),
                    ("load", load)):
        if v is not None:
            q[name] = v if isinstance(v, str) else (",".join(map(str, v)) if isinstance(v, tuple) else str(v))
    return view_from_query(q)


class Explorer:
    """The explorer served from a background thread (for Jupyter and scripts).

    Parameters as :func:`make_view` (the start view), plus ``out`` (the only
    folder "save this view as a scan" may write into; None: saving off),
    ``host``/``port`` (default 127.0.0.1, a free port), ``threads`` (numba
    threads per map), ``map_budget_s`` (the computing time one map may take,
    default ``compute.MAP_BUDGET_S``), ``device`` (where the maps run: cpu,
    cuda, auto; resolved here: a :class:`~dicetrace.devices.DeviceError` for
    cuda without a GPU), ``start`` (start now) and ``height`` (of the IFrame, px).
    """

    def __init__(self, slice: str = "seed", window="red-sea", *, res=None, preset: str = "seed", integrator=None,
                 gamma=None, dt=None, z=None, die=None, load=None, out=None, host: str = DEFAULT_HOST, port: int = 0,
                 threads: int | None = None, map_budget_s: float | None = None, start: bool = True,
                 height: int = 900, device: str = "cpu"):
        host, port = check_host(host), check_port(port)  # before anything starts (ValueError naming the parameter)
        threads, map_budget_s = check_threads(threads), check_budget(map_budget_s)
        self.device = resolve_device(device)  # a Device, resolved once here
        if isinstance(height, bool) or not isinstance(height, (int, np.integer)) or height < 1:
            raise ValueError(f"height must be a whole number of pixels >= 1, got {height!r}")
        self.view = make_view(slice, window, res=res, preset=preset, integrator=integrator, gamma=gamma, dt=dt, z=z,
                              die=die, load=load)
        self.out = None if out is None else Path(out)
        self.host, self.port, self.threads, self.height = host, port, threads, int(height)
        self.map_budget_s = map_budget_s
        self._server = None
        self._thread: threading.Thread | None = None
        self._sock: socket.socket | None = None
        if start:
            self.start()

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/?{self.view.query_string()}"

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> "Explorer":
        if self.running:
            return self
        require("explore", "Explorer")
        from dicetrace.explore.app import create_app  # starlette, and numba through dicetrace.scan: only when serving

        self._sock = bind_socket(self.host, self.port)
        self.port = self._sock.getsockname()[1]
        self.app = create_app(self.view, out=self.out, threads=self.threads, hosts=[self.host],
                              map_budget_s=self.map_budget_s, device=self.device)
        self._server = make_server(self.app, self._sock)
        self._thread = threading.Thread(target=self._server.run, kwargs={"sockets": [self._sock]},
                                        name="dicetrace-explore-server", daemon=True)
        self._thread.start()
        t0 = time.monotonic()
        while not self._server.started:
            if not self._thread.is_alive() or time.monotonic() - t0 > START_TIMEOUT_S:
                self.stop()
                raise RuntimeError(f"the explorer did not start on {self.host}:{self.port}")
            time.sleep(0.02)
        return self

    def stop(self) -> None:
        """Shut the server down (waits for it) and close its socket."""
        if self._server is not None:
            self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=60)
        if self._sock is not None:
            self._sock.close()
        self._server = self._thread = self._sock = None

    def __enter__(self) -> "Explorer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def widget(self, on_pick=None):
        """The explorer as a Jupyter widget whose ``throws`` and ``view`` follow the page (started if it is not).

        ``on_pick(info)`` is called with the hover info of each throw picked on the page:
        :class:`~dicetrace.explore.widget.ExplorerWidget`.
        """
        require("jupyter", "Explorer.widget()")
        from dicetrace.explore.widget import ExplorerWidget  # anywidget: imported only for a widget

        w = ExplorerWidget(url=self.start().url, height=self.height)
        if on_pick is not None:
            w.on_pick(on_pick)
        return w

    def __repr__(self) -> str:
        state = "running at " + self.url if self.running else "stopped"
        return f"Explorer({state})"

    def _repr_html_(self) -> str:
        if not self.running:
            return f"<p>dicetrace explorer (stopped): {html.escape(repr(self.view))}</p>"
        return (f'<iframe src="{html.escape(self.url)}" width="100%" height="{self.height}" '
                f'style="border:0" title="dicetrace explore"></iframe>')


def serve_forever(view: View, *, host: str = DEFAULT_HOST, port: int = 0, out=None, threads=None,
                  map_budget_s=None, on_ready=None, device: str = "cpu") -> None:
    """Serve the explorer in the foreground until interrupted; ``on_ready(url)`` is called once it listens.

    ``device``: where the maps run (cpu, cuda, auto), resolved before anything listens.
    """
    require("explore", "the explorer")
    from dicetrace.explore.app import create_app  # starlette, and numba through dicetrace.scan: only when serving

    host, port, threads = check_host(host), check_port(port), check_threads(threads)
    map_budget_s = check_budget(map_budget_s)
    device = resolve_device(device)
    sock = bind_socket(host, port)
    port = sock.getsockname()[1]
    app = create_app(view, out=out, threads=threads, hosts=[host], map_budget_s=map_budget_s, device=device)
    server = make_server(app, sock)
    url = f"http://{host}:{port}/?{view.query_string()}"
    if on_ready is not None:
        def watch():
            while not server.started and not server.should_exit:
                time.sleep(0.02)
            if server.started:
                on_ready(url)

        threading.Thread(target=watch, daemon=True).start()
    try:
        server.run(sockets=[sock])
    finally:
        sock.close()
