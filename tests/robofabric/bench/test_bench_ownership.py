"""``robofabric bench ownership`` end to end with small N: handovers, a SIGKILLed and a frozen owner."""

import pytest

from robofabric.bench.ownership import run_one


@pytest.mark.slow
def test_bench_small_run_completes():
    r = run_one(3, lease_s=0.3, kills=1)
    assert r["handovers"] == 2
    assert r["recovery_max"] > 0 and r["frozen_max"] > 0
