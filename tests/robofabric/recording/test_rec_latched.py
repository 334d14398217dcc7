"""A replay into a live world keeps latched keys latched: a late joiner gets the replayed map."""

from __future__ import annotations

import threading

import numpy as np

from fabric import keys
from fabric.codec import encode
from fabric.interfaces import Header, OccupancyGrid
from robofabric.recording import Replayer, plan_replay
from robofabric.testing import wait_until

from tests.fabric.recording.rec_helpers import joint_payload, write_recording


class Inbox:
    def __init__(self) -> None:
        self.got: list[str] = []
        self._lock = threading.Lock()

    def __call__(self, key: str, msg: object) -> None:
        with self._lock:
            self.got.append(key)

    def keys(self) -> list[str]:
        with self._lock:
            return list(self.got)


def test_a_replayed_map_is_latched_for_a_late_joiner(tmp_path, world, connect):
    t0 = 1_700_000_000_000_000_000
    grid = OccupancyGrid(0.05, np.zeros(3), np.full((8, 6), 100, np.uint8), header=Header(0.0, t0, 0, "compute"))
    path = tmp_path / "map.mcap"
    write_recording(
        path, [("rf/w/map/map", t0, encode(grid)), ("rf/w/robot/r0/joints", t0 + 1_000_000, joint_payload(1, t0))]
    )

    live = Inbox()
    listener = connect("viewer", "live")
    listener.subscribe(keys.world_all(world), live)
    replay_fab = connect("tool", "replay")
    with Replayer(replay_fab, plan_replay(path, remap_world=world), wait_for_subscribers=10.0) as rp:
        rp.start()
        wait_until(lambda: len(live.keys()) == 2, what="both replayed messages", seen=live.keys)
        late = Inbox()
        connect("viewer", "late").subscribe(keys.world_all(world), late, history=True)
        wait_until(
            lambda: late.keys() == [keys.map_key(world, "map")], what="the replayed map, latched", seen=late.keys
        )


def test_the_replayer_sees_whether_anyone_listens(world, connect):
    from fabric.matching import is_matched
    from fabric.publishers import declare_publisher

    fab = connect("tool", "replay")
    pub = declare_publisher(fab.session, keys.robot_joints(world, "r0"))
    try:
        assert not is_matched(pub)  # nobody yet: a replay waits (up to --wait) before its first message
        connect("viewer", "v").subscribe(keys.world_all(world), lambda k, m: None)
        wait_until(lambda: is_matched(pub), what="the subscriber to match")
    finally:
        pub.undeclare()
