"""An instructor's actions (ownership.staff): through the state machine's rules, each one logged as an event.

Pure (the state machine) and real (an Authority on a router: the staff's key, the reply, the event, the reset
and stop the sim would apply)."""

from __future__ import annotations

import pytest
from hypothesis import given, strategies as hs

from fabric import keys
from fabric.codec import decode, encode
from fabric.interfaces import STAFF_OPS, Event, OwnershipRecord, OwnRequest, ServiceError
from robofabric.testing import wait_until

from ownership import Authority, OwnershipClient
from ownership import staff, state as st


def _world(*users: str, owner: str = "", queue: tuple[str, ...] = (), moving: bool = False) -> st.OwnState:
    s = st.initial({"arm": "exclusive", "ball": "scene"}, lease_s=2.0, grace_s=10.0)
    for i, u in enumerate(users):
        s, _ = st.step(s, st.Join(u, float(i)))
    if owner:
        s, _ = st.step(s, st.Request(owner, "arm", 5.0))
    if moving:
        s, _ = st.step(s, st.Motion("arm", True))
    for u in queue:
        s, _ = st.step(s, st.Request(u, "arm", 5.0, wait=True))
    return s


def _kinds(effects: list[st.Effect]) -> list[tuple[str, str]]:
    return [(e.kind, e.user) for e in effects]


def test_take_back_stops_the_owners_robot_and_hands_it_to_the_queue():
    s = _world("alice", "bob", owner="alice", queue=("bob",), moving=True)
    s2, eff = staff.step(s, staff.Staff("teacher", "arm", "take_back", 6.0))
    rec = s2.records["arm"]
    assert rec.owner == "bob" and rec.epoch == s.records["arm"].epoch + 1 and rec.queue == ()
    assert (
        ("stop", "alice") in _kinds(eff) and ("revoked", "alice") in _kinds(eff) and ("handover", "bob") in _kinds(eff)
    )
    done = [e for e in eff if e.kind == "done"]
    assert done and done[0].user == "teacher" and "taken back from alice by instructor teacher" in done[0].reason


def test_give_goes_to_a_live_user_only_and_a_lock_refuses_every_request_until_unlocked():
    s = _world("alice", "bob", owner="alice")
    _, eff = staff.step(s, staff.Staff("teacher", "arm", "give", 6.0, to="carol"))
    assert _kinds(eff) == [("denied", "teacher")] and "carol is not logged in" in eff[0].reason
    s, eff = staff.step(s, staff.Staff("teacher", "arm", "give", 6.0, to="bob"))
    assert s.records["arm"].owner == "bob" and ("stop", "alice") in _kinds(eff)
    s, eff = staff.step(s, staff.Staff("teacher", "arm", "lock", 7.0))
    assert s.records["arm"].owner == "" and s.records["arm"].locked == "teacher" and ("stop", "bob") in _kinds(eff)
    s, eff = st.step(s, st.Request("alice", "arm", 7.5))
    assert _kinds(eff) == [("denied", "alice")] and "locked by instructor teacher" in eff[0].reason
    s, eff = st.step(s, st.Request("alice", "arm", 7.6, wait=True))
    assert eff[0].kind == "denied"
    s, eff = staff.step(s, staff.Staff("teacher", "arm", "unlock", 8.0))
    assert s.records["arm"].locked == "" and eff[-1].kind == "done"
    s, eff = st.step(s, st.Request("alice", "arm", 8.5))
    assert eff[0].kind == "granted"


def test_a_locked_robot_is_restored_to_nobody():
    s = _world("alice", owner="alice")
    s, _ = st.step(s, st.Leave("alice", 6.0))  # she left: her robot is free, hers again if she is back in grace
    s, _ = staff.step(s, staff.Staff("teacher", "arm", "lock", 6.5))
    s, eff = st.step(s, st.Join("alice", 7.0))
    assert s.records["arm"].owner == "" and not [e for e in eff if e.kind == "restored" and e.object == "arm"]


def test_stop_and_reset_leave_the_owner_her_robot():
    s = _world("alice", owner="alice", moving=True)
    for op, kind in (("stop", "stop"), ("reset", "reset")):
        s2, eff = staff.step(s, staff.Staff("teacher", "arm", op, 6.0))
        assert s2.records == s.records and (kind, "alice") in _kinds(eff) and eff[-1].kind == "done"


