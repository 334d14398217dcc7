"""The navigation service's session-free parts on their own: pose history, scan mapping, map store."""

from __future__ import annotations

import numpy as np
import pytest

from compute_peer.navigation.errors import NavigationError
from compute_peer.navigation.grid import UNKNOWN, make_grid
from compute_peer.navigation.map_store import COSTMAP_CACHE, MapStore
from compute_peer.navigation.mapping import MapperConfig
from compute_peer.navigation.poses import PoseHistory
from compute_peer.navigation.scan_mapping import ScanMapping
from navscenes import pose_at, scan_at, small_room

ROOM = MapperConfig(resolution=0.1, width=100, height=100, origin_x=0.0, origin_y=0.0)


def test_pose_history_nearest_in_sim_time_latest_without_stamp_and_bounded():
    poses = PoseHistory(depth=3)
    assert poses.at("r") is None and "r" not in poses
    assert poses.add("r", pose_at(0.0, 0.0, 0.0, stamp=1.0, seq=1)) is True
    assert poses.add("r", pose_at(1.0, 0.0, 0.0, stamp=2.0, seq=2)) is False
    poses.add("r", pose_at(2.0, 0.0, 0.0, stamp=3.0, seq=3))
    assert poses.at("r", 2.2).header.seq == 2
    assert poses.at("r").header.seq == 3  # no stamp: the latest
    poses.add("r", pose_at(3.0, 0.0, 0.0, stamp=4.0, seq=4))
    assert poses.at("r", 0.5).header.seq == 2  # the oldest kept: the first was dropped
    assert poses.robots() == {"r"} and len(poses) == 1


def test_a_scan_beyond_the_poses_kept_is_known_only_where_the_robot_moved_too_little_to_matter():
    import dataclasses

    poses = PoseHistory()
    still = pose_at(1.0, 0.0, 0.0, stamp=2.0)
    poses.add("parked", still)
    assert poses.known_at("parked", 2.5) is not None  # standing still: known at any time near its poses
    turning = dataclasses.replace(pose_at(1.0, 0.0, 0.0, stamp=2.0), angular=np.array([0.0, 0.0, 1.2]))
    poses.add("spinning", dataclasses.replace(turning, header=dataclasses.replace(turning.header, stamp=1.9)))
    poses.add("spinning", turning)
    assert poses.known_at("spinning", 1.95) is not None  # between two poses: interpolated
    assert poses.known_at("spinning", 2.01) is not None  # 10 ms on at 1.2 rad/s: 0.012 rad
    assert poses.known_at("spinning", 2.1) is None  # 0.1 s on: 0.12 rad, 7 degrees: not guessed
    assert poses.known_at("spinning", 1.8) is None  # before the oldest kept, alike
    assert poses.known_at("nobody", 2.0) is None


def test_scan_mapping_holds_a_scan_its_robot_turned_too_far_since_its_last_pose():
    import dataclasses

    scene = small_room()
    m, poses, counters = _mapping({"r": (0.0, 0.0, 0.0)})
    turning = dataclasses.replace(pose_at(2.0, 2.0, 0.0, stamp=1.0), angular=np.array([0.0, 0.0, 1.2]))
    poses.add("r", turning)
    assert not m.integrate("r", scan_at(scene, 2.0, 2.0, 0.3, stamp=1.25)) and counters["scans_held"] == 1
    assert m.integrate("r", scan_at(scene, 2.0, 2.0, 0.0, stamp=1.0)) and counters["scans"] == 1


