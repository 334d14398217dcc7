"""Shared helpers for the recording tests: small synthetic recordings written with the real sink."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fabric.codec import encode
from fabric.interfaces import Header, JointState, Pose, Scan


def joint_payload(seq: int, wall_ns: int, source: str = "sim") -> bytes:
    return encode(
        JointState(("a", "b"), np.array([0.1 * seq, 0.2]), np.zeros(2), Header(seq * 0.01, wall_ns, seq, source))
    )


def pose_payload(seq: int, wall_ns: int) -> bytes:
    return encode(Pose(np.array([seq, 0.0, 0.0]), header=Header(0.0, wall_ns, seq, "sim")))


def scan_payload(seq: int, wall_ns: int) -> bytes:
    return encode(
        Scan.from_ranges(
            np.full(240, 1.0 + seq),
            angle_min=-1.0,
            angle_increment=0.01,
            range_max=10.0,
            header=Header(0.0, wall_ns, seq, "sim"),
        )
    )


def synthetic(
    world: str, n: int = 50, t0: int = 1_700_000_000_000_000_000, dt_ns: int = 10_000_000
) -> list[tuple[str, int, bytes]]:
    """(key, log_time, payload) of a tiny world: two robots' joints every tick, a pose every 2nd, a scan every 5th, one raw blob."""
    out = []
    for i in range(n):
        t = t0 + i * dt_ns
        out.append((f"rf/{world}/robot/r0/joints", t, joint_payload(i, t - 1000)))
        out.append((f"rf/{world}/robot/r1/joints", t + 1, joint_payload(i, t - 999, "sim2")))
        if i % 2 == 0:
            out.append((f"rf/{world}/robot/r0/pose", t + 2, pose_payload(i, t - 500)))
        if i % 5 == 0:
            out.append((f"rf/{world}/robot/r0/scan", t + 3, scan_payload(i, t - 200)))
    out.append((f"rf/{world}/event/blob", t0 + n * dt_ns, b"\x00not msgpack\xff"))
    return out


def write_recording(path: Path, samples, **sink_kwargs) -> None:
    from fabric.recording import McapSink

    with McapSink(path, **sink_kwargs) as sink:
        for key, t, payload in samples:
            sink.write(key, payload, t)
