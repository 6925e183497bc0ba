"""Rerun's web viewer over HTTP, for ``record --serve``: a page and the viewer's files, on the bound address.

The viewer is rerun-notebook's build of Rerun's web viewer (its ``static`` folder, found without
importing the package: :func:`viewer_assets_folder`), in a page of dicetrace's (:data:`VIEWER_PAGE`)
that opens the recording's gRPC address, connects to nothing but this server and the gRPC port, and
turns off the viewer's update check.  :class:`WebViewerServer` serves it from threads of this
process on the address given (the SDK's own web server listens on every interface and has no bind
option in 0.41).  The recording itself is sent by :mod:`dicetrace.sinks.rerun_stream`.
"""

from __future__ import annotations

import importlib.util
import shutil
import socket
import threading
import urllib.parse
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path


#: The pages' icon (the explorer's and ``record --serve``'s): a die's face three in the writeup's red, SVG.  Both
#: pages name it in a ``<link rel="icon">`` (:data:`FAVICON_LINK`) and serve it at ``/favicon.ico`` too, so a
#: browser asks for nothing that is not there.
FAVICON_SVG = (b'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 16 16">'
               b'<rect x="1" y="1" width="14" height="14" rx="3" fill="#dc1e1e"/>'
               b'<g fill="#fff"><circle cx="4.5" cy="4.5" r="1.6"/><circle cx="8" cy="8" r="1.6"/>'
               b'<circle cx="11.5" cy="11.5" r="1.6"/></g></svg>')
#: The ``<link>`` that gives a page :data:`FAVICON_SVG` (a data: URL: no request at all).
FAVICON_LINK = f'<link rel="icon" type="image/svg+xml" href="data:image/svg+xml,{urllib.parse.quote(FAVICON_SVG)}">'


class WebViewerError(RuntimeError):
    """The web viewer cannot be served: its files are missing, or its address cannot be listened on."""


#: The web viewer's page: rerun-notebook's build of Rerun's viewer, full window, opening the ``url`` of the query
#: (a gRPC address; an unspecified host, 0.0.0.0 or [::], means the host this page came from).  It connects to
#: this server and the gRPC port only (a Content-Security-Policy), and turns off the viewer's update check (its
#: "check for updates on startup" setting, in this origin's localStorage) before the viewer starts: the viewer
#: would ask api.github.com for its latest release.
VIEWER_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>dicetrace record: Rerun viewer</title>
<meta http-equiv="Content-Security-Policy" content="connect-src 'self' http://*:__GRPC_PORT__">
__FAVICON__
<link rel="stylesheet" href="widget.css">
<style>html, body { margin: 0; height: 100%; overflow: hidden; } #viewer { width: 100vw; height: 100vh; }</style>
</head><body><div id="viewer"></div>
<script type="module">
const box = document.getElementById("viewer");
const given = new URLSearchParams(location.search).get("url") || "__GRPC_URL__";
const url = given.replace(/^(rerun(\\+https?)?:\\/\\/)(0\\.0\\.0\\.0|\\[::\\])(?=[:\\/])/, (_, scheme) => scheme + location.host.replace(/:\\d+$/, ""));
const size = () => [box.clientWidth, box.clientHeight];
const handlers = {};
const model = {
  get: (k) => ({_url: url, _panel_states: null, _width: size()[0], _height: size()[1], _fallback_token: null,
                _theme: null})[k],
  on: (ev, f) => { (handlers[ev] = handlers[ev] || []).push(f); },
  send: (m) => { if (m === "ready") document.body.dataset.ready = "1"; },
};
document.addEventListener("securitypolicyviolation", (ev) => {  // what the policy blocked, for the tests
  document.body.dataset.blocked = ((document.body.dataset.blocked || "") + " " + ev.blockedURI).trim();
});
try {  // the viewer's settings: "app" in RON; turn its update check off before it reads them
  const key = "app", off = "check_for_updates_on_startup:false", state = localStorage.getItem(key) || "";
  localStorage.setItem(key, /check_for_updates_on_startup:/.test(state) ? state.replace(/check_for_updates_on_startup:true/g, off)
                            : state.includes("(app_options:(") ? state.replace("(app_options:(", `(app_options:(${off},`)
                            : `(app_options:(${off}))`);
} catch (e) { console.warn("dicetrace: cannot turn off the Rerun viewer's update check:", e); }
const mod = await import("./widget.js");
mod.default.render({model, el: box});
window.addEventListener("resize", () => {
  (handlers["change:_width"] || []).forEach((f) => f(null, size()[0]));
  (handlers["change:_height"] || []).forEach((f) => f(null, size()[1]));
});
</script></body></html>
"""

#: The files of the web viewer (rerun-notebook's ``static`` folder) and their content types.
VIEWER_ASSETS = {"/widget.js": "text/javascript", "/widget.css": "text/css", "/re_viewer_bg.wasm": "application/wasm"}


def rerun_notebook_static() -> Path | None:
    """rerun-notebook's ``static`` folder (the files of Rerun's web viewer), found without importing the package."""
    try:
        spec = importlib.util.find_spec("rerun_notebook")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(list(spec.submodule_search_locations)[0]) / "static"


def viewer_assets_folder() -> Path | None:
    """rerun-notebook's ``static`` folder when it holds every file of :data:`VIEWER_ASSETS`, else None."""
    folder = rerun_notebook_static()
    if folder is None:
        return None
    return folder if all((folder / name.lstrip("/")).is_file() for name in VIEWER_ASSETS) else None


