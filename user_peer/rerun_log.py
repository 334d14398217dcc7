"""Map fabric messages to Rerun log calls: one function per kind of data, shared by live view and export.

:class:`WorldLogger` takes ``(key, message, log_time_ns)`` in the order they
arrived (live from Zenoh, or from an MCAP recording). Frequent streams (joints,
poses, scans, rates) are filed per stream and drawn at :meth:`WorldLogger.flush`
as columns, one ``send_columns`` per entity (:mod:`user_peer.rerun_columns`);
what never moves (link shapes, bodies, styles, plot names) is logged once,
static. It keeps only what drawing needs (the latest base pose to put scans in
the world frame, the latest map for the map view's overlay). The geometry it
needs (:func:`scan_world_points`, :func:`grid_rgb`, :func:`world_to_map_pixels`,
...) is pure and lives in :mod:`user_peer.geometry`, re-exported here.

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

from collections import defaultdict
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Sequence

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from fabric import keys
from fabric.interfaces import Event, JointState, OccupancyGrid, OwnershipRecord, Path, Pose, Scan
from user_peer.arm_geometry import ArmGeometry, Placement
from user_peer.geometry import EXTRAPOLATION_CAP_S, grid_rgb, scan_world_points, shown_position, world_to_map_pixels, yaw_of
from user_peer.geometry import compose as _compose
from user_peer.geometry import quat_xyzw as _quat_xyzw
from user_peer.rerun_columns import POSITIONS2, POSITIONS3, SCALARS, STRIPS3, ArmChain, column, scalars, send, strips, time_columns, transforms, vectors

__all__ = [
    "RobotDrawing",
    "WorldLogger",
    "blueprint",
    "framing",
    "scan_world_points",
    "grid_rgb",
    "world_to_map_pixels",
    "yaw_of",
    "shown_position",
    "EXTRAPOLATION_CAP_S",
    "TIMELINE_SIM",
    "TIMELINE_WALL",
]

TIMELINE_SIM = "sim_time"
TIMELINE_WALL = "wall_time"

ROBOT_COLORS = [(230, 120, 40), (40, 140, 230), (90, 200, 90), (200, 80, 200), (230, 200, 40)]


@dataclass
class RobotDrawing:
    """What the viewer knows about one robot: its kind and how to draw it.

    Built on the user's side from the robot descriptions (:class:`user_peer.catalog.RobotCatalog`); not the sim's
    ``RobotInfo`` message, which describes a robot of the world over the wire.
    """

    id: str
    type: str = ""
    kind: str = ""  # "arm" or "mobile"; "" until known
    arm: ArmGeometry | None = None
    base: Placement | None = None  # an arm's base in the world (fixed)
    radius: float = 0.25  # mobile footprint radius
    height: float = 0.3
    lidar_offset: tuple[float, float, float] = (0.0, 0.0, 0.3)
    sonar: tuple[float, float, float, float] | None = None  # ring centre x, y, height, radius (robot frame)
    color: tuple[int, int, int] = (230, 120, 40)


# --------------------------------------------------------------------------- blueprint


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


PLOT_WINDOW_S = 30.0
"""What a plot shows: the last this many seconds before the time cursor, as rqt_plot and PlotJuggler scroll. A
plot of the whole history costs the viewer more at every frame as a class session grows to hours; within
the first minute it makes no measurable difference (a lone software-rendered page: 35.4 s behind after 60 s
with the window, 33.3 s without; docs/benchmarks.md). The viewer's own time range controls widen it."""


def _recent() -> list[rrb.VisibleTimeRange]:
    return [rrb.VisibleTimeRange(t, start=rrb.TimeRangeBoundary.cursor_relative(seconds=-PLOT_WINDOW_S),
                                 end=rrb.TimeRangeBoundary.cursor_relative()) for t in (TIMELINE_WALL, TIMELINE_SIM)]


