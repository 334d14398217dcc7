"""What the web viewer's relay lets through to Rerun's gRPC server: reading the viewer's stream, nothing else.

Rerun's gRPC server (``rerun.sdk_comms.v1alpha1.MessageProxyService``) serves four methods on one port:
``ReadMessages`` and ``ReadTables`` stream the recording out; ``WriteMessages`` and ``WriteTable`` put data
*into* it, and the server sends what anyone writes to every page. The pages of ``view --serve-web`` only
ever read, so the relay (user_peer/web_relay.py) relays a request only when it is one of the two reads, as
a browser sends it: gRPC-web over HTTP/1.1 (a ``POST`` to the method's path, after a CORS preflight
``OPTIONS`` to the same path). Anything else gets a gRPC error status (``PERMISSION_DENIED``) and the
connection is closed: writes, unknown methods, other HTTP methods, oversized or chunked requests, and every
HTTP/2 (native gRPC) connection, which no page opens (a browser never speaks HTTP/2 without TLS). An HTTP/2
caller is answered in HTTP/2 (with ``h2``) so that its gRPC client reports the status, not a broken pipe.

The request side is parsed, never the response side: Rerun's stream flows back untouched.
"""

from __future__ import annotations

import re
import socket
import time
from dataclasses import dataclass
from typing import Callable
from urllib.parse import quote

__all__ = [
    "READ_METHODS",
    "H2_PREFACE",
    "Request",
    "Refused",
    "Http2",
    "parse_head",
    "read_request",
    "http1_refusal",
    "refuse_http2",
]

SERVICE = "/rerun.sdk_comms.v1alpha1.MessageProxyService/"
READ_METHODS = frozenset({SERVICE + "ReadMessages", SERVICE + "ReadTables"})
H2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"
MAX_HEAD_BYTES = 16 * 1024  # a browser's request head is well under 2 KiB
MAX_BODY_BYTES = 64 * 1024  # a read request's body is one empty gRPC-web frame (5 bytes)
PERMISSION_DENIED = 7
H2_MAX_REFUSED = 16  # streams answered on one HTTP/2 connection before it is closed


class Refused(Exception):
    """A request the relay does not pass on; ``method`` names what was asked (path or preface) for the log."""

    def __init__(self, reason: str, method: str = "") -> None:
        super().__init__(reason)
        self.reason = reason
        self.method = method


class Http2(Exception):
    """The connection speaks HTTP/2 (a native gRPC client): answered by :func:`refuse_http2`."""


@dataclass(frozen=True, slots=True)
class Request:
    """One HTTP/1.1 request head that may go to Rerun: its bytes as received, and its body's length."""

    method: str
    path: str
    head: bytes
    body_length: int


def parse_head(head: bytes) -> Request:
    """Check one request head (up to and including its blank line); raises :class:`Refused` unless it is a read.

    Strict, since the head goes on to Rerun's own parser as received: a head two parsers could read two ways (a
    bare LF or CR, a folded line, a space before a colon, a control character, two Content-Lengths, any
    Transfer-Encoding) is refused, never passed on. Pure: no socket, so every refusal is tested alone."""
    try:
        text = head.decode("latin-1")
        line, *fields = text.split("\r\n")
        method, path, version = line.split(" ")
    except ValueError:
        raise Refused("not an HTTP/1.1 request", head[:40].decode("latin-1", "replace")) from None
    if version not in ("HTTP/1.1", "HTTP/1.0"):
        raise Refused(f"HTTP version {version!r}", path)
    if _CONTROL.search(line):
        raise Refused("a control character in the request line", path)
    headers: dict[str, str] = {}
    for f in fields:
        if f:
            headers.update([_field(f, path, headers)])
    if path.split("?", 1)[0] not in READ_METHODS:
        raise Refused("only reading the viewer's stream is relayed", path)
    if method not in ("POST", "OPTIONS"):
        raise Refused(f"HTTP method {method}", path)
    if "transfer-encoding" in headers:
        raise Refused("chunked request bodies are not relayed", path)
    value = headers.get("content-length", "0")
    if not _LENGTH.fullmatch(value):
        raise Refused("a malformed Content-Length", path)
    length = int(value)
    if not 0 <= length <= MAX_BODY_BYTES:
        raise Refused(f"a request body of {length} bytes (a read's is a few)", path)
    return Request(method, path, head, length)


_CONTROL = re.compile(r"[\x00-\x08\x0a-\x1f\x7f]")  # every control character but the tab (a bare LF or CR too)
_TOKEN = re.compile(r"[!#$%&'*+.^_`|~0-9A-Za-z-]+")  # a header name (RFC 9110's token)
_LENGTH = re.compile(r"-?[0-9]+")
_FRAMING = ("content-length", "transfer-encoding")


