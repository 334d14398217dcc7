"""``robofabric bench viewer``: every message type is drawn and timed, the table has a row per type."""

from __future__ import annotations

from typer.testing import CliRunner

from robofabric.bench.cli import build_app
from robofabric.bench.viewer import format_table, measure


def test_measure_draws_every_type():
    r = measure(n=5, grids=2)
    assert list(r) == ["Pose", "JointState", "Scan", "OccupancyGrid"]
    assert [r[k]["n"] for k in r] == [4, 4, 4, 1]
    assert all(0 < v["median_us"] <= v["p99_us"] and v["per_s"] > 0 for v in r.values())
    table = format_table(r)
    assert "| JointState (Meca500" in table and "| OccupancyGrid 400x400 (image) | 1 |" in table


def test_bench_viewer_command(tmp_path):
    out = tmp_path / "viewer.md"
    res = CliRunner().invoke(build_app(), ["viewer", "--n", "3", "--grids", "2", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "| Scan (240 rays" in out.read_text()
    assert CliRunner().invoke(build_app(), ["viewer", "--n", "1"]).exit_code != 0
