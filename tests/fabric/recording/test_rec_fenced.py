"""Recordings and the authority epoch (issue 16): publish time and sequence are read from headers that
carry a term, and authority state of a lower term than one already written is left out and counted."""

from __future__ import annotations

from fabric.codec import encode
from fabric.interfaces import Header, JointState, Path
from fabric.recording.format import peek
from fabric.recording.reader import iter_messages
from fabric.recording.sink import STALE, McapSink


def _js(term: int, seq: int) -> bytes:
    return encode(JointState(("a",), [float(seq)], [0.0], Header(0.1 * seq, 1_000 + seq, seq, f"sim-{term}", term)))


def test_peek_reads_headers_with_and_without_a_term():
    assert peek(_js(0, 3)).seq == 3 and peek(_js(0, 3)).term == 0
    p = peek(_js(2, 4))
    assert (p.schema, p.wall_ns, p.seq, p.term) == ("JointState", 1_004, 4, 2)


def test_the_sink_leaves_out_authority_state_of_a_lower_term(tmp_path):
    path = tmp_path / "run.mcap"
    key = "rf/w/robot/arm1/joints"
    user_key = "rf/w/robot/base1/path"
    with McapSink(path) as sink:
        assert sink.write(key, _js(1, 1), 10) == "JointState"
        assert sink.write(key, _js(2, 2), 20) == "JointState"
        assert sink.write(key, _js(1, 3), 30) == STALE  # the old primary, heard after its successor
        assert sink.write(key, _js(2, 4), 40) == "JointState"
        path_msg = encode(Path([0.0], [0.0], [0.0], header=Header(0.0, 50, 0, "alice")))
        assert sink.write(user_key, path_msg, 50) == "Path"  # users' keys carry term 0 and are never fenced
        assert sink.stale == 1
    got = [(m.key, m.sequence, m.publish_time) for m in iter_messages(path)]
    assert got == [(key, 1, 1_001), (key, 2, 1_002), (key, 4, 1_004), (user_key, 0, 50)]
