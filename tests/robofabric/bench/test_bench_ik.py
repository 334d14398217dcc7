"""``robofabric bench ik`` runs end to end on a tiny workload and reports every solver."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from robofabric.bench.cli import build_app
from robofabric.bench.ik import format_table, measure_solve


def test_measure_solve_reports_every_workload():
    r = measure_solve(n=20, seed=3)
    for key in ("closed_form", "closed_form_position", "numerical", "casadi"):
        assert r[key]["n"] == 20 and r[key]["success"] == 1.0
        assert 0 < r[key]["median_us"] <= r[key]["p99_us"]
    assert 0 <= r["closed_form_position"]["numerical_fallback"] <= 20
    table = format_table(r)
    assert "| closed form, full pose | 20 | 100.00% |" in table and "numerical (LM)" in table
    assert "| CasADi + IPOPT, full pose | 20 | 100.00% |" in table


@pytest.mark.slow
def test_bench_ik_command(tmp_path):
    runner = CliRunner()
    out = tmp_path / "ik.md"
    res = runner.invoke(build_app(), ["ik", "--n", "5", "--queries", "20", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "closed form, full pose" in res.output and "numerical (LM)" in res.output
    assert "CasADi + IPOPT" in res.output
    assert "query round trip" in res.output and "ik_pose" in res.output
    assert "| closed form, full pose | 5 |" in out.read_text() and "| ik_pose |" in out.read_text()
    res = runner.invoke(build_app(), ["ik", "--n", "0"])
    assert res.exit_code != 0


@pytest.mark.slow
def test_ik_query_round_trip_bench_smoke():
    from robofabric.bench.ik_query import measure_query

    res = measure_query(n=20, warmup=5)
    assert set(res) == {"ik_pose", "ik_position", "fk"}
    assert all(0 < r["p50_ms"] <= r["p99_ms"] <= r["max_ms"] for r in res.values())
