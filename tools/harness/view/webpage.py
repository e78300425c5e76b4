"""The page in the browser: a small static page (``tools/web/``: HTML, CSS, one script,
no build step, nothing fetched from elsewhere) served by the standard library's HTTP
server, that connects to the live Foxglove WebSocket server and draws the run
(docs/design.md §10 "Seeing the fleet", a page in the browser with nothing to install;
docs/view.md).

``/config.json`` tells the page where the live server is (``ws``); the page also takes
``?ws=ws://HOST:PORT`` in its address. ``tools.view --web`` and ``tools.demo --view``
start it (:func:`serve_page`) in a thread of their own process.
"""

from __future__ import annotations

import json
import sys
import threading
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

from tools.harness.view.live import parse_address

#: the page's files
WEB = Path(__file__).resolve().parents[2] / "web"
DEFAULT_WEB = "127.0.0.1:8080"


class _Handler(SimpleHTTPRequestHandler):
    """Serves ``WEB`` and ``/config.json``; quiet (no line per request)."""

    config: bytes = b"{}"

    def do_GET(self) -> None:
        if self.path.split("?", 1)[0] == "/config.json":
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Cache-Control", "no-store")
            self.send_header("Content-Length", str(len(self.config)))
            self.end_headers()
            self.wfile.write(self.config)
            return
        super().do_GET()

    def end_headers(self) -> None:
        self.send_header("Cache-Control", "no-store")
        super().end_headers()

    def log_message(self, format: str, *args: Any) -> None:
        return


class PageServer:
    """The page's HTTP server on ``address`` (``HOST:PORT``; port 0: a free one), the
    page told to connect to ``ws_url``; serves from a daemon thread until :meth:`close`."""

    def __init__(self, address: str, ws_url: str) -> None:
        host, port = parse_address(address, default_port=8080)
        config = json.dumps({"ws": ws_url}).encode()
        handler = type("PageHandler", (_Handler,), {"config": config})
        self._httpd = ThreadingHTTPServer((host, port), partial(handler, directory=str(WEB)))
        self._httpd.daemon_threads = True
        self.host = host
        self.port = int(self._httpd.server_address[1])
        self._thread = threading.Thread(target=self._httpd.serve_forever, daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    def close(self) -> None:
        self._httpd.shutdown()
        self._httpd.server_close()


def serve_page(address: str, ws_url: str) -> PageServer:
    """Start the page's server and say where it is on standard error."""
    page = PageServer(address, ws_url)
    print(f"view: open {page.url} in a browser (live data from {ws_url})", file=sys.stderr)
    return page
