"""Pure drawing helpers: scans in the world frame, grid images, map pixel coordinates."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabric.interfaces import OccupancyGrid, Pose, Scan
from user_peer.geometry import grid_rgb, scan_world_points, world_to_map_pixels, yaw_of


def _pose(x, y, yaw):
    return Pose([x, y, 0.0], [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


@settings(max_examples=50, deadline=None)
@given(st.floats(-5, 5), st.floats(-5, 5), st.floats(-3.1, 3.1), st.floats(0.2, 9.0))
def test_scan_hits_lie_at_their_range_from_the_lidar(x, y, yaw, r):
    scan = Scan.from_ranges(np.full(9, r), angle_min=-1.0, angle_increment=0.25, range_max=10.0)
    origin, pts, hit = scan_world_points(scan, _pose(x, y, yaw), (0.1, 0.0, 0.3))
    assert hit.all()
    assert np.allclose(origin[:2], [x + 0.1 * math.cos(yaw), y + 0.1 * math.sin(yaw)])
    d = np.linalg.norm(pts[:, :2] - origin[:2], axis=1)
    assert np.allclose(d, round(r * 1000) / 1000, atol=1e-9)
    # the middle ray (angle 0) points along the heading
    mid = pts[4, :2] - origin[:2]
    assert math.isclose(math.atan2(mid[1], mid[0]), math.atan2(math.sin(yaw), math.cos(yaw)), abs_tol=1e-6)


def test_misses_are_masked_out():
    scan = Scan.from_ranges([1.0, float("inf"), 12.0, 2.0], angle_min=0, angle_increment=0.1, range_max=10.0)
    _, _, hit = scan_world_points(scan, None)
    assert hit.tolist() == [True, False, False, True]


def test_yaw_of_quaternion():
    for yaw in (-3.0, -1.0, 0.0, 0.5, 2.9):
        assert math.isclose(yaw_of(_pose(0, 0, yaw).quaternion), yaw, abs_tol=1e-9)


def test_grid_image_is_north_up_with_unknown_grey():
    cells = np.full((4, 6), 255, np.uint8)
    cells[0, 0] = 100  # row 0 = lowest y: bottom-left of the image
    cells[3, 5] = 0  # top-right, free
    img = grid_rgb(OccupancyGrid(0.1, [0, 0, 0], cells))
    assert img.shape == (4, 6, 3) and img.dtype == np.uint8
    assert img[3, 0].tolist() == [0, 0, 0]
    assert img[0, 5].tolist() == [255, 255, 255]
    assert img[1, 1].tolist() == [150, 160, 180]


def test_world_to_map_pixels_matches_grid_image():
    grid = OccupancyGrid(0.05, [-2.0, -1.0, 0.0], np.zeros((40, 80), np.uint8))
    uv = world_to_map_pixels(grid, np.array([[-2.0, -1.0], [2.0, 1.0], [0.0, 0.0]]))
    assert np.allclose(uv, [[0, 40], [80, 0], [40, 20]])


@pytest.mark.parametrize("skew_s", [-5.0, 0.0, 5.0])
def test_bases_are_drawn_where_they_are_by_now_eq8(skew_s):
    """The age is time since arrival on this machine's clock; the sender's header clock, here off ours by
    +-5 s, changes nothing."""
    from fabric.interfaces import Header
    from user_peer.geometry import EXTRAPOLATION_CAP_S, shown_position

    t = 1_700_000_000_000_000_000  # our clock when the pose arrived
    pose = Pose([1.0, 2.0, 0.0], linear=[0.5, -0.2, 0.0], header=Header(wall_ns=t + int(skew_s * 1e9)))
    at, age = shown_position(pose, t, t + 40_000_000)  # drawn 40 ms after it arrived
    assert math.isclose(age, 0.04) and np.allclose(at, [1.02, 1.992, 0.0])
    late, age = shown_position(pose, t, t + 5_000_000_000)  # 5 s stale: moved on by the cap only
    assert age == EXTRAPOLATION_CAP_S and np.allclose(
        late, [1.0 + 0.5 * EXTRAPOLATION_CAP_S, 2.0 - 0.2 * EXTRAPOLATION_CAP_S, 0.0]
    )
    at_once, age = shown_position(pose, t, t)
    assert age == 0.0 and np.allclose(at_once, pose.position)
    assert shown_position(pose, 0, t)[1] is None  # arrival unknown (a recording): no guess


def test_viewer_logger_ages_poses_by_arrival_not_by_the_senders_clock():
    """WorldLogger with a clock: the Eq. 8 age it plots is now - arrival, whatever the header says."""
    import rerun as rr

    from fabric.interfaces import Header
    from user_peer.rerun_log import WorldLogger

    now = [2_000_000_000_000]
    sent: list = []
    rec = rr.RecordingStream("skew-test")
    rec.send_columns = lambda path, indexes, columns: sent.append((path, list(columns)))  # type: ignore[method-assign]
    logger = WorldLogger(rec, max_hz=0, clock=lambda: now[0])
    for skew in (-5e9, 5e9):
        sent.clear()
        pose = Pose([0.0, 0.0, 0.0], linear=[1.0, 0.0, 0.0], header=Header(wall_ns=int(now[0] + skew)))
        arrived = now[0]
        logger.log("rf/w/robot/base1/pose", pose, arrived)
        now[0] += 30_000_000  # drawn 30 ms after arrival
        logger.flush()
        ages = [c for p, cols in sent if p == "plots/age/base1" for c in cols]
        assert len(ages) == 1
        assert np.allclose(np.asarray(ages[0].as_arrow_array().to_pylist()).ravel(), [30.0]), ages


def test_every_plot_shows_the_last_window_on_both_timelines():
    """Plots of the whole history cost more at every frame as a class session grows: each one is bounded."""
    import rerun.blueprint as rrb

    from user_peer.rerun_log import PLOT_WINDOW_S, TIMELINE_SIM, TIMELINE_WALL, blueprint

    plots = []

    def walk(node):
        if isinstance(node, rrb.TimeSeriesView):
            plots.append(node)
        for child in getattr(node, "contents", None) or []:
            if not isinstance(child, str):
                walk(child)

    walk(blueprint().root_container)
    assert len(plots) == 6
    for view in plots:
        ranges = {
            r["timeline"]: r["range"] for r in view.properties["VisibleTimeRanges"].ranges.as_arrow_array().to_pylist()
        }
        assert set(ranges) == {TIMELINE_WALL, TIMELINE_SIM}, view.name
        assert all(r == {"start": -int(PLOT_WINDOW_S * 1e9), "end": 0} for r in ranges.values()), ranges
