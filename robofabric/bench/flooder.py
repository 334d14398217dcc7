"""The flooder of :mod:`robofabric.bench.flood` (a child process): argv WORLD PORT LOAD_JSON. Sends everything once, as fast as it
can (zenoh drops what its queues cannot take), prints one JSON line of what it sent, exits."""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

from fabric import keys
from fabric.codec import encode
from fabric.interfaces import Command, JointState, JointTarget, OwnRequest
from robofabric.testing import client


def flood(world: str, port: int, load: dict) -> dict:
    sent: dict[str, int] = {}
    t0 = time.monotonic()
    with client(world, port, kind="tool", peer_id=f"flooder{os.getpid()}") as fab:
        s = fab.session  # raw on purpose: a flooder's junk is bytes no Fabric would encode, on keys it would not cache
        root = keys.world_root(world)
        cmd = encode(Command("mallory", 1, JointTarget(np.zeros(6))))
        for i in range(load["unique_commands"]):
            s.put(keys.robot_cmd(world, f"ghost{i}", "joints", "mallory"), cmd)
        sent["unique_commands"] = load["unique_commands"]
        sent["t_unique_commands"] = round(time.monotonic() - t0, 3)
        junk_keys = [
            keys.robot_cmd(world, "arm1", "joints", "mallory"),
            keys.robot_cmd(world, "arm1", "stop", "mallory"),
            keys.robot_cmd(world, "base1", "twist", "mallory"),
            keys.object_pose(world, "target", "mallory"),
            keys.object_pose(world, "goal", "mallory"),
            keys.robot_joints(world, "arm1"),
            keys.robot_pose(world, "base1"),
            keys.robot_scan(world, "base1"),
        ]
        pubs = [s.declare_publisher(k) for k in junk_keys]
        rng = np.random.default_rng(7)
        junk = [rng.integers(0, 256, int(n), dtype=np.uint8).tobytes() for n in rng.integers(1, 300, 64)]
        junk.append(msgpack_type_name(100_000))
        for i in range(load["junk_per_key"]):
            j = junk[i % len(junk)]
            for p in pubs:
                p.put(j)
        sent["junk"] = load["junk_per_key"] * len(pubs)
        sent["t_junk"] = round(time.monotonic() - t0, 3)
        for i in range(load["junk_per_key"] // 10):  # junk queries too: ownership and a service
            for k in (keys.own_request(world, "arm1", "mallory"), keys.srv(world, "ik", "arm1")):
                s.get(k, lambda r: None, payload=junk[i % len(junk)])
        sent["junk_queries"] = 2 * (load["junk_per_key"] // 10)
        sent["t_junk_queries"] = round(time.monotonic() - t0, 3)
        big = b"\x93" + bytes(load["big_bytes"])
        for i in range(load["big_payloads"]):
            pubs[i % 2 * 5].put(big)  # arm1's joints command and arm1's joint stream
        sent["big"] = load["big_payloads"]
        sent["t_big"] = round(time.monotonic() - t0, 3)
        js = encode(JointState([f"j{i}" for i in range(6)], np.zeros(6), np.zeros(6)))
        for i in range(load["fake_joint_streams"]):
            s.put(f"{root}/robot/fake{i}/joints", js)
        sent["fake_joint_streams"] = load["fake_joint_streams"]
        sent["t_fake_joint_streams"] = round(time.monotonic() - t0, 3)
        for i in range(load["forged_requests"]):
            s.get(
                keys.own_request(world, "arm1", f"forged{i}"),
                lambda r: None,
                payload=encode(OwnRequest("request", f"forged{i}", True)),
                timeout=5.0,
            )
        sent["forged_requests"] = load["forged_requests"]
        sent["t_forged_requests"] = round(time.monotonic() - t0, 3)
        time.sleep(1.0)  # let the last puts leave before the session closes
    sent["seconds"] = round(time.monotonic() - t0, 3)
    return sent


def msgpack_type_name(n: int) -> bytes:
    import msgpack

    return msgpack.packb(["T" * n, 1, 2])


if __name__ == "__main__":
    world, port, spec = sys.argv[1], int(sys.argv[2]), json.loads(sys.argv[3])
    print(json.dumps(flood(world, port, spec)), flush=True)
