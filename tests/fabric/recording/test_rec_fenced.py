"""Recordings and the term: publish time and sequence are read from headers that
carry a term, and authority state of a lower term than one already written is left out and counted."""

from __future__ import annotations

from fabric import keys
from fabric.codec import decode, encode
from fabric.interfaces import Header, JointState, Path
from fabric.recording.format import peek
from user_peer.recordings import iter_messages
from fabric.recording.sink import STALE, McapSink
from robofabric.testing import wait_until


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


def _js_from(source: str, term: int, seq: int) -> bytes:
    return encode(JointState(("a",), [float(seq)], [0.0], Header(0.1 * seq, 1_000 + seq, seq, source, term)))


def test_the_sinks_fence_resets_when_the_worlds_last_sim_leaves(tmp_path):
    """After a take-over (term 2) the world's sims all go; a sim started afresh at term 1 is recorded again,
    late samples of a departed sim are left out, and each world has a fence of its own."""
    key, other = "rf/w/robot/arm1/joints", "rf/v/robot/arm1/joints"
    with McapSink(tmp_path / "run.mcap") as sink:
        sink.sim_seen("w", "sim-a")
        sink.sim_seen("w", "sim-b")
        assert sink.write(key, _js_from("sim-a", 1, 1), 10) == "JointState"
        assert sink.write(key, _js_from("sim-b", 2, 2), 20) == "JointState"  # sim-b took over
        assert sink.write(other, _js_from("sim-v", 1, 3), 25) == "JointState"  # another world, its own fence
        sink.sim_left("w", "sim-a")
        assert sink.fence_resets == 0  # sim-b still serves the world
        assert sink.write(key, _js_from("sim-a", 1, 4), 30) == STALE
        sink.sim_left("w", "sim-b")
        assert sink.fence_resets == 1
        assert sink.write(key, _js_from("sim-b", 2, 5), 40) == STALE  # in flight when sim-b left
        sink.sim_seen("w", "sim-c")
        assert sink.write(key, _js_from("sim-c", 1, 6), 50) == "JointState"  # the world restarted from scratch
        assert sink.write(key, _js_from("sim-c", 1, 7), 60) == "JointState"
        assert sink.stale == 2
    assert [m.sequence for m in iter_messages(tmp_path / "run.mcap", key)] == [1, 2, 6, 7]


def _put(fab, key):
    fab.publish(key, JointState(("a",), [float(fab.stamp.term)], [0.0], fab.header(key)))
    return False


def test_a_recorder_records_a_world_restarted_after_a_take_over(world, connect, tmp_path):
    """Real sessions: a sim at term 2 leaves, a sim started afresh at term 1 is recorded (a session's fence
    resets the same way: tests/fabric/test_fencing.py)."""
    from fabric.recording import Recorder

    key = keys.robot_joints(world, "arm1")
    path = tmp_path / "run.mcap"
    with Recorder(connect("recorder", "rec"), path) as rec:
        old = connect("sim", "sim-old")
        old.assume_term(2)
        wait_until(lambda: _put(old, key) or rec.stats.messages > 0, timeout=20, what="term 2 recorded")
        wait_until(
            lambda: world in rec.sink.fences and rec.sink.fences[world].sims == {"sim-old"},
            timeout=20,
            what="the recorder follows the sim tokens",
        )
        old.close()
        wait_until(lambda: rec.sink.fence_resets >= 1, timeout=20, what="the fence reset")
        new = connect("sim", "sim-new")
        new.assume_term(1)
        n = rec.stats.messages
        wait_until(lambda: _put(new, key) or rec.stats.messages >= n + 3, timeout=20, what="term 1 recorded again")
    sources = [decode(m.payload).header.source for m in iter_messages(path, key)]
    assert sources[0] == "sim-old" and sources[-3:] == ["sim-new"] * 3, sources
