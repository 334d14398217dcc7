"""The kinematics services over real Zenoh: IK/FK/Jacobian queries, refusals, peer choice and IK streaming."""

from __future__ import annotations

import math
import subprocess

import msgpack
import numpy as np
import pytest

from compute_peer.kinematics.service import ArmPlacement, KinematicsService
from fabric.interfaces import Event, FKRequest, IKReply, IKRequest, IKStream, JacobianRequest, JointState, Pose
from fabric import keys
from fabric.codec import encode
from fabric.interfaces import NoReply, ServiceError
from robofabric.testing import robofabric_cmd, wait_until

BASE = (3.0, 0.5, 0.75, math.radians(30.0))  # an arm on a table, turned: exercises the world <-> base frames
Q = np.array([0.3, 0.2, -0.4, 0.5, 0.6, -0.2])


@pytest.fixture
def served(world, connect):
    comp = connect("compute", "c1")
    with KinematicsService(
        comp, arms={"arm1": ArmPlacement("meca500", BASE)}, streams=[("arm1", "target")], discover=False
    ) as svc:
        user = connect("user", "alice")
        # comp's queryables reach the router a moment after they are declared; a user that connects in that moment
        # is told nobody serves them (a whole run, load 20): the services are asked until they answer
        wait_until(lambda: _fk_served(user, keys.srv(world, "fk", "arm1")), timeout=10, what="the fk service served")
        yield svc, comp, user


def _fk_served(user, key: str) -> bool:
    try:
        user.rpc.call(key, FKRequest(Q), timeout=1.0)
    except NoReply:
        return False
    return True


def test_fk_ik_round_trip_in_world_and_base_frames(served, world):
    _, _, user = served
    fk_w = user.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(Q))
    fk_b = user.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(Q, frame="base"))
    c, s = math.cos(BASE[3]), math.sin(BASE[3])
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    assert np.allclose(fk_w.position, rot @ fk_b.position + np.array(BASE[:3]), atol=1e-12)

    rep = user.rpc.call(keys.srv(world, "ik", "arm1"), IKRequest.make(fk_w.position, fk_w.quaternion, Q))
    assert isinstance(rep, IKReply) and rep.solver == "closed_form" and rep.candidates >= 1
    assert np.allclose(rep.q, Q, atol=1e-9)  # seeded with Q, the nearest solution is Q itself
    back = user.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(rep.q))
    assert np.linalg.norm(back.position - fk_w.position) <= 1e-9

    # position only: any orientation will do, the flange must still land on the point
    pos = user.rpc.call(keys.srv(world, "ik", "arm1"), IKRequest.make(fk_w.position))
    reached = user.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(pos.q)).position
    assert np.linalg.norm(reached - fk_w.position) <= 1e-6


def test_jacobian_twist_and_speeds(served, world):
    svc, _, user = served
    dq = np.array([0.1, -0.2, 0.3, 0.0, 0.5, -0.1])
    rep = user.rpc.call(keys.srv(world, "jacobian", "arm1"), JacobianRequest(Q, dq))
    assert rep.jacobian.shape == (6, 6)
    assert np.allclose(rep.twist, rep.jacobian @ dq)
    assert np.allclose(rep.speeds, np.linalg.norm(rep.jacobian, axis=0) * np.abs(dq))
    # the linear rows are the flange velocity: compare with a finite difference of the FK service's answer
    h = 1e-6
    p1 = user.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(Q + h * dq)).position
    p0 = user.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(Q - h * dq)).position
    assert np.allclose((p1 - p0) / (2 * h), rep.twist[:3], atol=1e-6)
    assert svc.counters["jacobian"] == 1


def _answers(fab, key, request) -> bool:
    """Whether ``key`` is served yet (a queryable declared on another session reaches the router a moment later)."""
    try:
        fab.rpc.call(key, request, timeout=1.0)
        return True
    except ServiceError:
        return False


def _refusal(user, key, payload) -> str:
    with pytest.raises(ServiceError) as err:
        if isinstance(payload, bytes):
            replies = list(user.session.get(key, payload=payload, timeout=5.0))
            assert replies and replies[0].err is not None, "a garbage query must get an error reply"
            raise ServiceError(replies[0].err.payload.to_bytes().decode("utf-8", "replace"))
        user.rpc.call(key, payload, timeout=5.0)
    return str(err.value)


