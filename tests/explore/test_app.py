"""The explorer app under starlette's TestClient: maps equal ``dicetrace scan``, hover equals ``simulate``, bad input is a 400."""

from __future__ import annotations

import time

import numpy as np
import pytest

from explore_helpers import RES, WINDOW, png_outcomes, scan_outcomes


def test_page_serves_the_controls_and_the_view(client):
    r = client.get("/")
    assert r.status_code == 200 and "text/html" in r.headers["content-type"]
    for part in ('id="map"', 'id="viewerbox"', "/rerun/widget.js", "save view as scan", 'id="back"', 'id="reset"'):
        assert part in r.text
    assert '"window": "1.4,1.56,3.95,4.25"' in r.text  # the start view, as URL parameters


def test_map_colours_equal_dicetrace_scan(client, tmp_path):
    expected = scan_outcomes(tmp_path, WINDOW, RES)
    assert len(np.unique(expected)) >= 5  # a window worth comparing
    r = client.get("/api/map.png", params={"window": WINDOW, "res": RES})
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    got = png_outcomes(r.content)
    assert got.shape == (RES, RES)
    np.testing.assert_array_equal(got, expected)
    j = client.get("/api/map.json", params={"window": WINDOW, "res": RES}).json()
    np.testing.assert_array_equal(np.array(j["outcome"]), expected)


def test_zoom_recomputes_the_new_window(client, tmp_path):
    first = png_outcomes(client.get("/api/map.png", params={"window": WINDOW, "res": RES}).content)
    zoom = "1.45,1.5,4.0,4.1"
    expected = scan_outcomes(tmp_path, zoom, RES, name="zoom")
    got = png_outcomes(client.get("/api/map.png", params={"window": zoom, "res": RES}).content)
    np.testing.assert_array_equal(got, expected)
    assert not np.array_equal(got, first)


def test_coarse_pass_is_the_quarter_resolution_grid(client, tmp_path):
    r = client.get("/api/map.png", params={"window": WINDOW, "res": 32, "pass": "coarse"})
    assert r.headers["x-dicetrace-res"] == "8,8"
    np.testing.assert_array_equal(png_outcomes(r.content), scan_outcomes(tmp_path, WINDOW, 8))


def test_preview_pass_and_a_bad_pass(client, tmp_path):
    r = client.get("/api/map.png", params={"window": WINDOW, "res": 64, "pass": "preview"})
    assert r.headers["x-dicetrace-res"] == "4,4"
    np.testing.assert_array_equal(png_outcomes(r.content), scan_outcomes(tmp_path, WINDOW, 4))
    r = client.get("/api/map.png", params={"window": WINDOW, "res": RES, "pass": "sketch"})
    assert r.status_code == 400 and r.json()["param"] == "pass"


def test_hover_equals_simulate_of_that_ic(client):
    from dicetrace.ics import grid_axis, seed_slice
    from dicetrace.simulate import simulate

    j = client.get("/api/hover", params={"window": WINDOW, "res": RES, "x": 1.47, "y": 4.19}).json()
    xs, ys = grid_axis(1.4, 1.56, RES), grid_axis(3.95, 4.25, RES)
    i, k = int(np.argmin(abs(xs - 1.47))), int(np.argmin(abs(ys - 4.19)))
    assert (j["i"], j["j"]) == (i, k)
    assert j["coords"] == {"x": xs[i], "y": ys[k]}
    ic = seed_slice(xs[i], ys[k])
    assert [j["ic"][n] for n in ("vx", "vy", "vz", "Lx", "Ly", "Lz")] == ic.tolist()
    roll = simulate(ic)
    assert (j["outcome"], j["status"], j["steps"], j["contact_sequence"]) == (
        roll.outcome, roll.status.label, roll.steps, roll.contact_sequence)
    assert j["t_settle_s"] == roll.t_settle_s
    # the map's pixel there has that outcome
    m = client.get("/api/map.json", params={"window": WINDOW, "res": RES}).json()
    assert m["outcome"][i][k] == roll.outcome


