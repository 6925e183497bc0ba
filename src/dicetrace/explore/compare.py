"""The explorer's picked throws in one Rerun compare recording, as ``dicetrace record --ic A --ic B`` makes one.

``GET /api/compare.rrd?t=THROW&t=THROW...`` (2 to :data:`MAX_THROWS` ``t``): each ``THROW`` is the
query string of one throw as ``/api/throw.rrd`` takes it (its view's parameters and its grid point
``i``, ``j``), URL-encoded, so throws picked in different views (after a zoom or a pan) can be compared.
The throws must share their configuration (preset, integrator, γ, dt, die): the comparison steps them together.
The recording is :func:`dicetrace.sinks.rerun_compare.compare_logger`'s, throw 1 (the first picked)
the reference, with :func:`~dicetrace.sinks.rerun_compare.compare_blueprint` made active for Rerun's
web viewer, its camera framing for the viewer's ``aspect`` (``download=1``: default only and the default
camera, as ``record`` writes it).  Throws that ``record`` would refuse for their recording's memory
(a tiny ``dt``) are refused, a 400 naming ``dt``, before anything runs.
"""

from __future__ import annotations

import asyncio
import hashlib

import numpy as np

from dicetrace.explore.compute import check_recording, point_ic, throw_aspect, throw_name
from dicetrace.explore.view import View, ViewError, view_from_query
from dicetrace.simulate import Record, simulate
from dicetrace.sinks.rerun import encode_rrd
from dicetrace.sinks.rerun_compare import compare_blueprint, compare_logger

#: Most throws in one comparison (the compare recording's colours, :data:`dicetrace.sinks.rerun_compare.THROW_COLORS`).
MAX_THROWS = 6
#: Longest a comparison may take before the request gives up, s.
COMPARE_TIMEOUT_S = 240.0


def parse_throws(values, default: View) -> list[tuple[View, int, int]]:
    """The (view, i, j) of each ``t`` parameter; :class:`ViewError` (param ``t``) naming what is wrong."""
    from starlette.datastructures import QueryParams  # starlette: the server stack, imported only when serving

    if not 2 <= len(values) <= MAX_THROWS:
        raise ViewError("t", f"give 2 to {MAX_THROWS} throws to compare (t=...), got {len(values)}")
    out = []
    for k, text in enumerate(values):
        q = QueryParams(text)
        try:
            v = view_from_query(q, default)
        except ViewError as e:
            raise ViewError("t", f"throw {k + 1}: {e.param}: {e.message}") from None
        try:
            i, j = int(q.get("i", "")), int(q.get("j", ""))
        except ValueError:
            raise ViewError("t", f"throw {k + 1}: its pixel indices i and j must be whole numbers") from None
        nx, ny = v.res
        if not (0 <= i < nx and 0 <= j < ny):
            raise ViewError("t", f"throw {k + 1}: pixel ({i}, {j}) outside its {nx}×{ny} map")
        if k and v.config() != out[0][0].config():
            raise ViewError("t", f"throw {k + 1} has another configuration (preset, integrator, γ, dt, die) than throw 1: "
                                 "throws are compared step by step under one configuration")
        out.append((v, i, j))
    return out


def compare_rrd(throws: list[tuple[View, int, int]], activate: bool = False,
                aspect: float | None = None) -> tuple[str, bytes, dict]:
    """The compare recording of ``throws`` ((view, i, j) each, one configuration): (name, bytes, summary);
    ``aspect``: the width/height of the 3-D view its camera frames for (None: the recording's default)."""
    cfg = throws[0][0].config()
    rolls, labels, ics, names = [], [], [], []
    for v, i, j in throws:
        coords, ic = point_ic(v, i, j)
        rolls.append(simulate(ic, config=cfg, record=Record(states=True, energy=True)))
        labels.append(f"{v.slice} slice at " + ", ".join(f"{a} = {c!r}" for a, c in zip("xyz", coords)))
        ics.append(ic)
        names.append(throw_name(v, coords))
    digest = hashlib.sha1(np.ascontiguousarray(np.stack(ics), dtype="<f8").tobytes()).hexdigest()[:8]
    name = f"compare{len(throws)}_{names[0]}_{digest}"  # as `dicetrace record` names a comparison
    data = encode_rrd(compare_logger(rolls, labels, name=name), compare_blueprint(rolls, aspect=aspect), activate=activate)
    return name, data, {"outcomes": [r.outcome for r in rolls], "statuses": [r.status.label for r in rolls]}


async def compare_endpoint(request):
    """``GET /api/compare.rrd``: the app's worker (``app.state.worker``) computes it; a 400 names a bad ``t``,
    a 504 a comparison past :data:`COMPARE_TIMEOUT_S`."""
    from starlette.responses import JSONResponse, Response  # starlette: the server stack, imported only when serving

    download = bool(request.query_params.get("download"))
    try:
        throws = parse_throws(request.query_params.getlist("t"), request.app.state.default)
        aspect = None if download else throw_aspect(request.query_params.get("aspect"))
        check_recording(throws[0][0], len(throws))  # what `record --dt` refuses (its memory), before anything runs
    except ViewError as e:
        return JSONResponse({"error": str(e), "param": e.param}, status_code=400)
    fut = request.app.state.worker.submit_throw(compare_rrd, throws, not download, aspect)
    try:
        name, data, summary = await asyncio.wait_for(asyncio.wrap_future(fut), COMPARE_TIMEOUT_S)
    except TimeoutError:
        fut.cancel()  # still waiting for a thread: never run (one being simulated ends on its own)
        return JSONResponse({"error": f"t: the comparison took more than {COMPARE_TIMEOUT_S:g} s to simulate: "
                                      "choose a longer time step (dt)", "param": "t"}, status_code=504)
    headers = {"X-Dicetrace-Outcomes": ",".join(map(str, summary["outcomes"])), "Cache-Control": "no-store"}
    if download:
        headers["Content-Disposition"] = f'attachment; filename="{name}.rrd"'
    return Response(data, media_type="application/octet-stream", headers=headers)