def test_bad_requests_get_reasons_not_timeouts(served, world):
    svc, comp, user = served
    ik = keys.srv(world, "ik", "arm1")
    assert "unknown arm 'arm9'" in _refusal(user, keys.srv(world, "ik", "arm9"), IKRequest.make([3.0, 0.5, 1.0]))
    assert "out of reach" in _refusal(user, ik, IKRequest.make([9.0, 0.5, 1.0]))
    assert "finite" in _refusal(user, ik, IKRequest.make([float("nan"), 0.5, 1.0]))
    assert "6" in _refusal(user, ik, IKRequest.make([3.1, 0.5, 1.0], None, [0.0, 0.0]))
    assert "6" in _refusal(user, keys.srv(world, "fk", "arm1"), FKRequest(np.zeros(3)))
    assert "IKRequest" in _refusal(user, ik, encode(FKRequest(Q)))
    assert _refusal(user, ik, msgpack.packb(["IKRequest", [1, 2]]))
    assert _refusal(user, ik, b"\xc1garbage")
    # refusals of well-formed requests are the service's; undecodable payloads are counted by the session
    assert svc.counters["refusals"] == 4 and comp.counters["query_errors"] == 8
    # and the service still answers good requests
    fk = user.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(Q))
    assert user.rpc.call(ik, IKRequest.make(fk.position, fk.quaternion, Q)).solver == "closed_form"


def test_a_chosen_peer_answers_on_its_own_key(world, connect):
    svcs = [
        KinematicsService(connect("compute", pid), arms={"arm1": ArmPlacement("meca500", BASE)}, discover=False)
        for pid in ("c1", "c2")
    ]
    user = connect("user", "bob")
    try:
        wait_until(
            lambda: all(_answers(user, keys.srv(world, "fk", "arm1", pid), FKRequest(Q)) for pid in ("c1", "c2")),
            what="both peers",
        )
        fk = user.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(Q))
        everyone = user.rpc.query(
            keys.srv(world, "ik", "arm1"), IKRequest.make(fk.position, fk.quaternion, Q), all_replies=True, timeout=5.0
        )
        assert sorted(r.source for r in everyone) == ["c1", "c2"]
        for pid in ("c1", "c2"):
            rep = user.rpc.call(keys.srv(world, "ik", "arm1", pid), IKRequest.make(fk.position, fk.quaternion, Q))
            assert rep.header.source == pid
    finally:
        for s in svcs:
            s.close()


def test_ik_streaming_follows_the_target(served, world):
    svc, _, user = served
    got: list[IKStream] = []
    events: list[Event] = []
    user.subscribe(keys.robot_stream(world, "arm1", "ik"), lambda k, m: got.append(m))
    user.subscribe(keys.event_all(world), lambda k, m: events.append(m), expected=Event)
    q_now = np.array([0.1, 0.1, -0.2, 0.0, 0.3, 0.0])
    user.publish(
        keys.robot_joints(world, "arm1"), JointState(tuple(f"joint_{i}" for i in range(1, 7)), q_now, np.zeros(6))
    )
    wait_until(lambda: "arm1" in svc.joints, what="joints seen by the service")
    goal = user.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(Q)).position
    user.publish(keys.object_pose(world, "target", "alice"), Pose(goal))
    wait_until(lambda: any(np.allclose(m.position, goal) for m in got), what="a streamed solution", seen=lambda: got)
    sol = [m for m in got if np.allclose(m.position, goal)][-1]
    assert sol.ok and sol.robot == "arm1" and sol.target == "target"
    reached = user.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(sol.q)).position
    assert np.linalg.norm(reached - goal) <= 1e-6
    # a synchronised move at the speed limits: the slowest joint takes `seconds`, none is faster than its limit
    limits = np.radians([150, 150, 180, 300, 300, 500])
    assert np.allclose(sol.dq * sol.seconds, sol.q - q_now, atol=1e-9)
    assert np.all(np.abs(sol.dq) <= limits + 1e-9) and np.isclose(np.max(np.abs(sol.dq) / limits), 1.0)
    n_before = len(got)

    far = np.array([9.0, 9.0, 9.0])
    user.publish(keys.object_pose(world, "target", "alice"), Pose(far))
    wait_until(lambda: any(np.allclose(m.position, far) for m in got[n_before:]), what="a refusal on the stream")
    bad = [m for m in got if np.allclose(m.position, far)][-1]
    assert not bad.ok and "reach" in bad.reason and bad.q.size == 0
    wait_until(lambda: any(e.kind == "ik_unreachable" for e in events), what="an ik_unreachable event")