def test_hover_follows_the_configuration(client):
    from dicetrace.explore.view import view_from_query
    from dicetrace.explore.compute import point_ic
    from dicetrace.simulate import simulate

    q = {"window": WINDOW, "res": RES, "i": 3, "j": 5, "preset": "physical", "integrator": "semi-implicit-euler",
         "gamma": "0.01"}
    j = client.get("/api/hover", params=q).json()
    v = view_from_query({k: str(val) for k, val in q.items()})
    _, ic = point_ic(v, 3, 5)
    roll = simulate(ic, config=v.config())
    assert j["l_convention"] == "physical" and j["preset"] == "physical"
    assert (j["outcome"], j["steps"], j["contact_sequence"]) == (roll.outcome, roll.steps, roll.contact_sequence)
    assert roll.config.preset.gamma == 0.01


def test_throw_rrd_is_the_record_recording_of_that_point(client, tmp_path):
    from dicetrace.sinks.rerun import read_rrd_metadata

    q = {"window": WINDOW, "res": RES, "x": 1.47, "y": 4.19}
    hov = client.get("/api/hover", params=q).json()
    r = client.get("/api/throw.rrd", params={**q, "download": 1})
    assert r.status_code == 200
    assert r.headers["x-dicetrace-outcome"] == str(hov["outcome"])
    assert "attachment" in r.headers["content-disposition"] and ".rrd" in r.headers["content-disposition"]
    path = tmp_path / "throw.rrd"
    path.write_bytes(r.content)
    meta = read_rrd_metadata(path)
    assert meta["outcome"] == hov["outcome"] and meta["steps"] == hov["steps"]
    assert meta["contact_sequence"] == hov["contact_sequence"]
    assert list(meta["ic"]) == [hov["ic"][n] for n in ("vx", "vy", "vz", "Lx", "Ly", "Lz")]


@pytest.mark.parametrize(
    "path, params, param",
    [
        ("/api/map.png", {"res": "abc"}, "res"),
        ("/api/map.png", {"res": "5000"}, "res"),
        ("/api/map.png", {"window": "1,1,3,4"}, "window"),
        ("/api/map.json", {"window": "garbage"}, "window"),
        ("/api/map.png", {"slice": "nope"}, "slice"),
        ("/api/map.png", {"gamma": "abc"}, "gamma"),
        ("/api/view", {"dt": "-1"}, "dt"),
        ("/api/hover", {"x": "1.45"}, "x,y"),
        ("/api/hover", {"x": "9", "y": "4"}, "x,y"),
        ("/api/hover", {"i": "99", "j": "0"}, "i,j"),
        ("/api/throw.rrd", {"i": "a", "j": "0"}, "i,j"),
        # refused by the configuration layer (make_config, get_res), not by the explorer: a ConfigError naming its field
        ("/api/map.png", {"preset": "wood"}, "preset"),
        ("/api/map.json", {"integrator": "leapfrog"}, "integrator"),
        ("/api/hover", {"preset": "physical", "integrator": "contact-rosenbrock", "i": "1", "j": "1"}, "integrator"),
        ("/api/map.png", {"res": "3,4,5"}, "res"),
    ],
)
def test_bad_parameters_get_a_400_naming_them(client, path, params, param):
    r = client.get(path, params={"window": WINDOW, "res": RES, **params} if "window" not in params else {"res": RES, **params})
    assert r.status_code == 400, r.text
    body = r.json()
    assert body["param"] == param and body["error"].startswith(param)
    assert client.get("/api/health").json()["ok"] is True  # the server goes on


def test_save_writes_the_scan_dataset_only_inside_the_chosen_folder(client, tmp_path):
    from dicetrace.ics import Grid, get_window
    from dicetrace.scan import label_grid, scan_definition

    r = client.post("/api/save", params={"window": WINDOW, "res": RES, "name": "view-1"})
    assert r.status_code == 200, r.text
    folder = tmp_path / "saved" / "view-1"
    assert r.json()["path"] == str(folder.resolve()) and r.json()["n_ics"] == RES * RES
    defn = scan_definition(folder)
    assert defn.space == Grid("seed", get_window(WINDOW), RES)
    np.testing.assert_array_equal(label_grid(folder), scan_outcomes(tmp_path, WINDOW, RES))
    before = sorted(p.name for p in tmp_path.iterdir())
    for bad in ("../escape", "/abs", ".hidden", "", "a/b", "x" * 70):
        r = client.post("/api/save", params={"window": WINDOW, "res": RES, "name": bad})
        assert r.status_code == 400 and r.json()["param"] == "name", bad
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    assert sorted(p.name for p in (tmp_path / "saved").iterdir()) == ["view-1"]


