"""The soak's planted defects (fabric/plant.py) are parameters, never the environment: the pure state machine
plants ``double-owner`` only when its state says so, the authority admits a stale command only when it was
built with ``stale-command``, and ``ROBOFABRIC_PLANT`` in the environment changes nothing."""

from __future__ import annotations

import ast
import importlib
import os
import subprocess
import sys
from pathlib import Path

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
                return alice.rpc.call(
                    keys.own_request(world, "arm", "alice"), OwnRequest("request", "alice"), expected=OwnReply
                )
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


PURE_AND_HOOKED = (
    "ownership/state.py",
    "ownership/authority.py",
    "sim_peer/replica/following.py",
    "sim_peer/replica/replica_host.py",
    "fabric/plant.py",
)
"""The state machine and the modules that hold a defect's hook: none of them reads the environment."""


def test_no_module_that_holds_a_defect_reads_the_environment():
    """Their source names neither ``os.environ`` nor ``getenv`` (nor imports ``os``): a defect reaches them only as a
    parameter, set by the sim's command line (``robofabric sim --plant``)."""
    root = Path(__file__).resolve().parents[2]
    for rel in PURE_AND_HOOKED:
        tree = ast.parse((root / rel).read_text(), rel)
        names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)} | {
            n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)
        }
        imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        imported |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        assert not names & {"environ", "getenv", "environb"}, f"{rel} reads the environment"
        assert "os" not in imported, f"{rel} imports os"


TRIPWIRE = """
import os
import fabric.interfaces  # the state machine's dependencies read what settings they like, before the wire is up


class Tripwire(dict):
    def __getitem__(self, key):
        raise AssertionError(f"the environment read: {key}")

    def get(self, key, default=None):
        raise AssertionError(f"the environment read: {key}")

    def __contains__(self, key):
        raise AssertionError(f"the environment read: {key}")


os.environ = Tripwire()
os.getenv = lambda key, default=None: Tripwire()[key]
from ownership import state as st

s = st.initial({"arm": "exclusive"})
for ev in (st.Request("a", "arm", 0.0), st.Join("b", 0.2), st.Request("b", "arm", 0.5), st.Tick(9.0)):
    s, _ = st.step(s, ev)
print("epoch", s.records["arm"].epoch)
"""


@pytest.mark.slow  # a fresh interpreter
def test_the_state_machine_reads_no_environment_at_import_or_call_time():
    """Imported and stepped in a fresh interpreter whose ``os.environ`` and ``os.getenv`` raise on any read (with
    ``ROBOFABRIC_PLANT`` set before it started): the pure core never looks, and the take-over bumps the epoch."""
    env = dict(os.environ, ROBOFABRIC_PLANT="double-owner")
    out = subprocess.run([sys.executable, "-c", TRIPWIRE], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["epoch", "2"], out.stdout
