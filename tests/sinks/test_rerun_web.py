"""``record --serve``'s web viewer server (:mod:`dicetrace.sinks.rerun_web`), over real HTTP on 127.0.0.1.

What the page looks like in a browser is tests/sinks/test_rerun_stream.py's (slow); here: what the
server serves, and that a port it cannot listen on is one line, also through :class:`Stream`.
"""

from __future__ import annotations

import socket
import urllib.error
import urllib.request

import pytest

from dicetrace.sinks.rerun_stream import Stream, StreamError
from dicetrace.sinks.rerun_view import default_blueprint
from dicetrace.sinks.rerun_web import (FAVICON_LINK, FAVICON_SVG, VIEWER_ASSETS, WebViewerError, WebViewerServer,
                                      viewer_assets_folder)

pytestmark = pytest.mark.skipif(viewer_assets_folder() is None, reason="rerun-notebook (Rerun's web viewer) is missing")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _get(url: str, method: str = "GET"):
    with urllib.request.urlopen(urllib.request.Request(url, method=method), timeout=10) as r:
        return r.status, r.headers, r.read()


def test_serves_the_page_and_the_viewer_files_and_nothing_else():
    port = _free_port()
    grpc_url = "rerun+http://127.0.0.1:9876/proxy"
    server = WebViewerServer("127.0.0.1", port, grpc_url)
    try:
        status, headers, body = _get(f"http://127.0.0.1:{port}/")
        assert status == 200 and headers["Content-Type"].startswith("text/html")
        page = body.decode()
        assert grpc_url in page and "connect-src 'self' http://*:9876" in page  # the gRPC port, nothing else
        folder = viewer_assets_folder()
        for path, ctype in VIEWER_ASSETS.items():
            status, headers, body = _get(f"http://127.0.0.1:{port}{path}")
            assert (status, headers["Content-Type"]) == (200, ctype)
            assert body == (folder / path.lstrip("/")).read_bytes()
        # the page's icon: named in the page (a data: URL) and served where a browser looks for one (issue 46 item 13)
        assert FAVICON_LINK in page
        status, headers, body = _get(f"http://127.0.0.1:{port}/favicon.ico")
        assert (status, headers["Content-Type"], body) == (200, "image/svg+xml", FAVICON_SVG)
        status, headers, body = _get(f"http://127.0.0.1:{port}/widget.js", method="HEAD")
        assert status == 200 and body == b"" and int(headers["Content-Length"]) > 0
        with pytest.raises(urllib.error.HTTPError) as err:
            _get(f"http://127.0.0.1:{port}/../pyproject.toml")
        assert err.value.code == 404
    finally:
        server.close()


def test_a_taken_port_is_one_line():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(WebViewerError, match=rf"^cannot listen on 127\.0\.0\.1 port {port}: "):
            WebViewerServer("127.0.0.1", port, "rerun+http://127.0.0.1:9876/proxy")


def test_serve_reports_a_web_port_taken_after_its_check_as_a_serve_error(monkeypatch):
    """The web port checked free (``check_serve``) and taken before the server listens: one ``--serve:`` line."""
    monkeypatch.setenv("RUST_LOG", "off")  # before rerun loads (default_blueprint): no SDK log lines
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        web_port = taken.getsockname()[1]
        stream = Stream(default_blueprint())
        try:
            with pytest.raises(StreamError, match=rf"^--serve: cannot listen on 127\.0\.0\.1 port {web_port}: "):
                stream.serve(grpc_port=_free_port(), web_port=web_port)
        finally:
            stream.close()