def test_save_is_off_without_a_folder():
    from starlette.testclient import TestClient

    from dicetrace.explore import create_app

    with TestClient(create_app(), base_url="http://127.0.0.1") as c:
        r = c.post("/api/save", params={"res": 4, "name": "x"})
        assert r.status_code == 403 and "--out" in r.json()["error"]


def test_rerun_web_viewer_files_are_served(client):
    r = client.get("/rerun/widget.js")
    assert r.status_code == 200 and "javascript" in r.headers["content-type"]
    assert "re_viewer_bg.wasm" in r.text and "open_url" in r.text
    r = client.head("/rerun/re_viewer_bg.wasm")
    assert r.status_code == 200 and r.headers["content-type"] == "application/wasm"


def test_seed3_map_is_the_scan_of_that_z_level(client, tmp_path):
    from dicetrace.ics import Grid, get_window
    from dicetrace.scan import label_grid, scan

    r = client.get("/api/map.png", params={"slice": "seed3", "window": "home", "z": "0.03", "res": 8})
    assert r.status_code == 200, r.text
    scan(Grid("seed3", get_window("home") + ((0.03, 0.03),), (8, 8, 1)), tmp_path / "s3")
    np.testing.assert_array_equal(png_outcomes(r.content), label_grid(tmp_path / "s3")[:, :, 0])
    other = png_outcomes(client.get("/api/map.png", params={"slice": "seed3", "window": "home", "z": "0.09",
                                                            "res": 8}).content)
    scan(Grid("seed3", get_window("home") + ((0.09, 0.09),), (8, 8, 1)), tmp_path / "s3b")
    np.testing.assert_array_equal(other, label_grid(tmp_path / "s3b")[:, :, 0])


@pytest.mark.parametrize("headers, why", [
    ({"Origin": "http://evil.example"}, "Origin"),
    ({"Origin": "http://evil.example", "Sec-Fetch-Site": "cross-site"}, "Sec-Fetch-Site"),
    ({"Sec-Fetch-Site": "cross-site"}, "Sec-Fetch-Site"),  # a browser that sent no Origin
    ({"Sec-Fetch-Site": "same-site", "Origin": "http://localhost"}, "Sec-Fetch-Site"),
    ({"Origin": "null"}, "Origin"),  # a sandboxed frame, a file:// page
    ({"Origin": "http://127.0.0.1:9999"}, "Origin"),  # another port is another origin
    ({"Origin": "http://localhost"}, "Origin"),  # another name is another origin
    ({"Origin": "https://127.0.0.1"}, "Origin"),
])
def test_a_foreign_page_cannot_save(client, tmp_path, headers, why):
    r = client.post("/api/save", params={"window": WINDOW, "res": 4, "name": "planted"}, headers=headers)
    assert r.status_code == 403, r.text
    assert r.json()["error"].startswith(f"cross-origin request refused: {why}")
    assert not (tmp_path / "saved" / "planted").exists()
    assert not (tmp_path / "saved").exists() or not any((tmp_path / "saved").iterdir())


@pytest.mark.parametrize("headers", [
    {"Origin": "http://127.0.0.1", "Sec-Fetch-Site": "same-origin"},  # the page's own fetch
    {"Origin": "http://127.0.0.1"},  # a browser without Fetch Metadata
    {},  # not a browser (curl, urllib)
])
def test_the_pages_own_save_and_a_script_still_save(client, tmp_path, headers):
    r = client.post("/api/save", params={"window": WINDOW, "res": 4, "name": "mine"}, headers=headers)
    assert r.status_code == 200, r.text
    assert (tmp_path / "saved" / "mine" / "_scan.parquet").is_file()


@pytest.mark.parametrize("host", ["evil.example", "evil.example:8000", "127.0.0.1.evil.example", "10.0.0.1", "[::2]"])
def test_a_foreign_host_name_is_refused(client, host):
    """DNS rebinding: a page of evil.example whose name now points at 127.0.0.1 sends Host: evil.example."""
    for path in ("/", "/api/map.png?res=4", "/api/health", "/api/throw.rrd?i=0&j=0&res=4"):
        r = client.get(path, headers={"Host": host})
        assert r.status_code == 400, (path, r.status_code)
    r = client.post("/api/save", params={"res": 4, "name": "x"}, headers={"Host": host})
    assert r.status_code == 400