@pytest.mark.slow
def test_compute_cli_refuses_bad_flags():
    for args in (["--stream", "arm1"], ["--stream-rate", "0"], ["--no-kinematics", "--no-navigation"]):
        r = subprocess.run(robofabric_cmd("compute", *args), capture_output=True, text=True, timeout=60)
        assert r.returncode == 2, (args, r.stdout, r.stderr)
        assert "Traceback" not in r.stderr


@pytest.mark.slow
def test_compute_cli_arm_flag_names_bad_arms():
    for spec, words in (
        ("arm1", "ID:TYPE"),
        ("arm1:reeman", "not an arm"),
        ("arm1:meca500@1,2", "3 or 4"),
        ("arm1:nope", "unknown robot type"),
    ):
        r = subprocess.run(robofabric_cmd("compute", "--arm", spec), capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and words in r.stderr, (spec, r.stderr)


def test_a_user_can_pick_a_compute_peer(world, router, connect):
    from robofabric.testing import client_config
    from user_peer import services
    from user_peer.api import World

    svcs = {
        pid: KinematicsService(connect("compute", pid), arms={"arm1": ArmPlacement("meca500", BASE)}, discover=False)
        for pid in ("c1", "c2")
    }
    try:
        with World(client_config(world, router[1]), "carol", compute="c2") as w:
            wait_until(
                lambda: w.compute_peers() == ["c1", "c2"], what="both compute peers' tokens", seen=w.compute_peers
            )
            wait_until(lambda: _answers(w.fabric, keys.srv(world, "fk", "arm1", "c2"), FKRequest(Q)), what="c2 serving")
            fk = w.fabric.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(Q))
            for _ in range(3):
                q = services.ik(w.fabric, "arm1", fk.position, fk.quaternion, Q, peer=w.compute)
                assert np.allclose(q, Q, atol=1e-9)
        assert svcs["c2"].counters["ik"] == 3 and svcs["c1"].counters["ik"] == 0
    finally:
        for s in svcs.values():
            s.close()


def test_navigation_answers_on_its_own_key_too(world, connect):
    from fabric.interfaces import MapReply, MapRequest
    from compute_peer.navigation.service import NavigationService

    navs = [NavigationService(connect("compute", pid), discover=False) for pid in ("n1", "n2")]
    user = connect("user", "dave")
    try:
        wait_until(
            lambda: all(
                _answers(user, keys.srv(world, "map", "map", pid), MapRequest("status")) for pid in ("n1", "n2")
            ),
            what="both peers",
        )
        for pid in ("n1", "n2"):
            rep = user.rpc.call(keys.srv(world, "map", "map", pid), MapRequest("status"), timeout=5.0)
            assert isinstance(rep, MapReply) and rep.header.source == pid
        everyone = user.rpc.query(keys.srv(world, "map", "map"), MapRequest("status"), all_replies=True, timeout=5.0)
        assert sorted(r.message.header.source for r in everyone) == ["n1", "n2"]
    finally:
        for n in navs:
            n.close()


