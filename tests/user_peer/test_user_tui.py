"""The terminal UI under Textual's headless pilot, against a real world with a stand-in authority."""

import asyncio
import math
import threading

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import Header, JointState, OwnershipRecord, Pose, Scan
from robofabric.testing import client_config, wait_until
from user_peer.api import Arm, Base, World
from user_peer.services import RobotEntry
from user_peer.slider import JointSlider
from user_peer.tui import SPEEDS, UserApp

NAMES = tuple(f"joint_{i}" for i in range(1, 7))


async def until(pilot, predicate, what, timeout=10.0):
    """Let the app run until ``predicate()`` holds (the UI refreshes on timers)."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not predicate():
        if loop.time() > end:
            raise AssertionError(f"timed out waiting for {what}")
        await pilot.pause(0.05)


def publish_once_heard(fab, items, timeout=10.0) -> threading.Thread:
    """Publish each (key, message) once a subscriber of its key is known, as a live sim's stream reaches a handle
    within a period (a handle waits up to a second for its robot's first state: it was waited out, twice)."""

    def run():
        for key, msg in items:
            if fab.wait_matching(key, timeout):
                fab.publish(key, msg)

    thread = threading.Thread(target=run, name="first-states", daemon=True)
    thread.start()
    return thread


@pytest.fixture
def setup(world, router, connect):
    auth = connect("sim", "sim-test")
    # as the real authority, sim-test answers a replica that asks: a record that reached alice before its token was
    # refused as foreign, and her replica asks again once the token comes (tests/user_peer/test_user_api_local.py)
    records = {
        rec.object: rec
        for rec in (
            OwnershipRecord("arm1", owner="bob", epoch=1, queue=("carol",), authority="sim-test"),
            OwnershipRecord("base1", owner="", epoch=1, authority="sim-test"),
        )
    }
    for obj, rec in records.items():
        auth.rpc.serve(keys.own(world, obj), lambda key, req, rec=rec: rec)
    alice = World(client_config(world, router[1]), "alice", timeout=2.0)
    first = publish_once_heard(
        auth,
        [
            (keys.robot_joints(world, "arm1"), JointState(NAMES, np.full(6, 0.1), np.zeros(6), Header.now())),
            (keys.robot_pose(world, "base1"), Pose([1.0, 2.0, 0.0], header=Header.now())),
        ],
    )
    arm = Arm(alice, RobotEntry("arm1", "meca500", "arm", NAMES, (-1.0,) * 6, (1.0,) * 6))
    base = Base(alice, RobotEntry("base1", "reeman", "mobile", ("wheel_left", "wheel_right")))
    first.join(timeout=10.0)
    cmds = []
    auth.subscribe(keys.robot_cmd_all(world), lambda k, m: cmds.append((k, m)))
    h = Header(wall_ns=1)
    for obj, rec in records.items():
        auth.publish(keys.own(world, obj), rec)
    auth.publish(
        keys.robot_scan(world, "base1"),
        Scan.from_ranges(np.linspace(1, 4, 240), angle_min=-1.17, angle_increment=0.01, range_max=12, header=h),
    )
    wait_until(
        lambda: arm.record is not None and base.record is not None and base.scan is not None and arm.joints is not None,
        what="replicas",
    )
    yield auth, alice, arm, base, cmds
    alice.close()


@pytest.mark.slow
def test_controls_follow_ownership_and_send_commands(setup, world):
    asyncio.run(_drive_the_ui(*setup, world))


async def _drive_the_ui(auth, alice, arm, base, cmds, world):
    app = UserApp(alice, arm=arm, base=base)
    async with app.run_test(size=(120, 40)) as pilot:
        # the UI fills itself on timers: wait for it (a loaded CI machine may take a while) instead of a fixed pause
        await until(
            pilot, lambda: len(app.query(JointSlider)) == 6 and len(app.query("#arm-owner")) == 1, "the UI mounted"
        )
        sliders = list(app.query(JointSlider))
        assert all(s.disabled for s in sliders)
        await until(pilot, lambda: "carol" in str(app.query_one("#arm-owner").render()), "owner shown")
        owner_text = str(app.query_one("#arm-owner").render())
        assert "bob" in owner_text and "disabled" in owner_text
        await until(
            pilot,
            lambda: math.isclose(sliders[0].actual, 0.1) and len(app.query_one("#scan").data) == 240,
            "joints and scan shown",
        )

        # Arrow keys while not owning the base: refused locally, the reason on the status line, nothing sent.
        await pilot.press("up")
        await until(pilot, lambda: "does not own base1" in app.message, "the refusal on the status line")
        assert not cmds

        # The authority hands both robots to alice: controls come alive.
        auth.publish(keys.own(world, "arm1"), OwnershipRecord("arm1", owner="alice", epoch=2, authority="sim-test"))
        auth.publish(keys.own(world, "base1"), OwnershipRecord("base1", owner="alice", epoch=5, authority="sim-test"))
        await until(
            pilot, lambda: not sliders[0].disabled and not app.query_one("#base-stop").disabled, "controls enabled"
        )
        assert "you" in str(app.query_one("#arm-owner").render())

        sliders[1].focus()
        await pilot.press("plus", "plus", "plus")

        def joint_cmds() -> list:
            return [m for k, m in cmds if "/cmd/joints/by/alice" in k]

        # the last press's command: at load (the suite's make test) the first command came with two presses in it
        await until(
            pilot,
            lambda: joint_cmds() and math.isclose(joint_cmds()[-1].body.q[1], 0.1 + math.radians(3.0), abs_tol=1e-9),
            "the joint command of all three presses",
        )
        last = joint_cmds()[-1]
        assert last.user == "alice" and last.epoch == 2
        # Targets started from the robot's joints (0.1 rad): one slider moved, the others held.
        assert math.isclose(last.body.q[1], 0.1 + math.radians(3.0), abs_tol=1e-9)
        assert np.allclose(np.delete(last.body.q, 1), 0.1)

        # ←/→ move the focused slider, never the base: three Right presses, three degrees, no twist
        await pilot.press("right", "right", "right")
        await until(
            pilot,
            lambda: math.isclose(sliders[1].value, 0.1 + math.radians(6.0), abs_tol=1e-9),
            "the slider moved with right",
        )
        await until(
            pilot,
            lambda: math.isclose(
                [m for k, m in cmds if "/cmd/joints/by/alice" in k][-1].body.q[1], 0.1 + math.radians(6.0), abs_tol=1e-9
            ),
            "its joint target sent",
        )
        assert not any("/cmd/twist/by/alice" in k for k, _ in cmds)
        # the arm speed setting: ']' is already at full speed, '[' twice is 25 %, and the next target carries it
        await pilot.press("left_square_bracket", "left_square_bracket", "left")
        await until(
            pilot,
            lambda: math.isclose([m for k, m in cmds if "/cmd/joints/by/alice" in k][-1].body.speed_scale, 0.25),
            "a target at 25 % speed",
        )
        assert app.arm_speed == 0.25 and "25%" in str(app.query_one("#arm-speed").render())

        await pilot.press("escape", "3", "up", "left")  # escape leaves the slider: the arrows drive the base again
        await until(
            pilot, lambda: any("/cmd/twist/by/alice" in k and m.body.omega > 0 for k, m in cmds), "twist command"
        )
        tw = [m for k, m in cmds if "/cmd/twist/by/alice" in k][-1]
        assert tw.epoch == 5 and (tw.body.v, tw.body.omega) == SPEEDS[3]
        await pilot.press("space")
        await until(pilot, lambda: [m for k, m in cmds if "/cmd/twist/by/alice" in k][-1].body.v == 0.0, "stop twist")

        await pilot.click("#arm-stop")
        await until(pilot, lambda: any("/cmd/stop/by/alice" in k for k, _ in cmds), "stop command")
        await pilot.click("#arm-reset")
        await until(pilot, lambda: any("/cmd/reset/by/alice" in k for k, _ in cmds), "reset command")
        assert all(s.value == 0.0 for s in sliders)


def test_status_says_when_the_world_is_gone(setup, world):
    """The sim peer (here the test's "sim" session) leaves: the status line says the world is gone."""
    asyncio.run(_world_gone(*setup))


async def _world_gone(auth, alice, arm, base, cmds):
    app = UserApp(alice, arm=arm, base=base)
    async with app.run_test(size=(120, 40)) as pilot:
        await until(pilot, lambda: len(app.query("#status")) == 1, "the UI mounted")
        assert "WORLD GONE" not in str(app.query_one("#status").render())
        auth.close()
        await until(pilot, lambda: "WORLD GONE" in str(app.query_one("#status").render()), "world gone shown")


def test_an_event_its_authority_did_not_send_is_marked_display_only():
    """A 'reject' any login may write (event/decode/by/*) is shown, but as its writer's say-so."""
    from fabric.interfaces import Event
    from user_peer.tui import event_line

    ev = Event(kind="reject", object="arm1", user="alice", reason="arm1 is owned by mallory, not alice")
    assert event_line(ev, True) == "event reject arm1 [alice]: arm1 is owned by mallory, not alice"
    assert (
        event_line(ev, False)
        == "unverified, display only · event reject arm1 [alice]: arm1 is owned by mallory, not alice"
    )
    # a kind that holds a newline and a trusted line after it stays on the unverified line, escaped
    forged = Event(kind="decode_error\nevent reject arm1 [alice]", reason="\x1b[2J" + "\n" * 2000)
    line = event_line(forged, False)
    assert line.startswith("unverified") and line.isprintable() and len(line) < 400, line
    assert "decode_error\\nevent reject arm1" in line


def test_names_and_events_from_the_network_are_shown_as_text_and_garbage_is_skipped(setup, world, connect):
    """An owner named like markup, an event whose reason is markup with an escape sequence, garbage on an
    ownership key and a token that names no peer: the UI shows the text as it is, skips the garbage, keeps running."""
    asyncio.run(_hostile(*setup, world, connect))


async def _hostile(auth, alice, arm, base, cmds, world, connect):
    from fabric.interfaces import Event

    mallory = connect("tool", "mallory")
    app = UserApp(alice, arm=arm, base=base)
    async with app.run_test(size=(160, 40)) as pilot:
        await until(pilot, lambda: len(app.query("#arm-owner")) == 1, "the UI mounted")
        token = mallory.session.liveliness().declare_token(f"rf/{world}/peer/sim/with space")
        mallory.session.put(keys.own(world, "arm1"), b"\x00not msgpack")
        mallory.session.put(keys.own(world, "base1"), b"\x93\xa1x")
        auth.publish(
            keys.own(world, "arm1"),
            OwnershipRecord("arm1", owner="[/x]", epoch=2, queue=("[bold]q",), authority="sim-test"),
        )
        await until(
            pilot, lambda: "[/x]" in str(app.query_one("#arm-owner").render()), "the markup-like owner shown as text"
        )
        assert "[bold]q" in str(app.query_one("#arm-owner").render())
        await until(pilot, lambda: alice.fabric.counters["decode_errors"] >= 2, "the garbage counted and skipped")
        # alice's own report of the garbage reaches the status line first, then mallory's event replaces it
        await until(
            pilot, lambda: "decode_error" in str(app.query_one("#status").render()), "alice's decode report shown"
        )
        mallory.publish(
            keys.event_decode(world, "mallory"),
            Event(kind="decode_error", reason="[/oops] \x1b[2J gone", header=Header.now()),
        )
        await until(pilot, lambda: "[/oops]" in str(app.query_one("#status").render()), "the event shown as text")
        status = str(app.query_one("#status").render())
        assert "\x1b" not in status and "\\x1b[2J" in status and "unverified" in status
        assert app.is_running
        token.undeclare()


@pytest.mark.slow
def test_queue_for_an_owned_robot_shows_the_place_then_owns_it(live):
    """ "Queue for it" on a robot someone else moves, against a real sim: the place is shown, and the
    controls come alive when bob lets go (a still robot would be taken over at once instead)."""
    world, port, _ = live
    with (
        World(client_config(world, port), "bob", timeout=10.0) as bob,
        World(client_config(world, port), "alice", timeout=10.0) as alice,
    ):
        arm = bob.robot("arm1")
        arm.request()
        start = arm.wait_for("joints").q
        arm.move_joints(np.where(np.asarray(start) > 0, -1.0, 1.0), wait=False, speed_scale=0.02)  # a slow, long move
        wait_until(lambda: arm.record.state == "moving", timeout=10, what="bob's arm moving")
        asyncio.run(_queue(alice, bob))


async def _queue(alice, bob):
    arm = alice.robot("arm1")
    app = UserApp(alice, arm=arm)
    async with app.run_test(size=(120, 40)) as pilot:
        await until(
            pilot,
            lambda: len(app.query("#arm-queue")) == 1 and not app.query_one("#arm-queue").disabled,
            "Queue enabled",
        )
        assert app.query_one("#arm-request").disabled is False and all(s.disabled for s in app.query(JointSlider))
        await pilot.click("#arm-queue")
        await until(
            pilot,
            lambda: "you are #1 in the queue" in str(app.query_one("#arm-owner").render()),
            "the queue place shown",
            timeout=15,
        )
        assert app.message == "queue for arm1: place 1" and app.query_one("#arm-queue").disabled
        await asyncio.get_running_loop().run_in_executor(None, bob.robot("arm1").release)
        await until(
            pilot, lambda: not app.query(JointSlider).first().disabled, "alice owns arm1: controls enabled", timeout=15
        )
        assert "owner: you" in str(app.query_one("#arm-owner").render())


PANDA = tuple(f"panda_joint{i}" for i in range(1, 8))
PANDA_LO = (-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973)
PANDA_HI = (2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973)


@pytest.mark.slow
def test_a_seven_joint_arm_gets_seven_sliders_in_its_limits_and_its_owner_moves_one(world, router, connect):
    """An arm from a URDF (the Panda's names and limits, as `robots add` writes them): one slider per joint,
    each within its range (J4's excludes 0), and a moved slider sends all seven joints."""
    auth = connect("sim", "sim-test")
    alice = World(client_config(world, router[1]), "alice", timeout=2.0)
    try:
        arm = Arm(alice, RobotEntry("p1", "panda", "arm", PANDA, PANDA_LO, PANDA_HI))
        cmds = []
        auth.subscribe(keys.robot_cmd_all(world), lambda k, m: cmds.append(m))
        q = np.array([0.1, 0.2, 0.0, -1.5, 0.0, 1.6, 0.3])
        auth.publish(keys.own(world, "p1"), OwnershipRecord("p1", owner="alice", epoch=3, authority="sim-test"))
        auth.publish(keys.robot_joints(world, "p1"), JointState(PANDA, q, np.zeros(7), Header.now()))
        wait_until(lambda: arm.record is not None and arm.joints is not None, what="replicas")
        asyncio.run(_move_a_panda_slider(UserApp(alice, arm=arm), q, cmds))
    finally:
        alice.close()


async def _move_a_panda_slider(app, q, cmds):
    async with app.run_test(size=(120, 50)) as pilot:
        await until(pilot, lambda: len(app.query(JointSlider)) == 7, "seven sliders")
        sliders = list(app.query(JointSlider))
        assert [s.joint for s in sliders] == list(PANDA)
        assert [(s.lo, s.hi) for s in sliders] == list(zip(PANDA_LO, PANDA_HI))
        assert all(s.lo <= s.value <= s.hi for s in sliders)
        await until(
            pilot, lambda: not sliders[0].disabled and math.isclose(sliders[3].value, -1.5), "synced to the joints"
        )
        sliders[6].focus()
        await pilot.press("right")
        await until(pilot, lambda: bool(cmds), "a joint command sent")
        sent = cmds[-1].body.q
        assert len(sent) == 7 and math.isclose(sent[6], 0.3 + math.radians(1.0), abs_tol=1e-9)
        np.testing.assert_allclose(sent[:6], q[:6])


def test_the_tui_shows_the_first_arm_and_base_or_the_named_ones_of_their_kind():
    """``robofabric user`` picks its robots by their kinds' facts; a named robot of another kind is refused by name."""
    from fabric.cli_common import UserError
    from user_peer.cli import tui_robots

    kinds = {"base1": "mobile", "arm1": "arm", "odd": "", "arm2": "arm", "base2": "mobile"}
    assert tui_robots(kinds, None, None, "w") == ("arm1", "base1")
    assert tui_robots(kinds, "arm2", "base2", "w") == ("arm2", "base2")
    assert tui_robots({"base1": "mobile"}, None, None, "w") == (None, "base1")
    for arm, base, words in (
        ("base1", None, "'base1' is not an arm robot in world 'w'"),
        (None, "arm1", "'arm1' is not a mobile robot in world 'w'"),
        ("odd", None, "'odd' is not an arm robot"),
        (None, "nope", "'nope' is not a mobile robot"),
    ):
        with pytest.raises(UserError, match=words) as e:
            tui_robots(kinds, arm, base, "w")
        assert "robots: base1, arm1, odd, arm2, base2" in str(e.value)
