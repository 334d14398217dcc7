"""The soak's planted defects (fabric/plant.py) are parameters, never the environment: the pure state machine
plants ``double-owner`` only when its state says so, the authority admits a stale command only when it was
built with ``stale-command``, and ``ROBOFABRIC_PLANT`` in the environment changes nothing."""

from __future__ import annotations

import importlib

import pytest

import fabric.plant
from fabric import keys
from fabric.interfaces import Command, NoReply, OwnReply, OwnRequest, Stop
from ownership import Authority
from ownership import state as st
from robofabric.testing import wait_until


def _still_take_over(s: st.OwnState) -> tuple[int, int]:
    """a owns the arm, it stands still, b takes it: (a's epoch, b's epoch)."""
    s, _ = st.step(s, st.Request("a", "arm", 0.0))
    before = s.records["arm"].epoch
    s, _ = st.step(s, st.Join("b", 0.2))
    s, eff = st.step(s, st.Request("b", "arm", 0.5))
    assert s.records["arm"].owner == "b" and [e.kind for e in eff][:2] == ["granted", "revoked"]
    return before, s.records["arm"].epoch


def test_a_still_take_over_bumps_the_epoch_unless_double_owner_is_planted():
    before, after = _still_take_over(st.initial({"arm": "exclusive"}))
    assert after == before + 1
    before, after = _still_take_over(st.initial({"arm": "exclusive"}, plant="double-owner"))
    assert after == before  # the defect: two owners hold one epoch


def test_the_state_machine_ignores_the_environment(monkeypatch):
    """With ``ROBOFABRIC_PLANT=double-owner`` set before the defects' module loads, a state built without a plant
    still bumps the epoch at a take-over: the pure core reads no environment variable."""
    monkeypatch.setenv("ROBOFABRIC_PLANT", "double-owner")
    try:
        importlib.reload(fabric.plant)
        before, after = _still_take_over(st.initial({"arm": "exclusive"}))
        assert after == before + 1
    finally:
        monkeypatch.delenv("ROBOFABRIC_PLANT")
        importlib.reload(fabric.plant)


def test_an_unknown_defect_is_refused_with_the_known_ones():
    assert fabric.plant.check("") == "" and fabric.plant.check("reset") == "reset"
    with pytest.raises(ValueError, match="reset, double-owner, stale-command"):
        fabric.plant.check("everything")


@pytest.mark.parametrize(("plant", "admitted"), [("", False), ("stale-command", True)])
def test_the_authority_admits_a_stale_command_only_when_built_with_that_defect(connect, world, plant, admitted):
    auth = Authority(connect("sim", "host"), {"arm": "exclusive"}, plant=plant).start()
    alice = connect("user", "alice")
    try:

        def ask() -> OwnReply | None:  # the authority's queryable reaches the router in its own time
            try:
                return alice.rpc.call(keys.own_request(world, "arm", "alice"), OwnRequest("request", "alice"), expected=OwnReply)
            except NoReply:
                return None

        reply = wait_until(ask, timeout=20, what="the authority's answer")
        assert reply.outcome == "granted"
        epoch = reply.record.epoch
        assert auth.admit("arm", Command("alice", epoch, Stop())) is None
        reason = auth.admit("arm", Command("alice", epoch + 7, Stop()))
        if admitted:
            assert reason is None
        else:
            assert reason is not None and "stale epoch" in reason, reason
    finally:
        auth.close()
