"""``record --serve``'s web viewer in a real headless browser (Debian's chromium through Playwright).

Skipped, with the reason, where Playwright or a chromium is missing.  The page is served by
dicetrace on the bound address (:class:`dicetrace.sinks.rerun_web.WebViewerServer`): the
viewer starts, reads the recording from the gRPC server, and makes no request beyond the two
local servers (its update check, a request to api.github.com, is turned off).
"""

from __future__ import annotations

import socket
import subprocess
import sys
from urllib.parse import urlsplit

import pytest

from local_processes import interrupt

pytestmark = pytest.mark.slow


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.long
def test_served_web_viewer_reads_the_recording_and_asks_nothing_beyond_this_machine(tmp_path, browser):
    grpc, web = _free_port(), _free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "dicetrace.cli", "record", "--slice", "seed", "--at", "1.65,3.9", "--serve",
         "--port", str(grpc), "--web-port", str(web), "--serve-for", "300"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        outcome, first = proc.stdout.readline(), proc.stdout.readline()  # the outcome first, then the URL
        assert outcome.startswith("outcome 3 "), outcome
        assert first.startswith(f"serving the web viewer at http://127.0.0.1:{web}/"), first
        url = first.split(" at ", 1)[1].split(" ", 1)[0]
        page = browser.new_page(viewport={"width": 1200, "height": 800})
        requests, errors, missing = [], [], []
        page.on("request", lambda r: requests.append(r.url))
        page.on("response", lambda r: r.status == 404 and missing.append(r.url))
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(url)
        page.wait_for_function("document.body.dataset.ready === '1'", timeout=180_000)  # the viewer started
        # it reads the recording from the gRPC server (gRPC-web over HTTP): waited for, at most a minute
        for _ in range(300):
            if any(urlsplit(u).port == grpc and "MessageProxyService/ReadMessages" in u for u in requests):
                break
            page.wait_for_timeout(200)
        else:
            raise AssertionError(f"the viewer never read the recording from port {grpc}: {requests}")
        page.wait_for_timeout(2000)  # what it asks for once it runs (the update check came here) is seen too
        hosts = {(urlsplit(u).hostname, urlsplit(u).port) for u in requests if urlsplit(u).scheme in ("http", "https")}
        assert hosts <= {("127.0.0.1", web), ("127.0.0.1", grpc)}, hosts
        assert page.evaluate("document.body.dataset.blocked || ''") == ""  # and nothing had to be blocked
        assert not errors, errors
        assert not missing, f"answered 404: {missing}"  # issue 46 item 13: no /favicon.ico 404 either
    finally:
        interrupt(proc, 60)