def test_a_user_can_spread_ik_over_every_compute_peer(world, router, connect):
    from robofabric.testing import client_config
    from user_peer import services
    from user_peer.api import World

    svcs = {
        pid: KinematicsService(connect("compute", pid), arms={"arm1": ArmPlacement("meca500", BASE)}, discover=False)
        for pid in ("c1", "c2")
    }
    try:
        with World(client_config(world, router[1]), "erin", compute="spread") as w:
            wait_until(
                lambda: w.compute_peers() == ["c1", "c2"], what="both compute peers' tokens", seen=w.compute_peers
            )
            wait_until(
                lambda: all(_answers(w.fabric, keys.srv(world, "fk", "arm1", p), FKRequest(Q)) for p in ("c1", "c2")),
                what="both serving",
            )
            fk = w.fabric.rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(Q))
            for _ in range(4):
                q = w.compute_route.ask(
                    lambda peer: services.ik(w.fabric, "arm1", fk.position, fk.quaternion, Q, peer=peer)
                )
                assert np.allclose(q, Q, atol=1e-9)

            # an ask whose answer a lost link swallowed is asked again (fabric/rpc.py): at load the test's in-process
            # router starved past the lease and every client lost its link once, and c1 served one IK twice. Every rule
            # of asking again counts: in a fast suite (make test-fast, 1 run in 8) c1 served 3 and c2 2 with neither of
            # those two rules counted; which one asked again is not known (the session's counters are in the message)
            def again() -> int:
                c = w.fabric.counters
                return (
                    sum(c[f"queries_after_{k}"] for k in ("relink", "server_went", "server_left", "open"))
                    + c["queries_renewed"]
                )

            def counts() -> tuple[int, int]:
                return svcs["c1"].counters["ik"], svcs["c2"].counters["ik"]

            # a peer that did not answer in time is skipped, the nearest asked instead, and left out until the list is
            # read again (2 s; run 3 of 2026-12-04 at load: c1 served all four, why c2 did not answer is in skipped)
            skipped = list(w.compute_route.skipped)
            if not skipped:
                assert 2 <= counts()[0] <= 2 + again() and 2 <= counts()[1] <= 2 + again(), (
                    counts(),
                    {k: v for k, v in w.fabric.counters.items() if k.startswith("quer")},  # how many, asked again how
                )
            else:  # every ask answered all the same, by one peer or the other
                assert all(why.startswith("no reply") for _, why in skipped), skipped
                assert 4 <= sum(counts()) <= 4 + len(skipped) + again(), (counts(), skipped)
            c1_before = counts()[0]
            assert w.compute_route.navigation_peer() is None  # maps are not spread: the nearest peer holds one
            svcs.pop("c2").close()  # c2 stops serving; its token stays with its session until the list is read again
            for _ in range(2):
                q = w.compute_route.ask(
                    lambda peer: services.ik(w.fabric, "arm1", fk.position, fk.quaternion, Q, peer=peer)
                )
                assert np.allclose(q, Q, atol=1e-9)
            assert c1_before + 2 <= svcs["c1"].counters["ik"] <= c1_before + 2 + again()
    finally:
        for s in svcs.values():
            s.close()


@pytest.mark.slow
def test_robofabric_call_asks_a_service_from_the_command_line(served, world, router):
    import json

    ep = f"tcp/127.0.0.1:{router[1]}"

    def call(*args):
        return subprocess.run(
            robofabric_cmd("call", *args, "--world", world, "--connect", ep), capture_output=True, text=True, timeout=60
        )

    out = call("srv/fk/arm1", "-t", "FKRequest", "-d", '{"q": [0, 0, 0, 0, 0, 0], "frame": "base"}', "--json")
    assert out.returncode == 0, out.stdout + out.stderr
    reply = json.loads(out.stdout.splitlines()[0])
    assert reply["source"] == "c1" and reply["message"]["type"] == "FKReply"
    assert np.allclose(reply["message"]["position"], [0.190, 0.0, 0.308], atol=1e-9)  # the Meca500's zero pose

    out = call("srv/ik/arm1", "-t", "IKRequest", "-d", '{"position": [9, 9, 9]}')
    assert out.returncode == 1 and "out of reach" in out.stderr, out.stdout + out.stderr  # a refusal says why

    out = call("srv/ik/arm1", "-t", "NoSuchRequest")
    assert out.returncode == 2 and "unknown message type" in out.stderr, out.stdout + out.stderr
    out = call("srv/ik/arm1", "-t", "IKRequest", "-d", '{"position": [1, 2]}')
    # bad data names the field and what was wrong with it, in words
    assert out.returncode == 2 and "IKRequest.position: expected shape (3,)" in out.stderr, out.stdout + out.stderr


