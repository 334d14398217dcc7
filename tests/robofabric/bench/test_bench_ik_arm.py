"""``robofabric bench ik --robot NAME``: any installed arm's IK, timed and checked against the issue's bar."""

from __future__ import annotations

import pytest

import robots
from robofabric import cli
from robofabric.bench.ik_arm import format_table, measure_arm
from robofabric.testing import example_robot_urdf
from robots.urdf_import import install


@pytest.mark.slow  # a benchmark, through the CLI: seconds
def test_bench_ik_robot_measures_an_arm_from_a_urdf_and_refuses_an_unknown_type(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv(robots.description.ENV_PATH, str(tmp_path))
    install(example_robot_urdf("ur_description/urdf/ur5_robot.urdf"), into=tmp_path, name="ur5")
    result = measure_arm("ur5", 5, seed=1)
    assert result["joints"] == 6 and result["n"] == 5
    for key in ("full_far", "full_near", "position"):
        assert 0.0 <= result[key]["success"] <= 1.0 and result[key]["median_us"] > 0
    table = format_table(result)
    assert "ur5 (6 joints), 5 reachable targets" in table and table.count("\n| ") == 4
    out = tmp_path / "tables.md"
    assert cli.main(["bench", "ik", "--robot", "ur5", "--n", "3", "--out", str(out)]) == 0
    assert "| full pose, seed anywhere |" in out.read_text()
    assert cli.main(["bench", "ik", "--robot", "nosuch", "--n", "3"]) == 2
    assert "nosuch" in capsys.readouterr().err
