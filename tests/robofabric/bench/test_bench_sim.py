"""``robofabric bench sim``: its helpers measure a real MuJoCo world, and the command writes its table."""

from __future__ import annotations

import subprocess

import pytest

from robofabric.testing import robofabric_cmd
from robofabric.bench.sim import arm_mirror_cost, rtf, scan_cost
from sim_peer.physics.world import SimWorld


def test_benchmark_helpers_measure_something():
    w = SimWorld("combined")
    assert rtf(w, 0.2) > 0
    assert w.time >= 0.2 - 1e-9 and w.robot("base1").moving  # the mobile robot was driven during the run
    med, p99 = scan_cost(w, "base1", n=50)
    assert 0 < med <= p99
    med, p99 = arm_mirror_cost(n=20)
    assert 0 < med <= p99


@pytest.mark.slow
def test_bench_sim_command_writes_its_table(tmp_path):
    out = tmp_path / "sim.md"
    res = subprocess.run(
        robofabric_cmd("bench", "sim", "--seconds", "0.2", "--counts", "1,2", "--out", str(out)),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    table = out.read_text()
    assert (
        "| combined (Meca500 sweeping + Reeman driving)" in table
        and "| warehouse, 2 mobile robots" in table
        and "240-ray" in table
    )
    assert "| one arm mirror update" in table
