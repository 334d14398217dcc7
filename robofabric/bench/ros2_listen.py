"""The ROS 2 side of ``robofabric bench ros2``: a plain rclpy node that notes when each bridged message arrives.

``python -m robofabric.bench.ros2_listen --robots base0,base1 --seconds 10 --out FILE``: subscribes to every
robot's ``scan`` (sensor-data QoS), ``odom`` and ``joint_states``, prints ``ready``, and after ``--seconds``
writes one line per message, ``TOPIC STAMP_NS ARRIVAL_NS`` (arrival: ``time.time_ns()``, the clock the
benchmark's zenoh subscriber reads too) and one per garbage collection, ``gc GENERATION START_NS END_NS``, then exits. Kept in memory until the end: no file writes while it
measures. Imports rclpy only. ``--executor events`` (the default) spins with rclpy's EventsExecutor
(``rclpy.experimental``), whose cost per callback is a fraction of the SingleThreadedExecutor's
(``--executor single``): on two loaded cores the latter fell behind 1,300 messages a second by itself, and a
late callback reads as the bridge's latency.

``--take raw`` (the default) subscribes with ``raw=True``: the callback gets the serialized CDR bytes, notes the
arrival first and reads the stamp from the header at the start of each message (the CDR encapsulation's 4 bytes,
then ``int32 sec``, ``uint32 nanosec``), as the benchmark's zenoh subscriber notes its arrival before decoding:
both sides time the bytes' arrival, not a decoder. ``--take message`` builds rclpy's message first (a scan's 360
floats, an odometry's two 36-double covariances as numpy arrays), what a node that reads the values pays.
"""

from __future__ import annotations

import argparse
import gc
import struct
import time
from typing import Any

_STAMPS = (struct.Struct(">iI"), struct.Struct("<iI"))
"""A header's stamp (sec, nanosec) after the 4-byte encapsulation, whose second byte's low bit says the byte
order (CDR and XCDR2 alike: 0x0001 and 0x0007 little-endian, 0x0000 and 0x0006 big-endian)."""


def main() -> None:
    import rclpy
    from nav_msgs.msg import Odometry
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import JointState, LaserScan

    ap = argparse.ArgumentParser()
    ap.add_argument("--robots", required=True)
    ap.add_argument("--seconds", type=float, required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--executor", choices=("events", "single"), default="events")
    ap.add_argument("--take", choices=("raw", "message"), default="raw")
    args = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("bench_ros2_listen")
    got: list[tuple[str, int, int]] = []
    raw = args.take == "raw"

    def note(topic: str) -> Any:
        if raw:

            def on_raw(data: bytes) -> None:
                now = time.time_ns()
                sec, nsec = _STAMPS[data[1] & 1].unpack_from(data, 4)
                got.append((topic, sec * 1_000_000_000 + nsec, now))

            return on_raw
        return lambda m: got.append(
            (topic, m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec, time.time_ns())
        )

    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    for rid in args.robots.split(","):
        for leaf, cls, qos in (
            ("scan", LaserScan, qos_profile_sensor_data),
            ("odom", Odometry, reliable),
            ("joint_states", JointState, reliable),
        ):
            topic = f"/{rid}/{leaf}"
            node.create_subscription(cls, topic, note(topic), qos, raw=raw)
    if args.executor == "events":
        from rclpy.experimental import EventsExecutor

        executor = EventsExecutor()
    else:
        executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    pauses: list[tuple[int, int, int]] = []
    started = [0]

    def on_gc(phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            started[0] = time.time_ns()
        else:
            pauses.append((info["generation"], started[0], time.time_ns()))

    gc.callbacks.append(on_gc)
    # this node is the benchmark's instrument: a full collection of its ~80,000 objects (rclpy's, numpy's) stops
    # its thread for 20-180 ms on two loaded cores, and every message then in flight would read as the bridge's;
    # what exists now is frozen out of collection and none runs while it measures (the window's few MB are freed
    # at exit)
    gc.collect()
    gc.freeze()
    gc.disable()
    print("ready", flush=True)
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.1)
    with open(args.out, "w") as f:
        f.writelines(f"{t} {s} {a}\n" for t, s, a in got)
        f.writelines(f"gc {g} {a} {b}\n" for g, a, b in pauses)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
