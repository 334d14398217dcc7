"""The browser view, served from this machine alone: Rerun's web viewer with nothing that calls outside the LAN.

The page Rerun serves (``rr.serve_web_viewer``) makes requests to third parties as soon as it opens:
Google's fonts (its ``index.html``), Rerun's analytics (``tel.rerun.io``), a version check
(``api.github.com``) and the examples list of its welcome screen (``app.rerun.io``). In a class that is
students' activity sent to a third party, and on an offline LAN it is console errors. Rerun's web build
has no switch for any of them, so this module serves the same files itself, changed:

* ``index.html`` without the font links (its CSS falls back to the browser's sans-serif);
* the viewer's ``.wasm`` with each of those URLs replaced by a path of the same length on this server
  (``/_nonet/...``: the analytics are swallowed, the version check finds nothing, the examples list is
  empty), so the code is untouched and only where it sends changes;
* ``/`` without a ``?url=`` redirects to the live world's data on the host the browser used, so the
  plain ``http://HOST:PORT/`` a student types shows the world, not Rerun's welcome page.

The files come from Rerun's own web server, run once for a moment in a child process bound to a loopback
port (the wheel keeps them inside its native modules); they are kept in memory for the viewer's lifetime.
"""

from __future__ import annotations

import gzip
import logging
import re
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import parse_qs, quote, urlsplit

log = logging.getLogger("robofabric.viewer")

__all__ = [
    "NONET",
    "REMOTE_URLS",
    "PageServer",
    "fetch_assets",
    "free_loopback_port",
    "patch_index",
    "patch_wasm",
    "serve",
]

NONET = "/_nonet/"  # 8 characters, as "https://": a remote URL becomes a local path of the same length
REMOTE_URLS = (
    "https://tel.rerun.io/api/pog",  # analytics (PostHog), sent from the web build whatever `rerun analytics` says
    "https://api.github.com/repos/rerun-io/rerun/releases/latest",  # "a newer version is out"
    "https://app.rerun.io/version/",  # + VERSION/examples_manifest.json: the welcome screen's examples
)
FILES = {  # served path -> (Rerun's path, content type)
    "/index.html": ("index.html", "text/html; charset=utf-8"),
    "/re_viewer.js": ("re_viewer.js", "text/javascript"),
    "/re_viewer_bg.wasm": ("re_viewer_bg.wasm", "application/wasm"),
    "/favicon.ico": ("favicon.ico", "image/x-icon"),
    "/apple-touch-icon.png": ("apple-touch-icon.png", "image/png"),
    "/sw.js": ("sw.js", "text/javascript"),
    "/signed-in": ("signed-in", "text/html; charset=utf-8"),
    "/signed-out": ("signed-out", "text/html; charset=utf-8"),
}
REQUIRED = ("index.html", "re_viewer.js", "re_viewer_bg.wasm")

_assets: dict[str, bytes] | None = None
_assets_lock = threading.Lock()


def free_loopback_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _server_argv(port: int) -> list[str]:
    """Rerun's web server on ``127.0.0.1:port`` alone: the ``rerun`` binary of the wheel (``rerun_cli``) with
    ``--bind 127.0.0.1``, given a data URL so that it starts no gRPC server; without that binary, the SDK's
    ``rr.serve_web_viewer``, which has no bind option and listens on every interface for that moment."""
    try:
        import rerun_cli

        exe = Path(rerun_cli.__file__).with_name("rerun")
    except ImportError:
        exe = None
    if exe is not None and exe.is_file():
        return [
            str(exe),
            "--serve-web",
            "--bind",
            "127.0.0.1",
            "--web-viewer-port",
            str(port),
            "rerun+http://127.0.0.1:1/proxy",
        ]
    code = "import sys, time, rerun as rr; rr.serve_web_viewer(web_port=int(sys.argv[1]), open_browser=False); time.sleep(3600)"
    return [sys.executable, "-c", code, str(port)]


