"""The emulated page reads a NiceGUI page as the page's script does: its element tree (HTML-escaped in a JS raw
string) and its socket query (a Python literal), and finds controls by what a person reads on them."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robofabric.bench.console_client import EmulatedPage, PageGone, parse_page, scenes_to_start, student_address

ESC = (("&", "&amp;"), ("<", "&lt;"), (">", "&gt;"), ("`", "&#96;"), ("$", "&#36;"))  # nicegui's, & first


def _page(elements: dict, query: str) -> str:
    raw = json.dumps(elements)
    for a, b in ESC:
        raw = raw.replace(a, b)
    return f"<script>\n const app = createApp(parseElements(String.raw`{raw}`), {{\n  query: {query},\n  extra: 1,\n</script>"


@given(st.text(max_size=40))
def test_any_label_survives_the_pages_escaping(label):
    els, q = parse_page(
        _page(
            {"0": {"tag": "q-layout"}, "7": {"tag": "q-btn", "props": {"label": label}}},
            "{'client_id': 'c-1', 'next_message_id': 3, 'implicit_handshake': True}",
        )
    )
    assert els["7"]["props"]["label"] == label
    assert q == {"client_id": "c-1", "next_message_id": 3, "implicit_handshake": True}


def test_controls_are_found_by_label_aria_label_or_text_and_by_tag():
    page = EmulatedPage("http://x/")
    page.elements = {
        "1": {"tag": "nicegui-input", "props": {"aria-label": "Name"}},
        "2": {"tag": "q-btn", "props": {"label": "Log in"}},
        "3": {"tag": "div", "text": "Log in"},
        "4": {"tag": "div", "text": "request base3: you own it (epoch 2)"},
    }
    assert page.find("Name") == "1"
    assert page.find("Log in", tag="q-btn") == "2" and page.find("Log in", tag="div") == "3"
    assert page.find("you own it", exact=False) == "4" and page.find("you own it") is None
    assert "request base3" in page.text()


def test_a_3d_view_is_told_init_once_as_the_browsers_scene_says_it_is_mounted():
    """NiceGUI sends a 3D view's objects and moves only after the browser's scene said ``init``: an emulated page
    that never said it cost the server none of a real page's 3D traffic."""
    update = {
        "5": {"tag": "nicegui-scene", "events": [{"type": "init", "listener_id": "l1"}, {"type": "dragend"}]},
        "6": {"tag": "q-btn", "events": [{"type": "click", "listener_id": "l2"}]},
        "7": None,
    }
    assert scenes_to_start(update, set()) == ["5"]
    assert scenes_to_start(update, {"5"}) == []  # told once


def test_a_page_that_is_not_niceguis_is_refused_with_why():
    with pytest.raises(PageGone, match="not a NiceGUI page"):
        parse_page("<html><body>404</body></html>")


def test_each_student_has_a_loopback_address_of_her_own_past_the_consoles():
    addresses = [student_address(k) for k in range(253)]
    assert addresses[0] == "127.0.0.2" and addresses[-1] == "127.0.0.254" and len(set(addresses)) == 253
    for k in (-1, 253):
        with pytest.raises(ValueError, match="at most 253 students"):
            student_address(k)


def test_a_students_page_and_its_socket_both_come_from_her_address():
    """A real HTTP and socket.io server on 127.0.0.1 (the console's listening address): the page's load and its
    websocket (socket.io's own transport, which makes its own connection) each arrive from 127.0.0.5, the address
    of student 3's session, not from 127.0.0.1."""
    import asyncio

    import aiohttp
    import socketio
    from aiohttp import web

    from robofabric.testing import free_port

    seen: dict[str, str] = {}
    sio = socketio.AsyncServer(async_mode="aiohttp")
    app = web.Application()
    sio.attach(app, socketio_path="/_nicegui_ws/socket.io")

    async def page(request: web.Request) -> web.Response:
        seen["page"] = str(request.remote)
        return web.Response(
            text=_page({"0": {"tag": "q-layout"}}, "{'client_id': 'c-1', 'next_message_id': 0}"),
            content_type="text/html",
        )

    @sio.event
    async def connect(sid, environ, auth=None):
        seen["socket"] = str(environ["aiohttp.request"].remote)

    app.router.add_get("/", page)

    async def run() -> None:
        runner = web.AppRunner(app)
        await runner.setup()
        port = free_port()
        await web.TCPSite(runner, "127.0.0.1", port).start()
        try:
            async with aiohttp.ClientSession(
                connector=aiohttp.TCPConnector(local_addr=(student_address(3), 0))
            ) as http:
                p = EmulatedPage(f"http://127.0.0.1:{port}/")
                await p.open(http, timeout=20)
                await p.close()
        finally:
            await runner.cleanup()

    asyncio.run(run())
    assert seen == {"page": "127.0.0.5", "socket": "127.0.0.5"}
