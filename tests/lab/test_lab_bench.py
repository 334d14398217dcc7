"""``robofabric bench lab`` runs through once in real namespaces: each of its waits is a claim about the fabric
(a partitioned owner hears she lost the arm, the owner holds it again after a router restart), and a change
that breaks one must fail here, not first in a benchmark run."""

from __future__ import annotations

import pytest

from robofabric.bench.lab import run_lab_bench

pytestmark = pytest.mark.slow


def test_one_run_of_the_lab_bench_completes_every_figure(lab_ok, tmp_path):
    result = run_lab_bench(1, log_dir=tmp_path / "lab", progress=lambda line: None)
    figures = result["figures"]
    assert set(figures) >= {
        "partition_handover",
        "router_joints_back",
        "sim_gone_told",
        "sim_world_serving",
        "sim_first_move_done",
    }, figures
    assert all(f["n"] == 1 for f in figures.values()), figures


def test_bench_shards_over_the_lab_one_sim_per_host(lab_ok, tmp_path):
    """Two sims on two hosts of one world: each mirrors the other's bases, keeps pace, and answers commands."""
    from robofabric.bench.shards import run_lab

    r = run_lab(4, 2, 3.0, tmp_path / "lab")
    assert r["mirrored"] == [2, 2], r
    assert all(x > 0.5 for x in r["rtf"]) and r["cmd_n"] == 8, r
