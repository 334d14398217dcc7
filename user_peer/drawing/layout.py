"""The viewer's layout: its views (the blueprint), its two timelines, where the 3D camera looks.

Entity layout::

    world/robots/{id}/base          Transform3D of a mobile base (from its pose); .../body, .../heading, .../label static
    world/robots/{id}/links         an arm's base (static); .../links/joint_1/joint_2/... one transform per joint,
                                    the link shapes below their joint, static
    world/robots/{id}/skeleton      arm joint origins as a line strip and as points
    world/robots/{id}/flange        the flange frame an arm's pose stream carries
    world/robots/{id}/scan          LIDAR hits (Points3D) and rays (LineStrips3D), world frame; .../sonar alike
    world/robots/{id}/path          planned path (LineStrips3D)
    world/robots/{id}/label         an arm's ownership label (a base's: .../base/label)
    world/objects/{id}              scene objects (target sphere, goal pointer)
    map/{name}                      occupancy grid image; map/{name}/paths/{id}, map/{name}/robots/{id}
    plots/joints/{id}               an arm's joint angles (deg), one series per joint;  plots/joint_speed/{id} (deg/s)
    plots/wheels/{id}               a base's wheel angles (deg), apart from the arms' joints
    plots/speed/{id}                a base's v (m/s) and omega (rad/s);  plots/age/{id}: its pose's age when drawn (ms)
    plots/rates/{label}             stream rates (Hz), one value per 0.5 s
    plots/viewer/{lag_ms,dropped}   the live viewer's own lag and drops (user_peer.viewer)
    events                          TextLog of events and ownership changes
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import rerun.blueprint as rrb

__all__ = ["PLOT_WINDOW_S", "TIMELINE_SIM", "TIMELINE_WALL", "blueprint", "framing"]

TIMELINE_SIM = "sim_time"
TIMELINE_WALL = "wall_time"

PLOT_WINDOW_S = 30.0
"""What a plot shows: the last this many seconds before the time cursor, as rqt_plot and PlotJuggler scroll. A
plot of the whole history costs the viewer more at every frame as a class session grows to hours; within
the first minute it makes no measurable difference (a lone software-rendered page: 35.4 s behind after 60 s
with the window, 33.3 s without; docs/benchmarks.md). The viewer's own time range controls widen it."""


def framing(points: Sequence[Sequence[float]]) -> tuple[np.ndarray, np.ndarray] | None:
    """(eye position, look target) of a 3D camera that sees every point (the robots' places), from the
    south-west and above; None without points (the viewer's own default then: the scene's bounds, which
    shelves and walls dominate)."""
    pts = np.asarray([p[:3] if len(p) >= 3 else (*p[:2], 0.0) for p in points], dtype=float).reshape(-1, 3)
    if not len(pts):
        return None
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    target = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.3])
    radius = max(float(np.linalg.norm((hi - lo)[:2])) / 2 + 0.8, 1.2)  # half the spread, plus a robot's size
    # a ~60 degree field of view: the circle of `radius` fits at about 2 x radius, seen 40 degrees from above
    d = 2.0 * radius
    eye = target + d * np.array([-0.45, -0.6, 0.66])
    return eye, target


def _recent() -> list[rrb.VisibleTimeRange]:
    return [
        rrb.VisibleTimeRange(
            t,
            start=rrb.TimeRangeBoundary.cursor_relative(seconds=-PLOT_WINDOW_S),
            end=rrb.TimeRangeBoundary.cursor_relative(),
        )
        for t in (TIMELINE_WALL, TIMELINE_SIM)
    ]


def blueprint(frame: tuple[np.ndarray, np.ndarray] | None = None) -> rrb.Blueprint:
    """3D world on the left (its camera on ``frame``: see :func:`framing`); map view, plots of the last
    :data:`PLOT_WINDOW_S` seconds and events on the right."""
    eye = (
        rrb.EyeControls3D(position=frame[0], look_target=frame[1], eye_up=[0.0, 0.0, 1.0])
        if frame is not None
        else None
    )
    world = (
        rrb.Spatial3DView(name="world", origin="world", eye_controls=eye)
        if eye is not None
        else rrb.Spatial3DView(name="world", origin="world")
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            world,
            rrb.Vertical(
                rrb.Spatial2DView(name="map", origin="map"),
                rrb.Tabs(
                    rrb.TimeSeriesView(name="arm joints (deg)", origin="plots/joints", time_ranges=_recent()),
                    rrb.TimeSeriesView(name="wheels (deg)", origin="plots/wheels", time_ranges=_recent()),
                    rrb.TimeSeriesView(
                        name="arm joint speeds (deg/s)", origin="plots/joint_speed", time_ranges=_recent()
                    ),
                    rrb.TimeSeriesView(name="base speed", origin="plots/speed", time_ranges=_recent()),
                    rrb.TimeSeriesView(name="stream rates (Hz)", origin="plots/rates", time_ranges=_recent()),
                    rrb.TimeSeriesView(name="viewer lag (ms)", origin="plots/viewer", time_ranges=_recent()),
                ),
                rrb.TextLogView(name="events", origin="events"),
                row_shares=[3, 3, 1],
            ),
            column_shares=[3, 2],
        ),
        # the columns carry wall_time and sim_time only (Rerun's log_time is not theirs): open on the wall clock, live
        rrb.TimePanel(timeline=TIMELINE_WALL, play_state="following"),
        collapse_panels=False,
    )