class WebViewerServer:
    """Rerun's web viewer over HTTP on ``host:port`` (threads of this process), opening ``grpc_url`` by default.

    Serves the page, the viewer's three files and the page's icon (``/favicon.ico``), nothing else (GET and HEAD);
    :meth:`close` stops it.
    Raises :class:`WebViewerError` (one line) when the viewer's files are missing or ``host:port`` cannot be listened on.
    """

    def __init__(self, host: str, port: int, grpc_url: str) -> None:
        folder = viewer_assets_folder()
        if folder is None:
            raise WebViewerError("Rerun's web viewer was not found: it comes with rerun-notebook, in the explore "
                                 "extra (pip install 'dicetrace[explore]')")
        grpc_port = urllib.parse.urlsplit(grpc_url).port
        page = (VIEWER_PAGE.replace("__GRPC_URL__", grpc_url).replace("__GRPC_PORT__", str(grpc_port))
                .replace("__FAVICON__", FAVICON_LINK).encode())

        class Handler(BaseHTTPRequestHandler):
            server_version = "dicetrace-record"

            def _send(self, body_len: int, ctype: str) -> None:
                self.send_response(200)
                self.send_header("Content-Type", ctype)
                self.send_header("Content-Length", str(body_len))
                self.send_header("Cache-Control", "no-store")
                self.end_headers()

            def do_GET(self, head: bool = False) -> None:  # noqa: N802 - http.server's name
                path = urllib.parse.urlsplit(self.path).path
                try:
                    if path in ("/", "/index.html"):
                        self._send(len(page), "text/html; charset=utf-8")
                        if not head:
                            self.wfile.write(page)
                    elif path == "/favicon.ico":
                        self._send(len(FAVICON_SVG), "image/svg+xml")
                        if not head:
                            self.wfile.write(FAVICON_SVG)
                    elif path in VIEWER_ASSETS:
                        file = folder / path.lstrip("/")
                        self._send(file.stat().st_size, VIEWER_ASSETS[path])
                        if not head:
                            with open(file, "rb") as f:
                                shutil.copyfileobj(f, self.wfile)
                    else:
                        self.send_error(404)
                except (BrokenPipeError, ConnectionResetError):  # the browser went away
                    pass

            def do_HEAD(self) -> None:  # noqa: N802
                self.do_GET(head=True)

            def log_message(self, *args) -> None:  # no access log on the terminal
                pass

        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        server_cls = type("Server", (ThreadingHTTPServer,), {"address_family": family, "daemon_threads": True,
                                                             "request_queue_size": 64})
        try:
            self.httpd = server_cls((host, port), Handler)
        except OSError as e:
            raise WebViewerError(f"cannot listen on {host} port {port}: {e.strerror or e}") from None
        self.thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.2},
                                       name="dicetrace-web-viewer", daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
