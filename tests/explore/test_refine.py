"""The refined pass: strips of rows streamed as they are computed, coarse passes' results reused, and the viewer's throw."""

from __future__ import annotations

import base64
import json
import time
import urllib.request

import numpy as np
import pytest

from explore_helpers import RES, WINDOW, scan_outcomes


def strip_lines(lines) -> tuple[list[dict], dict]:
    """The strip messages of a ``/api/map.strips`` stream and its closing ``done`` message."""
    msgs = [json.loads(line) for line in lines if line.strip()]
    assert msgs and msgs[-1].get("done"), msgs[-1:]
    return msgs[:-1], msgs[-1]


def strips_outcomes(strips: list[dict], nx: int) -> np.ndarray:
    """The outcome grid [i, j] put together from the strips (each: image rows row0..row1, top first)."""
    rows = []
    for s in strips:
        b = np.frombuffer(base64.b64decode(s["outcome"]), dtype=np.uint8).reshape(s["row1"] - s["row0"], nx)
        rows.append(b.astype(np.int8) - 1)
    return np.concatenate(rows)[::-1].T


@pytest.mark.parametrize("n", [2, 3, 16, 31, 64, 100, 128, 200, 256, 257, 512, 1024])
def test_pass_grids_nest_bit_for_bit_in_the_full_grid(n):
    from dicetrace.explore.view import pass_res
    from dicetrace.ics import grid_axis

    rng = np.random.default_rng(n)
    for factor in (4, 16):
        c = pass_res(n, factor)
        assert 2 <= c <= max(2, n) and c <= max(2, 1.25 * n / factor + 1)
        if (n - 1) % (c - 1) == 0:
            k = (n - 1) // (c - 1)
            for lo, w in zip(rng.uniform(-3, 100, 20), 10.0 ** rng.uniform(-10, 1, 20)):
                np.testing.assert_array_equal(grid_axis(lo, lo + w, n)[::k], grid_axis(lo, lo + w, c))
    assert (pass_res(256, 16), pass_res(256, 4)) == (16, 52)  # the default view's passes nest
    assert pass_res(32, 4) == 8  # 31 is prime: a quarter, as before


def test_refined_pass_takes_the_coarse_passes_results_and_equals_scan(tmp_path):
    from dicetrace.explore import View, Worker, compute_map
    from dicetrace.ics import get_window

    view = View(window=get_window(WINDOW), res=(31, 31))
    assert view.coarse(4).res == (7, 7) and view.coarse(16).res == (2, 2)
    w = Worker()
    try:
        for v in (view.coarse(16), view.coarse(4)):
            w.submit_map(v, "c").result(timeout=120)
        m = w.submit_map(view, "c").result(timeout=120)
    finally:
        w.shutdown()
    assert m.reused == 7 * 7  # the 2×2 grid's points are among the 7×7's
    alone = compute_map(view)
    assert alone.reused == 0
    np.testing.assert_array_equal(m.outcome, alone.outcome)
    np.testing.assert_array_equal(m.steps, alone.steps)
    np.testing.assert_array_equal(m.status, alone.status)
    np.testing.assert_array_equal(m.outcome, scan_outcomes(tmp_path, WINDOW, 31))


def test_maps_of_another_configuration_are_not_reused():
    from dicetrace.explore import View, compute_map
    from dicetrace.ics import get_window

    view = View(window=get_window(WINDOW), res=(31, 31))
    other = compute_map(View(window=get_window(WINDOW), res=(7, 7), gamma=0.02))
    shifted = compute_map(View(window=((1.4, 1.57), (3.95, 4.25)), res=(7, 7)))
    assert compute_map(view, known=[other, shifted]).reused == 0


