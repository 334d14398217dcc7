"""How payloads are classified for MCAP (schema name, publish time), and world remapping."""

import msgpack
import pytest
from hypothesis import given, strategies as st

from fabric.recording import RAW_SCHEMA, peek, remap_world, world_of

from rec_helpers import joint_payload, scan_payload


def test_peek_reads_type_and_header_without_validating():
    p = peek(joint_payload(7, 123456789))
    assert (p.schema, p.wall_ns, p.seq) == ("JointState", 123456789, 7)
    assert peek(scan_payload(3, 42)).schema == "Scan"


@pytest.mark.parametrize(
    "payload",
    [
        b"",
        b"\xc1",
        b"hello",
        msgpack.packb({"a": 1}),
        msgpack.packb(["NoSuchType", 1]),
        msgpack.packb([1, 2]),
        msgpack.packb([]),
    ],
)
def test_peek_calls_anything_else_raw(payload):
    p = peek(payload)
    assert p.schema == RAW_SCHEMA and p.wall_ns is None


def test_peek_without_a_header_keeps_the_type_but_no_publish_time():
    p = peek(msgpack.packb(["Stop", ["NotHeader"]]))
    assert p.schema == "Stop" and p.wall_ns is None


@given(st.binary(max_size=300))
def test_peek_never_raises(data):
    assert isinstance(peek(data).schema, str)


def test_remap_world_replaces_only_the_world_chunk():
    assert remap_world("rf/a/robot/r0/joints", "b") == "rf/b/robot/r0/joints"
    assert remap_world("rf/a", "b") == "rf/b"
    assert remap_world("other/a/x", "b") == "other/a/x"
    assert world_of("rf/demo/robot/x/pose") == "demo" and world_of("/camera") is None
    with pytest.raises(ValueError):
        remap_world("rf/a/x", "bad/world")
