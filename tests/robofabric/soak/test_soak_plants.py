"""The checker is not vacuous: each defect ``--plant`` puts in the sims (fabric/plant.py) is caught by the
invariant it breaks, in a short soak in the lab with the fault that brings it out.

Each soak lasts about three times the longest it took the checker to catch its plant (seconds after the class
began, in the histories of four runs each, docs/testing.md), or a minute where that is less: a reset 6-9 s (the
first kill comes at about 6 s), so half a minute, but a whole suite at load 22 caught it only in the verdict after
its half minute, so a minute too; two owners 15-24 s and a stale command 10-40 s (a replay needs
an arm at its second epoch), so a minute each, as before. A run ends 3 s after the history so far first breaks its
invariant (``until``): its length is the most it may take, not what it costs. Each may take two minutes since a
whole run on a slow afternoon (34 min, load 20-35) saw the reset soak's two kills and no catch within its minute:
a slow box lengthens every fail-over, and a longer limit costs nothing where the plant is caught. The stale command
may take three: a whole run at load 15-24 (2026-12-01) saw no replay at all in its two minutes ("faults: 0", no
peer past its warm-up), and why its nemesis found no moment for one is not known."""

from __future__ import annotations

import pytest

from robofabric.soak.history import Mark
from robofabric.soak.run import SoakConfig, run_soak

pytestmark = [pytest.mark.lab, pytest.mark.slow]


@pytest.mark.parametrize(
    ("plant", "faults", "victims", "invariant", "minutes"),
    [
        ("reset", ("kill",), ("sim",), "reset", 2.0),  # a fail-over puts the arms back at their spawn pose
        ("double-owner", ("hog",), ("student",), "owners", 2.0),  # students take each other's still arms over
        (
            "stale-command",
            ("replay",),
            ("student",),
            "applied",
            3.0,
        ),  # an owner's command under an epoch she no longer holds
    ],
)
@pytest.mark.timeout(480)  # a soak of up to three minutes, its lab's start and its verdict
def test_a_planted_defect_is_caught(lab_ok, tmp_path, plant, faults, victims, invariant, minutes):
    res = run_soak(
        SoakConfig(
            minutes=minutes,
            log_dir=tmp_path,
            students=2,
            seed=2,
            plant=plant,
            kinds=faults,
            victims=victims,
            until=invariant,  # the run ends soon after the catch; the verdict below is still the whole history's
        )
    )
    caught = {v.invariant for v in res.violations}
    assert invariant in caught, f"plant {plant}: {res.summary}; violations: {[str(v) for v in res.violations[:3]]}"
    assert any(line.startswith("faults: ") and line != "faults: 0" for line in res.summary), res.summary
    caught_at = [r.t - res.started for r in res.history if isinstance(r, Mark) and r.what == "caught"]
    assert caught_at, "the run did not end at its catch: it ran its whole length"
    print(f"plant {plant}: caught {caught_at[0]:.1f} s after the run began")