def test_the_servers_own_names_are_answered(client):
    for host in ("127.0.0.1", "127.0.0.1:8765", "localhost:8765", "LOCALHOST", "[::1]:8765"):
        assert client.get("/api/health", headers={"Host": host}).status_code == 200, host


def test_no_cors_headers_for_a_foreign_origin(client):
    for path in ("/api/throw.rrd", "/api/hover", "/api/map.png", "/api/map.json", "/api/view", "/", "/favicon.ico"):
        r = client.get(path, params={"window": WINDOW, "res": 4, "i": 1, "j": 2},
                       headers={"Origin": "http://evil.example"})
        # what computes is refused to another origin (test_gets_that_compute_are_refused_to_other_sites); the rest
        # is answered, and nothing carries a CORS header
        assert r.status_code == (403 if path.startswith(("/api/throw", "/api/hover", "/api/map")) else 200), path
        assert not [k for k in r.headers if k.lower().startswith("access-control-")], (path, dict(r.headers))
    r = client.options("/api/save", headers={"Origin": "http://evil.example", "Access-Control-Request-Method": "POST"})
    assert not [k for k in r.headers if k.lower().startswith("access-control-")]


def test_allowed_hosts_are_the_local_names_and_the_listening_address():
    from dicetrace.explore.app import LOCAL_HOSTS, allowed_hosts

    assert allowed_hosts() == list(LOCAL_HOSTS)
    assert allowed_hosts(["192.168.1.7"]) == [*LOCAL_HOSTS, "192.168.1.7"]
    assert allowed_hosts(["::1"]) == list(LOCAL_HOSTS)
    assert allowed_hosts(["fe80::0001"]) == [*LOCAL_HOSTS, "[fe80::1]"]
    assert allowed_hosts(["My-Box"]) == [*LOCAL_HOSTS, "my-box"]
    assert allowed_hosts(["0.0.0.0"]) == ["*"]  # every interface, by the user's choice


def test_a_throw_past_its_time_limit_is_a_504_naming_dt(client, monkeypatch):
    from dicetrace.explore import app

    # 5.2 million steps at dt = 1e-7: at least ~0.05 s on any machine, far past a 2 ms limit (a 0.3 s limit
    # was met by a fast, idle machine)
    monkeypatch.setattr(app, "THROW_TIMEOUT_S", 0.002)
    r = client.get("/api/hover", params={"window": WINDOW, "res": RES, "i": 3, "j": 4, "dt": "1e-7"})
    assert r.status_code == 504, r.text
    assert r.json()["param"] == "dt" and r.json()["error"].startswith("dt: this throw took more than 0.002 s")
    assert client.get("/api/health").json()["ok"] is True


def test_throws_waiting_are_bounded_a_full_queue_is_a_503(client, monkeypatch):
    """Hovers at a tiny dt take seconds each: past MAX_THROWS_WAITING waiting, more are refused, not queued."""
    import threading

    from dicetrace.explore import compute

    worker = client.app.state.worker
    release, started = threading.Event(), threading.Semaphore(0)

    def hold():
        started.release()
        release.wait(60)

    for _ in range(2):  # both throw threads busy until released
        worker.submit_throw(hold)
    try:
        assert started.acquire(timeout=30) and started.acquire(timeout=30)
        waiting = [worker.submit_throw(lambda: None) for _ in range(compute.MAX_THROWS_WAITING)]
        for path in ("/api/hover", "/api/throw.rrd"):
            r = client.get(path, params={"window": WINDOW, "res": RES, "i": 1, "j": 1})
            assert r.status_code == 503, r.text
            assert "throws to simulate are waiting already" in r.json()["error"]
    finally:
        release.set()
    for f in waiting:
        f.result(timeout=30)
    assert client.get("/api/hover", params={"window": WINDOW, "res": RES, "i": 1, "j": 1}).status_code == 200


# -- issue 47 B1: GETs that compute are the explorer's own page's; a throw record would refuse is refused ----------

