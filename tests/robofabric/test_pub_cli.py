"""``robofabric pub`` on command keys against a live sim: applied, refused with the sim's reason, bad keys refused."""

from __future__ import annotations

import subprocess

import pytest

from robofabric.testing import robofabric_cmd, wait_until
from ownership import OwnershipClient

pytestmark = pytest.mark.slow  # starts a sim process


@pytest.fixture
def sim_world(router, procs, world):
    ep = f"tcp/127.0.0.1:{router[1]}"
    sim = procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep), name="sim")
    wait_until(lambda: router[0].live_peers("sim"), timeout=60, what="sim peer", seen=lambda: procs.output(sim)[-2000:])
    return ep


def _granted(client, robot: str) -> bool:
    """Whether a request is granted now; False while the sim's authority does not serve yet (its token comes first)."""
    from fabric.interfaces import ServiceError

    try:
        return client.request(robot).outcome == "granted"
    except ServiceError:
        return False


def _pub(world, ep, *args):
    return subprocess.run(
        robofabric_cmd("pub", *args, "--world", world, "--connect", ep), capture_output=True, text=True, timeout=60
    )


def test_pub_exit_codes_applied_refused_and_bad_keys(sim_world, world, connect):
    ep = sim_world
    twist = ("-t", "Twist", "-d", '{"v": 0.2, "omega": 0}')
    alice = OwnershipClient(connect("user", "alice"), "alice").start()
    try:
        wait_until(lambda: _granted(alice, "base1"), timeout=20, what="alice owns base1")
        ok = _pub(world, ep, "robot/base1/cmd/twist", *twist, "--user", "alice")
        assert ok.returncode == 0 and "applied" in ok.stdout, ok.stdout + ok.stderr
        # bob does not own it: the sim's reason, exit 1
        bob = _pub(world, ep, "robot/base1/cmd/twist", *twist, "--user", "bob")
        assert bob.returncode == 1 and "refused:" in bob.stderr and "alice" in bob.stderr, bob.stdout + bob.stderr
        # free robot: refused too
        free = _pub(world, ep, "robot/arm1/cmd/stop", "-t", "Stop", "--user", "bob")
        assert free.returncode == 1 and "not owned" in free.stderr, free.stdout + free.stderr
    finally:
        alice.close()
    # no user: refused before sending; a key of no layout too
    nouser = _pub(world, ep, "robot/base1/cmd/twist", *twist)
    assert nouser.returncode == 2 and "needs its user" in nouser.stderr, nouser.stdout + nouser.stderr
    nolayout = _pub(world, ep, "robot/base1/warp/drive", *twist)
    assert (
        nolayout.returncode == 2
        and "does not match any robofabric key layout" in nolayout.stderr
        and "nothing sent" in nolayout.stderr
    )
    badcmd = _pub(world, ep, "robot/base1/cmd/warp", *twist, "--user", "alice")
    assert badcmd.returncode == 2, badcmd.stdout + badcmd.stderr
    for out in (ok, bob, free, nouser, nolayout, badcmd):
        assert "Traceback" not in out.stderr


def test_pub_refuses_an_unknown_robot_a_wrong_type_and_bad_fields_in_words(sim_world, world):
    """``pub`` to an unknown robot, a Twist on a JointState key and bad data are refused in words with exit 2: never
    "applied" while the sim logs unknown_robot, never ``Twist.__init__() missing 1 required positional argument``."""
    ep = sim_world
    twist = ("-t", "Twist", "-d", '{"v": 0.2, "omega": 0}')
    wait_until(
        lambda: _pub(world, ep, "robot/base1/cmd/twist", *twist, "--user", "alice").returncode == 1,
        timeout=30,
        what="the sim serving its world (alice owns nothing: refused)",
    )
    nobody = _pub(world, ep, "robot/base9/cmd/twist", *twist, "--user", "alice")
    assert nobody.returncode == 1 and "unknown_robot" in nobody.stderr and "base1" in nobody.stderr, (
        nobody.stdout + nobody.stderr
    )
    assert "applied" not in nobody.stdout
    wrong = _pub(world, ep, "robot/base1/joints", *twist)
    assert wrong.returncode == 2 and "carries JointState" in wrong.stderr and "nothing sent" in wrong.stderr, (
        wrong.stderr
    )
    body = _pub(world, ep, "robot/arm1/cmd/joints", *twist, "--user", "alice")
    assert body.returncode == 2 and "carries JointTarget" in body.stderr, body.stderr
    missing = _pub(world, ep, "robot/base1/cmd/twist", "-t", "Twist", "-d", '{"v": 0.2}', "--user", "alice")
    assert missing.returncode == 2 and "Twist needs field 'omega' (a number)" in missing.stderr, missing.stderr
    bad = _pub(world, ep, "robot/base1/cmd/twist", "-t", "Twist", "-d", '{"v": "fast", "omega": 0}', "--user", "alice")
    assert bad.returncode == 2 and "Twist.v: expected a number, got str" in bad.stderr, bad.stderr
    extra = _pub(
        world, ep, "robot/arm1/cmd/joints", "-t", "JointTarget", "-d", '{"q": [0, 0], "speed": 1}', "--user", "alice"
    )
    assert extra.returncode == 2 and "JointTarget has no field 'speed'" in extra.stderr, extra.stderr
    for out in (nobody, wrong, body, missing, bad, extra):
        assert "Traceback" not in out.stderr and "__init__" not in out.stderr, out.stderr
