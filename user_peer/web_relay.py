"""The door between the pages of ``view --serve-web`` and Rerun's gRPC server: reads only, one queue per page,
memory bounded for the whole relay.

Rerun's gRPC server (``rr.GrpcServerSink``, re_grpc_server) hands every new message to all its clients
through one broadcast channel bounded in bytes, and its sender waits while the slowest client's share is
full: one frozen or slow page holds up the feed for every other page. And it serves writes
(``WriteMessages``) to whoever reaches its port: what anyone writes there, every page shows.

So the pages never talk to Rerun's server directly. It listens on a loopback port of its own, and this
relay listens where the pages are told to stream from (``--grpc-port``):

- **Reads only.** Each request a connection sends is checked (user_peer/grpc_gate.py) before anything
  reaches Rerun: only ``ReadMessages``/``ReadTables`` over gRPC-web (and their CORS preflights) are passed
  on; anything else gets ``PERMISSION_DENIED`` and the connection is closed, counted in
  ``refused_requests`` and logged. A connection opens its connection to Rerun at its first allowed
  request, so a refused or idle one costs Rerun nothing.
- **One queue per page.** A reading connection gets two more threads: one reads from Rerun as fast as
  Rerun sends (into the page's own queue), one writes to the page as fast as the page takes. Rerun's server
  only ever waits for this relay, which never waits for a page.
- **Bounded.** At most ``max_links`` connections (``max_links_per_address`` from one address), each with
  at most 3 threads; a connection whose first request has not come whole within ``header_timeout_s`` is closed; a page's
  queue holds at most ``max_queue_bytes`` and all queues together at most ``max_total_bytes``. A page that
  took nothing for ``max_stall_s`` while its data waited is cut off; when the total budget is full, the
  page that took nothing for the longest is cut off (else the one holding most). Every refusal and cut is
  counted (:meth:`Relay.counters`) and logged.
- **A page is cut for not taking, never for being slow.** A page joining a long session is sent Rerun's
  history for pages at once (``view``'s ``web_history``, a compacted start: the static scene and the
  blueprint always, and the newest data, newest first behind the live feed); it takes it at its own pace,
  and is cut only if it stops taking or falls a whole queue behind.

Responses flow back untouched: nothing of Rerun's answers is parsed or rewritten.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections import deque
from dataclasses import dataclass, field

from user_peer.grpc_gate import Http2, Refused, http1_refusal, read_request, refuse_http2

log = logging.getLogger("robofabric.viewer")

__all__ = ["Relay", "RelayLimits", "RelayCounters", "PageLink"]

CHUNK = 256 * 1024
SNDBUF = 512 * 1024
LOG_FIRST = 20  # refusals logged one by one; after that every LOG_EVERY-th (an attacker cannot flood the log)
LOG_EVERY = 100


@dataclass(frozen=True, slots=True)
class RelayLimits:
    """What the relay may hold. The defaults fit a class: a page opens 1-3 connections; a page's queue holds
    twice the viewer's default history for pages (32 MiB), so a page that joins late is never cut for it."""

    max_links: int = 64
    max_links_per_address: int = 8
    max_queue_bytes: int = 64 << 20
    max_total_bytes: int = 256 << 20
    max_stall_s: float = 10.0
    header_timeout_s: float = 10.0


@dataclass(frozen=True, slots=True)
class RelayCounters:
    """A snapshot of what the relay holds and refused so far."""

    links: int  # open connections
    queued_bytes: int  # in every page's queue, now
    peak_queued_bytes: int  # the most ever queued at once
    refused_requests: int  # writes, unknown methods, HTTP/2 calls, malformed or oversized requests
    refused_connections: int  # over max_links or max_links_per_address, or no request in time
    cut: int  # pages cut off for not taking their data, or for the total budget