COMPUTING_GETS = [("/api/map.png", {}), ("/api/map.json", {}), ("/api/map.strips", {}), ("/api/hover", {"i": 1, "j": 2}),
                  ("/api/throw.rrd", {"i": 1, "j": 2}),
                  ("/api/compare.rrd", {"t": [f"window={WINDOW}&res=4&i=1&j=2", f"window={WINDOW}&res=4&i=2&j=1"]})]


def _nothing_may_compute(worker, monkeypatch):
    def boom(*a, **k):
        raise AssertionError("a refused request computed something")

    monkeypatch.setattr(worker, "submit_map", boom)
    monkeypatch.setattr(worker, "submit_throw", boom)
    monkeypatch.setattr(worker, "submit_scan", boom)


@pytest.mark.parametrize("path, extra", COMPUTING_GETS, ids=[p for p, _ in COMPUTING_GETS])
@pytest.mark.parametrize("headers", [
    {"Sec-Fetch-Site": "cross-site"},  # an <img> or a no-cors fetch of another site's page
    {"Sec-Fetch-Site": "same-site"},  # a page on another port of this machine
    {"Origin": "http://evil.example"},  # a browser without Fetch Metadata, a CORS fetch
], ids=["cross-site", "same-site", "origin"])
def test_gets_that_compute_are_refused_to_other_sites(client, monkeypatch, path, extra, headers):
    """Issue 47 B1: any page could make the explorer compute (a map, a 1e-7 s throw) from an <img>; a GET that
    computes from another site gets a 403, as a POST does, and runs nothing."""
    _nothing_may_compute(client.app.state.worker, monkeypatch)
    r = client.get(path, params={"window": WINDOW, "res": 4, **extra}, headers=headers)
    assert r.status_code == 403, r.text
    assert r.json()["error"].startswith("cross-origin request refused")


@pytest.mark.parametrize("headers", [{"Sec-Fetch-Site": "same-origin", "Origin": "http://127.0.0.1"},
                                     {"Sec-Fetch-Site": "none"}, {}], ids=["page", "typed-url", "script"])
def test_gets_that_compute_serve_the_page_a_typed_url_and_a_script(client, headers):
    for path, extra in COMPUTING_GETS:
        r = client.get(path, params={"window": WINDOW, "res": 4, **extra}, headers=headers)
        assert r.status_code == 200, (path, r.text[:200])


def test_a_throw_record_would_refuse_for_its_memory_is_refused_before_it_runs(client, monkeypatch, tmp_path,
                                                                              dicetrace_cli):
    """Issue 47 B1: ``/api/throw.rrd?dt=1e-7`` took the server past 6 GB; ``record --dt 1e-7`` refuses the same
    throw up front.  The explorer applies record's bound (its recording may need more memory than is available)
    before anything runs, to the viewer's throw and to a comparison, a 400 naming dt; below the bound it records."""
    worker = client.app.state.worker
    q = {"window": WINDOW, "res": 16, "i": 8, "j": 8}
    with monkeypatch.context() as mp:  # the throw: 600 million steps at the time cap, terabytes
        _nothing_may_compute(worker, mp)
        for path, params in (("/api/throw.rrd", {**q, "dt": "1e-7"}),
                             ("/api/compare.rrd", {"t": [f"window={WINDOW}&res=16&i=8&j=8&dt=1e-7",
                                                         f"window={WINDOW}&res=16&i=2&j=8&dt=1e-7"]})):
            r = client.get(path, params=params)
            assert r.status_code == 400 and r.json()["param"] == "dt", r.text
            assert "more than the" in r.json()["error"] and "longer time step (dt)" in r.json()["error"]
    # the same bound as record's: with 1 GiB available, dt 1e-4 (600,000 steps, 1.39 GiB) is refused by both, before
    # simulating; dt 1e-3 (60,000 steps, 143 MiB) is recorded by both
    monkeypatch.setattr("dicetrace.memory.available_memory", lambda: 2**30)
    r = client.get("/api/throw.rrd", params={**q, "dt": "1e-4"})
    assert r.status_code == 400 and r.json()["param"] == "dt" and "1.39 GiB of memory, more than the 1 GiB" in r.json()["error"], r.text
    res = dicetrace_cli("record", "--slice", "seed", "--at", "1.45,4.1", "--dt", "1e-4", cwd=tmp_path)
    assert res.returncode == 2 and "1.39 GiB of memory, more than the 1 GiB" in res.stderr, res.stderr
    assert client.get("/api/throw.rrd", params={**q, "dt": "1e-3"}).status_code == 200
    res = dicetrace_cli("record", "--slice", "seed", "--at", "1.45,4.1", "--dt", "1e-3", cwd=tmp_path)
    assert res.returncode == 0, res.stderr