def test_a_scan_ahead_of_its_turning_robots_poses_waits_for_the_pose_after_it_then_is_folded_or_dropped():
    import dataclasses

    scene = small_room()
    now = [0.0]
    poses = PoseHistory()
    counters: dict[str, int] = {}
    m = ScanMapping(
        poses,
        sensor_offset=lambda r: (0.0, 0.0, 0.0),
        radius=lambda r: 0.2,
        counters=counters,
        config=ROOM,
        clock=lambda: now[0],
    )

    def turning(yaw: float, stamp: float):
        return dataclasses.replace(pose_at(2.0, 2.0, yaw, stamp=stamp), angular=np.array([0.0, 0.0, 1.2]))

    poses.add("r", turning(0.0, 1.0))
    assert not m.integrate("r", scan_at(scene, 2.0, 2.0, 0.06, stamp=1.05))  # 50 ms on at 1.2 rad/s: held
    assert counters["scans_held"] == 1 and counters["scans"] == 0 and counters["scans_out_of_step"] == 0
    poses.add("r", turning(0.03, 1.025))
    assert m.pose_added("r") == 0 and counters["scans"] == 0  # not there yet: it waits on
    poses.add("r", turning(0.12, 1.1))
    assert m.pose_added("r") == 1 and counters["scans"] == 1 and m.scans == 1  # interpolated between 1.025 and 1.1
    assert not m.integrate("r", scan_at(scene, 2.0, 2.0, 0.3, stamp=1.3))
    now[0] = 0.6  # its pose never came within the hold
    poses.add("r", turning(0.13, 1.11))
    assert m.pose_added("r") == 0 and counters["scans_out_of_step"] == 1 and counters["scans"] == 1
    for k in range(20):  # held scans are bounded per robot: the oldest goes
        m.integrate("r", scan_at(scene, 2.0, 2.0, 0.3, stamp=2.0 + k))
    assert counters["scans_out_of_step"] == 1 + 20 - 16
    assert not m.integrate("r", scan_at(scene, 2.0, 2.0, 0.0, stamp=0.5))  # behind the poses kept: dropped at once
    assert counters["scans_out_of_step"] == 6


def _mapping(
    offsets: dict[str, tuple[float, float, float] | None], on: bool = True
) -> tuple[ScanMapping, PoseHistory, dict]:
    poses = PoseHistory()
    counters: dict[str, int] = {}
    m = ScanMapping(poses, sensor_offset=offsets.get, radius=lambda r: 0.2, counters=counters, config=ROOM, on=on)
    return m, poses, counters


def test_scan_mapping_counts_each_reason_a_scan_is_dropped():
    scene = small_room()
    m, poses, counters = _mapping({"r": (0.0, 0.0, 0.0), "waiting": None})
    scan = scan_at(scene, 2.0, 2.0, 0.0, stamp=1.0)
    assert m.grid() is None
    assert not m.integrate("r", scan) and counters["scans_without_pose"] == 1
    poses.add("r", pose_at(2.0, 2.0, 0.0, stamp=1.0))
    poses.add("waiting", pose_at(2.0, 2.0, 0.0, stamp=1.0))
    assert not m.integrate("waiting", scan) and counters["scans_waiting_for_sensor"] == 1
    assert m.integrate("r", scan) and counters["scans"] == 1 and m.scans == 1
    m.on = False
    assert not m.integrate("r", scan) and counters["scans_ignored"] == 1
    grid = m.grid(threshold=0.65)
    assert (grid.cells == 100).any() and (grid.cells == 0).any()
    m.reset()
    assert m.scans == 0 and m.grid() is None


def test_a_burst_of_rejected_scans_writes_a_few_log_lines(caplog):
    """500 scans that cannot be placed: counted each, logged a few times per interval with the count
    suppressed (every one was logged before: a flood filled compute.log)."""
    from compute_peer.navigation import scan_mapping

    scene = small_room()
    now = [0.0]
    poses = PoseHistory()
    counters: dict[str, int] = {}
    m = ScanMapping(
        poses,
        sensor_offset=lambda r: (float("nan"), 0.0, 0.0),
        radius=lambda r: 0.2,
        counters=counters,
        config=ROOM,
        clock=lambda: now[0],
    )
    poses.add("r", pose_at(2.0, 2.0, 0.0, stamp=1.0))
    scan = scan_at(scene, 2.0, 2.0, 0.0, stamp=1.0)
    with caplog.at_level("WARNING", logger="robofabric.navigation"):
        for _ in range(500):
            assert not m.integrate("r", scan)
        now[0] += scan_mapping.REPORT_INTERVAL + 0.1
        assert not m.integrate("r", scan)
    assert counters["scans_rejected"] == 501
    lines = [r.getMessage() for r in caplog.records if "rejected" in r.getMessage()]
    assert len(lines) == scan_mapping.REPORT_BURST + 1, lines
    assert lines[-1].endswith(f"({500 - scan_mapping.REPORT_BURST} more rejected since the last report)")


