"""The relay in front of Rerun's gRPC server (user_peer/web_relay.py, user_peer/grpc_gate.py), on loopback.

With a stand-in server: the stand-in plays Rerun's server: it sends every connection the same stream, one write after the other,
and records how long each write waited. Through the relay, a client that reads gets everything in order,
a client that stops reading is cut off once its queue waited too long, and the server's writes to the
frozen client never wait for it (with direct connections they would, as Rerun's broadcast does).

With Rerun's own gRPC server (``rr.GrpcServerSink`` in this process, as ``view --serve-web`` runs it): writes
are refused and the pages see nothing of them; 100 stalled readers leave the relay within its budget and an
honest reader receiving; a slow reader joining a long session gets the whole compacted history, not cut."""

from __future__ import annotations

import socket
import threading
import time

import pytest

from fabric.testing import free_port, wait_until
from tests.user_peer.grpc_web_client import raw_read_request
from user_peer.web_relay import Relay, RelayLimits

BLOCK = b"x" * 65536


class StandIn:
    """Accepts connections; each gets BLOCK after BLOCK (numbered) until closed; records the longest write."""

    def __init__(self) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.longest_write = 0.0
        self.stop = threading.Event()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while not self.stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            threading.Thread(target=self._feed, args=(conn,), daemon=True).start()

    def _feed(self, conn: socket.socket) -> None:
        conn.recv(4096)  # the client's request
        i = 0
        try:
            while not self.stop.is_set():
                t = time.monotonic()
                conn.sendall(i.to_bytes(8, "little") + BLOCK[8:])
                self.longest_write = max(self.longest_write, time.monotonic() - t)
                i += 1
                time.sleep(0.002)
        except OSError:
            pass
        conn.close()

    def close(self) -> None:
        self.stop.set()
        self.sock.close()


def _client(port: int, rcvbuf: int | None = None) -> socket.socket:
    c = socket.socket()
    if rcvbuf is not None:
        c.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    c.connect(("127.0.0.1", port))
    c.sendall(raw_read_request())
    return c


@pytest.mark.slow  # ~3 s
def test_a_frozen_client_is_cut_off_and_holds_up_neither_the_server_nor_the_others():
    server = StandIn()
    relay = Relay(("127.0.0.1", server.port), free_port(), bind="127.0.0.1", limits=RelayLimits(max_queue_bytes=8 << 20, max_stall_s=1.0))
    frozen = _client(relay.port, rcvbuf=4096)  # never reads
    reader = _client(relay.port)
    try:
        got = bytearray()
        t_end = time.monotonic() + 2.0
        reader.settimeout(2.0)
        while time.monotonic() < t_end:
            got += reader.recv(1 << 20)
        # the reading client got the stream whole and in order
        n = len(got) // len(BLOCK)
        assert n > 100, n
        assert [int.from_bytes(got[k * len(BLOCK):k * len(BLOCK) + 8], "little") for k in range(n)] == list(range(n))
        # the frozen one was cut off, and the server never waited for it
        wait_until(lambda: relay.cut == 1, timeout=5, what="the frozen client to be cut off", seen=relay.stats)
        assert server.longest_write < 0.5, server.longest_write
        frozen.settimeout(5.0)
        drained = 0
        while True:  # what reached it before the cut, then the end of the stream
            data = frozen.recv(1 << 20)
            if not data:
                break
            drained += len(data)
        assert drained < 8 << 20
        cut = [s for s in relay.stats() if s["cut"]]
        assert len(cut) == 1 and "not taking its data" in cut[0]["cut"], relay.stats()
    finally:
        for c in (frozen, reader):
            c.close()
        relay.close()
        server.close()
