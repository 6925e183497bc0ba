"""Serving the explorer: uvicorn on a socket bound to 127.0.0.1, in the foreground or on a background thread (:class:`Explorer`).

``Explorer`` is the notebook face: it starts the server on a free port in a
thread, and displays as an IFrame of the page (``_repr_html_``), so
``dicetrace.explore.Explorer(window="red-sea")`` as a cell's last line
shows the explorer inside Jupyter; ``Explorer.widget()`` is the same page as
an anywidget whose picked throws and view come back to Python.  ``stop()``
(or leaving a ``with`` block) shuts it down and frees the port.
"""

from __future__ import annotations

import html
import ipaddress
import math
import socket
import threading
import time
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


def make_server(app, sock: socket.socket):
    """A uvicorn server of ``app`` that, told to stop (Ctrl-C, ``should_exit``), first cancels every map in the making,
    so the requests waiting for them answer at once, and cancels what is still running after ``GRACEFUL_S``."""
    import uvicorn  # the server stack: imported only when serving

    class Server(uvicorn.Server):
        async def shutdown(self, sockets=None):
            worker = getattr(getattr(app, "state", None), "worker", None)
            if worker is not None:
                worker.cancel_all()
            await super().shutdown(sockets)

    config = uvicorn.Config(app, log_level="warning", lifespan="on", access_log=False,
                            timeout_graceful_shutdown=GRACEFUL_S)
    return Server(config)


def make_view(slice: str = "seed", window="red-sea", *, res=None, preset: str = "seed", integrator=None,
              gamma=None, dt=None, z=None) -> View:
    """A :class:`View` from keyword options as the command line gives them (ViewError naming a bad one)."""
    q = {"slice": slice, "preset": preset}
    q["window"] = window if isinstance(window, str) else ",".join(repr(float(v)) for pair in window for v in pair)
    for name, v in (("res", res), ("integrator", integrator), ("gamma", gamma), ("dt", dt), ("z", z)):
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
                 gamma=None, dt=None, z=None, out=None, host: str = DEFAULT_HOST, port: int = 0,
                 threads: int | None = None, map_budget_s: float | None = None, start: bool = True,
                 height: int = 900, device: str = "cpu"):
        host, port = check_host(host), check_port(port)  # before anything starts (ValueError naming the parameter)
        threads, map_budget_s = check_threads(threads), check_budget(map_budget_s)
        self.device = resolve_device(device)  # "cpu" or "cuda"
        if isinstance(height, bool) or not isinstance(height, (int, np.integer)) or height < 1:
            raise ValueError(f"height must be a whole number of pixels >= 1, got {height!r}")
        self.view = make_view(slice, window, res=res, preset=preset, integrator=integrator, gamma=gamma, dt=dt, z=z)
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
