"""The interfaces of the fabric: every message, request and reply that crosses peers, the event kinds,
the errors that travel, and the shared geometry, in one package apart from the peers that use them (the
way ROS keeps its ``*_msgs`` packages apart from nodes).

Importing it registers every built-in message type with :mod:`fabric.codec` under its class name (the
wire type name, which recordings keep). Third-party packages add their own types with
:func:`fabric.codec.register` and declare the module under the entry-point group
``robofabric.messages``. It depends on nothing of the fabric but the codec's field specs and the
limits they check, and on no peer package (import-linter contracts in pyproject.toml).

Modules, one room each:

- :mod:`.std`: header, joint states, poses, scans, paths, occupancy grids, and the size caps
- :mod:`.commands`: what an owner sends a robot (joint targets, twists, paths, stop, reset) in a ``Command``
- :mod:`.ownership`: the ownership record and the request/reply of the ownership service
- :mod:`.events`: ``Event`` and ``EventKind``, every event kind robofabric sends
- :mod:`.sensors`: what a robot carries: its mobile base, LIDAR and sonar ring (parts of ``RobotInfo``)
- :mod:`.world`: the world description (robots, scene objects) and a standby's world state
- :mod:`.kinematics`: IK, FK and Jacobian requests and replies, the streamed IK solution
- :mod:`.navigation`: map and plan requests and replies
- :mod:`.errors`: ``ServiceError``, ``Refused``, ``NoReply`` (and the codec's ``DecodeError``)
- :mod:`.geometry`: angles and headings (``wrap_angle``, ``yaw_from_quaternion``, ``quaternion_from_yaw``)

A message's plain JSON view and its type's JSON Schema, read off the same ``SPEC``, are the exporters':
:mod:`user_peer.message_schema` (no peer sends JSON); the fields listing of ``robofabric interfaces`` is a
tool's, :mod:`robofabric.interface_fields`.
"""

from fabric.interfaces.std import (
    MAX_GRID_CELLS,
    MAX_JOINTS,
    MAX_PATH_POINTS,
    MAX_RAYS,
    Header,
    JointState,
    OccupancyGrid,
    Path,
    Pose,
    Scan,
)
from fabric.interfaces.robot_commands import (
    COMMAND_BODIES,
    Command,
    CommandBody,
    JointTarget,
    JointTrajectory,
    Reset,
    Stop,
    Twist,
    sample_trajectory,
)
from fabric.interfaces.ownership import MAX_QUEUE, STAFF_OPS, OwnershipRecord, OwnReply, OwnRequest
from fabric.interfaces.events import REJECT_KINDS, Event, EventKind
from fabric.interfaces.sensors import BaseInfo, LidarInfo, SonarInfo
from fabric.interfaces.world import ObjectInfo, RobotInfo, RobotState, WorldInfo, WorldState
from fabric.interfaces.kinematics import (
    FRAMES,
    IK_METHODS,
    FKReply,
    FKRequest,
    IKReply,
    IKRequest,
    IKStream,
    JacobianReply,
    JacobianRequest,
)
from fabric.interfaces.navigation import (
    DIRECTIONS,
    MAP_ACTIONS,
    PLANNER_NAMES,
    MapReply,
    MapRequest,
    PlanReply,
    PlanRequest,
    empty_grid,
)
from fabric.interfaces.errors import DecodeError, NoReply, Refused, ServiceError
from fabric.interfaces.geometry import TWO_PI, quaternion_from_yaw, wrap_angle, yaw_from_quaternion

__all__ = [
    # std
    "MAX_GRID_CELLS",
    "MAX_JOINTS",
    "MAX_PATH_POINTS",
    "MAX_RAYS",
    "Header",
    "JointState",
    "OccupancyGrid",
    "Path",
    "Pose",
    "Scan",
    # commands
    "COMMAND_BODIES",
    "Command",
    "CommandBody",
    "JointTarget",
    "JointTrajectory",
    "sample_trajectory",
    "Reset",
    "Stop",
    "Twist",
    # ownership
    "MAX_QUEUE",
    "STAFF_OPS",
    "OwnershipRecord",
    "OwnReply",
    "OwnRequest",
    # events
    "REJECT_KINDS",
    "Event",
    "EventKind",
    # sensors, world
    "BaseInfo",
    "LidarInfo",
    "SonarInfo",
    "ObjectInfo",
    "RobotInfo",
    "RobotState",
    "WorldInfo",
    "WorldState",
    # kinematics
    "FRAMES",
    "IK_METHODS",
    "FKReply",
    "FKRequest",
    "IKReply",
    "IKRequest",
    "IKStream",
    "JacobianReply",
    "JacobianRequest",
    # navigation
    "DIRECTIONS",
    "MAP_ACTIONS",
    "PLANNER_NAMES",
    "MapReply",
    "MapRequest",
    "PlanReply",
    "PlanRequest",
    "empty_grid",
    # errors
    "DecodeError",
    "NoReply",
    "Refused",
    "ServiceError",
    # geometry
    "TWO_PI",
    "quaternion_from_yaw",
    "wrap_angle",
    "yaw_from_quaternion",
]