def _field(f: str, path: str, seen: dict[str, str]) -> tuple[str, str]:
    """One header line as (lower-case name, value); :class:`Refused` for one a strict parser would not read alike."""
    if f[0] in " \t":
        raise Refused("an obsolete folded header line", path)
    if _CONTROL.search(f):
        raise Refused("a bare LF, CR or control character in a header line", path)
    name, sep, value = f.partition(":")
    if not sep:
        raise Refused("a malformed header line", path)
    if not _TOKEN.fullmatch(name):
        raise Refused(f"a malformed header name {name[:40]!r}", path)
    key = name.lower()
    if key in _FRAMING and any(k in seen for k in _FRAMING):
        raise Refused(f"a second framing header ({name}) after {', '.join(k for k in _FRAMING if k in seen)}", path)
    return key, value.strip(" \t")


def read_request(sock: socket.socket, buf: bytearray, deadline: float | None = None) -> tuple[Request, bytes] | None:
    """The next request head and body from ``sock`` (``buf``: what was received beyond the previous one), or
    None when the page closed between requests. ``deadline`` (monotonic): the whole request must have come by
    then (a client sending a byte now and then does not hold a connection open). Raises :class:`Refused`, :class:`Http2` (the connection opened
    with HTTP/2's preface: what was received stays in ``buf``), and OSError (a timeout included)."""
    while True:
        start = bytes(buf[: len(H2_PREFACE)])
        if start == H2_PREFACE:
            raise Http2()
        if not H2_PREFACE.startswith(start):  # not (the beginning of) HTTP/2's preface, whose text has a blank line
            end = buf.find(b"\r\n\r\n")
            if end >= 0:
                break
        if len(buf) > MAX_HEAD_BYTES:
            raise Refused(f"a request head over {MAX_HEAD_BYTES} bytes")
        data = _recv(sock, deadline)
        if not data:
            if buf:
                raise Refused("the connection closed inside a request head")
            return None
        buf += data
    req = parse_head(bytes(buf[: end + 4]))
    del buf[: end + 4]
    while len(buf) < req.body_length:
        data = _recv(sock, deadline)
        if not data:
            raise Refused("the connection closed inside a request body", req.path)
        buf += data
    body = bytes(buf[: req.body_length])
    del buf[: req.body_length]
    return req, body


def _recv(sock: socket.socket, deadline: float | None) -> bytes:
    if deadline is not None:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError("the request did not come in time")
        sock.settimeout(left)
    return sock.recv(65536)


def http1_refusal(reason: str) -> bytes:
    """A gRPC-web error response (trailers-only: the status in the headers), ``PERMISSION_DENIED``; the
    connection closes after it."""
    msg = quote(f"robofabric relay: {reason}", safe=" /:'(),.")
    return (
        f"HTTP/1.1 200 OK\r\ncontent-type: application/grpc-web+proto\r\ngrpc-status: {PERMISSION_DENIED}\r\n"
        f"grpc-message: {msg}\r\ncontent-length: 0\r\nconnection: close\r\n\r\n"
    ).encode("latin-1")


def refuse_http2(sock: socket.socket, received: bytes, on_refused: Callable[[str], None], *, timeout_s: float) -> None:
    """Answer every gRPC call of an HTTP/2 connection with ``PERMISSION_DENIED`` (``on_refused(path)`` for each),
    until the caller closes, ``timeout_s`` passes, or :data:`H2_MAX_REFUSED` calls were refused; then GOAWAY."""
    import h2.config
    import h2.connection
    import h2.events
    import h2.exceptions

    conn = h2.connection.H2Connection(config=h2.config.H2Configuration(client_side=False, header_encoding="utf-8"))
    conn.initiate_connection()
    refused = 0
    deadline = time.monotonic() + timeout_s
    data = received
    try:
        while True:
            for ev in conn.receive_data(data) if data else ():
                if isinstance(ev, h2.events.RequestReceived):
                    path = dict(ev.headers).get(":path", "?")
                    on_refused(path)
                    refused += 1
                    msg = quote(
                        f"robofabric relay: only reading the viewer's stream (gRPC-web) is relayed; {path} refused",
                        safe=" /:'(),.;",
                    )
                    conn.send_headers(
                        ev.stream_id,
                        [
                            (":status", "200"),
                            ("content-type", "application/grpc"),
                            ("grpc-status", str(PERMISSION_DENIED)),
                            ("grpc-message", msg),
                        ],
                        end_stream=True,
                    )
                    try:  # the caller may still be streaming its request: that half ends here too
                        conn.reset_stream(ev.stream_id, error_code=0)
                    except h2.exceptions.H2Error:
                        pass
                elif isinstance(ev, h2.events.DataReceived):
                    try:
                        conn.acknowledge_received_data(ev.flow_controlled_length, ev.stream_id)
                    except h2.exceptions.H2Error:
                        pass
                elif isinstance(ev, h2.events.ConnectionTerminated):
                    return
            if refused >= H2_MAX_REFUSED:
                conn.close_connection()
            sock.sendall(conn.data_to_send())
            if refused >= H2_MAX_REFUSED:
                return
            left = deadline - time.monotonic()
            if left <= 0:
                conn.close_connection()
                sock.sendall(conn.data_to_send())
                return
            sock.settimeout(left)
            data = sock.recv(65536)
            if not data:
                return
    except (OSError, h2.exceptions.H2Error):
        return