def blueprint(frame: tuple[np.ndarray, np.ndarray] | None = None) -> rrb.Blueprint:
    """3D world on the left (its camera on ``frame``: see :func:`framing`); map view, plots of the last
    :data:`PLOT_WINDOW_S` seconds and events on the right."""
    eye = rrb.EyeControls3D(position=frame[0], look_target=frame[1], eye_up=[0.0, 0.0, 1.0]) if frame is not None else None
    world = rrb.Spatial3DView(name="world", origin="world", eye_controls=eye) if eye is not None else rrb.Spatial3DView(name="world", origin="world")
    return rrb.Blueprint(
        rrb.Horizontal(
            world,
            rrb.Vertical(
                rrb.Spatial2DView(name="map", origin="map"),
                rrb.Tabs(
                    rrb.TimeSeriesView(name="arm joints (deg)", origin="plots/joints", time_ranges=_recent()),
                    rrb.TimeSeriesView(name="wheels (deg)", origin="plots/wheels", time_ranges=_recent()),
                    rrb.TimeSeriesView(name="arm joint speeds (deg/s)", origin="plots/joint_speed", time_ranges=_recent()),
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


# --------------------------------------------------------------------------- the logger


def _clear(rows: "_Rows") -> None:
    rows.wall.clear()
    rows.sim.clear()
    rows.items.clear()


class _Rows:
    """Rows of one stream waiting for the next flush: their times and what each message brought."""

    __slots__ = ("wall", "sim", "items")

    def __init__(self) -> None:
        self.wall: list[int] = []
        self.sim: list[float] = []
        self.items: list[Any] = []

    def add(self, wall: int, sim: float, item: Any) -> None:
        self.wall.append(wall)
        self.sim.append(sim)
        self.items.append(item)

    def times(self) -> list[rr.TimeColumn]:
        return time_columns(self.wall, self.sim)


class WorldLogger:
    """Logs a world's messages to one Rerun recording; the same code serves ``view`` and ``export``.

    ``drawing(id, hint)`` is asked once per robot the first time it appears, with a hint dict
    (``joint_names`` for arms, ``mobile`` for robots with a pose/scan) and returns a :class:`RobotDrawing`.
    ``max_hz`` thins out 3D and plot updates per key (0: log everything).

    :meth:`log` only files what a message brings under its stream; :meth:`flush` draws everything filed
    since the last flush, one ``send_columns`` per entity (:mod:`user_peer.rerun_columns`). The live viewer
    flushes once per window (0.1 s); a caller that never flushes still gets a flush every ``max_pending``
    messages. Rare messages (maps, paths, objects, ownership,
    events) are logged at once, row by row.
    """

    def __init__(
        self,
        rec: rr.RecordingStream,
        *,
        drawing: Callable[[str, dict], RobotDrawing] | None = None,
        max_hz: float = 30.0,
        rate_period_s: float = 0.5,
        clock: Callable[[], int] | None = None,
        max_pending: int = 4000,
    ) -> None:
        self.rec = rec
        # live views: the clock that stamped log_time_ns when a message arrived (Eq. 8 ages are now - arrival);
        # None (export from a recording): no extrapolation, nothing is "now"
        self.clock = clock
        self.drawing = drawing or (lambda rid, hint: RobotDrawing(rid))
        self.robots: dict[str, RobotDrawing] = {}
        self.poses: dict[str, Pose] = {}
        self.grids: dict[str, OccupancyGrid] = {}
        self.paths: dict[str, Path] = {}
        self.owners: dict[str, OwnershipRecord] = {}
        self.min_dt = int(1e9 / max_hz) if max_hz > 0 else 0
        self.max_pending = max_pending
        self._last: dict[str, int] = {}
        self._keys: dict[str, tuple[keys.ParsedKey, str] | None] = {}
        self._rate_window: dict[str, list[int]] = {}  # label -> [window start ns, messages since]
        self.rate_period = int(rate_period_s * 1e9)
        self._static_done: set[str] = set()
        self._chains: dict[int, ArmChain] = {}
        # filed rows per stream, drawn by flush()
        self._joints: dict[str, _Rows] = {}
        self._bases: dict[str, _Rows] = {}
        self._flanges: dict[str, _Rows] = {}
        self._scans: dict[tuple[str, str], _Rows] = {}
        self._rates: dict[str, _Rows] = {}
        self._labels: dict[str, tuple[str, np.ndarray]] = {}  # robot -> (label entity, where)
        self._t: tuple[int, float] = (0, 0.0)  # the message being filed: (wall_time ns, sim_time s)
        self.pending = 0
        self.counts: dict[str, int] = defaultdict(int)
        self.skipped = 0

    # ------------------------------------------------------------------ entry point

    def log(self, key: str, msg: Any, log_time_ns: int) -> bool:
        """File one message for drawing; returns False when the key is not something the viewer draws."""
        parsed = self._keys.get(key, False)
        if parsed is False:
            parsed = self._parse(key)
        if parsed is None:
            return False
        p, label = parsed
        self._t = self._times(msg, log_time_ns)
        self._count_rate(label, log_time_ns)
        handled = self._dispatch(p, msg, key, log_time_ns)
        if handled:
            self.counts[type(msg).__name__] += 1
        if self.pending >= self.max_pending:
            self.flush()
        return handled

    def _parse(self, key: str) -> tuple[keys.ParsedKey, str] | None:
        try:
            p = keys.parse(key)
        except ValueError:
            return None
        if p.category == "robot":
            label = f"{p.subject}/{p.leaf}"
        elif p.category == "cmd":
            label = f"{p.subject}/cmd_{p.leaf}"
        else:
            label = f"{p.category}/{p.subject}" if p.subject else p.category
        if len(self._keys) < 100_000:  # a world's keys repeat; a flood of odd ones is parsed each time
            self._keys[key] = (p, label)
        return p, label

    def _count_rate(self, label: str, t_ns: int) -> None:
        """Messages per second per stream, one value per ``rate_period`` (the messages since the last one)."""
        w = self._rate_window.get(label)
        if w is None:
            self._rate_window[label] = [t_ns, 0]
            return
        w[1] += 1
        if t_ns - w[0] >= self.rate_period:
            rows = self._rates.get(label)
            if rows is None:
                rows = self._rates[label] = _Rows()
            rows.add(t_ns, 0.0, w[1] * 1e9 / (t_ns - w[0]))
            self.pending += 1
            w[0], w[1] = t_ns, 0

    @staticmethod
    def _times(msg: Any, log_time_ns: int) -> tuple[int, float]:
        """(wall_time ns: the header's wall clock, else the receive time; sim_time s, 0 when unknown)."""
        header = getattr(msg, "header", None)
        if header is None:
            return log_time_ns, 0.0
        return (header.wall_ns if header.wall_ns > 0 else log_time_ns), (float(header.stamp) if header.stamp > 0 else 0.0)

    def _set_time(self, msg: Any, log_time_ns: int) -> None:
        """The stream's time for the row-by-row logs of rare messages."""
        wall, sim = self._t
        self.rec.reset_time()
        self.rec.set_time(TIMELINE_WALL, timestamp=np.datetime64(int(wall), "ns"))
        if sim > 0:
            self.rec.set_time(TIMELINE_SIM, duration=sim)

    def _due(self, key: str, t_ns: int) -> bool:
        if self.min_dt <= 0:
            return True
        last = self._last.get(key)
        if last is not None and t_ns - last < self.min_dt:
            self.skipped += 1
            return False
        self._last[key] = t_ns
        return True

    def _dispatch(self, p: keys.ParsedKey, msg: Any, key: str, t: int) -> bool:
        if p.category == "robot":
            if isinstance(msg, JointState):
                return self.log_joints(p.subject, msg, due=self._due(key, t))
            if isinstance(msg, Pose):
                return self.log_pose(p.subject, msg, due=self._due(key, t), received_ns=t)
            if isinstance(msg, Scan):
                return self.log_scan(p.subject, msg, sonar=p.leaf == "sonar") if self._due(key, t) else True
            if isinstance(msg, Path):
                self._set_time(msg, t)
                return self.log_path(p.subject, msg)
        elif p.category == "cmd" and p.leaf == "path":
            body = getattr(msg, "body", None)
            if isinstance(body, Path):
                self._set_time(msg, t)
                return self.log_path(p.subject, body)
        elif p.category == "object" and isinstance(msg, Pose):
            if not self._due(key, t):
                return True
            self._set_time(msg, t)
            return self.log_object(p.subject, msg)
        elif p.category == "map" and isinstance(msg, OccupancyGrid):
            self._set_time(msg, t)
            return self.log_map(p.subject, msg)
        elif p.category == "own" and isinstance(msg, OwnershipRecord):
            self._set_time(msg, t)
            return self.log_ownership(msg)
        elif p.category == "event" and isinstance(msg, Event):
            self._set_time(msg, t)
            return self.log_event("/".join((p.subject, *p.rest[1:])) if p.rest else p.subject, msg, any_login=p.subject == keys.DECODE)
        return False

    # ------------------------------------------------------------------ robots: filing

    def _robot(self, rid: str, hint: dict) -> RobotDrawing:
        info = self.robots.get(rid)
        if info is None or (not info.kind and hint):
            info = self.drawing(rid, hint)
            if not info.color or info.color == RobotDrawing.color:
                info.color = ROBOT_COLORS[len(self.robots) % len(ROBOT_COLORS)]
            self.robots[rid] = info
            self._static_robot(rid, info)
        return info

    def _chain(self, info: RobotDrawing) -> ArmChain | None:
        if info.arm is None:
            return None
        chain = self._chains.get(id(info.arm))
        if chain is None:
            chain = self._chains[id(info.arm)] = ArmChain(info.arm)
        return chain if chain.supported else None

    def log_joints(self, rid: str, js: JointState, *, due: bool = True) -> bool:
        """File a JointState: an arm's joint plots and 3D pose, or a base's wheel angles (their own plot)."""
        self._robot(rid, {"joint_names": js.names})  # its drawing, made the first time the robot is seen
        if not due:
            return True
        rows = self._joints.get(rid)
        if rows is None:
            rows = self._joints[rid] = _Rows()
        elif rows.items and len(rows.items[0][0]) != len(js.names):
            self._flush_joints(rid, rows)  # the robot changed shape: draw what came before on its own
        rows.add(*self._t, (tuple(js.names), js.q, js.dq))
        self.pending += 1
        return True

    def log_pose(self, rid: str, pose: Pose, *, due: bool = True, received_ns: int = 0) -> bool:
        """File a pose: an arm's flange frame, or a mobile base (drawn where it is by now: paper Eq. 8)."""
        known = self.robots.get(rid)
        info = self._robot(rid, {"mobile": True} if not known or not known.arm else {})
        if info.arm is None:
            self.poses[rid] = pose
        if not due:
            return True
        store = self._flanges if info.arm is not None else self._bases
        rows = store.get(rid)
        if rows is None:
            rows = store[rid] = _Rows()
        rows.add(*self._t, (pose, received_ns))
        self.pending += 1
        return True

    def log_scan(self, rid: str, scan: Scan, *, sonar: bool = False) -> bool:
        """File a LIDAR scan (or the ultrasonic ring's): its hits and rays in the world frame, from the base's
        latest pose."""
        info = self._robot(rid, {"mobile": True})
        if sonar:
            cx, cy, h, radius = info.sonar or (0.0, 0.0, 0.12, 0.26)
            # ranges are measured from the rim: from the ring's centre they are `radius` longer
            ranges = np.where(np.isfinite(scan.ranges), scan.ranges + radius, np.inf)
            centred = Scan.from_ranges(ranges, angle_min=scan.angle_min, angle_increment=scan.angle_increment,
                                       range_max=scan.range_max + radius, header=scan.header)
            origin, pts, hit = scan_world_points(centred, self.poses.get(rid), (cx, cy, h))
            ends = pts[hit]
        else:
            origin, pts, hit = scan_world_points(scan, self.poses.get(rid), info.lidar_offset)
            ends = pts[:: max(1, len(pts) // 60)]
        rays = np.empty((len(ends), 2, 3))
        rays[:, 0] = origin
        rays[:, 1] = ends
        name = "sonar" if sonar else "scan"
        rows = self._scans.get((rid, name))
        if rows is None:
            rows = self._scans[(rid, name)] = _Rows()
        rows.add(*self._t, (pts[hit], rays))
        self.pending += 1
        return True

    # ------------------------------------------------------------------ robots: drawing

    def flush(self) -> int:
        """Draw everything filed since the last flush; returns how many rows went out."""
        n = self.pending
        if not n:
            return 0
        for rid, rows in self._joints.items():
            if rows.items:
                self._flush_joints(rid, rows)
        for rid, rows in self._bases.items():
            if rows.items:
                self._flush_base(rid, rows)
        for rid, rows in self._flanges.items():
            if rows.items:
                self._flush_flange(rid, rows)
        for (rid, name), rows in self._scans.items():
            if rows.items:
                self._flush_scan(rid, name, rows)
        for label, rows in self._rates.items():
            if rows.items:
                send(self.rec, f"plots/rates/{label}", rows.times(), [scalars(SCALARS, np.asarray(rows.items, dtype=float))])
                _clear(rows)
        self.pending = 0
        return n

    def _once(self, key: str) -> bool:
        """True the first time ``key`` is asked: static parts are logged once."""
        if key in self._static_done:
            return False
        self._static_done.add(key)
        return True

    def _static_robot(self, rid: str, info: RobotDrawing) -> None:
        """What never moves: an arm's base, its link shapes below their joints, the skeleton's style; a base's body,
        heading and label; done again if a robot's kind is learnt late."""
        root = f"world/robots/{rid}"
        chain = self._chain(info)
        if chain is not None and self._once(f"{rid}/arm"):
            base = info.base
            links = f"{root}/links"
            if base is not None:
                self.rec.log(links, rr.Transform3D(translation=base.translation, quaternion=rr.Quaternion(xyzw=base.quat_xyzw)), static=True)
            for shape, joint, pl in chain.shapes():
                path = f"{chain.path(links, joint - 1)}/{rr.escape_entity_path_part(shape.name)}"
                self.rec.log(path, rr.Transform3D(translation=pl.translation, quaternion=rr.Quaternion(xyzw=pl.quat_xyzw)), static=True)
                self._log_shape(path, shape)
            self.rec.log(f"{root}/skeleton", rr.LineStrips3D.from_fields(radii=0.006, colors=[info.color]),
                         rr.Points3D.from_fields(radii=0.012, colors=[(60, 60, 60)]), static=True)
            at = base.translation if base is not None else np.zeros(3)
            self._label(rid, f"{root}/label", np.asarray(at, dtype=float) + [0.0, 0.0, 0.05])
        if info.kind == "mobile" and self._once(f"{rid}/base"):
            path = f"{root}/base"
            r, h = info.radius, info.height
            self.rec.log(f"{path}/body", rr.Cylinders3D(lengths=[h], radii=[r], centers=[[0, 0, h / 2]], colors=[info.color], fill_mode="solid"), static=True)
            self.rec.log(f"{path}/heading", rr.Arrows3D(vectors=[[r * 1.4, 0, 0]], origins=[[0, 0, h + 0.02]], colors=[(20, 20, 20)]), static=True)
            self.rec.log(f"{root}/scan", rr.Points3D.from_fields(radii=0.02, colors=[(230, 40, 40)]),
                         rr.LineStrips3D.from_fields(radii=0.002, colors=[(240, 150, 150)]), static=True)
            self.rec.log(f"{root}/sonar", rr.Points3D.from_fields(radii=0.03, colors=[(40, 170, 230)]),
                         rr.LineStrips3D.from_fields(radii=0.003, colors=[(120, 200, 240)]), static=True)
            self.rec.log(f"plots/speed/{rid}", rr.SeriesLines(names=["v (m/s)", "omega (rad/s)"]), static=True)
            self._label(rid, f"{path}/label", np.array([0.0, 0.0, h + 0.25]))

    def _flush_joints(self, rid: str, rows: _Rows) -> None:
        info = self.robots[rid]
        names = rows.items[0][0]
        q = np.array([it[1] for it in rows.items], dtype=float)
        times = rows.times()
        n, k = q.shape
        plot = "wheels" if info.kind == "mobile" else "joints"
        if self._once(f"plots/{plot}/{rid}"):
            self.rec.log(f"plots/{plot}/{rid}", rr.SeriesLines(names=list(names)), static=True)
        send(self.rec, f"plots/{plot}/{rid}", times, [scalars(SCALARS, np.degrees(q))])
        if plot == "joints":
            dq = np.array([it[2] for it in rows.items], dtype=float)
            if self._once(f"plots/joint_speed/{rid}"):
                self.rec.log(f"plots/joint_speed/{rid}", rr.SeriesLines(names=list(names)), static=True)
            send(self.rec, f"plots/joint_speed/{rid}", times, [scalars(SCALARS, np.degrees(dq))])
        chain = self._chain(info)
        if chain is not None and k == chain.nq:
            root = f"world/robots/{rid}"
            local = ts, qs = chain.local(q)
            for j in range(len(chain.joints)):
                send(self.rec, chain.path(f"{root}/links", j), times, transforms(ts[:, j], qs[:, j]))
            origins = chain.origins(q, info.base, local)  # the skeleton: a line strip through the joint origins, and points at them
            send(self.rec, f"{root}/skeleton", times, [column(STRIPS3, strips(origins)),
                                                      column(POSITIONS3, vectors(origins.reshape(-1, 3), 3), np.full(n, origins.shape[1]))])
        elif info.arm is not None and k == len(info.arm.joint_names):
            self._draw_arm_rows(rid, info, rows)  # a URDF joint kind the chain does not know: Pinocchio per row
        _clear(rows)

    def _draw_arm_rows(self, rid: str, info: RobotDrawing, rows: _Rows) -> None:
        arm = info.arm
        assert arm is not None
        for wall, sim, (_names, q, _dq) in zip(rows.wall, rows.sim, rows.items):
            self.rec.set_time(TIMELINE_WALL, timestamp=np.datetime64(int(wall), "ns"))
            if sim > 0:
                self.rec.set_time(TIMELINE_SIM, duration=sim)
            q = np.asarray(q, dtype=float)
            origins = [(_compose(info.base, pl))[0] for pl in arm.fk(q)]
            self.rec.log(f"world/robots/{rid}/skeleton", rr.LineStrips3D([origins], radii=0.006, colors=[info.color]))
            for shape, placement in arm.shape_placements(q):
                path = f"world/robots/{rid}/links/{rr.escape_entity_path_part(shape.name)}"
                t, quat = _compose(info.base, placement)
                self.rec.log(path, rr.Transform3D(translation=t, quaternion=rr.Quaternion(xyzw=quat)))
                if self._once(path):
                    self._log_shape(path, shape)

    def _flush_base(self, rid: str, rows: _Rows) -> None:
        info = self.robots[rid]
        poses = [it[0] for it in rows.items]
        pos = np.array([p.position for p in poses], dtype=float)
        lin = np.array([p.linear for p in poses], dtype=float)
        quat = np.array([p.quaternion for p in poses], dtype=float)[:, [1, 2, 3, 0]]  # w, x, y, z -> x, y, z, w
        received = np.array([it[1] for it in rows.items], dtype=np.int64)
        times = rows.times()
        shown = pos
        if self.clock is not None and (received > 0).all():
            # Eq. 8: moved on by velocity x the time since arrival (capped), as of this drawing
            age = np.clip((self.clock() - received) * 1e-9, 0.0, EXTRAPOLATION_CAP_S)
            shown = pos + lin * age[:, None]
            send(self.rec, f"plots/age/{rid}", times, [scalars(SCALARS, age * 1e3)])
        send(self.rec, f"world/robots/{rid}/base", times, transforms(shown, quat))
        speed = np.stack([np.hypot(lin[:, 0], lin[:, 1]), np.array([p.angular[2] for p in poses], dtype=float)], axis=1)
        send(self.rec, f"plots/speed/{rid}", times, [scalars(SCALARS, speed)])
        for name, grid in self.grids.items():
            entity = f"map/{name}/robots/{rid}"
            if self._once(entity):
                self.rec.log(entity, rr.Points2D.from_fields(radii=max(2.0, info.radius / grid.resolution), colors=[info.color], labels=[rid]), static=True)
            send(self.rec, entity, times, [column(POSITIONS2, vectors(world_to_map_pixels(grid, pos[:, :2]), 2))])
        _clear(rows)

    def _flush_flange(self, rid: str, rows: _Rows) -> None:
        poses = [it[0] for it in rows.items]
        pos = np.array([p.position for p in poses], dtype=float)
        quat = np.array([p.quaternion for p in poses], dtype=float)[:, [1, 2, 3, 0]]
        path = f"world/robots/{rid}/flange"
        if self._once(path):
            self.rec.log(f"{path}/axes", rr.TransformAxes3D(0.05), static=True)
        send(self.rec, path, rows.times(), transforms(pos, quat))
        _clear(rows)

    def _flush_scan(self, rid: str, name: str, rows: _Rows) -> None:
        times = rows.times()
        hits = [it[0] for it in rows.items]
        rays = [it[1] for it in rows.items]
        # hits as points and rays as lines, one entity
        send(self.rec, f"world/robots/{rid}/{name}", times,
             [column(POSITIONS3, vectors(np.concatenate(hits).reshape(-1, 3), 3), [len(h) for h in hits]),
              column(STRIPS3, strips(np.concatenate(rays).reshape(-1, 2, 3)), [len(r) for r in rays])])
        _clear(rows)

    def _log_shape(self, path: str, shape) -> None:
        color = [shape.color]
        if shape.kind == "box":
            arch = rr.Boxes3D(half_sizes=[shape.size], colors=color, fill_mode="solid")
        elif shape.kind == "sphere":
            arch = rr.Ellipsoids3D(half_sizes=[[shape.size[0]] * 3], colors=color, fill_mode="solid")
        elif shape.kind == "cylinder":
            arch = rr.Cylinders3D(lengths=[shape.size[1]], radii=[shape.size[0]], colors=color, fill_mode="solid")
        elif shape.kind == "capsule":
            # Rerun's capsules run along +z from the origin; URDF's are centred.
            arch = rr.Capsules3D(lengths=[shape.size[1]], radii=[shape.size[0]], translations=[[0, 0, -shape.size[1] / 2]], colors=color)
        elif shape.kind == "mesh" and shape.mesh_path:
            try:
                arch = rr.Asset3D(path=shape.mesh_path)
            except Exception:
                return
        else:
            return
        self.rec.log(f"{path}/shape", arch, static=True)

    def log_path(self, rid: str, path: Path) -> bool:
        info = self._robot(rid, {})
        self.paths[rid] = path
        if len(path) == 0:
            self.rec.log(f"world/robots/{rid}/path", rr.Clear(recursive=False))
            return True
        pts = np.stack([path.x, path.y, np.full(len(path), 0.02)], axis=1)
        self.rec.log(f"world/robots/{rid}/path", rr.LineStrips3D([pts], radii=0.015, colors=[info.color]))
        for name, grid in self.grids.items():
            self.rec.log(f"map/{name}/paths/{rid}", rr.LineStrips2D([world_to_map_pixels(grid, pts[:, :2])], colors=[info.color]))
        return True

    def log_object(self, oid: str, pose: Pose) -> bool:
        path = f"world/objects/{oid}"
        self.rec.log(path, rr.Transform3D(translation=pose.position, quaternion=rr.Quaternion(xyzw=_quat_xyzw(pose.quaternion))))
        if path not in self._static_done:
            self._static_done.add(path)
            if "goal" in oid:
                self.rec.log(f"{path}/shape", rr.Arrows3D(vectors=[[0.5, 0, 0]], colors=[(40, 200, 80)], labels=[oid]), static=True)
            else:
                self.rec.log(f"{path}/shape", rr.Ellipsoids3D(half_sizes=[[0.02, 0.02, 0.02]], colors=[(40, 200, 80)], fill_mode="solid", labels=[oid]), static=True)
        for name, grid in self.grids.items():
            if "goal" in oid:
                self.rec.log(f"map/{name}/objects/{oid}", rr.Points2D(world_to_map_pixels(grid, pose.position[:2]), radii=4.0, colors=[(40, 200, 80)], labels=[oid]))
        return True

    def log_map(self, name: str, grid: OccupancyGrid) -> bool:
        self.grids[name] = grid
        self._static_done -= {k for k in self._static_done if k.startswith(f"map/{name}/robots/")}  # its scale may differ
        self.rec.log(f"map/{name}", rr.Image(grid_rgb(grid)))
        for rid, path in self.paths.items():
            if len(path):
                xy = np.stack([path.x, path.y], axis=1)
                self.rec.log(f"map/{name}/paths/{rid}", rr.LineStrips2D([world_to_map_pixels(grid, xy)], colors=[self._robot(rid, {}).color]))
        return True

    # ------------------------------------------------------------------ ownership and events

    def _label(self, rid: str, entity: str | None = None, at: np.ndarray | None = None) -> None:
        """The robot's ownership label, at the time of the message being filed: drawn once where the robot
        is known (an arm's base, above a base's body: it moves with the base) and again when its owner changes."""
        if entity is not None and at is not None:
            self._labels[rid] = (entity, at)
            self.rec.log(entity, rr.Points3D.from_fields(radii=0.005, colors=[(0, 0, 0)]), static=True)
        where = self._labels.get(rid)
        if where is None:
            return
        rec = self.owners.get(rid)
        text = f"{rid}: " + (f"{rec.owner} (epoch {rec.epoch})" if rec and rec.owner else "free")
        if rec and rec.queue:
            text += f", waiting {', '.join(rec.queue)}"
        send(self.rec, where[0], time_columns([self._t[0]], [self._t[1]]), rr.Points3D.columns(positions=[where[1]], labels=[text]))

    def log_ownership(self, rec: OwnershipRecord) -> bool:
        before = self.owners.get(rec.object)
        self.owners[rec.object] = rec
        if before is None or before.owner != rec.owner or before.epoch != rec.epoch or before.queue != rec.queue:
            self._label(rec.object)
        if before is None or before.owner != rec.owner or before.epoch != rec.epoch:
            who = rec.owner or "nobody"
            self.rec.log("events", rr.TextLog(f"{rec.object}: owned by {who} (epoch {rec.epoch}, {rec.state})", level="INFO"))
        self.rec.log(f"ownership/{rec.object}", rr.TextDocument(f"owner: {rec.owner or '-'}\nepoch: {rec.epoch}\nqueue: {', '.join(rec.queue) or '-'}\nstate: {rec.state}"))
        return True

    def log_event(self, where: str, ev: Event, *, any_login: bool = False) -> bool:
        """One line of the event log; ``any_login``: it came on a key any login may write (a decode report),
        so it is marked as such: its kind, user and object are the writer's say-so (docs/security.md)."""
        level = {"debug": "DEBUG", "info": "INFO", "warning": "WARN", "error": "ERROR"}.get(ev.severity, "INFO")
        who = f" [{ev.user}]" if ev.user else ""
        obj = f" {ev.object}:" if ev.object else ""
        mark = f"(unverified: {where}, any login may write it) " if any_login else ""
        self.rec.log("events", rr.TextLog(f"{mark}{ev.kind}{who}{obj} {ev.reason}".strip(), level=level))
        return True

    def log_scene(self, boxes: Iterable[Any], name: str = "scene") -> None:
        """The static scene (walls, shelves, tables) once, as boxes: see :mod:`user_peer.scene_geometry`."""
        boxes = list(boxes)
        if not boxes:
            return
        self.rec.log(
            f"world/{name}",
            rr.Boxes3D(
                centers=[b.center for b in boxes],
                half_sizes=[b.half_size for b in boxes],
                quaternions=[rr.Quaternion(xyzw=b.quat_xyzw) for b in boxes],
                colors=[b.rgba for b in boxes],
                labels=[b.name for b in boxes],
                fill_mode="solid",
                show_labels=False,
            ),
            static=True,
        )

