"""The robot streams: the one table of every ``rf/{world}/robot/{id}/{name}`` stream and what follows from it.

Each row says what a stream carries, who writes it, how it travels and where ROS 2 users see it. The key layout
(:data:`fabric.keys.ROBOT_STREAMS`), fencing (:data:`fabric.fencing.AUTHORITY_STREAMS`), latching
(:func:`fabric.keys.is_latched`), the router's access rules (``robofabric.secure``), the declared message types
(``robofabric.declarations.STREAM_TYPES``), the sim's default rates, a user's robot handle, the ROS 2 export
(``user_peer.openfmt.ros2``) and the live bridge (``user_peer.ros2.bridge``) all read it; a new sensor stream is
one row here (docs/howto.md, "A new sensor stream"), and ``tests/fabric/test_stream_table.py`` fails when another
module lists stream names of its own. Pure: no zenoh, no ROS (ROS names are strings).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "SIM",
    "COMPUTE",
    "WRITERS",
    "ROS2_QOS",
    "Ros2Topic",
    "RobotStream",
    "STREAMS",
    "NAMES",
    "stream",
    "access",
    "ros2_topic",
    "default_rates",
]

SIM = "sim"
"""A stream the sim peer that is its robot's authority writes: robot state, stamped with the authority's term."""
COMPUTE = "compute"
"""A stream a compute peer writes (a planned path, a streamed IK solution): term 0, never fenced."""
WRITERS = (SIM, COMPUTE)
"""Who may write a robot stream: the router's role (``robofabric.secure.ROLES``) whose logins put it."""

ROS2_QOS = ("stream", "sensor_data", "latched")
"""A ROS 2 topic's QoS, by name (the bridge holds the profiles): ``stream`` reliable with a deep history,
``sensor_data`` ROS's best-effort profile for sensors, ``latched`` reliable and transient-local."""


@dataclass(frozen=True, slots=True)
class Ros2Topic:
    """Where a robot stream appears in ROS 2: ``/NS/ROBOT/{name}`` of ``type`` with QoS ``qos`` (:data:`ROS2_QOS`),
    for robots of ``kind`` ("" for every kind: a stream whose ROS type depends on the robot, like a pose, has
    one topic per kind)."""

    name: str
    type: str
    qos: str
    kind: str = ""

    def __post_init__(self) -> None:
        if self.qos not in ROS2_QOS:
            raise ValueError(
                f"ROS 2 topic {self.name!r}: unknown QoS {self.qos!r}; expected one of {', '.join(ROS2_QOS)}"
            )
        if self.type.count("/") != 2:
            raise ValueError(f"ROS 2 topic {self.name!r}: type {self.type!r} is not 'package/msg/Name'")


@dataclass(frozen=True, slots=True)
class RobotStream:
    """One robot stream, ``rf/{world}/robot/{id}/{name}``.

    ``message``: the fabric message type it carries. ``writer``: who writes it (:data:`WRITERS`), which gives
    the router's access rule (:attr:`access`) and whether fencing applies (:attr:`fenced`). QoS: ``rate_group``
    and ``hz`` are the sim's rate loop that paces it by default and that loop's rate (None: published when
    there is something to say, not at a rate); ``latched``: the publisher keeps its last sample for late joiners
    and waits rather than drops under congestion (other streams take zenoh's default, dropping). ``followed``:
    a user's robot handle keeps its latest (``user_peer.following``). ``ros2``: its ROS 2 topics (none: not
    bridged)."""

    name: str
    message: str
    writer: str
    rate_group: str | None = None
    hz: float | None = None
    latched: bool = False
    followed: bool = True
    ros2: tuple[Ros2Topic, ...] = ()

    def __post_init__(self) -> None:
        if self.writer not in WRITERS:
            raise ValueError(
                f"stream {self.name!r}: unknown writer {self.writer!r}; expected one of {', '.join(WRITERS)}"
            )
        if (self.rate_group is None) != (self.hz is None):
            raise ValueError(f"stream {self.name!r}: a rate group needs its rate, and a rate its group")

    @property
    def fenced(self) -> bool:
        """Whether consumers fence it by term: only what a sim authority writes carries a term (fabric.fencing)."""
        return self.writer == SIM

    @property
    def access(self) -> str:
        """The key expression, below a world, the router lets the :attr:`writer`'s logins put (robofabric.secure)."""
        return f"robot/*/{self.name}"


