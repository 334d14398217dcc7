"""A console page played by a raw socket.io client, as a script on the LAN can: no browser.

It loads the page over HTTP, reads the elements and the socket's query NiceGUI put in it, connects the websocket
with the page's own ids (NiceGUI's implicit handshake), keeps the elements the server sends, and sends events (a
click, a field's new value) naming any client it is told to: its own, or another page's.
"""

from __future__ import annotations

import ast
import asyncio
import json
import re
import uuid
from typing import Any

import httpx
import socketio

ELEMENTS = re.compile(r"parseElements\(String\.raw`(.*?)`\)", re.S)
QUERY = re.compile(r"query: (\{.*?\}),\n")


def _unescape(raw: str) -> str:
    return (
        raw.replace("&#36;", "$").replace("&#96;", "`").replace("&gt;", ">").replace("&lt;", "<").replace("&amp;", "&")
    )


class RawPage:
    """One page: :meth:`load`, then :meth:`connect` (or not: a page that never connects)."""

    def __init__(self, url: str, *, verify: Any = True) -> None:
        self.url, self.verify = url, verify
        self.elements: dict[int, dict] = {}
        self.query: dict[str, Any] = {}
        self.sio: socketio.AsyncClient | None = None
        self.tab_id = str(uuid.uuid4())  # a browser tab's: the same on every connection of the page

    @property
    def client_id(self) -> str:
        return self.query["client_id"]

    async def load(self, http: httpx.AsyncClient) -> int:
        """GET the page; its status (the elements and ids kept when 200)."""
        r = await http.get(self.url)
        if r.status_code == 200:
            self.elements = {int(k): v for k, v in json.loads(_unescape(ELEMENTS.search(r.text).group(1))).items()}
            self.query = ast.literal_eval(QUERY.search(r.text).group(1))  # NiceGUI writes it as a Python dict
        return r.status_code

    async def connect(self, *, as_client: str | None = None) -> None:
        """Open the websocket with this page's ids (``as_client``: another page's client id in the query)."""
        self.sio = socketio.AsyncClient(reconnection=False, ssl_verify=self.verify)
        self.sio.on("update", self._update)
        q = {
            **self.query,
            "client_id": as_client or self.client_id,
            "tab_id": self.tab_id,
            "document_id": str(uuid.uuid4()),
            "implicit_handshake": "true",
        }
        qs = "&".join(f"{k}={v}" for k, v in q.items())
        await self.sio.connect(
            f"{self.url}?{qs}", socketio_path="/_nicegui_ws/socket.io", transports=["websocket"], wait_timeout=20
        )

    async def _update(self, data: dict) -> None:
        for k, v in data.items():
            if k.isdigit():
                if v is None:
                    self.elements.pop(int(k), None)
                else:
                    self.elements[int(k)] = v

    def find(self, *, text: str | None = None, label: str | None = None) -> int:
        """The id of the element with this text (a button's label is its text) or this ``label`` prop (a field)."""
        for eid, e in self.elements.items():
            props = e.get("props", {})
            if (text is not None and (e.get("text") == text or props.get("label") == text)) or (
                label is not None and props.get("label") == label
            ):
                return eid
        raise KeyError(text or label)

    def listener(self, eid: int, kind: str) -> str:
        return [ev["listener_id"] for ev in self.elements[eid].get("events", []) if ev["type"] == kind][0]

    async def send(
        self, eid: int, kind: str, *args: Any, client_id: str | None = None, listener: str | None = None
    ) -> None:
        """Send event ``kind`` of element ``eid`` (this page's listener unless ``listener``) naming ``client_id``."""
        assert self.sio is not None
        await self.sio.emit(
            "event",
            {
                "id": eid,
                "client_id": client_id or self.client_id,
                "listener_id": listener or self.listener(eid, kind),
                "args": [json.dumps(a) for a in args],
            },
        )

    async def close(self) -> None:
        if self.sio is not None:
            await self.sio.disconnect()

    async def wait_for(self, what: str, cond, timeout: float = 60.0) -> None:
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        while not cond():
            if loop.time() > end:
                texts = sorted(set(self.texts()))
                raise AssertionError(f"{what} not within {timeout} s; the page's texts: {texts[:60]}")
            await asyncio.sleep(0.05)

    def texts(self) -> list[str]:
        """Every element's text and label (a button's label is a prop)."""
        return [str(t) for e in self.elements.values() for t in (e.get("text"), e.get("props", {}).get("label")) if t]
