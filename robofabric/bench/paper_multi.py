"""The paper's multi-user test for robofabric: N students (5, as the paper's PUN test) on one world for ``--minutes``.

The paper ran 5 users on Photon (PUN) for 2 hours and reports that "all users had a 100 ms delay when
interacting with non-owned network objects" (Section 3.3). Here: a router and one sim serving N Meca500 arms
and N Reeman bases (``warehouse``, no scene robots), and N student processes (``python -m
robofabric.bench.paper_multi student ...``). Each student joins through the user API, owns ``armI`` and
``baseI`` and, while the test runs, turns her base with ``twist`` and moves her arm back and forth with
``move_joints(wait=True)``, as the class benchmark's students do, while she watches the pose streams of the
robots she does not own (the other arms' flanges at 100 Hz, the other bases at 50 Hz).

Two delays per student, both on one machine and one clock (``time.time_ns``, which the sim's headers carry):

- *delay*: for every pose message of a robot she does not own, her receive time minus the wall time the sim
  stamped it with (taken as it built the message, just after reading the physics): transport, routing and
  decoding, what Photon adds between an owner's client and the others';
- *age*: every 0.1 s, how old the newest pose she holds of each robot she does not own is (now minus its
  stamp): the delay plus the wait for the next message, which is what a user looking at the robot sees.

Messages missing from a stream (gaps in its header sequence) are counted, and the sim's real-time factor
(sim time against wall time in the poses she received). Nobody here renders: the users are scripts.
"""

from __future__ import annotations

import json
import math
import os
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Any, Callable

from robofabric.bench.common import pct, proc_cpu_s, proc_rss_mb
from robofabric.bench.paper_figures import PAPER_MULTI_USER

__all__ = ["measure_multi_user", "student", "summarise", "format_multi_user", "PoseWatch", "PAPER_MULTI_USER"]

STUDENT = [sys.executable, "-m", "robofabric.bench.paper_multi", "student"]
TARGETS_DEG = ([25.0, 15.0, -15.0, 0.0, 20.0, 0.0], [-25.0, -10.0, 10.0, 0.0, -20.0, 0.0])
"""The two arm poses a student alternates between (well inside the Meca500's limits)."""
AGE_PERIOD_S = 0.1


# ---------------------------------------------------------------------- a student (child process)


class PoseWatch:
    """The poses of the robots a student does not own: each message's delay, the newest stamp, sequence gaps."""

    def __init__(self, robots: list[str]) -> None:
        self.lock = threading.Lock()
        self.window = (math.inf, math.inf)  # wall seconds; samples outside it are not kept
        self.delays: list[tuple[float, float]] = []  # (receive wall s, delay ms)
        self.count = {r: 0 for r in robots}
        self.newest: dict[str, int] = {}  # robot -> wall_ns of its newest pose
        self.last_seq: dict[str, int] = {}
        self.missing = 0
        self.stamps: dict[str, list[tuple[int, float]]] = {r: [] for r in robots}  # first and last (wall_ns, sim s)

    def set_window(self, start: float, end: float) -> None:
        """Keep only messages received between wall times ``start`` and ``end`` (s); before it, none are kept."""
        with self.lock:
            self.window = (start, end)

    def callback(self, robot: str) -> Callable[[str, Any], None]:
        def on(_key: str, msg: Any) -> None:
            now = time.time_ns()
            h = msg.header
            with self.lock:
                prev = self.last_seq.get(robot)
                self.last_seq[robot] = h.seq
                self.newest[robot] = max(self.newest.get(robot, 0), h.wall_ns)
                if not self.window[0] <= now / 1e9 <= self.window[1]:
                    return
                if prev is not None and h.seq > prev + 1:
                    self.missing += h.seq - prev - 1
                self.delays.append((now / 1e9, (now - h.wall_ns) / 1e6))
                self.count[robot] += 1
                st = self.stamps[robot]
                st[min(len(st), 1) :] = [(h.wall_ns, h.stamp)]  # [first] then [first, newest]

        return on

    def ages(self) -> list[float]:
        now = time.time_ns()
        with self.lock:
            return [(now - t) / 1e6 for t in self.newest.values()]

    def rtf(self) -> float:
        """Sim seconds per wall second over the window, from the robot with the longest record."""
        with self.lock:
            spans = [(b[0] - a[0], b[1] - a[1]) for a, b in (s for s in self.stamps.values() if len(s) == 2)]
        wall, sim = max(spans, default=(0, 0.0))
        return sim / (wall / 1e9) if wall > 0 else float("nan")


