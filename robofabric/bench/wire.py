"""A counting TCP proxy: the bytes and segments a publisher puts on its link to a broker or router.

A benchmark points its publisher at :class:`CountingProxy` instead of the broker; the proxy forwards both
directions unchanged and counts what flows from the publisher to the broker. Two counts, so a table can say
what a message costs on the link and not only in payload:

- the TCP stream bytes (everything the protocol sends: zenoh or MQTT framing, keep-alives, declarations);
- the TCP segments the kernel received from the publisher (``tcpi_segs_in`` of ``TCP_INFO``, data and pure
  ACKs alike), each of which costs :data:`HEADER_BYTES` of Ethernet, IPv4 and TCP header on a wire.

It needs no root (a veth's counters in a network namespace would). On loopback the MTU is 64 KiB, so a
message is rarely split: the segment count is loopback's, and on a 1500-byte Ethernet a message of more than
1448 bytes takes more segments (:func:`ethernet_segments` gives the least number).
"""

from __future__ import annotations

import math
import socket
import struct
import threading
from dataclasses import dataclass

__all__ = ["CountingProxy", "LinkCount", "HEADER_BYTES", "MSS_ETHERNET", "ethernet_segments"]

HEADER_BYTES = 14 + 20 + 32
"""Per TCP segment on an Ethernet link: Ethernet II header (14), IPv4 (20), TCP with the timestamp option (32)."""

MSS_ETHERNET = 1448
"""Payload of a full TCP segment on a 1500-byte MTU link with timestamps (1500 - 20 - 32)."""

_TCPI_BYTES_RECEIVED = 128  # struct tcp_info offsets (linux/tcp.h, kernel >= 4.6; 8-aligned u64s)
_TCPI_SEGS_IN = 140


def ethernet_segments(stream_bytes: float) -> int:
    """The fewest data segments ``stream_bytes`` of one message take on a 1500-byte MTU Ethernet link."""
    return max(1, math.ceil(stream_bytes / MSS_ETHERNET))


@dataclass(frozen=True, slots=True)
class LinkCount:
    """What the publisher had sent up to one moment: stream bytes and TCP segments (all its connections)."""

    stream_bytes: int
    segments: int

    @property
    def wire_bytes(self) -> int:
        """Stream bytes plus :data:`HEADER_BYTES` per segment."""
        return self.stream_bytes + HEADER_BYTES * self.segments

    def __sub__(self, other: "LinkCount") -> "LinkCount":
        return LinkCount(self.stream_bytes - other.stream_bytes, self.segments - other.segments)


class CountingProxy:
    """Listens on a free loopback port and forwards every connection to ``upstream`` (host, port), counting
    the client-to-upstream direction. :meth:`count` may be called from any thread while traffic flows."""

    def __init__(self, upstream: tuple[str, int]) -> None:
        self._upstream = upstream
        self._lock = threading.Lock()
        self._bytes = 0
        self._closed_segments = 0
        self._open: list[socket.socket] = []
        self._threads: list[threading.Thread] = []
        self._stop = threading.Event()
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._server.bind(("127.0.0.1", 0))
        self._server.listen(8)
        self._server.settimeout(0.2)
        self.port: int = self._server.getsockname()[1]
        self._accepter = threading.Thread(target=self._accept_loop, name="proxy-accept", daemon=True)
        self._accepter.start()

    # ------------------------------------------------------------------ counting

    @staticmethod
    def _segments_in(sock: socket.socket) -> int:
        try:
            info = sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 256)
        except OSError:
            return 0
        return struct.unpack_from("<I", info, _TCPI_SEGS_IN)[0] if len(info) >= _TCPI_SEGS_IN + 4 else 0

    @staticmethod
    def kernel_bytes_received(sock: socket.socket) -> int:
        """``tcpi_bytes_received`` of ``sock``: the kernel's own count, to check the proxy's against."""
        info = sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 256)
        return struct.unpack_from("<Q", info, _TCPI_BYTES_RECEIVED)[0]

    def count(self) -> LinkCount:
        """Bytes forwarded upstream so far and segments received from the clients so far."""
        with self._lock:
            segs = self._closed_segments + sum(self._segments_in(s) for s in self._open)
            return LinkCount(self._bytes, segs)

    def connections(self) -> list[socket.socket]:
        """The client sockets open now (for checks)."""
        with self._lock:
            return list(self._open)

    # ------------------------------------------------------------------ forwarding

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                client, _ = self._server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            try:
                up = socket.create_connection(self._upstream, timeout=5.0)
            except OSError:
                client.close()
                continue
            up.settimeout(None)
            client.settimeout(None)
            for s in (client, up):
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._open.append(client)
            for src, dst, counted in ((client, up, True), (up, client, False)):
                t = threading.Thread(
                    target=self._pump, args=(src, dst, counted, client), daemon=True, name="proxy-pump"
                )
                t.start()
                self._threads.append(t)

    def _pump(self, src: socket.socket, dst: socket.socket, counted: bool, client: socket.socket) -> None:
        try:
            while True:
                data = src.recv(65536)
                if not data:
                    break
                if counted:
                    with self._lock:
                        self._bytes += len(data)
                dst.sendall(data)
        except OSError:
            pass
        finally:
            if counted:
                with self._lock:
                    if client in self._open:
                        self._closed_segments += self._segments_in(client)
                        self._open.remove(client)
            for s in (src, dst):
                try:
                    s.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
            if counted:
                client.close()  # the other pump's recv returns on the shutdown above, then closes its side
            else:
                src.close()

    def close(self) -> None:
        """Stop accepting, close every connection and wait for the pumps."""
        self._stop.set()
        self._server.close()
        self._accepter.join(timeout=2.0)
        with self._lock:
            socks = list(self._open)
        for s in socks:
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        for t in self._threads:
            t.join(timeout=2.0)

    def __enter__(self) -> "CountingProxy":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
