"""``robofabric bench shards`` at its smallest: 4 bases over 2 sims, each mirroring the other's robots."""

from __future__ import annotations

import math

import pytest

from robofabric.bench.shards import row, run_one, spots


def test_spots_are_distinct_and_parse():
    s = spots(6)
    assert len(set(s)) == 6 and all(x.startswith(f"reeman:base{i}@") for i, x in enumerate(s))


@pytest.mark.slow
def test_two_sims_each_mirror_the_others_robots_and_answer_commands(tmp_path):
    r = run_one(4, 2, 3.0, tmp_path)
    assert r["mirrored"] == [2, 2], r  # every sim saw the other's two bases
    assert all(x > 0.5 for x in r["rtf"]), r
    assert r["cmd_n"] == 8 and not math.isnan(r["mirror_p50"]), r
    assert row(r).startswith("| 2 | 2 |")
