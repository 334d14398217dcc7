"""Two minutes of a class in the lab under the nemesis, every fault kind it knows: faults of several kinds, and
the checker finds no violation in the history (the long run's figures are in docs/benchmarks.md, "Soak")."""

from __future__ import annotations

import re

import pytest

from robofabric.soak.run import SoakConfig, run_soak

pytestmark = [pytest.mark.lab, pytest.mark.slow]


def test_two_minutes_under_the_nemesis_break_no_invariant(lab_ok, tmp_path):
    res = run_soak(SoakConfig(minutes=2.0, log_dir=tmp_path, students=2, seed=7))
    assert not res.violations, "\n".join(str(v) for v in res.violations[:10])
    kinds = int(next(m.group(1) for line in res.summary if (m := re.match(r"fault kinds: (\d+)", line))))
    assert kinds >= 3, res.summary
    assert not res.bad_lines, res.bad_lines[:3]
