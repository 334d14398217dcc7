"""The relay passes a request head on to Rerun's server only when it parses it strictly (issue 42): a head two parsers
could read two ways is refused, never relayed. The relay once passed a bare-LF ``transfer-encoding`` header on
to Rerun unchanged (Rerun refused it; the relay did not)."""

from __future__ import annotations

import socket
import threading

import pytest

from robofabric.bench.grpc_web import raw_read_request
from robofabric.testing import free_port, wait_until
from user_peer.grpc_gate import Refused, parse_head
from user_peer.web_relay import Relay

READ = "POST /rerun.sdk_comms.v1alpha1.MessageProxyService/ReadMessages HTTP/1.1"


def head(*fields: str, line: str = READ) -> bytes:
    return ("\r\n".join([line, "host: lab-pc:9876", *fields]) + "\r\n\r\n").encode("latin-1")


@pytest.mark.parametrize(
    "raw, why",
    [
        (head("x-note: a\ntransfer-encoding: chunked", "content-length: 5"), "bare LF"),
        (head("x-note: a\rtransfer-encoding: chunked", "content-length: 5"), "bare LF, CR"),
        (head("content-length: 5", " chunked"), "folded"),
        (head("content-length: 5", "\tx"), "folded"),
        (head("content-length: 5", "content-length: 5"), "second framing header (content-length) after content-length"),
        (head("content-length: 5", "content-length: 7"), "second framing header"),
        (head("content-length: 5", "transfer-encoding: chunked"), "second framing header (transfer-encoding)"),
        (
            head("transfer-encoding: chunked", "content-length: 5"),
            "second framing header (content-length) after transfer-encoding",
        ),
        (head("content-length : 5"), "malformed header name"),
        (head("content length: 5"), "malformed header name"),
        (head("content-length: +5"), "malformed Content-Length"),
        (head("content-length: 1_0"), "malformed Content-Length"),
        (head("content-length: 5 5"), "malformed Content-Length"),
        (head("x-note: a\x00b", "content-length: 5"), "control character"),
        (head("content-length: 5", line=READ + "x"), "HTTP version"),
        (head("content-length: 5", line=READ.replace("POST", "POST\x0b")), "control character in the request line"),
    ],
)
def test_a_head_two_parsers_could_read_two_ways_is_refused(raw, why):
    with pytest.raises(Refused) as err:
        parse_head(raw)
    assert why in err.value.reason, err.value.reason


def test_a_strict_head_still_passes_with_its_tabs_and_spaces_around_values():
    req = parse_head(head("content-type:\tapplication/grpc-web+proto ", "content-length:  5", "x-grpc-web: 1"))
    assert req.body_length == 5


class Recorder:
    """A stand-in for Rerun's server that records every byte it is sent."""

    def __init__(self) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.got = bytearray()
        self.connections = 0
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.connections += 1
            threading.Thread(target=self._read, args=(conn,), daemon=True).start()

    def _read(self, conn: socket.socket) -> None:
        with conn:
            while data := conn.recv(65536):
                self.got += data

    def close(self) -> None:
        self.sock.close()


def test_the_relay_refuses_a_bare_lf_transfer_encoding_and_rerun_sees_nothing_of_it():
    up = Recorder()
    relay = Relay(("127.0.0.1", up.port), free_port(), bind="127.0.0.1")
    try:
        smuggled = head("x-note: a\ntransfer-encoding: chunked", "content-length: 5") + b"\x00\x00\x00\x00\x00"
        with socket.create_connection(("127.0.0.1", relay.port), timeout=10) as c:
            c.sendall(smuggled)
            answer = c.recv(4096)
        assert b"grpc-status: 7" in answer and b"bare LF" in answer, answer
        assert relay.counters().refused_requests == 1 and up.connections == 0 and not up.got
        with socket.create_connection(("127.0.0.1", relay.port), timeout=10) as c:  # an honest read still goes through
            c.sendall(raw_read_request())
            wait_until(lambda: bytes(up.got).startswith(raw_read_request()), timeout=10, what="the read relayed whole")
    finally:
        relay.close()
        up.close()
