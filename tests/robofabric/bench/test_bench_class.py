"""A class of 8 students on one world: eight student processes, each owning an arm and a base,
drive and move for 15 s through one router and one sim: everyone joins, nothing is lost, no command is
refused, and every student's arm moves. The figures (move times, pace, CPU) come from ``robofabric bench
class``; this checks only what must hold at any speed."""

from __future__ import annotations

import pytest

from robofabric.bench.klass import run_one

pytestmark = pytest.mark.slow


def test_a_class_of_eight_loses_nothing(tmp_path):
    r = run_one(8, 15.0, tmp_path)
    assert r["joined"] == 8, r["errors"]
    # a robot lost because its owner's own process stalled past her lease (she says so: renewals of sNN: a round
    # began 1.6 s late) is the lease doing its job on a loaded box, said here; any other loss fails
    if r["lost_to_stalls"]:
        print(f"lost with their owner's stall past the lease: {r['lost_to_stalls']}: {r['lost_detail']}")
    assert r["lost"] == r["lost_to_stalls"], r["lost_detail"]
    # and the commands she went on sending to what the lease took back are refused as hers no longer (run 51: s03's
    # round began 1.7 s late, arm3 and base3 went back, and 56 of her commands were refused): any other refusal fails
    assert r["refused"] == r["refused_after_stalls"], r["errors"]
    assert r["fewest_moves"] >= 1, r  # every student's arm moved (0.35 s a move when alone)
