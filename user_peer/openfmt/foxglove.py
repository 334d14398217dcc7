"""Foxglove's MCAP: well-known protobuf schemas where they fit, JSON with a JSON Schema for the rest.

=====================  ================================  =========================================
fabric                 Foxglove topic                    schema
=====================  ================================  =========================================
robot poses, arm FK    ``/tf``                           ``foxglove.FrameTransforms``
robot / object shapes  ``/scene``                        ``foxglove.SceneUpdate`` (when first seen)
Scan (LIDAR, sonar)    ``/KEY`` (the fabric key)         ``foxglove.LaserScan`` in ``ID/laser``
OccupancyGrid          ``/KEY``                          ``foxglove.Grid`` (uint8 ``occupancy``)
Path                   ``/KEY``                          ``foxglove.PosesInFrame``
Pose of an object      ``/KEY``                          ``foxglove.PoseInFrame``
anything else          ``/KEY``                          JSON, schema from the type's SPEC
=====================  ================================  =========================================

JointState goes to JSON (so every joint can be plotted, by index or by name under ``by_name``)
and to ``/tf`` through forward kinematics. JSON has no NaN or infinity: a message holding a
non-finite number is not written but counted in ``skipped``, as the ROS 2 writer does. Such a
message cannot come from the fabric (the codec refuses non-finite floats in every field), only from
a caller handing the writer a message built in-process; skipping keeps every file valid JSON and
the declared schemas exact (a plotted number is never ``null``). Written with the ``mcap`` writer and
``mcap-protobuf-support``'s schema registration (the FileDescriptorSet Foxglove expects).
"""

from __future__ import annotations

import json
from pathlib import Path as FsPath
from typing import Any

import numpy as np
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.CubePrimitive_pb2 import CubePrimitive
from foxglove_schemas_protobuf.CylinderPrimitive_pb2 import CylinderPrimitive
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.Grid_pb2 import Grid
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.Pose_pb2 import Pose as FgPose
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.SpherePrimitive_pb2 import SpherePrimitive
from foxglove_schemas_protobuf.Vector2_pb2 import Vector2
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.timestamp_pb2 import Timestamp
from mcap_protobuf.schema import register_schema

from fabric.recording.mcap_file import McapFile, mcap_writer
from fabric.interfaces import JointState, OccupancyGrid, Path, Pose, Scan
from user_peer.arm_geometry import Placement, Shape
from user_peer.catalog import RobotCatalog
from user_peer.message_schema import json_schema, plain_view
from user_peer.openfmt.frames import MAP, Frame, FrameTracker, key_owner, ros_frame, scan_frame, yaw_quat_xyzw

__all__ = ["FoxgloveWriter", "TF_TOPIC", "SCENE_TOPIC", "JOINTS_EXTRA"]

TF_TOPIC = "/tf"
SCENE_TOPIC = "/scene"
JOINTS_EXTRA = {
    "by_name": {
        "type": "object",
        "description": "position and velocity of each joint by name (for plots)",
        "additionalProperties": {
            "type": "object",
            "properties": {"position": {"type": "number"}, "velocity": {"type": "number"}},
            "required": ["position", "velocity"],
        },
    }
}


