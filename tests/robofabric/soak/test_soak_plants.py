"""The checker is not vacuous: each defect ``--plant`` puts in the sims (fabric/plant.py) is caught by the
invariant it breaks, in a short soak in the lab with the fault that brings it out."""

from __future__ import annotations

import pytest

from robofabric.soak.run import SoakConfig, run_soak

pytestmark = [pytest.mark.lab, pytest.mark.slow]


@pytest.mark.parametrize(("plant", "faults", "victims", "invariant"), [
    ("reset", ("kill",), ("sim",), "reset"),  # a fail-over puts the arms back at their spawn pose
    ("double-owner", ("hog",), ("student",), "owners"),  # students take each other's still arms over
    ("stale-command", ("replay",), ("student",), "applied"),  # an owner's command under an epoch she no longer holds
])
def test_a_planted_defect_is_caught(lab_ok, tmp_path, plant, faults, victims, invariant):
    res = run_soak(SoakConfig(minutes=1.0, log_dir=tmp_path, students=2, seed=2, plant=plant, kinds=faults, victims=victims))
    caught = {v.invariant for v in res.violations}
    assert invariant in caught, f"plant {plant}: {res.summary}; violations: {[str(v) for v in res.violations[:3]]}"
    assert any(line.startswith("faults: ") and line != "faults: 0" for line in res.summary), res.summary

