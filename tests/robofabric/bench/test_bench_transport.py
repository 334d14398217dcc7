"""The transport benchmark runs end to end (zenoh and a real mosquitto); figures go to docs, not asserts."""

import shutil

import pytest

from robofabric.bench.transport import format_table, run_bench


@pytest.mark.slow
def test_bench_transport_delivers_through_zenoh_and_mosquitto():
    assert shutil.which("mosquitto") or shutil.which("/usr/sbin/mosquitto"), (
        "mosquitto is required (.ci/run installs it)"
    )
    results = run_bench([200.0], 1.0, mqtt=True)
    assert [r["transport"] for r in results] == ["zenoh", "mqtt"]
    for r in results:
        assert r["sent"] == 200
        assert r["received"] == r["unique"] > 0
        assert r["bytes_per_msg"] <= 600
    assert results[0]["delivered_pct"] == 100.0  # BLOCK congestion control through the router: nothing dropped
    assert "| zenoh | 200 |" in format_table(results)
