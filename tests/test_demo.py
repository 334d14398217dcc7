"""`robofabric demo`: the embedded default runs both of the paper's scenarios and exits 0 with a summary."""

import subprocess

from mcap.reader import make_reader
import pytest

from robofabric.testing import free_port, robofabric_cmd

pytestmark = pytest.mark.slow  # every test here starts processes or runs for seconds

# The demo takes about 20 s on a 2-core machine; the cap only bounds a hung run (tasks still running at the cap are
# stopped and reported as failed, so a slow machine fails loudly rather than passing quietly). 90 s was too short for
# bob's Test B in a whole run at load (2026-12-01: the sim stopped under his release).
CAP_S = 180


def test_demo_runs_both_scenarios_and_writes_its_files(tmp_path):
    port = free_port()
    out = subprocess.run(
        robofabric_cmd("demo", "--duration", str(CAP_S), "--out", str(tmp_path), "--router", f"tcp/127.0.0.1:{port}"),
        capture_output=True,
        text=True,
        timeout=CAP_S + 100,
    )
    text = out.stdout + out.stderr
    assert out.returncode == 0, text[-5000:]
    assert "demo summary" in out.stdout and "all tasks finished" in out.stdout, text[-3000:]
    assert "[test-a alice] ok:" in out.stdout and "streamed=8" in out.stdout, text[-3000:]
    assert "[test-b bob] ok:" in out.stdout and "took arm1 over where it was" in out.stdout, text[-3000:]
    assert out.stdout.splitlines()[-1].strip() == "ok"

    assert (tmp_path / "demo.rrd").stat().st_size > 100_000
    with open(tmp_path / "demo.mcap", "rb") as f:
        topics = {ch.topic for ch in make_reader(f).get_summary().channels.values()}
    # Test B plans on the map bob built: his own, map/bob.map (a student never rebuilds the class map)
    for leaf in ("robot/arm1/joints", "robot/arm1/ik", "robot/base1/scan", "robot/base1/path", "map/bob.map"):
        assert f"rf/demo/{leaf}" in topics, sorted(topics)
    assert any(t.startswith("rf/demo/object/target/pose/by/") for t in topics), sorted(topics)  # the writer in the key
