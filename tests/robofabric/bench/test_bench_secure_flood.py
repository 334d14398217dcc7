"""bench secure's flood row (robofabric.bench.secure_flood): a short real run, and its table."""

from __future__ import annotations

import math

import pytest

from robofabric.bench import secure_flood


@pytest.mark.slow
def test_a_short_flood_row_measures_both_phases():
    rows = secure_flood.run(1.5)
    quiet, flood = rows["quiet"], rows["flood"]
    assert quiet["mallory_sent"] == 0 and quiet["commands"] > 0 and not math.isnan(quiet["world_p50"])
    assert flood["mallory_sent"] > 0 and flood["rate_limited"] > 0, flood["flooder"]  # her budgets held her back
    assert set(flood["flooder"]) == {"requests", "state"}
    table = secure_flood.table(rows, 1.5)
    assert table.count("\n") == 3 and "mallory floods requests + srv/state" in table
