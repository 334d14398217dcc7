"""A gRPC-web reader of Rerun's stream, as a browser page is (HTTP/1.1, ``application/grpc-web+proto``), for the
relay's tests and ``python -m robofabric.bench.web_relay``: it reads at a pace it is given, and decodes what it read far enough to search the recording's
Arrow payloads (``ReadMessagesResponse.log_msg.arrow_msg``, LZ4-decompressed) for a marker.

Protobuf is walked without its schema (field numbers from Rerun's ``sdk_comms.proto`` and ``log_msg.proto``):
the tests need three fields, not the whole of Rerun's protocol."""

from __future__ import annotations

import http.client
import socket
import threading
import time

import lz4.block

READ = "/rerun.sdk_comms.v1alpha1.MessageProxyService/ReadMessages"
WRITE = "/rerun.sdk_comms.v1alpha1.MessageProxyService/WriteMessages"
HEADERS = {"content-type": "application/grpc-web+proto", "x-grpc-web": "1", "accept": "application/grpc-web+proto"}
EMPTY_FRAME = b"\0\0\0\0\0"  # a gRPC-web data frame holding the empty ReadMessagesRequest
LZ4 = 2  # rerun.common.v1alpha1.Compression.COMPRESSION_LZ4


def raw_read_request(host: str = "127.0.0.1") -> bytes:
    """The bytes of a page's ReadMessages request, for clients that send it and never read."""
    return (
        f"POST {READ} HTTP/1.1\r\nhost: {host}\r\ncontent-type: application/grpc-web+proto\r\n"
        f"x-grpc-web: 1\r\ncontent-length: {len(EMPTY_FRAME)}\r\n\r\n"
    ).encode() + EMPTY_FRAME


def stalled_reader(port: int, source: str = "127.0.0.1") -> socket.socket:
    """A connection that asks for the stream and never reads (a small receive buffer, so it stalls soon)."""
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.bind((source, 0))
    s.connect(("127.0.0.1", port))
    s.sendall(raw_read_request())
    return s


def _varint(buf: bytes, i: int) -> tuple[int, int]:
    v = shift = 0
    while True:
        b = buf[i]
        i += 1
        v |= (b & 0x7F) << shift
        if b < 0x80:
            return v, i
        shift += 7


def _fields(buf: bytes) -> dict[int, list]:
    """Top-level fields of a protobuf message: number -> values (ints, or bytes for length-delimited)."""
    out: dict[int, list] = {}
    i = 0
    while i < len(buf):
        key, i = _varint(buf, i)
        wt = key & 7
        if wt == 0:
            v, i = _varint(buf, i)
        elif wt == 2:
            n, i = _varint(buf, i)
            v, i = buf[i : i + n], i + n
        elif wt == 1:
            v, i = buf[i : i + 8], i + 8
        elif wt == 5:
            v, i = buf[i : i + 4], i + 4
        else:
            raise ValueError(f"wire type {wt}")
        out.setdefault(key >> 3, []).append(v)
    return out


def arrow_payload(message: bytes) -> bytes:
    """The Arrow IPC bytes of one ReadMessagesResponse (b"" for a message that holds none)."""
    log_msg = _fields(message).get(1, [b""])[0]
    arrow = _fields(log_msg).get(2)
    if not arrow:
        return b""
    f = _fields(arrow[0])
    payload = f.get(5, [b""])[0]
    if f.get(2, [0])[0] == LZ4:
        return lz4.block.decompress(payload, uncompressed_size=f.get(3, [0])[0])
    return payload


class WebReader:
    """Reads Rerun's stream through ``port`` from ``source`` in a thread, at most ``rate`` bytes/s (None: as fast
    as it comes); ``close()`` ends it. ``frames``: the gRPC-web data frames read so far."""

    def __init__(self, port: int, *, source: str = "127.0.0.1", rate: float | None = None) -> None:
        self.received = 0
        self.frames: list[bytes] = []
        self.status: int | None = None
        self.ended = ""  # why the stream ended, if it did
        self._buf = bytearray()
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self.conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10, source_address=(source, 0))
        self.conn.request("POST", READ, body=EMPTY_FRAME, headers=HEADERS)
        self.response = self.conn.getresponse()
        self.status = self.response.status
        self.rate = rate
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        t0 = time.monotonic()
        try:
            while not self._stop.is_set():
                data = self.response.read1(16384)
                if not data:
                    self.ended = "end of stream"
                    return
                with self._lock:
                    self.received += len(data)
                    self._buf += data
                    self._split()
                if self.rate:  # a reader of limited bandwidth: it takes no more than rate bytes a second
                    ahead = self.received / self.rate - (time.monotonic() - t0)
                    if ahead > 0:
                        self._stop.wait(ahead)
        except (
            OSError,
            http.client.HTTPException,
            AttributeError,
            ValueError,
        ) as exc:  # AttributeError: closed under it
            self.ended = self.ended or f"{type(exc).__name__}: {exc}"

    def _split(self) -> None:
        while len(self._buf) >= 5:
            n = int.from_bytes(self._buf[1:5], "big")
            if len(self._buf) < 5 + n:
                return
            if self._buf[0] == 0:  # a data frame (0x80: trailers)
                self.frames.append(bytes(self._buf[5 : 5 + n]))
            del self._buf[: 5 + n]

    def saw(self, marker: bytes) -> bool:
        """Whether any Arrow payload read so far holds ``marker``."""
        with self._lock:
            frames = list(self.frames)
        return any(marker in arrow_payload(f) for f in frames)

    def close(self) -> None:
        self._stop.set()
        self.ended = self.ended or "closed by the test"
        try:
            self.conn.sock.shutdown(socket.SHUT_RDWR)
        except (OSError, AttributeError):
            pass
        self._thread.join(5)
        self.conn.close()