def fetch_assets(timeout: float = 60.0) -> dict[str, bytes]:
    """The web viewer's files (Rerun's names) from Rerun's own server, run for a moment in a child process."""
    port = free_loopback_port()
    child = subprocess.Popen(_server_argv(port), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    out: dict[str, bytes] = {}
    try:
        deadline = time.monotonic() + timeout
        for name, _type in FILES.values():
            while True:
                try:
                    with urllib.request.urlopen(f"http://127.0.0.1:{port}/{name}", timeout=timeout) as r:
                        out[name] = r.read()
                    break
                except urllib.error.HTTPError:
                    break  # this Rerun has no such file: not served
                except OSError:
                    if child.poll() is not None or time.monotonic() > deadline:
                        raise RuntimeError(f"Rerun's web viewer server did not start (exit {child.poll()})") from None
                    time.sleep(0.2)
    finally:
        child.kill()
        child.wait(10)
    missing = [n for n in REQUIRED if n not in out]
    if missing:
        raise RuntimeError(f"Rerun's web viewer server lacks {', '.join(missing)}")
    return out


def patch_index(html: bytes) -> bytes:
    """index.html without requests to other hosts: the font links go, and so does the page-view script Rerun
    adds on app.rerun.io."""
    text = html.decode("utf-8")
    text = re.sub(r"<link\b[^>]*?fonts\.(?:googleapis|gstatic)\.com[^>]*?>\s*", "", text, flags=re.S)
    text = text.replace("https://fifteen-thirtyeight.rerun.io/script.js", f"{NONET}script.js")
    # the viewer's handle where a test or a benchmark reads the page's own state (its time cursor: how live it is)
    text = text.replace(
        "let handle = new wasm_bindgen.WebHandle(options);",
        "let handle = new wasm_bindgen.WebHandle(options); window.rerun_handle = handle;",
    )
    return text.encode("utf-8")


def patch_wasm(wasm: bytes) -> tuple[bytes, dict[str, int]]:
    """The viewer's code with each of :data:`REMOTE_URLS` pointing at this server (same length); returns the
    new bytes and how often each URL was replaced (0: this Rerun does not have it)."""
    counts = {}
    for url in REMOTE_URLS:
        local = NONET + url[len("https://") :]
        assert len(local) == len(url)
        counts[url] = wasm.count(url.encode())
        wasm = wasm.replace(url.encode(), local.encode())
    return wasm, counts


class PageServer:
    """The patched page on ``(bind, port)``; ``grpc_port``: where each page is told to stream from (on the
    host the browser reached this one by). ``close()`` stops it."""

    def __init__(self, assets: dict[str, bytes], port: int, grpc_port: int, *, bind: str = "0.0.0.0") -> None:
        wasm, counts = patch_wasm(assets["re_viewer_bg.wasm"])
        for url, n in counts.items():
            if n == 0:
                log.warning("web viewer: %s not found in this Rerun's viewer (nothing to keep local)", url)
        self.files = dict(assets)
        self.files["re_viewer_bg.wasm"] = wasm
        self.files["index.html"] = patch_index(assets["index.html"])
        self._gzipped: dict[str, bytes] = {}
        self._gzip_lock = threading.Lock()
        self.grpc_port = grpc_port
        self.requests = 0
        self.nonet = 0  # requests the page meant for other hosts, answered here
        handler = _handler(self)
        self.httpd = ThreadingHTTPServer((bind, port), handler)
        self.httpd.daemon_threads = True
        self.port = self.httpd.server_address[1]
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="web-page", daemon=True)
        self._thread.start()

    def data_url(self, host: str) -> str:
        """The gRPC URL a page reached as ``host`` streams from."""
        h = f"[{host}]" if ":" in host and not host.startswith("[") else host
        return f"rerun+http://{h}:{self.grpc_port}/proxy"

    def gzipped(self, name: str) -> bytes:
        with self._gzip_lock:
            if name not in self._gzipped:
                self._gzipped[name] = gzip.compress(self.files[name], compresslevel=6)
            return self._gzipped[name]

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        self._thread.join(5)


def _handler(server: PageServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"

        def log_message(self, format: str, *args: object) -> None:  # noqa: A002 - the base class's name
            log.debug("web page: " + format, *args)

        def _send(
            self, code: int, body: bytes = b"", ctype: str = "text/plain", headers: dict[str, str] | None = None
        ) -> None:
            self.send_response(code)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            for k, v in (headers or {}).items():
                self.send_header(k, v)
            self.end_headers()
            if self.command != "HEAD":
                self.wfile.write(body)

        def _host(self) -> str:
            host = self.headers.get("Host") or self.server.server_address[0]
            return urlsplit(f"//{host}").hostname or "localhost"

        def do_GET(self) -> None:  # noqa: N802 - http.server's name
            server.requests += 1
            parts = urlsplit(self.path)
            path = parts.path
            if path.startswith(NONET):
                server.nonet += 1
                if path.endswith("examples_manifest.json"):
                    return self._send(200, b"[]", "application/json")
                return self._send(404, b"not served: this viewer makes no requests outside the LAN")
            if path in ("/", "/index.html") and "url" not in parse_qs(parts.query):
                # the plain address leads to the live world, streamed from the host the browser used
                target = f"/?url={quote(server.data_url(self._host()), safe='')}"
                return self._send(302, b"", headers={"Location": target})
            name, ctype = FILES.get("/index.html" if path == "/" else path, (None, ""))
            if name is None or name not in server.files:
                return self._send(404, b"not found")
            body = server.files[name]
            headers = {"rerun-final-length": str(len(body)), "Cache-Control": "no-cache"}
            if len(body) > 100_000 and "gzip" in (self.headers.get("Accept-Encoding") or ""):
                body = server.gzipped(name)
                headers["Content-Encoding"] = "gzip"
            self._send(200, body, ctype, headers)

        do_HEAD = do_GET

        def do_POST(self) -> None:  # noqa: N802
            server.requests += 1
            length = int(self.headers.get("Content-Length") or 0)
            if length:
                self.rfile.read(min(length, 1 << 20))
            if urlsplit(self.path).path.startswith(NONET):
                server.nonet += 1  # analytics: swallowed
                return self._send(204)
            self._send(404, b"not found")

    return Handler


def serve(port: int, grpc_port: int, *, bind: str = "0.0.0.0") -> PageServer:
    """Serve the patched web viewer on ``port`` (all interfaces by default); the files are fetched once per process."""
    global _assets
    with _assets_lock:
        if _assets is None:
            _assets = fetch_assets()
        assets = _assets
    return PageServer(assets, port, grpc_port, bind=bind)