def test_refusals_say_why():
    s = _world("alice")
    for ev, words in (
        (staff.Staff("t", "arm", "take_back", 1.0), "is free"),
        (staff.Staff("t", "ball", "lock", 1.0), "scene object"),
        (staff.Staff("t", "nope", "stop", 1.0), "unknown object"),
        (staff.Staff("t", "arm", "unlock", 1.0), "not locked"),
        (staff.Staff("t", "arm", "fly", 1.0), "not a staff action"),
    ):
        s2, eff = staff.step(s, ev)
        assert s2 is s and _kinds(eff) == [("denied", "t")] and words in eff[0].reason


@given(
    hs.lists(
        hs.tuples(
            hs.sampled_from(STAFF_OPS + ("request", "release", "leave", "join")),
            hs.sampled_from(("alice", "bob", "carol")),
        ),
        max_size=30,
    )
)
def test_any_mix_keeps_one_live_owner_at_most_and_nobody_owns_a_locked_robot(steps):
    s = _world("alice", "bob")
    now = 10.0
    for op, who in steps:
        now += 0.1
        if op == "request":
            ev = st.Request(who, "arm", now, wait=True)
        elif op == "release":
            ev = st.Release(who, "arm", now)
        elif op in ("leave", "join"):
            ev = st.Leave(who, now) if op == "leave" else st.Join(who, now)
        else:
            ev = staff.Staff("teacher", "arm", op, now, to=who)
        before = s.records["arm"]
        s, eff = staff.step(s, ev)
        rec = s.records["arm"]
        assert not (rec.locked and rec.owner), rec
        assert rec.epoch >= before.epoch and (rec.owner == before.owner or rec.epoch > before.epoch)
        assert not rec.owner or rec.owner in s.live
        if before.owner and rec.owner != before.owner:
            assert ("stop", before.owner) in _kinds(eff)


def test_the_records_new_field_keeps_the_old_wire_form():
    rec = OwnershipRecord("arm", owner="alice")
    assert decode(encode(rec), OwnershipRecord) == rec and len(encode(rec)) == len(
        encode(OwnershipRecord("arm", owner="alice"))
    )
    locked = OwnershipRecord("arm", locked="teacher")
    assert decode(encode(locked), OwnershipRecord).locked == "teacher"
    assert decode(encode(OwnRequest("give", "t", to="bob")), OwnRequest).to == "bob"


@pytest.mark.slow
def test_the_authority_serves_the_staff_key_and_logs_each_action(connect, world):
    """An instructor takes alice's arm back and gives it to bob: the authority stops it, bob's client renews what
    he was given, and each action is an own_staff event naming the instructor. A staff op on a user's key is refused."""
    sim = connect("sim", "host")
    auth = Authority(sim, {"arm": "exclusive"}, lease_s=1.0, grace_s=5.0).start()
    stops: list[tuple[str, str, str]] = []
    resets: list[tuple[str, str, str]] = []
    auth.watch_stops(lambda *a: stops.append(a))
    auth.watch_resets(lambda *a: resets.append(a))
    events: list[Event] = []
    watcher = connect("tool", "watcher")
    watcher.subscribe(keys.event_all(world), lambda key, ev: events.append(ev), expected=Event)
    alice = OwnershipClient(connect("user", "alice"), "alice", renew_s=0.2).start()
    bob = OwnershipClient(connect("user", "bob"), "bob", renew_s=0.2).start()
    teacher = OwnershipClient(connect("user", "teacher"), "teacher", renew_s=0.2).start()
    try:
        wait_until(
            lambda: {"alice", "bob", "teacher"} <= set(auth._state.live), timeout=30, what="the three logins live"
        )
        assert alice.request("arm").granted
        with pytest.raises(ServiceError, match="staff action"):
            alice.fabric.rpc.call(keys.own_request(world, "arm", "alice"), OwnRequest("take_back", "alice"))
        out = teacher.staff("arm", "take_back")
        assert out.outcome == "done" and auth.records()["arm"].owner == "" and ("arm", "alice") == stops[-1][:2]
        assert teacher.staff("arm", "take_back").outcome == "denied"
        assert teacher.staff("arm", "give", to="bob").outcome == "done"
        wait_until(lambda: bob.owns("arm"), timeout=10, what="bob's replica to name him owner")
        # bob never asked, yet his client renews what he was given: still his after several leases
        wait_until(
            lambda: auth.records()["arm"].epoch and bob.renewal.held() == ["arm"], timeout=10, what="bob renewing"
        )
        t0 = auth.clock.now()
        wait_until(lambda: auth.clock.now() - t0 > 3.0, timeout=30, what="three leases to pass")
        assert auth.records()["arm"].owner == "bob"
        assert teacher.staff("arm", "reset").outcome == "done" and resets[-1][:2] == ("arm", "bob")
        wait_until(lambda: sum(e.kind == "own_staff" for e in events) >= 3, timeout=10, what="three own_staff events")
        staff_events = [e for e in events if e.kind == "own_staff"]
        assert all(e.user == "teacher" for e in staff_events)
        assert any("given to bob by instructor teacher" in e.reason for e in staff_events)
    finally:
        for c in (alice, bob, teacher):
            c.close()
        auth.close()


