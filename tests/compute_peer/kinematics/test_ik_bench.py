"""``robofabric bench ik`` runs end to end on a tiny workload and reports every solver."""

from __future__ import annotations

import typer
from typer.testing import CliRunner

from compute_peer.kinematics.bench import format_table, measure_solve, register_bench


def test_measure_solve_reports_every_workload():
    r = measure_solve(n=20, seed=3)
    for key in ("closed_form", "closed_form_position", "numerical", "casadi"):
        assert r[key]["n"] == 20 and r[key]["success"] == 1.0
        assert 0 < r[key]["median_us"] <= r[key]["p99_us"]
    assert 0 <= r["closed_form_position"]["numerical_fallback"] <= 20
    table = format_table(r)
    assert "| closed form, full pose | 20 | 100.00% |" in table and "numerical (LM)" in table
    assert "| CasADi + IPOPT, full pose | 20 | 100.00% |" in table


def test_bench_ik_command():
    bench = typer.Typer()
    register_bench(bench)
    register_bench(bench)  # idempotent: one command, not two
    assert [c.name for c in bench.registered_commands].count("ik") == 1
    app = typer.Typer()
    app.add_typer(bench, name="bench")
    runner = CliRunner()
    res = runner.invoke(app, ["bench", "ik", "--n", "5", "--queries", "20"])
    assert res.exit_code == 0, res.output
    assert "closed form, full pose" in res.output and "numerical (LM)" in res.output
    assert "CasADi + IPOPT" in res.output
    assert "query round trip" in res.output and "ik_pose" in res.output
    res = runner.invoke(app, ["bench", "ik", "--n", "0"])
    assert res.exit_code != 0
