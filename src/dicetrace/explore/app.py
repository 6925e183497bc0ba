"""The explorer's ASGI app (starlette): the page, the map as PNG or JSON, hover info, throws as .rrd, saved scans.

Every endpoint reads the view from the query string (:mod:`dicetrace.explore.view`);
bad input gets a 400 JSON ``{"error": ..., "param": ...}`` and the server goes on.
Maps, throws and scans run on the :class:`~dicetrace.explore.compute.Worker`'s
threads, so the event loop keeps answering while they compute.

Endpoints::

    GET  /                      the page (its view in the URL query)
    GET  /api/view              the normalised view: its query, axes, limits, the device the maps run on, the die
    GET  /api/map.png           the outcome map, one pixel per grid point, y up (pass=preview/coarse: about 1/16, 1/4 resolution)
    GET  /api/map.json          the same map's outcome labels, [i][j] with i along x
    GET  /api/map.strips        the refined map as it is computed: NDJSON, a line per strip of image rows, then "done"
    GET  /api/hover?x=&y=       the nearest grid point's throw: coordinates, IC, outcome, steps, settle time, contacts
    GET  /api/throw.rrd?x=&y=   that throw as a Rerun recording (as ``dicetrace record`` writes it)
    GET  /api/compare.rrd?t=&t= picked throws in one compare recording (:mod:`dicetrace.explore.compare`)
    POST /api/save?name=        the view as a scan dataset (as ``dicetrace scan`` writes it) in the start-up folder
    GET  /rerun/widget.js, /rerun/re_viewer_bg.wasm   Rerun's web viewer (shipped by rerun-notebook)
    GET  /favicon.ico           the page's icon (a die face, SVG)

Only the server's own names are served (starlette's ``TrustedHostMiddleware``:
127.0.0.1, localhost, [::1] and the address it listens on; another ``Host:``, as
a DNS-rebinding page sends, gets a 400), a request that changes something
(``POST``) or computes (the maps, hovers, throws: :data:`COMPUTING_PATHS`) from
another origin is refused with a 403 (:class:`SameOriginOnly`), and no response
carries CORS headers, so no other site's page can read one.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import io
import ipaddress
import json
from pathlib import Path

import numpy as np
from starlette.applications import Starlette
from starlette.datastructures import Headers
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import FileResponse, HTMLResponse, JSONResponse, Response, StreamingResponse
from starlette.routing import Route

from dicetrace.body_text import die_text
from dicetrace.explore.compare import compare_endpoint
from dicetrace.explore.compute import (Busy, OverBudget, Worker, check_recording, scan_folder_for, throw_aspect,
                                       throw_info, throw_rrd)
from dicetrace.explore.outcome_map import Cancelled, strip_rows
from dicetrace.explore.page import page_html
from dicetrace.explore.view import MAX_RES, MIN_RES, View, ViewError, _num, view_from_query
from dicetrace.scan.colours import outcome_rgb_table
from dicetrace.sinks.rerun_web import FAVICON_SVG, rerun_notebook_static

#: The passes of a view and their resolution divisors: the page asks for each in turn.
PASSES = {"preview": 16, "coarse": 4, "fine": 1}
#: Longest a hover or throw may take before the request gives up, s.
THROW_TIMEOUT_S = 120.0
#: How often a streamed map looks for new strips, s.
STRIP_POLL_S = 0.03


#: The names a browser on this machine reaches a loopback server by (the Host header's name, IPv6 in brackets).
LOCAL_HOSTS = ("127.0.0.1", "localhost", "[::1]")
#: Methods that only read (a browser's cross-origin check applies to the others, and to :data:`COMPUTING_PATHS`).
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
#: Paths whose GET computes (a map, a throw): any page could ask for one from an ``<img>``, so they are
#: answered to the explorer's own page only, as the writes are.
COMPUTING_PATHS = frozenset({"/api/map.png", "/api/map.json", "/api/map.strips", "/api/hover", "/api/throw.rrd",
                             "/api/compare.rrd"})


def allowed_hosts(hosts=()) -> list[str]:
    """The Host names the app answers: :data:`LOCAL_HOSTS` and ``hosts`` (the listening address);
    ``["*"]`` (any) when that address is a wildcard (0.0.0.0, ::), which serves every interface by choice."""
    names = list(LOCAL_HOSTS)
    for h in hosts:
        h = str(h).strip().lower()
        try:
            ip = ipaddress.ip_address(h.strip("[]"))
        except ValueError:
            names.append(h)
            continue
        if ip.is_unspecified:
            return ["*"]
        names.append(f"[{ip.compressed}]" if ip.version == 6 else ip.compressed)
    return list(dict.fromkeys(names))


class SameOriginOnly:
    """ASGI middleware: a request that may change state (not GET/HEAD/OPTIONS), or that computes (a GET of
    :data:`COMPUTING_PATHS`: a map, a hover, a throw), from another origin gets a 403 and runs nothing.

    The check browsers make possible (the design of Go's ``http.CrossOriginProtection``
    and of Jupyter's ``check_origin``): a browser marks every request with
    ``Sec-Fetch-Site`` (only ``same-origin``, or ``none`` for one the user typed, pass)
    and, on a POST, with ``Origin``, which must be this server's own origin, the
    scheme and the ``Host`` it was reached by (a Host that
    :class:`~starlette.middleware.trustedhost.TrustedHostMiddleware` has already
    checked).  ``Origin: null`` (a sandboxed frame, a file) is refused.  A request
    with neither header is not a browser's (curl, urllib, a test): no other site can
    make one, so it passes.
    """

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] == "http" and (scope["method"] not in SAFE_METHODS or scope.get("path") in COMPUTING_PATHS):
            why = self.refusal(scope)
            if why is not None:
                await JSONResponse({"error": f"cross-origin request refused: {why}", "param": None},
                                   status_code=403)(scope, receive, send)
                return
        await self.app(scope, receive, send)

    @staticmethod
    def refusal(scope) -> str | None:
        """Why this request is not the explorer's own page's (None: it is, or it is not a browser's)."""
        h = Headers(scope=scope)
        site = h.get("sec-fetch-site")
        if site is not None and site.lower() not in ("same-origin", "none"):
            return f"Sec-Fetch-Site is {site[:40]!r}, not same-origin"
        origin = h.get("origin")
        if origin is None:
            return None
        own = f"{scope.get('scheme', 'http')}://{h.get('host', '')}".lower()
        if origin.lower() != own:
            return f"Origin {origin[:100]!r} is not this server's ({own})"
        return None


def map_png(outcome: np.ndarray) -> bytes:
    """A PNG of an outcome grid [i, j] (i along x): one pixel per point, x to the right, y up."""
    from PIL import Image  # PIL: imported only when a map is drawn

    img = outcome_rgb_table()[np.asarray(outcome, dtype=np.int64).T[::-1] + 1]
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(img), "RGB").save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def outcome_from_rgb(img: np.ndarray) -> np.ndarray:
    """Inverse of :func:`map_png`'s colouring: an (ny, nx, 3) image back to outcomes [i, j] (-9: no outcome's colour)."""
    table = outcome_rgb_table()
    out = np.full(img.shape[:2], -9, dtype=np.int8)
    for k in range(8):
        out[(img[..., :3] == table[k]).all(axis=-1)] = k - 1
    return out[::-1].T


def strip_line(m, row0: int, row1: int) -> bytes:
    """One NDJSON line of :func:`create_app`'s ``/api/map.strips``: image rows row0..row1 (top first) of map ``m``.

    ``outcome`` is base64 of one byte per pixel, row by row, left to right: the
    outcome + 1 (0 undefined-grey ... 7 face 6), the row of :func:`outcome_rgb_table`.
    """
    img = (np.asarray(m.strip(row0, row1), dtype=np.int16).T[::-1] + 1).astype(np.uint8)
    return (json.dumps({"row0": row0, "row1": row1, "outcome": base64.b64encode(img.tobytes()).decode()}) + "\n").encode()


def _error(e: Exception, status: int = 400) -> JSONResponse:
    param = getattr(e, "param", None)
    return JSONResponse({"error": str(e), "param": param}, status_code=status)


def _view(request: Request, default: View) -> View:
    return view_from_query(request.query_params, default)


def _point(request: Request, view: View) -> tuple[int, int]:
    q = request.query_params
    if "i" in q or "j" in q:
        try:
            i, j = int(q.get("i", "")), int(q.get("j", ""))
        except ValueError:
            raise ViewError("i,j", "pixel indices must be whole numbers") from None
        nx, ny = view.res
        if not (0 <= i < nx and 0 <= j < ny):
            raise ViewError("i,j", f"pixel ({i}, {j}) outside the {nx}×{ny} map")
        return i, j
    if "x" not in q or "y" not in q:
        raise ViewError("x,y", "give the point's slice coordinates x and y (or pixel indices i and j)")
    x, y = _num("x", q["x"]), _num("y", q["y"])
    (x0, x1), (y0, y1) = view.window
    if not (x0 <= x <= x1 and y0 <= y <= y1):
        raise ViewError("x,y", f"({x!r}, {y!r}) is outside the window x {x0!r}..{x1!r}, y {y0!r}..{y1!r}")
    return view.pixel(x, y)


#: HTTP statuses of a map that is not made: superseded by the same tab's newer view, over the budget, busy.
MAP_REFUSALS = {Cancelled: 409, OverBudget: 422, Busy: 503}


def _map_refusal(e: Exception) -> tuple[int, dict] | None:
    for cls, status in MAP_REFUSALS.items():
        if isinstance(e, cls):
            msg = (str(e) or "superseded by a newer view") if cls is Cancelled else str(e)
            return status, {"error": msg, "param": getattr(e, "param", None)}
    return None


class ThrowTimeout(TimeoutError):
    """A throw took longer than ``THROW_TIMEOUT_S`` (the view's dt names what to change)."""

    param = "dt"


async def _throw_within(fut):
    """The result of a throw's future, or :class:`ThrowTimeout` after ``THROW_TIMEOUT_S`` (a throw still waiting
    for a thread is then cancelled; one being simulated cannot be cut and ends on its own)."""
    try:
        return await asyncio.wait_for(asyncio.wrap_future(fut), THROW_TIMEOUT_S)
    except TimeoutError:
        fut.cancel()
        raise ThrowTimeout(f"dt: this throw took more than {THROW_TIMEOUT_S:g} s to simulate: "
                           "choose a longer time step (dt)") from None


def create_app(default: View | None = None, *, out: Path | None = None, threads: int | None = None,
               worker: Worker | None = None, hosts=(), map_budget_s: float | None = None,
               device: str = "cpu") -> Starlette:
    """The explorer app; ``default`` is the view of a bare URL, ``out`` the only folder it may write scans into.

    ``hosts``: the address(es) the server listens on, answered besides :data:`LOCAL_HOSTS`
    (:func:`allowed_hosts`); every other ``Host:`` gets a 400.  ``map_budget_s``: the
    computing time one map may take (:class:`~dicetrace.explore.compute.Worker`'s ``budget_s``);
    ``device``: where the maps run (the worker's ``device``: cpu, cuda, auto), shown on the page and in
    ``/api/view`` and ``/api/health``.
    """

    default = default or View()
    worker = worker or Worker(threads=threads, budget_s=map_budget_s, device=device)
    out = None if out is None else Path(out).resolve()

    async def page(request: Request) -> Response:
        return HTMLResponse(page_html(default, can_save=out is not None, device=worker.device))

    async def view_info(request: Request) -> Response:
        v = _view(request, default)
        return JSONResponse({"query": v.to_query(), "window": v.window, "res": v.res, "ndim": v.ndim,
                             "limits": {"res": [MIN_RES, MAX_RES]}, "device": worker.device,
                             "die": die_text(v.config().preset)})

    async def _map(request: Request):
        v = _view(request, default)
        name = request.query_params.get("pass", "fine")
        if name not in PASSES:
            raise ViewError("pass", f"one of {', '.join(PASSES)}, got {name[:20]!r}")
        if PASSES[name] > 1:
            v = v.coarse(PASSES[name])
        client = request.query_params.get("client", "")[:64]
        fut = worker.submit_map(v, client)
        return await asyncio.wrap_future(fut)

    async def map_png_ep(request: Request) -> Response:
        m = await _map(request)
        png = await asyncio.to_thread(map_png, m.outcome)
        headers = {"X-Dicetrace-Wall-S": f"{m.wall_s:.6f}", "X-Dicetrace-Res": f"{m.view.res[0]},{m.view.res[1]}",
                   "X-Dicetrace-Counts": json.dumps(m.counts()), "Cache-Control": "no-store"}
        return Response(png, media_type="image/png", headers=headers)

    async def map_json_ep(request: Request) -> Response:
        m = await _map(request)
        return JSONResponse({"query": m.view.to_query(), "xs": m.xs.tolist(), "ys": m.ys.tolist(),
                             "outcome": m.outcome.tolist(), "steps": m.steps.tolist(),
                             "counts": m.counts(), "wall_s": m.wall_s})

    async def map_strips_ep(request: Request) -> Response:
        v = _view(request, default)
        fut = asyncio.wrap_future(worker.submit_map(v, request.query_params.get("client", "")[:64]))
        rows = strip_rows(v)

        async def lines():
            sent = 0
            while True:
                finished = fut.done()
                try:
                    m = fut.result() if finished else worker.progress(v)
                except (Cancelled, OverBudget, Busy) as e:
                    status, body = _map_refusal(e)
                    if status == 409:
                        body = {"error": body["error"]}
                    yield (json.dumps({**body, "status": status}) + "\n").encode()
                    return
                except Exception as e:
                    yield (json.dumps({"error": f"internal error: {type(e).__name__}: {e}", "status": 500}) + "\n").encode()
                    return
                for row0 in range(sent, m.rows_done if m is not None else 0, rows):  # a line per strip computed
                    yield strip_line(m, row0, min(row0 + rows, m.rows_done))
                    sent = min(row0 + rows, m.rows_done)
                if finished:
                    yield (json.dumps({"done": True, "res": list(m.view.res), "wall_s": m.wall_s, "reused": m.reused,
                                       "counts": m.counts()}) + "\n").encode()
                    return
                await asyncio.wait([fut], timeout=STRIP_POLL_S)

        return StreamingResponse(lines(), media_type="application/x-ndjson", headers={"Cache-Control": "no-store"})

    async def hover(request: Request) -> Response:
        v = _view(request, default)
        i, j = _point(request, v)
        return JSONResponse(await _throw_within(worker.submit_throw(throw_info, v, i, j)))

    async def throw(request: Request) -> Response:
        v = _view(request, default)
        i, j = _point(request, v)
        download = bool(request.query_params.get("download"))
        # for the download, record's file as it is; for the viewer, record's blueprint made active, its camera
        # framing for the 3-D view's aspect the page gives
        aspect = None if download else throw_aspect(request.query_params.get("aspect"))
        check_recording(v)  # what `record --dt` refuses (its memory), refused before anything runs
        name, data, summary = await _throw_within(worker.submit_throw(throw_rrd, v, i, j, not download, aspect))
        # no CORS header: the page's viewer fetches this from the page's own origin
        headers = {"X-Dicetrace-Outcome": str(summary["outcome"]), "X-Dicetrace-Status": summary["status"]}
        if download:
            headers["Content-Disposition"] = f'attachment; filename="{name}.rrd"'
        return Response(data, media_type="application/octet-stream", headers=headers)

    async def save(request: Request) -> Response:
        if out is None:
            return JSONResponse({"error": "saving is off: start the explorer with --out DIR (Explorer(out=...))",
                                 "param": "name"}, status_code=403)
        v = _view(request, default)
        name = request.query_params.get("name", "")
        scan_folder_for(out, name)
        worker.check_save_room()  # a full queue of saves is a 503 before any computing
        # the map budget: the view's map first (the cache's when the page has shown it), on the map worker's
        # turns: a view whose map would be refused for its cost (OverBudget, a 422) is not saved either
        await asyncio.wrap_future(worker.submit_map(v))
        try:
            summary = await asyncio.wrap_future(worker.submit_scan(v, out, name))
        except (ValueError, OSError) as e:  # a folder holding another scan, a full disk, ...
            return _error(e, 409)
        return JSONResponse(summary)

    async def health(request: Request) -> Response:
        return JSONResponse({"ok": True, "computed": worker.computed_count, "cancelled": worker.cancelled_count,
                             "over_budget": worker.refused_count, "cache_bytes": worker.cache_nbytes,
                             "device": worker.device})

    def asset(name: str, media: str):
        async def ep(request: Request) -> Response:
            path = rerun_asset(name)
            if path is None:
                return JSONResponse({"error": "Rerun's web viewer is not installed (pip install rerun-notebook)",
                                     "param": None}, status_code=404)
            return FileResponse(path, media_type=media)

        return ep

    async def favicon(request: Request) -> Response:
        return Response(FAVICON_SVG, media_type="image/svg+xml", headers={"Cache-Control": "max-age=86400"})

    async def on_error(request: Request, exc: Exception) -> Response:
        return JSONResponse({"error": f"internal error: {type(exc).__name__}: {exc}", "param": None}, status_code=500)

    routes = [
        Route("/", page),
        Route("/api/view", view_info),
        Route("/api/map.png", map_png_ep),
        Route("/api/map.json", map_json_ep),
        Route("/api/map.strips", map_strips_ep),
        Route("/api/hover", hover),
        Route("/api/throw.rrd", throw),
        Route("/api/compare.rrd", compare_endpoint),
        Route("/api/save", save, methods=["POST"]),
        Route("/api/health", health),
        Route("/rerun/widget.js", asset("widget.js", "text/javascript")),
        Route("/rerun/re_viewer_bg.wasm", asset("re_viewer_bg.wasm", "application/wasm")),
        Route("/rerun/widget.css", asset("widget.css", "text/css")),
        Route("/favicon.ico", favicon),
    ]
    @contextlib.asynccontextmanager
    async def lifespan(app):
        try:
            yield
        finally:
            worker.shutdown()

    middleware = [Middleware(TrustedHostMiddleware, allowed_hosts=allowed_hosts(hosts), www_redirect=False),
                  Middleware(SameOriginOnly)]
    def answer(status: int):
        async def handler(request: Request, exc: Exception) -> Response:
            return _error(exc, status)

        return handler

    async def refused(request: Request, exc: Exception) -> Response:
        status, body = _map_refusal(exc)
        return JSONResponse(body, status_code=status)

    # what an endpoint raises, answered as one JSON error naming the parameter: a bad view or point (400), a
    # throw past THROW_TIMEOUT_S (504, naming dt), a map superseded, over its budget, or a full worker
    # (MAP_REFUSALS: 409, 422, 503; any endpoint)
    handlers = {ViewError: answer(400), ThrowTimeout: answer(504), Cancelled: refused, OverBudget: refused,
                Busy: refused, Exception: on_error}
    app = Starlette(routes=routes, middleware=middleware, exception_handlers=handlers, lifespan=lifespan)
    app.state.worker = worker
    app.state.default = default
    app.state.out = out
    return app


def rerun_asset(name: str) -> Path | None:
    """A file of Rerun's web viewer as the rerun-notebook package ships it (found without importing it)."""
    folder = rerun_notebook_static()
    path = None if folder is None else folder / name
    return path if path is not None and path.is_file() else None
