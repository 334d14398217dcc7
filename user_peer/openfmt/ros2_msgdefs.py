"""ROS 2 message definitions (``ros2msg`` text, dependencies appended as rosbag2 writes them).

The definitions are the standard ones of ``std_msgs``, ``geometry_msgs``, ``sensor_msgs``,
``nav_msgs`` (Odometry), ``rosgraph_msgs`` (Clock) and ``tf2_msgs`` (comments dropped; Kilted's, whose
``sensor_msgs/Range`` has a ``variance``);
``builtin_interfaces/Time`` is built into the
CDR codec.
"""

from __future__ import annotations

__all__ = ["definition", "TYPES"]

_SEP = "=" * 80

_BASE: dict[str, str] = {
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/String": "string data\n",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/PoseStamped": "std_msgs/Header header\nPose pose\n",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/TransformStamped": "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
    "sensor_msgs/JointState": "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
    "sensor_msgs/LaserScan": (
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\nfloat32 time_increment\n"
        "float32 scan_time\nfloat32 range_min\nfloat32 range_max\nfloat32[] ranges\nfloat32[] intensities\n"
    ),
    "nav_msgs/MapMetaData": "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\ngeometry_msgs/Pose origin\n",
    "nav_msgs/OccupancyGrid": "std_msgs/Header header\nMapMetaData info\nint8[] data\n",
    "nav_msgs/Path": "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n",
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    "geometry_msgs/Twist": "Vector3 linear\nVector3 angular\n",
    "rosgraph_msgs/Clock": "builtin_interfaces/Time clock\n",
    "sensor_msgs/Range": (
        "uint8 ULTRASOUND=0\nuint8 INFRARED=1\nstd_msgs/Header header\nuint8 radiation_type\nfloat32 field_of_view\n"
        "float32 min_range\nfloat32 max_range\nfloat32 range\nfloat32 variance\n"
    ),
    "geometry_msgs/PoseWithCovariance": "Pose pose\nfloat64[36] covariance\n",
    "geometry_msgs/TwistWithCovariance": "Twist twist\nfloat64[36] covariance\n",
    "nav_msgs/Odometry": "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
}

_DEPS: dict[str, tuple[str, ...]] = {
    "std_msgs/String": (),
    "geometry_msgs/PoseStamped": (
        "std_msgs/Header",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
    ),
    "sensor_msgs/JointState": ("std_msgs/Header",),
    "sensor_msgs/LaserScan": ("std_msgs/Header",),
    "nav_msgs/OccupancyGrid": (
        "std_msgs/Header",
        "nav_msgs/MapMetaData",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
    ),
    "nav_msgs/Path": (
        "std_msgs/Header",
        "geometry_msgs/PoseStamped",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
    ),
    "tf2_msgs/TFMessage": (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header",
        "geometry_msgs/Transform",
        "geometry_msgs/Vector3",
        "geometry_msgs/Quaternion",
    ),
    "rosgraph_msgs/Clock": (),
    "sensor_msgs/Range": ("std_msgs/Header",),
    "nav_msgs/Odometry": (
        "std_msgs/Header",
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3",
    ),
}

TYPES = tuple(f"{k.split('/')[0]}/msg/{k.split('/')[1]}" for k in _DEPS)
"""The full ROS 2 type names this export writes."""


def definition(type_name: str) -> str:
    """The concatenated ros2msg text of ``pkg/msg/Type``: its own fields, then each dependency."""
    pkg, _, name = type_name.split("/")
    short = f"{pkg}/{name}"
    parts = [_BASE[short]]
    for dep in _DEPS[short]:
        parts.append(f"{_SEP}\nMSG: {dep}\n{_BASE[dep]}")
    return "".join(parts)