def _stamp(ns: int) -> Timestamp:
    return Timestamp(seconds=ns // 1_000_000_000, nanos=ns % 1_000_000_000)


def _pose(t: Any, q: Any) -> FgPose:
    return FgPose(
        position=Vector3(x=float(t[0]), y=float(t[1]), z=float(t[2])),
        orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
    )


def _color(rgba: tuple[int, ...]) -> Color:
    r, g, b, a = (list(rgba) + [255])[:4]
    return Color(r=r / 255.0, g=g / 255.0, b=b / 255.0, a=a / 255.0)


def msg_time_ns(msg: Any, log_time_ns: int) -> int:
    """The message's own wall time when it has one, else the time it was recorded."""
    header = getattr(msg, "header", None)
    wall = getattr(header, "wall_ns", 0) or 0
    return int(wall) if wall > 0 else int(log_time_ns)


class FoxgloveWriter(McapFile):
    """Write fabric messages as a Foxglove-readable MCAP file; ``close()`` finishes it."""

    def __init__(self, path: FsPath, *, catalog: RobotCatalog | None = None, scene: str | None = None) -> None:
        super().__init__(path, mcap_writer(""))
        self._proto_schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._json_schemas: dict[str, int] = {}
        self.frames = FrameTracker(catalog or RobotCatalog(None, scene=scene))
        self._drawn: set[str] = set()
        self._tf_pub = 0
        self._static: list[SceneEntity] = []  # the scene's fixed geometry, written with the first message
        self.written = 0
        self.skipped = 0
        if scene:
            self._static_scene(scene)

    # ------------------------------------------------------------------ channels

    def _proto_channel(self, topic: str, cls: type) -> int:
        ch = self._channels.get(topic)
        if ch is None:
            name = cls.DESCRIPTOR.full_name
            if name not in self._proto_schemas:
                self._proto_schemas[name] = register_schema(self.writer, cls)
            ch = self._channels[topic] = self.writer.register_channel(topic, "protobuf", self._proto_schemas[name])
        return ch

    def _json_channel(self, topic: str, type_name: str, cls: type) -> int:
        ch = self._channels.get(topic)
        if ch is None:
            if type_name not in self._json_schemas:
                schema = json_schema(cls, extra=JOINTS_EXTRA if cls is JointState else None)
                self._json_schemas[type_name] = self.writer.register_schema(
                    f"robofabric.{type_name}", "jsonschema", json.dumps(schema).encode()
                )
            ch = self._channels[topic] = self.writer.register_channel(topic, "json", self._json_schemas[type_name])
        return ch

    def _put(self, channel: int, data: bytes, log_time: int, publish_time: int) -> None:
        self.writer.add_message(channel, log_time=log_time, data=data, publish_time=publish_time)
        self.written += 1

    def _proto(self, topic: str, m: Any, log_time: int, publish_time: int) -> None:
        self._put(self._proto_channel(topic, type(m)), m.SerializeToString(), log_time, publish_time)

    # ------------------------------------------------------------------ messages

    def write(self, key: str, msg: Any, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """One fabric message received on ``key`` at ``log_time_ns`` (ns since the epoch)."""
        pub = int(publish_time_ns if publish_time_ns is not None else log_time_ns)
        if self._static:
            self._proto(SCENE_TOPIC, SceneUpdate(entities=self._static), log_time_ns, pub)
            self._static = []
        t = msg_time_ns(msg, log_time_ns)
        topic = "/" + key
        frames = self.frames.frames(key, msg, t)
        if frames:
            self._tf_pub = max(self._tf_pub, pub)  # /tf's publish times never go back (it merges every robot's keys)
            self._proto(
                TF_TOPIC, FrameTransforms(transforms=[self._tf(f, t) for f in frames]), log_time_ns, self._tf_pub
            )
            self._draw_new(key, t, log_time_ns, pub)
        if isinstance(msg, Scan):
            owner = key_owner(key)
            frame = scan_frame(owner[1] if owner else MAP, key)
            n = int(msg.ranges_mm.shape[0])
            self._proto(
                topic,
                LaserScan(
                    timestamp=_stamp(t),
                    frame_id=frame,
                    pose=_pose((0, 0, 0), (0, 0, 0, 1)),
                    start_angle=float(msg.angle_min),
                    end_angle=float(msg.angle_min + msg.angle_increment * max(n - 1, 0)),
                    ranges=[float(r) for r in msg.ranges],
                ),
                log_time_ns,
                pub,
            )
        elif isinstance(msg, OccupancyGrid):
            h, w = msg.cells.shape
            ox, oy, oth = (float(v) for v in msg.origin)
            self._proto(
                topic,
                Grid(
                    timestamp=_stamp(t),
                    frame_id=MAP,
                    pose=_pose((ox, oy, 0.0), yaw_quat_xyzw(oth)),
                    column_count=int(w),
                    cell_size=Vector2(x=float(msg.resolution), y=float(msg.resolution)),
                    row_stride=int(w),
                    cell_stride=1,
                    fields=[PackedElementField(name="occupancy", offset=0, type=PackedElementField.UINT8)],
                    data=np.ascontiguousarray(msg.cells, dtype=np.uint8).tobytes(),
                ),
                log_time_ns,
                pub,
            )
        elif isinstance(msg, Path):
            frame = ros_frame(msg.frame)
            poses = [
                _pose((float(x), float(y), 0.0), yaw_quat_xyzw(float(th))) for x, y, th in zip(msg.x, msg.y, msg.theta)
            ]
            self._proto(topic, PosesInFrame(timestamp=_stamp(t), frame_id=frame, poses=poses), log_time_ns, pub)
        elif isinstance(msg, Pose):
            q = msg.quaternion
            self._proto(
                topic,
                PoseInFrame(
                    timestamp=_stamp(t),
                    frame_id=ros_frame(msg.frame),
                    pose=_pose(msg.position, (q[1], q[2], q[3], q[0])),
                ),
                log_time_ns,
                pub,
            )
        else:
            self._json(topic, msg, log_time_ns, pub)

    def _json(self, topic: str, msg: Any, log_time: int, pub: int) -> None:
        cls = type(msg)
        if not hasattr(cls, "SPEC"):
            self.skipped += 1
            return
        plain = plain_view(msg)
        type_name = plain["type"]
        if isinstance(msg, JointState):
            plain["by_name"] = {
                n: {"position": float(q), "velocity": float(dq)} for n, q, dq in zip(msg.names, msg.q, msg.dq)
            }
        try:
            data = json.dumps(plain, allow_nan=False)
        except ValueError:  # NaN or infinity: not JSON, and not a message the fabric's codec accepts
            self.skipped += 1
            return
        self._put(self._json_channel(topic, type_name, cls), data.encode(), log_time, pub)

    def _tf(self, f: Frame, t: int) -> FrameTransform:
        return FrameTransform(
            timestamp=_stamp(t),
            parent_frame_id=f.parent,
            child_frame_id=f.child,
            translation=Vector3(x=f.translation[0], y=f.translation[1], z=f.translation[2]),
            rotation=Quaternion(x=f.rotation[0], y=f.rotation[1], z=f.rotation[2], w=f.rotation[3]),
        )

    # ------------------------------------------------------------------ scene

    def _draw_new(self, key: str, t: int, log_time: int, pub: int) -> None:
        """A SceneUpdate with a robot's or object's shapes the first time it moves."""
        owner = key_owner(key)
        if owner is None:
            return
        what, oid = owner
        name = f"{what}/{oid}"
        if name in self._drawn:
            return
        self._drawn.add(name)
        if what == "object":
            ent = SceneEntity(
                timestamp=_stamp(t),
                frame_id=f"object/{oid}",
                id=name,
                frame_locked=True,
                spheres=[
                    SpherePrimitive(
                        pose=_pose((0, 0, 0), (0, 0, 0, 1)),
                        size=Vector3(x=0.06, y=0.06, z=0.06),
                        color=_color((230, 60, 60, 255)),
                    )
                ],
            )
            self._proto(SCENE_TOPIC, SceneUpdate(entities=[ent]), log_time, pub)
            return
        ents = []
        for frame, shape, pl in self.frames.shapes(oid):
            ent = _entity(f"{name}/{shape.name}", frame, shape, pl, t)
            if ent is not None:
                ents.append(ent)
        if ents:
            self._proto(SCENE_TOPIC, SceneUpdate(entities=ents), log_time, pub)

    def _static_scene(self, scene: str) -> None:
        try:
            import robots
            from user_peer.scene_geometry import static_boxes

            boxes = static_boxes(robots.scene(scene).mjcf_path)
        except Exception:
            return
        self._static = [
            SceneEntity(
                frame_id=MAP,
                id=f"scene/{b.name}",
                cubes=[
                    CubePrimitive(
                        pose=_pose(b.center, b.quat_xyzw),
                        size=Vector3(
                            x=2 * float(b.half_size[0]), y=2 * float(b.half_size[1]), z=2 * float(b.half_size[2])
                        ),
                        color=_color(b.rgba),
                    )
                ],
            )
            for b in boxes
        ]


def _entity(eid: str, frame: str, shape: Shape, pl: Placement, t: int) -> SceneEntity | None:
    pose = _pose(pl.translation, pl.quat_xyzw)
    color = _color(shape.color)
    ent = SceneEntity(timestamp=_stamp(t), frame_id=frame, id=eid, frame_locked=True)
    if shape.kind == "box":
        hx, hy, hz = shape.size
        ent.cubes.append(CubePrimitive(pose=pose, size=Vector3(x=2 * hx, y=2 * hy, z=2 * hz), color=color))
    elif shape.kind in ("cylinder", "capsule"):
        r, length = shape.size
        ent.cylinders.append(
            CylinderPrimitive(
                pose=pose, size=Vector3(x=2 * r, y=2 * r, z=length), bottom_scale=1.0, top_scale=1.0, color=color
            )
        )
    elif shape.kind == "sphere":
        (r,) = shape.size
        ent.spheres.append(SpherePrimitive(pose=pose, size=Vector3(x=2 * r, y=2 * r, z=2 * r), color=color))
    else:
        return None
    return ent
