"""Two browser pages on one console server, each a student driving her own base by holding ←: both
join, nothing is lost, nothing refused, every key press moves its base, and each page reads the age of what it
shows. The figures (lag, key to motion, the server's CPU, the browsers' CPU per page) come from ``robofabric bench console``; this checks
only what must hold at any speed."""

from __future__ import annotations

import math

import pytest

from robofabric.bench.console import _joined_renderer, run_one

pytestmark = pytest.mark.slow


def test_two_pages_drive_their_bases_and_lose_nothing(tmp_path):
    """Beside them, two emulated students (the page's socket protocol, no browser) log in and steer theirs."""
    r = run_one(2, 6.0, tmp_path, clients=2, view_fps=2)  # 2 frames a second: the box's other tests beside it
    assert r["c_joined"] == 2 and r["c_turned"] == 2 and r["c_keys"] >= 4, (r["c_errors"], r)  # both in, both turned
    assert r["c_back"] == r["c_dropped"] == r["c_refused"] == 0 and not r["c_errors"], r
    assert r["joined"] == 2 and r["lost"] == 0 and r["refused"] == 0, r
    assert r["logged_out"] == 0 and r["reloads"] == 0, r  # no page went back to its login
    assert r["presses"] >= 2 and r["missed"] == 0, r  # each press moved its base
    assert math.isfinite(r["lag_p50"]) and r["lag_p50"] > 0, r  # the pages showed a pose with its stamp
    assert r["page_cpu"] > 0 and r["join_cpu"] > 0, r  # the pages' own browsers were found and measured
    assert 0 < r["busy"] <= 1 and set(r["waited"]) == {"console", "sim", "router", "class"}, r  # how full the box was
    assert all(w >= 0 for w in r["waited"].values()), r


def test_a_join_is_counted_on_the_renderer_that_took_the_page():
    """Chromium's spare renderer, made before the join, takes the page: its CPU meanwhile is the join's, not
    the 0.0 s of the renderers new since; a renderer an earlier page took is never counted again."""
    claimed: set[str] = set()
    before = {"renderer:10": 5.0, "renderer:11": 0.1, "gpu-process:3": 1.0}
    after = {"renderer:10": 5.3, "renderer:11": 0.9, "gpu-process:3": 2.0, "renderer:12": 0.05}
    assert _joined_renderer(before, after, claimed) == pytest.approx(0.8)
    assert claimed == {"renderer:11"}
    later = {**after, "renderer:11": 2.0, "renderer:12": 0.6}
    assert _joined_renderer(after, later, claimed) == pytest.approx(0.55)
    assert math.isnan(_joined_renderer({}, {"gpu-process:3": 1.0}, claimed))
