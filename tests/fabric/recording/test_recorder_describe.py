"""A recording gets its world's description even when the sim answers late: the recorder asks ``srv/world`` again
for about half a minute after a sim's token comes (fabric/recording/recorder.py, ``DESCRIBE_WAITS_S``). It asked
once, 0.2 s after the token; on a loaded box the sim had not answered in that ask's 3 s, and the recording went on
with no description (its export then needs ``--scene``)."""

from __future__ import annotations

from fabric import keys
from fabric.interfaces import ServiceError, WorldInfo
from fabric.recording.recorder import Recorder
from robofabric.testing import wait_until
from user_peer.recordings import iter_messages


def test_a_sim_that_refuses_the_first_ask_is_asked_again_and_its_world_recorded(world, connect, tmp_path):
    asked: list[int] = []

    def answer(key: str, request: object) -> WorldInfo:
        asked.append(1)
        if len(asked) == 1:
            raise ServiceError("not ready: still building its scene")  # the first ask meets no description
        return WorldInfo(world, "combined", 0.002, {}, ())

    path = tmp_path / "run.mcap"
    rec = Recorder(connect("recorder", "rec"), path).start()
    try:
        sim = connect("sim", "sim-a")  # its token: the recorder asks for the world
        sim.rpc.serve(keys.srv(world, "world"), answer)
        wait_until(lambda: rec.described >= 1, timeout=30, what="the world described", seen=lambda: len(asked))
        assert len(asked) >= 2, asked
    finally:
        rec.close()
    (m,) = list(iter_messages(path, keys.srv(world, "world")))
    assert m.key == keys.srv(world, "world")
