"""The pages' still pictures (the view's PNG: the scene's boxes and her map), served by URL, not inlined.

NiceGUI sends an element's every property with each of its updates: a view whose picture was a data: URL
carried the whole PNG (a built map: ~10 kB) with every redraw of its overlay, five times a second, through the
server's JSON encoder, the websocket, the page's parser and NiceGUI's replay history. A URL is a few dozen
bytes; the browser fetches the picture once per map, from the console server itself (no other host: a class
LAN may have no internet).
"""

from __future__ import annotations

import secrets
import threading
from collections import OrderedDict

__all__ = ["Pictures", "ROUTE"]

ROUTE = "/rf/view"
"""Where the console serves the pictures: ``ROUTE/<token>.png?v=<version>``."""


class Pictures:
    """The latest picture of each page, under a token nobody can guess (a student's map is hers to show).

    Bounded: past ``limit`` pictures the oldest is forgotten (a page that went away without saying so)."""

    def __init__(self, limit: int = 1000) -> None:
        self._lock = threading.Lock()
        self._png: OrderedDict[str, tuple[int, bytes]] = OrderedDict()
        self.limit = limit

    @staticmethod
    def new_token() -> str:
        return secrets.token_urlsafe(16)

    def put(self, token: str, png: bytes) -> str:
        """Keep ``png`` as ``token``'s picture; the URL the page shows it by (a new one for each new picture, so
        the browser fetches it once and never shows a stale one)."""
        with self._lock:
            version = self._png[token][0] + 1 if token in self._png else 1
            self._png[token] = (version, png)
            self._png.move_to_end(token)
            while len(self._png) > self.limit:
                self._png.popitem(last=False)
        return f"{ROUTE}/{token}.png?v={version}"

    def get(self, token: str) -> bytes | None:
        with self._lock:
            item = self._png.get(token)
        return item[1] if item is not None else None

    def drop(self, token: str) -> None:
        with self._lock:
            self._png.pop(token, None)

    def __len__(self) -> int:
        return len(self._png)
