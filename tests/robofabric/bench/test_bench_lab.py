"""``robofabric bench lab``'s report, from made-up figures (the lab itself runs in tests/lab; this is fast)."""

from __future__ import annotations

from robofabric.bench.lab import run_stats, to_markdown


def test_report_has_a_row_per_figure_with_median_and_max():
    raw = {
        "partition_handover": [1.9, 1.8, 2.4],
        "router_joints_back": [0.7, 0.5, 3.25],
        "router_owner_back": [0.7, 3.2],
        "sim_gone_told": [0.03, 0.05, 0.02],
    }
    result = {
        "runs": 3,
        "figures": {k: run_stats(v) for k, v in raw.items()},
        "raw": raw,
        "router_owner_restored": "2/3",
    }
    assert result["figures"]["router_owner_back"] == {"n": 2, "median_s": (0.7 + 3.2) / 2, "max_s": 3.2, "min_s": 0.7}
    lines = to_markdown(result).splitlines()
    assert lines[:2] == ["| figure (3 runs) | median | max |", "|---|---|---|"]
    assert lines[2:6] == [
        "| handover after the owner's link drops (bob queued → granted) | 1.90 s | 2.40 s |",
        "| router SIGKILLed and restarted: joints at a user again, after the router listens | 0.70 s | 3.25 s |",
        "| … the owner holds the arm again (kept under her epoch, or restored within grace) | 1.95 s | 3.20 s |",
        "| sim SIGKILLed: the user is told the world is gone | 0.03 s | 0.05 s |",
    ]
    assert lines[-1] == (
        "After the router's restart the owner was restored in 2/3 runs "
        "(otherwise the lease had expired first and the arm was free)."
    )