_SCAN = "sensor_msgs/msg/LaserScan"

STREAMS: tuple[RobotStream, ...] = (
    RobotStream(
        "joints",
        "JointState",
        SIM,
        "joints",
        100.0,
        ros2=(Ros2Topic("joint_states", "sensor_msgs/msg/JointState", "stream"),),
    ),
    RobotStream(
        "pose",
        "Pose",
        SIM,
        "pose",
        50.0,  # a base's pose and velocities; an arm's flange (in its joints loop)
        ros2=(
            Ros2Topic("odom", "nav_msgs/msg/Odometry", "stream", kind="mobile"),
            Ros2Topic("pose", "geometry_msgs/msg/PoseStamped", "stream", kind="arm"),
        ),
    ),
    RobotStream("scan", "Scan", SIM, "scan", 20.0, ros2=(Ros2Topic("scan", _SCAN, "sensor_data"),)),
    RobotStream(
        "sonar",
        "Scan",
        SIM,
        "scan",
        20.0,
        followed=False,  # the ring shares the LIDAR's loop
        ros2=(Ros2Topic("sonar", _SCAN, "sensor_data"),),
    ),
    RobotStream("path", "Path", COMPUTE, latched=True, ros2=(Ros2Topic("path", "nav_msgs/msg/Path", "latched"),)),
    RobotStream("ik", "IKStream", COMPUTE),
)
"""Every robot stream, in the order :data:`fabric.keys.ROBOT_STREAMS` gives them (and error messages list them)."""

NAMES: tuple[str, ...] = tuple(s.name for s in STREAMS)
_BY_NAME = {s.name: s for s in STREAMS}
if len(_BY_NAME) != len(STREAMS):
    raise ValueError(f"a robot stream is listed twice: {NAMES}")


def stream(name: str) -> RobotStream | None:
    """The row of stream ``name``; None for a name that is no robot stream."""
    return _BY_NAME.get(name)


def access(writer: str, *, latched: bool = False) -> list[str]:
    """The key expressions, below a world, that ``writer``'s logins put (with ``latched``, the latched streams'
    only), sorted: the router's rules (``robofabric.secure``) read the same whatever the table's order."""
    return sorted(s.access for s in STREAMS if s.writer == writer and (s.latched or not latched))


def ros2_topic(name: str, kind: str | None = None) -> Ros2Topic | None:
    """The ROS 2 topic of stream ``name`` for a robot of ``kind``: its kind's own, else the one for every kind;
    None when it has none (not bridged, an unknown stream, or a kind-specific stream of an unknown kind)."""
    row = _BY_NAME.get(name)
    if row is None:
        return None
    own = [t for t in row.ros2 if t.kind and t.kind == kind]
    common = [t for t in row.ros2 if not t.kind]
    found = own or common
    return found[0] if found else None


def default_rates() -> dict[str, float]:
    """The sim's rate groups and their default rates (Hz), in the table's order: ``{"joints": 100.0, ...}``;
    the streams of one group share its rate (checked at import)."""
    rates: dict[str, float] = {}
    for s in STREAMS:
        if s.rate_group is not None and s.hz is not None:
            if rates.setdefault(s.rate_group, s.hz) != s.hz:
                raise ValueError(f"stream {s.name!r}: rate group {s.rate_group!r} has two rates")
    return rates


default_rates()  # a table whose groups disagree fails at import, not in a sim
