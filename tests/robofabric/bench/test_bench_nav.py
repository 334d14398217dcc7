"""``robofabric bench nav`` runs end to end on a tiny workload and reports every planner."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from robofabric.bench.cli import build_app
from robofabric.bench.nav import bench_mapping, bench_planning, format_tables


def test_bench_functions_report_all_planners():
    mapping = bench_mapping(scans=5)
    assert mapping["n"] == 5 and mapping["p50_ms"] > 0
    planning = bench_planning(queries=2, planners=("hybrid_astar", "ompl:bitstar"), directions=(False,))
    assert [r["planner"] for r in planning] == ["hybrid_astar", "ompl:bitstar"]
    assert all(r["solved"] == 2 and r["mean_length_m"] >= 5.0 for r in planning)
    table = format_tables(mapping, planning)
    assert "| hybrid_astar | dubins | 2/2 |" in table and "400x400" in table


def test_bench_nav_command(tmp_path):
    app = build_app()
    runner = CliRunner()
    out = tmp_path / "nav.md"
    res = runner.invoke(app, ["nav", "--scans", "3", "--queries", "1", "--planners", "hybrid_astar", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "| hybrid_astar | dubins | 1/1 |" in out.read_text()
    res = runner.invoke(app, ["nav", "--scans", "3", "--queries", "1", "--planners", "hybrid_astar", "--json"])
    assert json.loads(res.output)["planning"][0]["solved"] == 1
    res = runner.invoke(app, ["nav", "--planners", "dijkstra"])
    assert res.exit_code != 0
