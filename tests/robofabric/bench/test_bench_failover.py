"""``robofabric bench failover`` with one take-over: real sim processes, a SIGKILLed primary, the standby's state."""

from __future__ import annotations

import re
import subprocess

import pytest

from robofabric.testing import robofabric_cmd


@pytest.mark.slow
def test_bench_failover_runs_one_round(tmp_path):
    out = tmp_path / "failover.md"
    proc = subprocess.run(
        robofabric_cmd("bench", "failover", "--kills", "1", "--out", str(out)),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    text = out.read_text()
    took = re.search(r"new term, here \| (\d+) / (\d+) ms", text)
    err = re.search(r"joint error at take-over, motion-compensated \| ([\d.]+) / ([\d.]+) rad", text)
    assert took and err, text
    assert 0 < int(took.group(1)) and float(err.group(2)) <= 0.01, text + proc.stdout[-2000:]
