"""A second sim on a world another live sim serves is refused with one line (exit 2), instead of the two
elections making one of them step down while its robots vanish without a word:
a robot id already served, or another scene. A sim of disjoint robots joins as a shard (test_shards.py)."""

from __future__ import annotations

import subprocess

import pytest

from robofabric.testing import SimRoles, robofabric_cmd, wait_until

pytestmark = pytest.mark.slow


def test_a_second_sim_on_a_served_world_is_refused_with_one_line(world, router, connect, procs):
    ep = f"tcp/127.0.0.1:{router[1]}"
    common = ("--world", world, "--connect", ep)
    first = procs.start(
        robofabric_cmd(
            "sim", "--scene", "warehouse", "--no-scene-robots", "--robot", "reeman:base0@0,0", *common, "--id", "sim-a"
        ),
        name="sim-a",
    )
    probe = connect("tool", "probe")
    wait_until(
        lambda: probe.live_peers("sim") and _answers(probe, world),
        timeout=60,
        what="sim-a serving the world",
        seen=lambda: procs.output(first)[-800:],
    )
    cases = {
        (
            "--scene",
            "warehouse",
            "--no-scene-robots",
            "--robot",
            "reeman:base0@1.5,0,180",
        ): "robot base0 is already served by sim sim-a",
        ("--scene", "arm_cell"): "runs scene 'warehouse' (sim sim-a), not 'arm_cell'",
        # one robot of two already served: the whole sim is refused (disjoint robots join as a shard: test_shards.py)
        (
            "--scene",
            "warehouse",
            "--no-scene-robots",
            "--robot",
            "reeman:base1@1.5,0,180",
            "--robot",
            "reeman:base0@3,0",
        ): "robot base0 is already served by sim sim-a",
    }
    for args, said in cases.items():
        r = subprocess.run(
            robofabric_cmd("sim", *args, *common, "--id", "sim-b"), capture_output=True, text=True, timeout=120
        )
        assert r.returncode == 2, (args, r.stdout[-500:], r.stderr[-800:])
        assert said in r.stderr and "Traceback" not in r.stderr, (args, r.stderr[-800:])
        assert len([ln for ln in r.stderr.splitlines() if ln.strip()]) == 1, r.stderr
    assert first.poll() is None  # the first sim still serves
    # a standby is the one exception: it follows sim-a
    standby = procs.start(
        robofabric_cmd(
            "sim",
            "--scene",
            "warehouse",
            "--no-scene-robots",
            "--robot",
            "reeman:base0@0,0",
            *common,
            "--id",
            "sim-c",
            "--standby",
        ),
        name="sim-c",
    )
    SimRoles(probe).wait("sim-c", "standby", leader="sim-a", timeout=60, seen=lambda: procs.output(standby)[-800:])


def _answers(fab, world: str) -> bool:
    from fabric import keys
    from fabric.interfaces import ServiceError

    try:
        fab.rpc.call(keys.srv(world, "world"), timeout=1.0)
        return True
    except ServiceError:
        return False
