"""The page `view --serve-web` serves (user_peer.web_page): Rerun's web viewer with nothing calling outside the LAN.

The browser test (test_view_web.py) records every request Chromium makes; these check the pieces on a real
HTTP server with stand-in files, fast."""

from __future__ import annotations

import http.client

from robofabric.testing import free_port
from user_peer.web_page import NONET, REMOTE_URLS, PageServer, patch_index, patch_wasm

INDEX = b"""<html><head>
    <link rel="preconnect" href="https://fonts.googleapis.com" />
    <link rel="preconnect" href="https://fonts.gstatic.com" crossorigin />
    <link
      href="https://fonts.googleapis.com/css2?family=Inter:wght@100;500&display=swap"
      rel="stylesheet"
    />
    <title>Rerun Viewer</title></head><body><script src="re_viewer.js"></script></body></html>"""
WASM = (
    b"\x00asm"
    + b"identify"
    + REMOTE_URLS[0].encode()
    + b"event_id"
    + REMOTE_URLS[1].encode()
    + b"x"
    + REMOTE_URLS[2].encode()
    + b"0.41"
)


def test_the_page_loses_its_font_links_and_the_code_its_remote_urls():
    html = patch_index(INDEX)
    assert b"fonts.g" not in html and b"<title>Rerun Viewer</title>" in html and b"re_viewer.js" in html
    wasm, counts = patch_wasm(WASM)
    assert counts == {u: 1 for u in REMOTE_URLS}
    assert len(wasm) == len(WASM) and b"https://" not in wasm  # same length: the code's offsets stay right
    assert f"{NONET}tel.rerun.io/api/pog".encode() in wasm


def _get(port: int, path: str, host: str, method: str = "GET", body: bytes | None = None) -> http.client.HTTPResponse:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    c.request(method, path, body=body, headers={"Host": f"{host}:{port}"})
    r = c.getresponse()
    r.read()
    return r


def test_the_plain_address_leads_to_the_live_world_on_the_host_the_browser_used():
    server = PageServer(
        {"index.html": INDEX, "re_viewer.js": b"js", "re_viewer_bg.wasm": WASM}, free_port(), 9876, bind="127.0.0.1"
    )
    try:
        r = _get(server.port, "/", "lab-pc")
        assert r.status == 302 and r.getheader("Location") == "/?url=rerun%2Bhttp%3A%2F%2Flab-pc%3A9876%2Fproxy"
        page = _get(server.port, "/?url=rerun%2Bhttp%3A%2F%2Flab-pc%3A9876%2Fproxy", "lab-pc")
        assert page.status == 200 and page.getheader("Content-Type").startswith("text/html")
        assert _get(server.port, "/re_viewer_bg.wasm", "lab-pc").getheader("rerun-final-length") == str(len(WASM))
        # what the page meant for other hosts is answered here: analytics swallowed, no examples, no version news
        assert _get(server.port, f"{NONET}tel.rerun.io/api/pog", "lab-pc", "POST", b'{"event": "x"}').status == 204
        examples = _get(server.port, f"{NONET}app.rerun.io/version/0.41.0/examples_manifest.json", "lab-pc")
        assert examples.status == 200 and examples.getheader("Content-Type") == "application/json"
        assert _get(server.port, f"{NONET}api.github.com/repos/rerun-io/rerun/releases/latest", "lab-pc").status == 404
        assert server.nonet == 3
        assert _get(server.port, "/../etc/passwd", "lab-pc").status == 404
    finally:
        server.close()
