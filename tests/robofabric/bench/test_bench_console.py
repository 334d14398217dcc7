"""Two browser pages on one console server, each a student driving her own base by holding ←: both
join, nothing is lost, nothing refused, every key press moves its base, and each page reads the age of what it
shows. The figures (lag, key to motion, the server's CPU, the browsers' CPU per page) come from ``robofabric bench console``; this checks
only what must hold at any speed."""

from __future__ import annotations

import math

import pytest

from robofabric.bench.console import run_one

pytestmark = pytest.mark.slow


def test_two_pages_drive_their_bases_and_lose_nothing(tmp_path):
    r = run_one(2, 6.0, tmp_path)
    assert r["joined"] == 2 and r["lost"] == 0 and r["refused"] == 0, r
    assert r["logged_out"] == 0 and r["reloads"] == 0, r  # no page went back to its login
    assert r["presses"] >= 2 and r["missed"] == 0, r  # each press moved its base
    assert math.isfinite(r["lag_p50"]) and r["lag_p50"] > 0, r  # the pages showed a pose with its stamp
    assert r["page_cpu"] > 0 and r["join_cpu"] > 0, r  # the pages' own browsers were found and measured
