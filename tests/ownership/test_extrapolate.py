"""Eq. 8 latency compensation: position + velocity * age, age clamped to [0, cap]."""

import numpy as np
from hypothesis import given, strategies as hs

from ownership.extrapolate import age_s, extrapolate

fl = hs.floats(-100, 100)


@given(
    hs.lists(fl, min_size=3, max_size=3), hs.lists(fl, min_size=3, max_size=3), hs.floats(-5, 5), hs.floats(0.01, 1.0)
)
def test_extrapolate_moves_by_velocity_times_clamped_age(p, v, age, cap):
    out = extrapolate(p, v, age, cap_s=cap)
    a = min(max(age, 0.0), cap)
    assert np.allclose(out, np.asarray(p) + np.asarray(v) * a)
    assert np.all(np.abs(out - np.asarray(p)) <= np.abs(np.asarray(v)) * cap + 1e-9)


def test_age_from_header_wall_times_is_clamped():
    assert age_s(1_000_000_000, 1_050_000_000) == 0.05
    assert age_s(2_000_000_000, 1_000_000_000) == 0.0  # clock skew: never negative
    assert age_s(0, 10_000_000_000, cap_s=0.2) == 0.2