def test_map_store_versions_invalidate_costmaps_and_the_cache_is_bounded():
    store = MapStore()
    with pytest.raises(NavigationError, match="no map named 'm'"):
        store.costmap("m", 0.2, threshold=50, unknown_is_occupied=True)
    cells = np.zeros((40, 40), dtype=np.uint8)
    store.put("m", make_grid(cells, 0.1))
    first = store.costmap("m", 0.2, threshold=50, unknown_is_occupied=True)
    assert store.costmap("m", 0.2, threshold=50, unknown_is_occupied=True) is first  # cached
    cells[10:20, 10:20] = 100
    store.put("m", make_grid(cells, 0.1))  # a new version
    second = store.costmap("m", 0.2, threshold=50, unknown_is_occupied=True)
    assert second is not first and second.collision.any()
    for k in range(COSTMAP_CACHE + 3):
        store.costmap("m", 0.1 + 0.01 * k, threshold=50, unknown_is_occupied=True)
    assert store.costmaps_cached() == COSTMAP_CACHE
    store.put("dark", make_grid(np.full((10, 10), UNKNOWN, np.uint8), 0.1))
    with pytest.raises(NavigationError, match="is empty"):
        store.costmap("dark", 0.2, threshold=50, unknown_is_occupied=True)
    store.drop("m")
    assert store.get("m") is None


def test_map_store_files_stay_inside_the_maps_folder(tmp_path):
    with pytest.raises(NavigationError, match="no maps folder"):
        MapStore().file("a.yaml")
    store = MapStore(tmp_path)
    for bad in ("", "../a.yaml", "sub/a.yaml", ".hidden", "a\\b"):
        with pytest.raises(NavigationError, match="plain file name"):
            store.file(bad)
    with pytest.raises(NavigationError, match="no map named 'm' to save"):
        store.save("m", "m.npz")
    cells = np.zeros((20, 30), dtype=np.uint8)
    cells[5, 5] = 100
    store.put("m", make_grid(cells, 0.1, (1.0, 2.0)))
    assert store.save("m", "m.npz") == tmp_path / "m.npz"
    grid, path = store.read("m.npz")
    assert path == tmp_path / "m.npz" and np.array_equal(grid.cells, cells)


def test_a_pose_between_two_kept_is_the_two_interpolated():
    """A scan between two poses is folded in where the robot was at its stamp: position and heading mixed by time
    (the heading along the shorter arc), the header the nearest pose's with the scan's stamp."""
    from fabric.interfaces import yaw_from_quaternion

    poses = PoseHistory()
    poses.add("r", pose_at(1.0, 0.0, 3.0, stamp=1.0, seq=1))
    poses.add("r", pose_at(2.0, 1.0, -3.0, stamp=2.0, seq=2))  # turned through pi, not back through 0
    mid = poses.at("r", 1.25)
    assert mid.position[:2] == pytest.approx([1.25, 0.25])
    assert abs(np.angle(np.exp(1j * (yaw_from_quaternion(mid.quaternion) - (3.0 + 0.25 * (2 * np.pi - 6.0)))))) < 1e-3
    assert mid.header.seq == 1 and mid.header.stamp == 1.25
    assert poses.at("r", 2.0).header.seq == 2 and poses.at("r", 5.0).position[0] == 2.0  # past the last: the last