def _note(res: dict[str, Any], exc: Exception) -> None:
    res["refused"] += 1
    if len(res["errors"]) < 5:
        res["errors"].append(f"{type(exc).__name__}: {exc}")


def _keep(robot: Any, res: dict[str, Any]) -> bool:
    """Own ``robot`` again if it was lost (a lease that lapsed under load), as the paper's users take a robot
    over with a button; whether she owns it now."""
    if robot.is_owner:
        return True
    try:
        robot.request(timeout=10.0)
        res["retaken"] += 1
        return True
    except Exception as exc:
        _note(res, exc)
        return False


def _drive(arm: Any, base: Any, until: float, res: dict[str, Any]) -> None:
    """Turn the base and move the arm back and forth until wall time ``until``; a robot lost is taken again,
    refusals are counted, never fatal."""
    import numpy as np

    k = 0
    while time.time() < until:
        if not all([_keep(arm, res), _keep(base, res)]):  # both asked for, whatever the first answers
            time.sleep(0.5)
            continue
        try:
            base.twist(0.0, 0.4 if k % 2 else -0.4)
            t = time.monotonic()
            arm.move_joints(
                np.radians(TARGETS_DEG[k % 2]),
                wait=True,
                tol=2e-3,
                timeout=min(20.0, max(1.0, until - time.time() + 5)),
            )
            res["moves"].append(time.monotonic() - t)
        except Exception as exc:  # a refusal or a timeout: counted, and the student goes on
            _note(res, exc)
            time.sleep(0.2)
        k += 1
    try:
        base.twist(0.0, 0.0)
    except Exception:
        pass


def student(world: str, endpoint: str, index: int, n: int, out: str) -> None:
    """Join, own armI and baseI, say ready (``out``.ready), wait for the go file (``out``.go: start and end wall
    times), drive while watching the others' poses, write the results to ``out`` (JSON) and the delays beside
    it (``out``.npy: receive time, delay ms)."""
    import numpy as np

    from user_peer.api import connect

    res: dict[str, Any] = {"student": f"s{index}", "moves": [], "refused": 0, "retaken": 0, "errors": [], "lost": []}
    others = [f"{k}{j}" for j in range(n) if j != index for k in ("arm", "base")]
    watch = PoseWatch(others)
    ages: list[float] = []
    try:
        with connect(world, endpoint, user=f"s{index}", timeout=10.0, join_timeout=180.0) as w:
            w.ownership.on_lost(
                lambda obj, rec: res["lost"].append(
                    f"{time.strftime('%H:%M:%S')} {obj}: owner {rec.owner or 'none'} epoch {rec.epoch}"
                )
            )
            arm, base = w.robot(f"arm{index}"), w.robot(f"base{index}")
            arm.request(timeout=60.0)
            base.request(timeout=60.0)
            subs = [w.robot(r).on("pose", watch.callback(r)) for r in others]
            Path(out + ".ready").write_text("ready")
            go = Path(out + ".go")
            deadline = time.monotonic() + 600.0
            while not go.exists() and time.monotonic() < deadline:
                time.sleep(0.1)  # the orchestrator's go: every student is in
            start, end = json.loads(go.read_text())
            watch.set_window(start, end)
            sampler = threading.Thread(target=_sample_ages, args=(watch, start, end, ages), daemon=True)
            sampler.start()
            time.sleep(max(0.0, start - time.time()))
            _drive(arm, base, end, res)
            sampler.join(timeout=max(1.0, end - time.time() + 2.0))
            for s in subs:
                s.close()
    except Exception as exc:
        res["errors"].append(f"{type(exc).__name__}: {exc}")
    with watch.lock:
        delays = np.asarray(watch.delays, dtype=np.float64).reshape(-1, 2)
        res.update(received=dict(watch.count), missing=watch.missing)
    res["rtf"] = watch.rtf()
    res["ages_ms"] = [round(a, 2) for a in ages]
    np.save(out + ".npy", delays)
    Path(out).write_text(json.dumps(res))


def _sample_ages(watch: PoseWatch, start: float, end: float, into: list[float]) -> None:
    t = start
    while t < end:
        time.sleep(max(0.0, t - time.time()))
        into.extend(watch.ages())
        t += AGE_PERIOD_S


# ---------------------------------------------------------------------- the orchestrator (this process)