def test_the_favicon_is_served(client):
    """Issue 46 item 13: no 404 for /favicon.ico; the page names the same icon (a data: URL, no request)."""
    from dicetrace.sinks.rerun_web import FAVICON_LINK, FAVICON_SVG

    r = client.get("/favicon.ico")
    assert r.status_code == 200 and r.headers["content-type"].startswith("image/svg+xml") and r.content == FAVICON_SVG
    assert FAVICON_LINK in client.get("/").text


# -- issue 47 B3: saves get the map budget and a bounded queue ------------------------------------------------------


def test_a_save_the_map_budget_would_refuse_is_refused_and_writes_nothing(tmp_path):
    """Issue 47 B3: ``POST /api/save?res=1024&preset=physical&dt=1e-6`` ran for hours on the save thread.  A save is
    refused (422 naming res) where the view's map would be: here a 32×32 view at dt 1e-4 under a 1 ms budget."""
    from starlette.testclient import TestClient

    from dicetrace.explore import View, create_app
    from dicetrace.ics import get_window

    out = tmp_path / "saved"
    app = create_app(View(window=get_window(WINDOW), res=(RES, RES)), out=out, map_budget_s=0.001)
    with TestClient(app, base_url="http://127.0.0.1") as c:
        c.get("/api/map.png", params={"res": 4})  # the kernel compiled (not the point here)
        r = c.post("/api/save", params={"res": 32, "dt": "1e-4", "name": "big"})
        assert r.status_code == 422, r.text
        assert r.json()["param"] == "res" and "more than the explorer's 0.001 s per map" in r.json()["error"]
        assert not (out / "big").exists()
        assert c.get("/api/health").json()["over_budget"] == 1


def test_saves_waiting_are_bounded_a_full_queue_is_a_503_before_any_computing(client, tmp_path):
    import threading

    from dicetrace.explore import compute

    worker = client.app.state.worker
    release, started = threading.Event(), threading.Event()

    def hold():
        started.set()
        release.wait(60)

    worker._saves.submit(hold)  # the save thread busy until released
    try:
        assert started.wait(30)
        waiting = [worker._saves.submit(lambda: None) for _ in range(compute.MAX_SAVES_WAITING)]
        before = worker.computed_count
        r = client.post("/api/save", params={"window": WINDOW, "res": 8, "name": "queued"})
        assert r.status_code == 503, r.text
        assert "saves are waiting already" in r.json()["error"]
        assert worker.computed_count == before and not (tmp_path / "saved" / "queued").exists()
    finally:
        release.set()
    for f in waiting:
        f.result(timeout=30)
    r = client.post("/api/save", params={"window": WINDOW, "res": 8, "name": "queued"})
    assert r.status_code == 200, r.text


def test_stopping_fails_the_throws_and_saves_in_progress_at_once_and_quietly():
    """What Ctrl-C does first (``Worker.cancel_all``): the requests waiting for a save or a throw answer at once
    (Cancelled), and the call still running on its thread ends later without an error escaping its thread."""
    import threading

    from dicetrace.explore import Cancelled, Worker

    w = Worker()
    release, started = threading.Event(), threading.Event()
    escaped = []
    old_hook = threading.excepthook
    threading.excepthook = lambda a: escaped.append(a.exc_value)
    try:
        def hold():
            started.set()
            release.wait(60)
            return "done"

        save = w._saves.submit(hold)
        queued = w._saves.submit(lambda: "never")
        throw = w.submit_throw(hold)
        assert started.wait(30)
        w.cancel_all()
        for f in (save, queued, throw):
            with pytest.raises(Cancelled):
                f.result(timeout=1)
        release.set()
        time.sleep(0.5)  # the held calls return into their settled futures
        assert not escaped, escaped
    finally:
        threading.excepthook = old_hook
        release.set()
        w.shutdown()
