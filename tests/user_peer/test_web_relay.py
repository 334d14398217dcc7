"""The relay in front of Rerun's gRPC server (user_peer/web_relay.py, user_peer/grpc_gate.py), on loopback.

With a stand-in server: the stand-in plays Rerun's server: it sends every connection the same stream, one write after the other,
and records how long each write waited. Through the relay, a client that reads gets everything in order,
a client that stops reading is cut off once its queue waited too long, and the server's writes to the
frozen client never wait for it (with direct connections they would, as Rerun's broadcast does).

With Rerun's own gRPC server (``rr.GrpcServerSink`` in this process, as ``view --serve-web`` runs it): writes
are refused and the pages see nothing of them; 100 stalled readers leave the relay within its budget and an
honest reader receiving; a slow reader joining a long session gets the whole compacted history, not cut."""

from __future__ import annotations

import http.client
import socket
import threading
import time

import numpy as np
import pytest

from robofabric.testing import free_port, wait_until
from robofabric.bench.grpc_web import HEADERS, WRITE, WebReader, arrow_payload, raw_read_request, stalled_reader
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
    relay = Relay(
        ("127.0.0.1", server.port),
        free_port(),
        bind="127.0.0.1",
        limits=RelayLimits(max_queue_bytes=8 << 20, max_stall_s=1.0),
    )
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
        assert [int.from_bytes(got[k * len(BLOCK) : k * len(BLOCK) + 8], "little") for k in range(n)] == list(range(n))
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


def test_connections_are_capped_in_all_and_per_address_and_idle_ones_are_closed():
    server = StandIn()
    relay = Relay(
        ("127.0.0.1", server.port),
        free_port(),
        bind="0.0.0.0",
        limits=RelayLimits(max_links=3, max_links_per_address=2, header_timeout_s=30.0),
    )
    conns: list[socket.socket] = []

    def connect(source: str) -> socket.socket:
        c = socket.socket()
        c.bind((source, 0))
        c.connect(("127.0.0.1", relay.port))
        conns.append(c)
        return c

    def refused(c: socket.socket) -> bytes:
        c.settimeout(10)
        return c.recv(4096)

    try:
        connect("127.0.0.5"), connect("127.0.0.5")  # idle, within header_timeout_s
        wait_until(lambda: relay.counters().links == 2, timeout=5, what="two connections", seen=relay.counters)
        third = refused(connect("127.0.0.5"))
        assert b"grpc-status: 7" in third and b"max_links_per_address" in third, third
        connect("127.0.0.6")
        wait_until(lambda: relay.counters().links == 3, timeout=5, what="three connections", seen=relay.counters)
        fourth = refused(connect("127.0.0.7"))
        assert b"grpc-status: 7" in fourth and b"max_links" in fourth, fourth
        assert relay.counters().refused_connections == 2, relay.counters()
    finally:
        for c in conns:
            c.close()
        relay.close()
        server.close()


def test_a_connection_that_sends_no_request_is_closed():
    server = StandIn()
    relay = Relay(("127.0.0.1", server.port), free_port(), bind="127.0.0.1", limits=RelayLimits(header_timeout_s=0.3))
    c = socket.create_connection(("127.0.0.1", relay.port))
    try:
        c.settimeout(10)
        got = c.recv(4096)
        assert b"grpc-status: 7" in got and b"no request within" in got, got
        wait_until(
            lambda: relay.counters().links == 0, timeout=5, what="the idle connection to be closed", seen=relay.counters
        )
        assert relay.counters().refused_connections == 1, relay.counters()
    finally:
        c.close()
        relay.close()
        server.close()


# -- with Rerun's own gRPC server ---------------------------------------------------------------------


