"""``robofabric bench viewer``: every message type is drawn and costed, the table has a row per type and the class world's line."""

from __future__ import annotations

from typer.testing import CliRunner

from robofabric.bench.cli import build_app
from robofabric.bench.viewer import format_table, measure, measure_world


def test_measure_draws_every_type():
    r = measure(n=5, grids=2)
    assert list(r) == ["JointState", "Pose", "wheels", "Scan", "OccupancyGrid"]
    assert [r[k]["n"] for k in r] == [4, 4, 4, 4, 1]  # the first of each stream sets up: drawn, not costed
    assert all(v["us_per_msg"] > 0 and v["per_s"] > 0 for v in r.values())
    world = measure_world(arms=1, bases=1, seconds=0.3)
    # 0.3 s of 1 arm (joints, flange: 100 Hz) and 1 base (pose 50, wheels 100, scan and sonar 20 Hz), less each stream's first
    assert world["n"] == 30 + 30 + 15 + 30 + 6 + 6 - 6 and world["core"] > 0
    table = format_table(r, world)
    assert "| JointState (Meca500" in table and "| OccupancyGrid 400x400 (image), 2 Hz | 1 |" in table
    assert "Class world, 1 arms + 1 bases" in table


def test_bench_viewer_command(tmp_path):
    out = tmp_path / "viewer.md"
    res = CliRunner().invoke(
        build_app(),
        ["viewer", "--n", "3", "--grids", "2", "--arms", "1", "--bases", "1", "--seconds", "0.2", "--out", str(out)],
    )
    assert res.exit_code == 0, res.output
    assert "| Scan (240 rays" in out.read_text() and "us per message" in out.read_text()
    assert CliRunner().invoke(build_app(), ["viewer", "--n", "1"]).exit_code != 0