@dataclass(eq=False)
class PageLink:
    """One connection's state (internal, mutable; guarded by ``cond``)."""

    peer: str
    address: str
    down: socket.socket
    up: socket.socket | None = None
    opened: float = field(default_factory=time.monotonic)
    cond: threading.Condition = field(default_factory=threading.Condition)  # on the relay's one lock
    queued: deque = field(default_factory=deque)  # bytes read from Rerun, not yet taken by the page
    queued_bytes: int = 0
    sent_bytes: int = 0
    read_bytes: int = 0
    progress: float = field(default_factory=time.monotonic)  # the page last took bytes, or its queue filled from empty
    cut_reason: str = ""
    closed: bool = False
    sockets_closed: bool = False

    def stalled_for(self, now: float) -> float:
        """How long this page has taken nothing while data waited for it (0 with an empty queue)."""
        return now - self.progress if self.queued_bytes else 0.0


class Relay:
    """Listen on ``(bind, port)``; every accepted connection's read requests are relayed to ``upstream``
    (host, port) with its own queue. ``close()`` stops listening and closes every link."""

    def __init__(
        self, upstream: tuple[str, int], port: int, *, bind: str = "0.0.0.0", limits: RelayLimits = RelayLimits()
    ) -> None:
        self.upstream = upstream
        self.limits = limits
        self.links: list[PageLink] = []
        self.cut = 0
        self.refused_requests = 0
        self.refused_connections = 0
        self.queued_total = 0
        self.peak_queued = 0
        # one lock for every link's queue and the counters (each link's cond is a condition on it): the total
        # budget is checked and enforced in the same step as each read is queued, so it is never exceeded
        self._lock = threading.Lock()
        self._closed = threading.Event()
        family = socket.AF_INET6 if ":" in bind else socket.AF_INET
        self._sock = socket.create_server((bind, port), family=family, reuse_port=False, backlog=128)
        self._sock.settimeout(0.5)
        self.port = self._sock.getsockname()[1]
        self._thread = threading.Thread(target=self._accept_loop, name="web-relay", daemon=True)
        self._thread.start()

    # -- accepting -------------------------------------------------------------------------------------

    def _accept_loop(self) -> None:
        while not self._closed.is_set():
            self._sweep()
            try:
                down, addr = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            why = self._over_cap(addr[0])
            if why:
                self._refuse_connection(down, f"{addr[0]}:{addr[1]}", why)
                continue
            down.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            # what a page has not taken waits in its queue, where it is counted, not in a kernel buffer that
            # grows to megabytes on its own (a LAN's round trip needs far less)
            down.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SNDBUF)
            link = PageLink(
                peer=f"{addr[0]}:{addr[1]}", address=addr[0], down=down, cond=threading.Condition(self._lock)
            )
            with self._lock:
                self.links.append(link)
            threading.Thread(target=self._serve_requests, args=(link,), daemon=True, name="web-relay-req").start()

    def _over_cap(self, address: str) -> str:
        with self._lock:
            self.links = [lk for lk in self.links if not lk.closed]
            if len(self.links) >= self.limits.max_links:
                return f"the relay holds {len(self.links)} connections (max_links)"
            mine = sum(lk.address == address for lk in self.links)
        if mine >= self.limits.max_links_per_address:
            return f"{address} holds {mine} connections (max_links_per_address)"
        return ""

    def _refuse_connection(self, down: socket.socket, peer: str, why: str) -> None:
        with self._lock:
            self.refused_connections += 1
            n = self.refused_connections
        if n <= LOG_FIRST or n % LOG_EVERY == 0:
            log.warning("web relay: connection from %s refused: %s (%d refused so far)", peer, why, n)
        try:
            down.settimeout(0.5)
            down.sendall(http1_refusal(why))
        except OSError:
            pass
        _close(down)

    def _sweep(self) -> None:
        """Cut off every page that took nothing for ``max_stall_s`` while its data waited."""
        now = time.monotonic()
        with self._lock:
            links = list(self.links)
        for lk in links:
            stalled = lk.stalled_for(now)
            if not lk.closed and stalled > self.limits.max_stall_s:
                self._finish(
                    lk,
                    f"not taking its data (took nothing for {stalled:.1f} s while "
                    f"{lk.queued_bytes / 1e6:.1f} MB waited)",
                )

    # -- one connection ----------------------------------------------------------------------------------

    def _serve_requests(self, link: PageLink) -> None:
        """Page -> Rerun: each request checked, an allowed one passed on whole; the first opens the link to Rerun."""
        buf = bytearray()
        first_by = time.monotonic() + self.limits.header_timeout_s
        try:
            while not link.closed:
                got = read_request(link.down, buf, first_by if link.up is None else None)
                if got is None:
                    break
                req, body = got
                if link.up is None:
                    self._open_upstream(link)
                    link.down.settimeout(None)  # a page's stream stays open for as long as it shows the world
                link.up.sendall(req.head + body)
        except Http2:
            refuse_http2(
                link.down,
                bytes(buf),
                lambda path: self._count_refusal(link, path, "HTTP/2 (native gRPC)"),
                timeout_s=self.limits.header_timeout_s,
            )
        except Refused as exc:
            self._count_refusal(link, exc.method, exc.reason)
            if link.up is None:  # nothing relayed yet on this connection: the caller gets the status
                try:
                    link.down.sendall(http1_refusal(exc.reason))
                except OSError:
                    pass
        except TimeoutError:
            if link.up is None:
                self._refuse_connection(link.down, link.peer, f"no request within {self.limits.header_timeout_s:g} s")
        except OSError:
            pass
        self._finish(link)

    def _count_refusal(self, link: PageLink, method: str, reason: str) -> None:
        with self._lock:
            self.refused_requests += 1
            n = self.refused_requests
        if n <= LOG_FIRST or n % LOG_EVERY == 0:
            log.warning(
                "web relay: refused %s from %s: %s (%d requests refused so far)",
                method.rsplit("/", 1)[-1] or "a request",
                link.peer,
                reason,
                n,
            )

    def _open_upstream(self, link: PageLink) -> None:
        try:
            up = socket.create_connection(self.upstream, timeout=5)
        except OSError as exc:
            log.warning("web relay: Rerun's gRPC server at %s:%d refused a page: %s", *self.upstream, exc)
            raise
        up.settimeout(None)
        up.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with link.cond:
            if link.closed:
                _close(up)
                raise OSError("closed")
            link.up = up
        threading.Thread(target=self._read_upstream, args=(link,), daemon=True, name="web-relay-up").start()
        threading.Thread(target=self._write_page, args=(link,), daemon=True, name="web-relay-down").start()

    def _read_upstream(self, link: PageLink) -> None:
        """Rerun -> the page's queue, never waiting for the page; the budgets are checked at every read."""
        up = link.up
        assert up is not None
        try:
            while True:
                data = up.recv(CHUNK)
                if not data:
                    break
                n = len(data)
                now = time.monotonic()
                closed: list[PageLink] = []
                with link.cond:
                    if link.closed:
                        return
                    if link.queued_bytes + n > self.limits.max_queue_bytes:
                        self._close_locked(
                            link,
                            f"not taking its data ({(link.queued_bytes + n) / 1e6:.1f} MB to queue, "
                            f"max_queue_bytes {self.limits.max_queue_bytes / 1e6:.0f} MB)",
                        )
                    while not link.closed and self.queued_total + n > self.limits.max_total_bytes:
                        victim = self._victim(now, link)
                        stalled = victim.stalled_for(now)
                        self._close_locked(
                            victim,
                            f"the relay's budget is full ({self.limits.max_total_bytes / 1e6:.0f} MB "
                            f"queued for every page) and this page holds {victim.queued_bytes / 1e6:.1f} MB"
                            + (f", taking nothing for {stalled:.1f} s" if stalled >= 1.0 else ""),
                        )
                        closed.append(victim)
                    if not link.closed:
                        if not link.queued:
                            link.progress = now  # its wait starts now
                        link.queued.append(data)
                        link.queued_bytes += n
                        link.read_bytes += n
                        self.queued_total += n
                        self.peak_queued = max(self.peak_queued, self.queued_total)
                        link.cond.notify_all()
                for lk in closed:
                    self._after_close(lk)
                if link.closed:
                    self._after_close(link)
                    return
        except OSError:
            pass
        # Rerun closed the stream: let the page have what is queued (the sweep cuts it if it stops taking), then close
        with link.cond:
            while link.queued and not link.closed:
                link.cond.wait(1.0)
        self._finish(link)

    def _victim(self, now: float, reading: PageLink) -> PageLink:
        """(Under ``_lock``.) The page to cut when the total budget is full: the one that took nothing for the
        longest (a second at least), else the one holding most (``reading``, whose read needs the room, included)."""
        live = [lk for lk in self.links if not lk.closed and lk.queued_bytes] + [reading]
        stalled = max(live, key=lambda lk: lk.stalled_for(now))
        if stalled.stalled_for(now) >= 1.0:
            return stalled
        return max(live, key=lambda lk: lk.queued_bytes)

    def _write_page(self, link: PageLink) -> None:
        """The page's queue -> the page, as fast as it takes it; a frozen page stalls only this thread."""
        down = link.down
        try:
            while True:
                with link.cond:
                    while not link.queued and not link.closed:
                        link.cond.wait(1.0)
                    if link.closed:
                        return
                    data = link.queued[0]  # counted as queued until the page took it
                view = memoryview(data)
                while view:
                    k = down.send(view)
                    view = view[k:]
                    with link.cond:
                        if link.closed:
                            return
                        link.progress = time.monotonic()
                        link.queued_bytes -= k
                        link.sent_bytes += k
                        self.queued_total -= k
                with link.cond:
                    if link.queued and link.queued[0] is data:
                        link.queued.popleft()
                    link.cond.notify_all()
        except OSError:
            self._finish(link)

    def _finish(self, link: PageLink, reason: str = "") -> None:
        """Close a link (idempotent); with a ``reason`` it was cut off: counted and logged."""
        with link.cond:
            self._close_locked(link, reason)
        self._after_close(link)

    def _close_locked(self, link: PageLink, reason: str) -> None:
        """(Under ``_lock``.) Mark a link closed, its queue dropped from the total; its sockets close in
        :meth:`_after_close`, outside the lock."""
        if link.closed:
            return
        link.closed = True
        link.cut_reason = reason
        self.queued_total -= link.queued_bytes
        if reason:
            self.cut += 1
        link.queued.clear()
        link.queued_bytes = 0
        link.cond.notify_all()

    def _after_close(self, link: PageLink) -> None:
        with link.cond:
            if link.sockets_closed:
                return
            link.sockets_closed = True
        if link.cut_reason:
            log.warning("web relay: page %s cut off: %s", link.peer, link.cut_reason)
        _close(link.down)
        if link.up is not None:
            _close(link.up)

    # -- reporting, closing ----------------------------------------------------------------------------

    def counters(self) -> RelayCounters:
        with self._lock:
            return RelayCounters(
                links=sum(not lk.closed for lk in self.links),
                queued_bytes=self.queued_total,
                peak_queued_bytes=self.peak_queued,
                refused_requests=self.refused_requests,
                refused_connections=self.refused_connections,
                cut=self.cut,
            )

    def stats(self) -> list[dict]:
        """Per link still listed: peer, bytes read from Rerun and sent to the page, queued, stalled, cut."""
        now = time.monotonic()
        with self._lock:
            links = list(self.links)
        return [
            {
                "peer": lk.peer,
                "read": lk.read_bytes,
                "sent": lk.sent_bytes,
                "queued": lk.queued_bytes,
                "stalled_s": round(lk.stalled_for(now), 2),
                "closed": lk.closed,
                "cut": lk.cut_reason,
            }
            for lk in links
        ]

    def close(self) -> None:
        """Stop listening and close every link (idempotent)."""
        if self._closed.is_set():
            return
        self._closed.set()
        self._sock.close()
        self._thread.join(5)
        with self._lock:
            links = list(self.links)
        for lk in links:
            self._finish(lk)


def _close(s: socket.socket) -> None:
    try:
        s.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
    s.close()