def test_strips_stream_is_the_map_row_by_row(client, tmp_path, monkeypatch):
    from dicetrace.explore import outcome_map

    monkeypatch.setattr(outcome_map, "BLOCK", 4 * RES)  # four rows per strip
    with client.stream("GET", "/api/map.strips", params={"window": WINDOW, "res": RES}) as r:
        assert r.status_code == 200 and r.headers["content-type"].startswith("application/x-ndjson")
        strips, done = strip_lines(r.iter_lines())
    assert [(s["row0"], s["row1"]) for s in strips] == [(0, 4), (4, 8), (8, 12), (12, 16)]
    assert done["res"] == [RES, RES] and sum(done["counts"].values()) == RES * RES
    np.testing.assert_array_equal(strips_outcomes(strips, RES), scan_outcomes(tmp_path, WINDOW, RES))
    # a cached map comes back at once, in the same strips
    with client.stream("GET", "/api/map.strips", params={"window": WINDOW, "res": RES}) as r:
        again, _ = strip_lines(r.iter_lines())
    assert again == strips
    r = client.get("/api/map.strips", params={"window": WINDOW, "res": "0"})
    assert r.status_code == 400 and r.json()["param"] == "res"


@pytest.mark.slow
def test_strips_arrive_while_the_map_computes(monkeypatch):
    from dicetrace.explore import Explorer, outcome_map

    monkeypatch.setattr(outcome_map, "BLOCK", 4 * 96)  # 24 strips of 4 rows
    with Explorer(window="red-sea", res=RES) as ex:
        base = f"http://127.0.0.1:{ex.port}/api/map.strips?window=red-sea"
        urllib.request.urlopen(base + "&res=8", timeout=120).read()  # compiled and warm
        t0 = time.perf_counter()
        arrived = []
        with urllib.request.urlopen(base + "&res=96&client=s", timeout=300) as r:
            for line in r:
                arrived.append((time.perf_counter() - t0, json.loads(line)))
    strips = [m for _, m in arrived if "row0" in m]
    assert len(strips) == 24 and arrived[-1][1].get("done")
    first, last = arrived[0][0], arrived[-1][0]
    assert first < last / 3, f"the first strip came at {first:.2f} s of {last:.2f} s: not as it was computed"


def test_viewer_throw_is_record_recording_with_its_blueprint(client, tmp_path, dicetrace_cli):
    from rrd_blueprint import blueprint_tree

    q = {"window": WINDOW, "res": RES, "x": 1.47, "y": 4.19}
    hov = client.get("/api/hover", params=q).json()
    served = tmp_path / "served.rrd"
    served.write_bytes(client.get("/api/throw.rrd", params=q).content)  # as the page's viewer opens it
    downloaded = tmp_path / "downloaded.rrd"
    downloaded.write_bytes(client.get("/api/throw.rrd", params={**q, "download": 1}).content)
    rec = tmp_path / "record"
    rec.mkdir()
    x, y = hov["coords"]["x"], hov["coords"]["y"]
    res = dicetrace_cli("record", "--slice", "seed", "--at", f"{x!r},{y!r}", cwd=rec)
    assert res.returncode == 0, res.stderr
    (recorded,) = rec.glob("**/*.rrd")
    want = blueprint_tree(recorded)
    assert blueprint_tree(served) == want and blueprint_tree(downloaded) == want
    origins = {v["ViewBlueprint:space_origin"][0] for v in want.values() if "ViewBlueprint:space_origin" in v}
    assert origins == {"/world", "/energy", "/stop_test", "/stop_margin", "/contacts", "/summary"}


@pytest.mark.slow
def test_a_newer_view_ends_the_stale_strips_stream_at_its_next_strip(monkeypatch):
    from dicetrace.explore import Explorer, outcome_map

    monkeypatch.setattr(outcome_map, "BLOCK", 2 * 200)  # strips of 2 rows: 100 of them
    with Explorer(window="red-sea", res=RES) as ex:
        base = f"http://127.0.0.1:{ex.port}/api/map.strips?window=red-sea"
        urllib.request.urlopen(base + "&res=8", timeout=120).read()  # compiled and warm
        with urllib.request.urlopen(base + "&res=200&client=z", timeout=300) as stale:
            first = json.loads(stale.readline())
            assert (first["row0"], first["row1"]) == (0, 2)
            with urllib.request.urlopen(base + f"&res={RES}&client=z", timeout=300) as fresh:
                strips, done = strip_lines(fresh)
            rest = [json.loads(line) for line in stale]
        assert done["res"] == [RES, RES] and strips[-1]["row1"] == RES
        assert rest[-1] == {"error": "superseded by a newer view", "status": 409}
        assert len(rest) - 1 < 99, "the stale map went on to its end"
        assert ex.app.state.worker.cancelled_count == 1