def summarise(results: list[dict[str, Any]], delays: list[Any], start: float, minutes: float) -> dict[str, Any]:
    """Overall, per-student and per-minute delay and age percentiles (ms) from the students' files."""
    import numpy as np

    both = np.concatenate([d for d in delays if d.size] or [np.zeros((0, 2))])
    ages = [a for r in results for a in r.get("ages_ms", [])]
    per_student = []
    for r, d in zip(results, delays):
        a = r.get("ages_ms", [])
        per_student.append(
            {
                "student": r["student"],
                "delay_ms_p50": pct(d[:, 1], 50),
                "delay_ms_p99": pct(d[:, 1], 99),
                "age_ms_p50": pct(a, 50),
                "age_ms_p99": pct(a, 99),
                "messages": int(d.shape[0]),
                "received": r.get("received", {}),
                "missing": r.get("missing", 0),
                "moves": len(r["moves"]),
                "refused": r["refused"],
                "lost": r["lost"],
                "retaken": r.get("retaken", 0),
                "errors": r["errors"],
                "rtf": r.get("rtf", float("nan")),
            }
        )
    per_minute = []
    for k in range(max(1, math.ceil(minutes - 1e-9))):
        sel = both[(both[:, 0] >= start + 60 * k) & (both[:, 0] < start + 60 * (k + 1))][:, 1]
        per_minute.append(
            {"minute": k + 1, "delay_ms_p50": pct(sel, 50), "delay_ms_p99": pct(sel, 99), "messages": int(sel.size)}
        )
    return {
        "delay_ms_p50": pct(both[:, 1], 50),
        "delay_ms_p99": pct(both[:, 1], 99),
        "delay_ms_max": pct(both[:, 1], 100),
        "age_ms_p50": pct(ages, 50),
        "age_ms_p99": pct(ages, 99),
        "messages": int(both.shape[0]),
        "missing": sum(r.get("missing", 0) for r in results),
        "moves": sum(len(r["moves"]) for r in results),
        "refused": sum(r["refused"] for r in results),
        "lost": sum(len(r["lost"]) for r in results),
        "retaken": sum(r.get("retaken", 0) for r in results),
        "per_student": per_student,
        "per_minute": per_minute,
    }