class Session:
    """Rerun's gRPC server in this process, as ``view --serve-web`` runs it (newest first, a history limit), with
    the relay in front; ``log_bulk`` logs incompressible points (a long session's history), ``live`` keeps logging."""

    def __init__(self, history: str, limits: RelayLimits = RelayLimits(), bind: str = "127.0.0.1") -> None:
        import rerun as rr

        self.rr = rr
        self.inner = free_port()
        self.rec = rr.RecordingStream("robofabric", recording_id=f"relay-{self.inner}")
        self.rec.set_sinks(
            rr.GrpcServerSink(bind_ip="127.0.0.1", port=self.inner, newest_first=True, server_memory_limit=history)
        )
        self.relay = Relay(("127.0.0.1", self.inner), free_port(), bind=bind, limits=limits)
        self.rng = np.random.default_rng(0)
        self._stop = threading.Event()
        self._live: threading.Thread | None = None
        self.rec.log("scene/static", self.rr.TextLog("STATIC-SCENE-MARKER"), static=True)

    def log_bulk(self, nbytes: int, each: int = 120_000) -> None:
        for i in range(nbytes // each):
            self.rec.set_time("step", sequence=i)
            self.rec.log("bulk", self.rr.Points3D(self.rng.random((each // 12, 3), dtype=np.float32)))
        self.rec.flush(timeout_sec=30)

    def live(self, rate: float) -> None:
        """Log ~``rate`` bytes a second until close (the world going on while pages watch)."""

        def run() -> None:
            while not self._stop.wait(0.1):
                self.rec.log("live", self.rr.Points3D(self.rng.random((int(rate / 10 / 12), 3), dtype=np.float32)))

        self._live = threading.Thread(target=run, daemon=True)
        self._live.start()

    def close(self) -> None:
        self._stop.set()
        if self._live is not None:
            self._live.join(5)
        self.relay.close()
        self.rec.disconnect()


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:")) / 1024


@pytest.mark.slow  # ~10 s: Rerun's server, native gRPC and gRPC-web writers
def test_writes_are_refused_and_pages_see_nothing_of_them():
    import grpc

    s = Session("8MiB")
    honest = WebReader(s.relay.port)
    try:
        assert honest.status == 200
        wait_until(lambda: honest.saw(b"STATIC-SCENE-MARKER"), timeout=10, what="the honest page to get the scene")
        # mallory's Rerun SDK, as she logged fake events and a recursive Clear into every page
        m = s.rr.RecordingStream("robofabric", recording_id=f"relay-{s.inner}")
        m.set_sinks(s.rr.GrpcSink(f"rerun+http://127.0.0.1:{s.relay.port}/proxy"))
        for step in (
            lambda: m.log("events", s.rr.TextLog("MALLORY-SDK-MARKER")),
            lambda: m.log("world/robots", s.rr.Clear(recursive=True)),
            lambda: m.flush(timeout_sec=5),
            m.disconnect,
        ):
            try:
                step()
            except RuntimeError as exc:  # the SDK hears of the refusal when its sink's stream ends: at any step
                # in its own words, or (a flush racing the refusal, its log says PermissionDenied) as a flush that
                # failed on an open connection; the relay's count of refusals below says which it was
                assert "permission" in str(exc) or "flush still failed" in str(exc), exc
        # a native gRPC client: WriteMessages and a method Rerun does not have, each answered PERMISSION_DENIED
        with grpc.insecure_channel(f"127.0.0.1:{s.relay.port}") as ch:
            with pytest.raises(grpc.RpcError) as err:
                ch.stream_unary(WRITE)(iter([b"\x0a\x00"]), timeout=10)
            assert err.value.code() == grpc.StatusCode.PERMISSION_DENIED, err.value
            with pytest.raises(grpc.RpcError) as err:
                ch.unary_unary("/rerun.sdk_comms.v1alpha1.MessageProxyService/DropEverything")(b"", timeout=10)
            assert err.value.code() == grpc.StatusCode.PERMISSION_DENIED, err.value
        # gRPC-web, as a page would send it
        c = http.client.HTTPConnection("127.0.0.1", s.relay.port, timeout=10)
        c.request("POST", WRITE, body=b"\0\0\0\0\0", headers=HEADERS)
        r = c.getresponse()
        assert (r.status, r.getheader("grpc-status")) == (200, "7"), r.getheaders()
        c.close()
        counted = s.relay.counters()
        assert counted.refused_requests >= 4, counted
        # control: the same write straight to Rerun's server reaches the page, so the page would have shown mallory's
        direct = s.rr.RecordingStream("robofabric", recording_id=f"relay-{s.inner}")
        direct.set_sinks(s.rr.GrpcSink(f"rerun+http://127.0.0.1:{s.inner}/proxy"))
        direct.log("events", s.rr.TextLog("DIRECT-CONTROL-MARKER"))
        direct.flush(timeout_sec=5)
        wait_until(lambda: honest.saw(b"DIRECT-CONTROL-MARKER"), timeout=10, what="the control write to reach the page")
        direct.disconnect()
        assert not honest.saw(b"MALLORY-SDK-MARKER"), "a write through the relay reached the page"
        assert honest.ended == "", honest.ended
    finally:
        honest.close()
        s.close()


@pytest.mark.slow  # ~15 s: 100 connections against Rerun's server
def test_100_stalled_readers_leave_the_relay_within_its_budget_and_an_honest_page_receiving():
    limits = RelayLimits(
        max_links=64,
        max_links_per_address=8,
        max_queue_bytes=16 << 20,
        max_total_bytes=48 << 20,
        max_stall_s=2.0,
        header_timeout_s=1.0,
    )
    s = Session("8MiB", limits, bind="0.0.0.0")  # every loopback address: readers come from 127.0.0.x
    s.log_bulk(12 << 20)  # a session going on: 8 MiB of history for each new reader
    s.live(1e6)
    rss0 = _rss_mb()
    threads0 = threading.active_count()
    honest = WebReader(s.relay.port, source="127.0.0.2")
    stalled: list[socket.socket] = []
    idle: list[socket.socket] = []
    peak_threads = 0
    try:
        wait_until(lambda: honest.received > 1 << 20, timeout=20, what="the honest page to receive")
        for i in range(100):  # 100 addresses: the per-address cap does not stop them, the others must
            try:
                stalled.append(stalled_reader(s.relay.port, source=f"127.0.0.{10 + i}"))
            except OSError:
                pass
        for _ in range(3):  # connections that send nothing
            c = socket.socket()
            c.bind(("127.0.0.3", 0))
            c.connect(("127.0.0.1", s.relay.port))
            idle.append(c)
        before = honest.received
        t0 = time.monotonic()

        def settled() -> bool:
            nonlocal peak_threads
            peak_threads = max(peak_threads, threading.active_count())
            k = s.relay.counters()
            return k.links == 1 and k.cut + k.refused_connections >= 100 + 3 and time.monotonic() - t0 > 3

        wait_until(
            settled,
            timeout=60,
            interval=0.2,
            what="every stalled and idle connection to be cut or refused",
            seen=lambda: (s.relay.counters(), [x for x in s.relay.stats() if not x["closed"]][:5]),
        )
        k = s.relay.counters()
        rss = _rss_mb()
        print(f"100 stalled readers: {k}; RSS {rss0:.0f} -> {rss:.0f} MB; threads {threads0} -> peak {peak_threads}")
        assert k.peak_queued_bytes <= limits.max_total_bytes, k  # never over, not even for a moment
        assert k.refused_connections >= 3, k  # the idle ones, at least (others over max_links when cuts lag)
        assert peak_threads <= threads0 + 3 * limits.max_links + 16, peak_threads
        got = honest.received
        wait_until(
            lambda: honest.received > got + (1 << 20),
            timeout=20,
            what="the honest page to keep receiving",
            seen=lambda: (honest.received, honest.ended, s.relay.stats()),
        )
        assert honest.received > before and honest.ended == "", (honest.ended, s.relay.stats())
        assert all(not x["cut"] for x in s.relay.stats() if x["peer"].startswith("127.0.0.2:")), s.relay.stats()
        # the relay's counters are the measure; RSS also holds Rerun's server (its history, each client's stream)
        assert rss - rss0 < 1000, (rss0, rss)
    finally:
        for c in stalled + idle:
            c.close()
        honest.close()
        s.close()


@pytest.mark.slow  # ~15 s: a reader of 1 MB/s takes a 12 MiB history
def test_a_slow_reader_joining_a_long_session_gets_the_world_first_and_is_not_cut():
    s = Session("12MiB")  # Rerun keeps the static scene and the newest 12 MiB: the compacted start
    s.log_bulk(40 << 20)  # a long session: far more than the history holds
    s.live(100e3)
    slow = WebReader(s.relay.port, rate=1e6)  # a page on a slow link: 1 MB/s
    try:
        wait_until(
            lambda: slow.received > 12 << 20,
            timeout=60,
            interval=0.5,
            what="the slow reader to take the history",
            seen=lambda: (slow.received, slow.ended, s.relay.stats()),
        )
        assert s.relay.cut == 0 and slow.ended == "", (slow.ended, s.relay.stats())
        # the scene (static) came first, before the history's bulk
        first = [arrow_payload(f) for f in slow.frames[:20]]
        assert any(b"STATIC-SCENE-MARKER" in p for p in first), [len(p) for p in first]
        assert max(x["queued"] for x in s.relay.stats()) <= s.relay.limits.max_queue_bytes
    finally:
        slow.close()
        s.close()


@pytest.mark.slow  # ~1 s
def test_a_request_sent_a_byte_at_a_time_must_still_come_within_the_timeout():
    server = StandIn()
    relay = Relay(("127.0.0.1", server.port), free_port(), bind="127.0.0.1", limits=RelayLimits(header_timeout_s=0.5))
    c = socket.create_connection(("127.0.0.1", relay.port))
    try:
        c.settimeout(10)
        got = b""
        for byte in raw_read_request():  # bounded: the request's length; each byte well within the timeout
            try:
                c.sendall(bytes([byte]))
            except OSError:
                break
            time.sleep(0.05)
            if relay.counters().refused_connections:
                break
        got = c.recv(4096)
        assert b"grpc-status: 7" in got and b"no request within" in got, got
        assert relay.counters().refused_connections == 1, relay.counters()
    finally:
        c.close()
        relay.close()
        server.close()