def _one_arm_world(world: str):
    from fabric.interfaces import RobotInfo, WorldInfo

    six = np.zeros(6)
    arm = RobotInfo(
        "arm1", "meca500", "arm", np.array(BASE), tuple(f"j{i}" for i in range(6)), six - 3, six + 3, six + 1
    )
    return WorldInfo(world, "test", 0.002, {}, (arm,))


def test_an_arm_asked_for_before_its_joints_arrive_is_looked_up_not_refused(world, connect):
    """A sim that comes after the compute peer, and a request before any joints: the request waits for
    the world's description instead of failing with "serves no arms yet" (a lab run failed that way)."""
    svc = KinematicsService(connect("compute"), discover=True).start()
    try:
        sim = connect("sim")
        info = _one_arm_world(world)
        sim.rpc.serve(keys.srv(world, "world"), lambda key, req: info)
        user = connect("user")
        wait_until(lambda: user.rpc.call(keys.srv(world, "world"), timeout=1.0), timeout=10.0, what="the world served")
        target = np.array(BASE[:3]) + np.array([0.19, 0.0, 0.31])
        reply = user.rpc.call(keys.srv(world, "ik", "arm1"), IKRequest(target), timeout=10.0, expected=IKReply)
        assert reply.robot == "arm1" and svc.arms == ["arm1"], svc.counters
    finally:
        svc.close()


@pytest.mark.slow  # seconds: a sim that answers in 2.5 s, asked twice
def test_a_world_too_slow_to_answer_is_asked_again_with_longer_to_answer(world, connect):
    """A sim that answers ``srv/world`` in 2.5 s, past a lookup's 2 s, and nothing else that would set a lookup off
    (its token came before the service started, no request, no stream): the arm is learnt all the same, from a retry
    that waits longer (a compute peer beside two starved sims knew no arm 90 s on, in a whole `make test`)."""
    import time

    info = _one_arm_world(world)
    asked: list[float] = []

    def slow(key: str, req: object) -> object:
        asked.append(time.monotonic())
        time.sleep(2.5)
        return info

    sim = connect("sim")
    sim.rpc.serve(keys.srv(world, "world"), slow)
    svc = KinematicsService(connect("compute"), discover=True)
    try:
        wait_until(lambda: ("sim", sim.peer_id) in svc.fabric.live_peers("sim"), what="the sim's token")
        svc.start()
        wait_until(lambda: svc.arms == ["arm1"], timeout=20, what="arm1 learnt", seen=lambda: (svc.counters, asked))
        assert svc.counters.get("discovery_failed", 0) >= 1 and len(asked) >= 2, (svc.counters, asked)
    finally:
        svc.close()


def _threads(prefix: str) -> list[str]:
    import threading

    return [t.name for t in threading.enumerate() if t.name.startswith(prefix)]


def test_the_service_starts_its_threads_on_start_not_on_construction(world, connect):
    """Declared on construction (it answers at once); streaming and background lookups only once started."""
    sim = connect("sim")  # a sim's token (no srv/world): seen while declaring, it would set a lookup off
    streams = len(_threads("rate-ik-stream"))
    svc = KinematicsService(
        connect("compute", "c9"), arms={"arm1": ArmPlacement("meca500", BASE)}, streams=[("arm1", "target")]
    )
    try:
        wait_until(lambda: ("sim", sim.peer_id) in svc.fabric.live_peers("sim"), what="the sim's token")
        assert len(_threads("rate-ik-stream")) == streams
        # a lookup thread lives until its lookup has failed and been counted: neither means none ran
        assert not _threads("kinematics-discovery") and "discovery_failed" not in svc.counters, svc.counters
        assert connect("user").rpc.call(keys.srv(world, "fk", "arm1"), FKRequest(Q)).position.shape == (
            3,
        )  # serving already
        with svc as same:
            assert same is svc and len(_threads("rate-ik-stream")) == streams + 1
            wait_until(lambda: svc.counters.get("discovery_failed", 0) >= 1, what="the first lookup, in the background")
            svc.start()  # once
            assert len(_threads("rate-ik-stream")) == streams + 1
        wait_until(lambda: len(_threads("rate-ik-stream")) == streams, what="the stream loop stopped on close")
    finally:
        svc.close()
