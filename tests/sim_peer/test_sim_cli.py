"""The CLI's ownership wiring (with stand-in ownership modules)."""

from __future__ import annotations

import sys
import types

import pytest

from fabric.gate import OpenGate
from sim_peer.cli import make_gate
from sim_peer.physics.world import SimWorld


class FakeAuthority:
    def __init__(self, fabric, *, objects, budgets=None, plant=""):
        self.fabric = fabric
        self.objects = objects
        self.budgets = budgets
        self.plant = plant
        self.started = False

    def start(self):
        self.started = True
        return self


def test_ownership_gate_is_built_with_exclusive_robots_and_scene_objects(monkeypatch):
    monkeypatch.setitem(sys.modules, "ownership", types.SimpleNamespace(Authority=FakeAuthority))
    w = SimWorld("combined")
    gate = make_gate("FAB", w, True)
    assert isinstance(gate, FakeAuthority) and gate.fabric == "FAB" and gate.started  # leases tick from the start
    assert gate.objects == {"arm1": "exclusive", "base1": "exclusive", "target": "scene", "goal": "scene"}
    assert (
        gate.budgets is None and make_gate("FAB", w, True, budgets="B").budgets == "B"
    )  # --budget reaches the authority
    assert gate.plant == "" and make_gate("FAB", w, True, plant="stale-command").plant == "stale-command"  # the soak's


def test_without_an_authority_the_sim_warns_and_opens_the_gate(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ownership", types.ModuleType("ownership"))  # no Authority in it
    gate = make_gate("FAB", SimWorld("arm_cell"), True)
    assert isinstance(gate, OpenGate)
    assert "not gated" in capsys.readouterr().err
    assert isinstance(make_gate("FAB", SimWorld("arm_cell"), False), OpenGate)


@pytest.mark.slow
def test_sim_list_shows_robot_types_and_scenes():
    import subprocess

    from robofabric.testing import robofabric_cmd

    out = subprocess.run(robofabric_cmd("sim", "--list"), capture_output=True, text=True, timeout=60)
    assert out.returncode == 0
    assert "meca500      arm" in out.stdout and "reeman       mobile" in out.stdout
    assert "combined     arm1 (meca500), base1 (reeman); objects target, goal" in out.stdout


@pytest.mark.slow
def test_a_planted_defect_is_a_hidden_option_and_an_unknown_one_is_refused():
    """``--plant`` (test-only, fabric/plant.py) is not on the sim's ``--help``; an unknown defect is refused, exit 2."""
    import subprocess

    from robofabric.testing import robofabric_cmd

    out = subprocess.run(robofabric_cmd("sim", "--help"), capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "--plant" not in out.stdout, out.stdout
    out = subprocess.run(robofabric_cmd("sim", "--plant", "everything"), capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "--plant" in out.stderr and "double-owner" in out.stderr, out.stderr