@pytest.mark.slow
def test_the_instructors_stop_and_reset_reach_the_sims_robot_and_her_lock_refuses_the_owner(
    world, router, connect, procs
):
    """A real sim: alice moves arm1 away from zero; the instructor's stop holds it where it is, her reset takes it
    back to zero while alice keeps it, and her lock takes it from alice, whose next command is refused."""
    from fabric.interfaces import Command, JointState, JointTarget
    from robofabric.testing import robofabric_cmd

    import numpy as np

    ep = f"tcp/127.0.0.1:{router[1]}"
    sim = procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep), name="sim")
    fa = connect("user", "alice")
    wait_until(lambda: fa.live_peers("sim"), timeout=60, what="the sim peer", seen=lambda: procs.output(sim)[-2000:])
    joints: list[JointState] = []
    fa.subscribe(keys.robot_joints(world, "arm1"), lambda k, m: joints.append(m), expected=JointState)
    events: list[Event] = []
    fa.subscribe(keys.event_all(world), lambda k, e: events.append(e), expected=Event)
    alice = OwnershipClient(fa, "alice", renew_s=0.2, timeout=10.0).start()
    teacher = OwnershipClient(connect("user", "teacher"), "teacher", renew_s=0.2, timeout=10.0).start()
    try:
        wait_until(lambda: alice.record("arm1") is not None and joints, timeout=30, what="arm1's record and joints")
        assert alice.request("arm1").granted
        fa.publish(
            keys.robot_cmd(world, "arm1", "joints", "alice"),
            Command(
                "alice",
                alice.epoch("arm1"),
                JointTarget(np.radians([60.0, 30.0, -40.0, 30.0, 50.0, -30.0]), speed_scale=0.2),
            ),
        )
        wait_until(
            lambda: np.linalg.norm(joints[-1].q) > 0.2, timeout=30, what="arm1 on its way", seen=lambda: joints[-1].q
        )
        assert teacher.staff("arm1", "stop").outcome == "done"
        wait_until(
            lambda: np.max(np.abs(joints[-1].dq)) < 1e-3, timeout=30, what="arm1 held", seen=lambda: joints[-1].dq
        )
        held = np.asarray(joints[-1].q).copy()
        assert np.linalg.norm(held) > 0.2 and alice.owns("arm1")
        assert teacher.staff("arm1", "reset").outcome == "done"
        wait_until(
            lambda: np.linalg.norm(joints[-1].q) < 1e-3, timeout=60, what="arm1 back at zero", seen=lambda: joints[-1].q
        )
        assert alice.owns("arm1")
        out = teacher.staff("arm1", "lock")
        assert out.outcome == "done" and out.record.locked == "teacher" and out.record.owner == ""
        denied = alice.request("arm1")
        assert denied.outcome == "denied" and "locked by instructor teacher" in denied.reason
        fa.publish(
            keys.robot_cmd(world, "arm1", "joints", "alice"), Command("alice", alice.epoch("arm1"), JointTarget(held))
        )
        wait_until(
            lambda: any(e.kind == "reject" and e.user == "alice" and e.object == "arm1" for e in events),
            timeout=30,
            what="alice's command after the lock refused",
            seen=lambda: events[-5:],
        )
        assert any(
            e.kind == "own_staff" and "locked by instructor teacher (taken from alice)" in e.reason for e in events
        )
    finally:
        alice.close()
        teacher.close()
