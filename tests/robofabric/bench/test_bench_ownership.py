"""``robofabric bench ownership`` end to end with small N: handovers, a SIGKILLed and a frozen owner."""

import pytest
from typer.testing import CliRunner

from fabric.cli_common import UserError
from robofabric.bench.cli import build_app
from robofabric.bench.ownership import format_row, header, run_one


@pytest.mark.slow
def test_bench_small_run_completes():
    r = run_one(3, lease_s=0.3, kills=1, grace_s=5.0)  # a starved authority holds a frozen owner for a grace
    assert r["handovers"] == 2
    assert r["recovery_max"] > 0 and r["frozen_max"] > 0
    assert format_row(r).startswith("| 3 | 2 | ") and "lease 300 ms" in header(0.3)[0]


@pytest.mark.parametrize("args", [["--users", "ten"], ["--users", "1"], ["--lease", "0"]])
def test_bench_ownership_refuses_bad_options(args):
    res = CliRunner().invoke(build_app(), ["ownership", *args])
    assert isinstance(res.exception, UserError), res.output
