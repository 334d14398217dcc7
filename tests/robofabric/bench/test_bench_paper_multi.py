"""The paper's multi-user test (``bench paper --multi-user``): what a student counts of the robots she does not own,
how the class's files are summed up, and one short run of real students on a real router and sim."""

from __future__ import annotations

import math
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from robofabric.bench.paper_multi import PAPER_MULTI_USER, PoseWatch, format_multi_user, measure_multi_user, summarise


def _pose(seq: int, wall_ns: int, stamp: float) -> SimpleNamespace:
    return SimpleNamespace(header=SimpleNamespace(seq=seq, wall_ns=wall_ns, stamp=stamp))


def test_a_watch_keeps_only_the_window_and_counts_sequence_gaps():
    w = PoseWatch(["arm1", "base1"])
    on_arm = w.callback("arm1")
    now = time.time_ns()
    on_arm("k", _pose(0, now - 5_000_000, 1.0))  # before the window: its sequence is noted, nothing kept
    assert w.delays == [] and w.count == {"arm1": 0, "base1": 0}
    w.set_window(time.time() - 1.0, time.time() + 60.0)
    on_arm("k", _pose(1, now - 3_000_000, 1.01))
    on_arm("k", _pose(4, now - 2_000_000, 1.04))  # 2 and 3 never came
    assert w.count == {"arm1": 2, "base1": 0} and w.missing == 2
    assert all(d >= 2.0 for _, d in w.delays)  # received after it was stamped, on one clock
    assert w.newest["arm1"] == now - 2_000_000 and all(a >= 2.0 for a in w.ages())


def _student(name: str, delays: list[tuple[float, float]], ages: list[float]) -> tuple[dict, np.ndarray]:
    r = {
        "student": name,
        "moves": [0.3, 0.4],
        "refused": 1,
        "retaken": 1,
        "lost": [],
        "errors": [],
        "ages_ms": ages,
        "missing": 3,
        "received": {"arm1": len(delays)},
        "rtf": 1.0,
    }
    return r, np.asarray(delays, dtype=np.float64).reshape(-1, 2)


def test_the_summary_pools_every_student_and_splits_the_minutes():
    start = 1000.0
    a = _student("s0", [(start + 1, 1.0), (start + 2, 3.0), (start + 61, 10.0)], [5.0, 7.0])
    b = _student("s1", [(start + 5, 2.0), (start + 90, 20.0)], [9.0])
    doc = summarise([a[0], b[0]], [a[1], b[1]], start, 1.6)
    assert doc["messages"] == 5 and doc["delay_ms_p50"] == 3.0 and doc["delay_ms_max"] == 20.0
    assert (
        doc["age_ms_p50"] == 7.0
        and doc["missing"] == 6
        and doc["moves"] == 4
        and doc["refused"] == 2
        and doc["retaken"] == 2
    )
    assert [m["messages"] for m in doc["per_minute"]] == [3, 2] and doc["per_minute"][1]["delay_ms_p50"] == 15.0
    assert [s["student"] for s in doc["per_student"]] == ["s0", "s1"] and doc["per_student"][1][
        "delay_ms_p99"
    ] == pytest.approx(19.82)


def test_a_student_with_nothing_gives_nan_not_an_error():
    r, d = _student("s0", [], [])
    doc = summarise([r], [d], 0.0, 1.0)
    assert doc["messages"] == 0 and math.isnan(doc["delay_ms_p50"]) and math.isnan(doc["per_student"][0]["age_ms_p99"])


@pytest.mark.slow
def test_three_students_each_see_every_robot_they_do_not_own_and_none_of_their_own(tmp_path: Path):
    """Real processes: router, sim, 3 students owning and driving an arm and a base each for 15 s. Each watches
    the 4 robots of the others (and only those): every one delivered, each delay positive, the paper's figure beside."""
    doc = measure_multi_user(minutes=0.25, students=3, logs=tmp_path, progress=lambda s: None)
    assert doc["students"] == 3 and doc["robots"] == 6 and doc["paper_reported"] == PAPER_MULTI_USER
    for i, s in enumerate(doc["per_student"]):
        others = {f"{k}{j}" for j in range(3) if j != i for k in ("arm", "base")}
        # her own log and the sim's say why (at load 4 s1 once received nothing in her 15 s: not understood)
        why = "".join(f"\n--- {p.name}:\n{p.read_text()[-2500:]}" for p in sorted(tmp_path.glob(f"s{i}-*.log")))
        assert set(s["received"]) == others and all(n > 0 for n in s["received"].values()), f"{s}{why}"
        assert s["errors"] == [] and s["moves"] > 0, s
        assert 0 < s["delay_ms_p50"] <= s["delay_ms_p99"] and s["age_ms_p50"] > 0, s
    assert doc["messages"] == sum(s["messages"] for s in doc["per_student"]) and len(doc["per_minute"]) == 1
    assert 0 < doc["delay_ms_p50"] <= doc["delay_ms_p99"] <= doc["delay_ms_max"]
    table = format_multi_user(doc)
    assert all(doc["rss_mb"][k][0] > 0 and doc["rss_mb"][k][1] > 0 for k in ("router", "sim"))
    assert "| s2 |" in table and "the paper (PUN, 5 users, 2 h) | ~100" in table and "Per minute" in table
    assert not _running(doc["world"]), "every process of the test's world ended"


def _running(world: str) -> list[str]:
    """Command lines of processes that name ``world`` (the test's router, sim and students)."""
    import os

    found = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                cmd = open(f"/proc/{d}/cmdline", "rb").read().decode(errors="replace").split("\0")
            except OSError:
                continue
            if world in cmd:
                found.append(" ".join(cmd))
    return found
