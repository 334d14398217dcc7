"""What the web relay passes on to Rerun's gRPC server (user_peer/grpc_gate.py): reads, as a browser sends them."""

from __future__ import annotations

import pytest

from user_peer.grpc_gate import READ_METHODS, Refused, http1_refusal, parse_head

SVC = "/rerun.sdk_comms.v1alpha1.MessageProxyService/"


def head(line: str, *fields: str) -> bytes:
    return ("\r\n".join([line, "host: lab-pc:9876", *fields]) + "\r\n\r\n").encode()


@pytest.mark.parametrize("method", ["ReadMessages", "ReadTables"])
def test_a_read_and_its_preflight_pass_whole(method):
    post = head(f"POST {SVC}{method} HTTP/1.1", "content-type: application/grpc-web+proto", "content-length: 5")
    req = parse_head(post)
    assert (req.method, req.path, req.head, req.body_length) == ("POST", SVC + method, post, 5)
    pre = parse_head(head(f"OPTIONS {SVC}{method} HTTP/1.1", "access-control-request-method: POST"))
    assert (pre.method, pre.body_length) == ("OPTIONS", 0)
    assert SVC + method in READ_METHODS


@pytest.mark.parametrize(
    "raw, why",
    [
        (head(f"POST {SVC}WriteMessages HTTP/1.1", "content-length: 5"), "only reading"),
        (head(f"POST {SVC}WriteTable HTTP/1.1", "content-length: 5"), "only reading"),
        (head("POST /rerun.cloud.v1alpha1.RerunCloudService/DeleteEntry HTTP/1.1"), "only reading"),
        (head("POST /proxy HTTP/1.1"), "only reading"),
        (head("GET / HTTP/1.1"), "only reading"),
        (head(f"GET {SVC}ReadMessages HTTP/1.1"), "HTTP method GET"),
        (head(f"POST {SVC}ReadMessages HTTP/1.1", "transfer-encoding: chunked"), "chunked"),
        (head(f"POST {SVC}ReadMessages HTTP/1.1", "content-length: 10000000"), "request body of 10000000"),
        (head(f"POST {SVC}ReadMessages HTTP/1.1", "content-length: -1"), "request body of -1"),
        (head(f"POST {SVC}ReadMessages HTTP/1.1", "content-length: lots"), "Content-Length"),
        (head(f"POST {SVC}ReadMessages HTTP/1.1", "no colon here"), "malformed header"),
        (head(f"POST {SVC}ReadMessages HTTP/2.0"), "HTTP version"),
        (b"\x16\x03\x01\x02\x00garbage\r\n\r\n", "not an HTTP/1.1 request"),
    ],
)
def test_everything_else_is_refused_with_its_reason(raw, why):
    with pytest.raises(Refused) as err:
        parse_head(raw)
    assert why in err.value.reason, err.value.reason


def test_a_refusal_is_a_grpc_web_status_the_caller_reads():
    resp = http1_refusal("only reading the viewer's stream is relayed").decode()
    lines = resp.split("\r\n")
    assert lines[0] == "HTTP/1.1 200 OK" and resp.endswith("\r\n\r\n")
    assert "grpc-status: 7" in lines  # PERMISSION_DENIED
    assert "grpc-message: robofabric relay: only reading the viewer's stream is relayed" in lines
    assert "connection: close" in lines and "content-length: 0" in lines