def measure_multi_user(
    minutes: float = 10.0,
    students: int = 5,
    logs: Path | None = None,
    progress: Callable[[str], None] = lambda s: print(s, file=sys.stderr, flush=True),
) -> dict[str, Any]:
    """One world, ``students`` student processes for ``minutes``; the ``multi_user`` member of ``bench paper --json``."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="bench-paper-multi-") as tmp:
        return _run(minutes, students, logs or Path(tmp), progress)


def _run(minutes: float, n: int, logs: Path, progress: Callable[[str], None]) -> dict[str, Any]:
    import numpy as np

    from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, wait_until

    world, port = f"multi{uuid.uuid4().hex[:6]}", free_port()
    ep = f"tcp/127.0.0.1:{port}"
    logs.mkdir(parents=True, exist_ok=True)
    outs = [str(logs / f"s{i}.json") for i in range(n)]
    with ProcessGroup(logs) as procs:
        router = procs.start(robofabric_cmd("router", "--world", world, "--listen", ep), name="router")
        wait_until(
            lambda: "listening" in procs.output(router),
            timeout=120,
            what="the router",
            seen=lambda: procs.output(router)[-500:],
        )
        robots = [x for i in range(n) for x in ("--robot", f"meca500:arm{i}", "--robot", f"reeman:base{i}")]
        sim = procs.start(
            robofabric_cmd(
                "sim",
                "--scene",
                "warehouse",
                "--no-scene-robots",
                *robots,
                "--world",
                world,
                "--connect",
                ep,
                "--id",
                "sim",
            ),
            name="sim",
        )
        kids = [procs.start([*STUDENT, world, ep, str(i), str(n), out], name=f"s{i}") for i, out in enumerate(outs)]
        progress(f"multi-user: {n} students joining {world}")
        wait_until(
            lambda: all(Path(o + ".ready").exists() for o in outs),
            timeout=400,
            interval=0.5,
            what="every student owning her robots",
            seen=lambda: [procs.output(k)[-300:] for k in kids if k.poll() is not None][:2] or procs.output(sim)[-500:],
        )
        start = time.time() + 1.0
        end = start + 60.0 * minutes
        for o in outs:
            Path(o + ".go").write_text(json.dumps([start, end]))
        load0 = os.getloadavg()
        cpu0 = {name: proc_cpu_s(p.pid) for name, p in (("router", router), ("sim", sim))}
        rss0 = {name: proc_rss_mb(p.pid) for name, p in (("router", router), ("sim", sim))}
        progress(f"multi-user: {n} students for {minutes:g} min")
        wait_until(lambda: time.time() > end, timeout=60 * minutes + 30, interval=1.0, what="the end of the test")
        cpu1 = {name: proc_cpu_s(p.pid) for name, p in (("router", router), ("sim", sim))}
        rss1 = {name: proc_rss_mb(p.pid) for name, p in (("router", router), ("sim", sim))}
        load1 = os.getloadavg()
        wait_until(
            lambda: all(k.poll() is not None for k in kids),
            timeout=180,
            interval=0.5,
            what="every student done",
            seen=lambda: [procs.output(k)[-300:] for k in kids if k.poll() is None][:2],
        )
        results = [
            json.loads(Path(o).read_text())
            if Path(o).exists()
            else {"student": f"s{i}", "moves": [], "refused": 0, "lost": [], "errors": ["no result"]}
            for i, o in enumerate(outs)
        ]
        delays = [np.load(o + ".npy") if Path(o + ".npy").exists() else np.zeros((0, 2)) for o in outs]
    doc = summarise(results, delays, start, minutes)
    doc.update(
        students=n,
        minutes=minutes,
        robots=2 * n,
        scene="warehouse",
        world=world,
        streams="flange pose 100 Hz (arms), pose 50 Hz (bases)",
        age_period_s=AGE_PERIOD_S,
        cpu_cores={k: (cpu1[k] - cpu0[k]) / (end - start) for k in cpu0},
        rss_mb={k: [round(rss0[k], 1), round(rss1[k], 1)] for k in rss0},  # start, end: growth over the run
        load_average=[round(load0[0], 1), round(load1[0], 1)],
        paper_reported=PAPER_MULTI_USER,
    )
    return doc


def format_multi_user(doc: dict[str, Any]) -> str:
    """The multi-user test as markdown: one row per student and the whole class, beside the paper's figure."""
    paper = doc["paper_reported"]
    lines = [
        f"Multi-user test: {doc['students']} students, {doc['minutes']:g} min, {doc['robots']} robots ({doc['scene']}); "
        f"load average {doc['load_average'][0]} at the start, {doc['load_average'][1]} at the end; "
        f"router {doc['cpu_cores']['router']:.2f} cores, sim {doc['cpu_cores']['sim']:.2f}; RSS from start to end: "
        f"router {doc['rss_mb']['router'][0]:.0f} -> {doc['rss_mb']['router'][1]:.0f} MB, sim {doc['rss_mb']['sim'][0]:.0f} -> {doc['rss_mb']['sim'][1]:.0f} MB",
        "",
        "| student | delay p50 / p99 (ms) | age p50 / p99 (ms) | poses received | missing | arm moves | refused | robots lost / taken again | real-time factor |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in doc["per_student"]:
        lines.append(
            f"| {r['student']} | {r['delay_ms_p50']:.1f} / {r['delay_ms_p99']:.1f} | {r['age_ms_p50']:.1f} / {r['age_ms_p99']:.1f} | "
            f"{r['messages']} | {r['missing']} | {r['moves']} | {r['refused']} | {len(r['lost'])} / {r['retaken']} | {r['rtf']:.3f} |"
        )
    lines.append(
        f"| all | {doc['delay_ms_p50']:.1f} / {doc['delay_ms_p99']:.1f} (max {doc['delay_ms_max']:.0f}) | "
        f"{doc['age_ms_p50']:.1f} / {doc['age_ms_p99']:.1f} | {doc['messages']} | {doc['missing']} | {doc['moves']} | "
        f"{doc['refused']} | {doc['lost']} / {doc['retaken']} | |"
    )
    lines.append(
        f"| the paper (PUN, {paper['users']} users, {paper['hours']:g} h) | ~{paper['delay_ms']:.0f} | | | | | | | |"
    )
    lines += [
        "",
        "Per minute, delay p50 / p99 (ms): "
        + "; ".join(f"{m['minute']}: {m['delay_ms_p50']:.1f} / {m['delay_ms_p99']:.1f}" for m in doc["per_minute"]),
    ]
    return "\n".join(lines)


def _main(argv: list[str]) -> None:
    if argv and argv[0] == "student" and len(argv) == 6:
        student(argv[1], argv[2], int(argv[3]), int(argv[4]), argv[5])
    else:
        raise SystemExit("usage: python -m robofabric.bench.paper_multi student WORLD ENDPOINT INDEX N OUT.json")


if __name__ == "__main__":
    _main(sys.argv[1:])
