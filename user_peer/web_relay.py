"""One queue per browser page between Rerun's gRPC server and the pages of ``view --serve-web``.

Rerun's gRPC server (``rr.GrpcServerSink``, re_grpc_server) hands every new message to all its
clients through one broadcast channel bounded in bytes, and its sender waits while the slowest
client's share is full: one frozen or slow page (a student's laptop asleep, a tab in the
background, a software-rendered browser) holds up the feed for every other page, and the viewer
logs ``re_grpc_server broadcast: Sender has been blocked``.

So the pages never talk to Rerun's server directly. It listens on a loopback port of its own, and
this relay listens where the pages are told to stream from (``--grpc-port``). Each connection a page
opens gets its own connection to Rerun's server and two threads: one reads from Rerun as fast as
Rerun sends (into the page's own queue, bounded in bytes), one writes to the page as fast as the page
takes. Rerun's server therefore only ever waits for this relay, which never waits for a page. A page
whose queue holds more than ``max_queue_bytes``, or whose oldest queued bytes waited longer than
``max_wait_s``, is cut off (both its connections closed, counted in ``cut``): it has stopped taking
data, and catching up on a backlog would only put it further behind. A student's page that was cut
(``Connection lost`` in Rerun's page) is reloaded to join again, from Rerun's history.

The relay forwards bytes (HTTP/1.1 requests, gRPC-web frames, CORS preflights) untouched: nothing
of Rerun's protocol is parsed or rewritten, so a Rerun upgrade does not break it.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections import deque
from dataclasses import dataclass, field

log = logging.getLogger("robofabric.viewer")

__all__ = ["Relay", "PageLink"]

CHUNK = 256 * 1024
SNDBUF = 512 * 1024


@dataclass
class PageLink:
    """One page's connection: its queue, what went through, and when it was cut."""

    peer: str
    opened: float = field(default_factory=time.monotonic)
    queued: deque = field(default_factory=deque)  # (monotonic time read from Rerun, bytes)
    queued_bytes: int = 0
    sent_bytes: int = 0
    read_bytes: int = 0
    cut_reason: str = ""
    closed: bool = False
    sockets: tuple = ()


class Relay:
    """Listen on ``(bind, port)``; every accepted connection is relayed to ``upstream`` (host, port) with its
    own queue. ``close()`` stops listening and closes every link."""

    def __init__(self, upstream: tuple[str, int], port: int, *, bind: str = "0.0.0.0",
                 max_queue_bytes: int = 64 << 20, max_wait_s: float = 10.0) -> None:
        self.upstream = upstream
        self.max_queue_bytes = max_queue_bytes
        self.max_wait_s = max_wait_s
        self.links: list[PageLink] = []
        self.cut = 0  # links cut off for not taking their data
        self._lock = threading.Lock()
        self._closed = threading.Event()
        self._sock = socket.create_server((bind, port), reuse_port=False)
        self._sock.settimeout(0.5)
        self.port = self._sock.getsockname()[1]
        self._thread = threading.Thread(target=self._accept_loop, name="web-relay", daemon=True)
        self._thread.start()

    def _accept_loop(self) -> None:
        while not self._closed.is_set():
            try:
                down, addr = self._sock.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            try:
                up = socket.create_connection(self.upstream, timeout=5)
            except OSError as exc:
                log.warning("web relay: Rerun's gRPC server at %s:%d refused a page: %s", *self.upstream, exc)
                down.close()
                continue
            for s in (down, up):
                s.settimeout(None)
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            # what a page has not taken waits in its queue, where its age is seen, not in a kernel buffer that
            # grows to megabytes on its own (a LAN's round trip needs far less)
            down.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SNDBUF)
            link = PageLink(peer=f"{addr[0]}:{addr[1]}", sockets=(down, up))
            with self._lock:
                self.links = [lk for lk in self.links if not lk.closed] + [link]
            cond = threading.Condition()
            # page -> Rerun: requests are small; a plain blocking copy
            threading.Thread(target=self._pump_requests, args=(down, up, link, cond), daemon=True, name="web-relay-req").start()
            threading.Thread(target=self._read_upstream, args=(up, down, link, cond), daemon=True, name="web-relay-up").start()
            threading.Thread(target=self._write_page, args=(down, up, link, cond), daemon=True, name="web-relay-down").start()

    def _finish(self, link: PageLink, cond: threading.Condition, down: socket.socket, up: socket.socket, reason: str = "") -> None:
        with cond:
            if link.closed:
                return
            link.closed = True
            link.cut_reason = reason
            link.queued.clear()
            cond.notify_all()
        if reason:
            with self._lock:
                self.cut += 1
            log.warning("web relay: page %s cut off: %s", link.peer, reason)
        for s in (down, up):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            s.close()

    def _pump_requests(self, down: socket.socket, up: socket.socket, link: PageLink, cond: threading.Condition) -> None:
        try:
            while True:
                data = down.recv(CHUNK)
                if not data:
                    break
                up.sendall(data)
        except OSError:
            pass
        self._finish(link, cond, down, up)

    def _read_upstream(self, up: socket.socket, down: socket.socket, link: PageLink, cond: threading.Condition) -> None:
        """Rerun -> the page's queue, never waiting for the page."""
        try:
            while True:
                data = up.recv(CHUNK)
                if not data:
                    break
                now = time.monotonic()
                with cond:
                    if link.closed:
                        return
                    link.queued.append((now, data))
                    link.queued_bytes += len(data)
                    link.read_bytes += len(data)
                    cond.notify_all()
                    too_big = link.queued_bytes > self.max_queue_bytes
                    too_old = now - link.queued[0][0] > self.max_wait_s
                if too_big or too_old:
                    why = (f"{link.queued_bytes / 1e6:.1f} MB queued" if too_big
                           else f"its oldest queued data waited {now - link.queued[0][0]:.1f} s")
                    self._finish(link, cond, down, up, f"not taking its data ({why})")
                    return
        except (OSError, IndexError):
            pass
        # Rerun closed the stream: let the page have what is queued, then close
        with cond:
            while link.queued and not link.closed:
                cond.wait(1.0)
        self._finish(link, cond, down, up)

    def _write_page(self, down: socket.socket, up: socket.socket, link: PageLink, cond: threading.Condition) -> None:
        """The page's queue -> the page, as fast as it takes it; a frozen page stalls only this thread."""
        try:
            while True:
                with cond:
                    while not link.queued and not link.closed:
                        cond.wait(1.0)
                    if link.closed:
                        return
                    parts = list(link.queued)
                    link.queued.clear()
                    n = sum(len(p) for _, p in parts)
                for _, data in parts:
                    down.sendall(data)
                with cond:
                    link.queued_bytes -= n
                    link.sent_bytes += n
                    cond.notify_all()
        except OSError:
            self._finish(link, cond, down, up)

    def stats(self) -> list[dict]:
        """Per link ever opened and still listed: peer, bytes read from Rerun and sent to the page, queued, cut."""
        now = time.monotonic()
        with self._lock:
            links = list(self.links)
        out = []
        for lk in links:
            oldest = lk.queued[0][0] if lk.queued else now
            out.append({"peer": lk.peer, "read": lk.read_bytes, "sent": lk.sent_bytes, "queued": lk.queued_bytes,
                        "waited_s": now - oldest, "closed": lk.closed, "cut": lk.cut_reason})
        return out

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        self._sock.close()
        self._thread.join(5)
        with self._lock:
            links = list(self.links)
        for lk in links:
            for s in lk.sockets:
                try:
                    s.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
