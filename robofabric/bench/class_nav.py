"""``robofabric bench class-nav``: N students do the paper's Test B at once, in one warehouse, each a process.

A fresh world: a router, one ``robofabric sim --scene warehouse --no-scene-robots`` with N Reeman bases on a row
across the hall (y = 0, 1 to 2 m apart), a compute peer, and N student processes (``python -m
robofabric.bench.class_nav student ...``). Each student joins through the user API, requests ``baseI``, turns it
on the spot a little more than once around (the other bases in view of its LIDAR, and it in theirs), builds her
own map, plans on it to a goal across the room (an aisle behind the shelves, through the gap between two:
:func:`goal_of`),
follows the path, plans again when her base reports ``blocked``, and writes what she saw to a JSON file.

Per student: whether the base ended within 0.1 m of the goal, each plan's round trip, the base's stops for
something in its way (``obstacle_stop`` / ``waiting`` events), its collisions (bumper ``collision`` events), and
the cells of her map within a robot's radius of any base's centre at the time of the build that are occupied
(robots kept as walls; 0 when maps hold the world, not the robots in it: docs/navigation.md).
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from robofabric.bench.common import TableOut, append, end_process, machine, pct

STUDENT = [sys.executable, "-m", "robofabric.bench.class_nav", "student"]
RADIUS = 0.30  # the Reeman's, about its turn point
REACHED = 0.1  # m from the goal that counts as reached
ATTEMPTS = 5  # plans a student makes before she gives up


def placements(n: int) -> list[tuple[float, float, float]]:
    """Where the N bases start: a row across the hall at y = 0 (x within [-3.5, 3.5]), facing +x."""
    if n == 1:
        return [(0.0, 0.0, 0.0)]
    span = min(7.0, 2.0 * (n - 1))
    return [(-span / 2 + span * i / (n - 1), 0.0, 0.0) for i in range(n)]


GOAL_Y = 4.5
"""The aisle behind the shelves (y 2.8 to 5.0 north; mirrored south): goals 0.5 m from its wall, so that a base
parked at its goal leaves a lane between it and the shelves (y 3.2 to 3.7 for the turn point) to the bases going on."""
SLOTS = (1.2, 2.5)
"""|x| of the goals along the aisle. A student maps the hall from her start, so she knows the aisle only through
the gap between the shelves (|x| < 1): the goal, and the floor around it, must lie in that cone (goals at |x| 3.5
lay in unknown space, planned for as an obstacle). From (+-1, 0) the cone at y 4.5 reaches |x| 2.2 on the far side,
from (+-3, 0) |x| 0.2 to 3.4."""


def goal_of(index: int, start: tuple[float, float, float], n: int) -> tuple[float, float, float]:
    """A goal across the room, in an aisle behind the shelves, reached through the gap between two of them.

    Up to 4 bases all go north; with more, odd students go south. A base starting west of the hall's middle goes
    east, the others west, so that the paths cross in the gap, where bases meet. Each side's goals are slots
    along the aisle (:data:`SLOTS`): of two bases going one way, the one starting further out takes the further
    slot (the nearer one takes the nearer: the further lies outside what it saw through the gap); a base alone
    takes the slot nearest its start mirrored through the gap's middle. Goals face the way the base goes, 1.3 m
    apart or more, and off the lane from the gap along the aisle. ``start`` is the base's own
    (:func:`placements`)."""
    south = n > 4 and index % 2 == 1
    x0 = start[0]
    side = [
        placements(n)[i][0]
        for i in range(n)
        if (n > 4 and i % 2 == 1) == south and (placements(n)[i][0] < 0) == (x0 < 0)
    ]
    if len(side) > 1:
        slot = SLOTS[1] if abs(x0) == max(abs(v) for v in side) else SLOTS[0]
    else:
        slot = min(SLOTS, key=lambda s: abs(s - 0.8 * abs(x0)))
    x = slot if x0 < 0 else -slot
    return (x, -GOAL_Y if south else GOAL_Y, 0.0 if x > 0 else math.pi)


# ---------------------------------------------------------------------- a student (child process)


def _at(p: Any, goal: tuple[float, float, float]) -> bool:
    """Her base stands within 0.1 m of its goal, stopped."""
    return (
        p is not None
        and math.hypot(p.position[0] - goal[0], p.position[1] - goal[1]) < REACHED
        and math.hypot(p.linear[0], p.linear[1]) < 0.02
        and abs(p.angular[2]) < 0.05
    )


def _stopped(events: list[Any], robot: str) -> str:
    """Why her base stopped short of its goal, from the events since she sent the path: "blocked" (its way guard
    dropped the path), "bumped" (the bumper stopped it: a collision, counted as one, and the path is gone), "done"
    (the path ended, not within 0.1 m: a goal moved off an obstacle), or "" (still going). Each is what a student
    in the console sees, and each makes her plan again."""
    from fabric.interfaces import EventKind

    for e in events:
        if e.object != robot:
            continue
        if e.kind == EventKind.OBSTACLE_STOP and e.reason == "blocked":
            return "blocked"
        if e.kind == EventKind.COLLISION:
            return "bumped"
        if e.kind == EventKind.PATH_DONE:
            return "done"
    return ""


def student(world: str, endpoint: str, index: int, n: int, out: str, reverse_when_asked: bool = True) -> None:
    """Join, own baseI, map by turning, build her map, plan across the room, follow; results to ``out`` (JSON).

    ``reverse_when_asked``: a refusal that asks "allow reversing?" (a forward-only base with no first move forwards,
    beside another base) is answered as a student does in the console, by ticking "reverse" and planning again."""
    import numpy as np

    from compute_peer.navigation.robot_cells import Footprint, robot_cells
    from fabric import keys
    from fabric.interfaces import EventKind, Pose
    from user_peer.api import connect

    start = placements(n)[index]
    goal = goal_of(index, start, n)
    res: dict[str, Any] = {
        "index": index,
        "plans": [],
        "reached": False,
        "final": None,
        "stops": 0,
        "collisions": 0,
        "blocked": 0,
        "robot_cells": None,
        "errors": [],
        "notes": [],
    }
    try:
        with connect(world, endpoint, user=f"s{index:02d}", timeout=10.0, join_timeout=120.0) as w:
            poses: dict[str, Any] = {}
            w.fabric.subscribe(
                keys.robot_stream_all(w.name, "pose"),
                lambda k, m: poses.__setitem__(keys.parse(k).subject, m),
                expected=Pose,
            )
            base = w.robot(f"base{index}")
            base.request(timeout=30.0)
            until = time.monotonic() + 30.0
            while not base.can_command and time.monotonic() < until:  # the grant's record on its way here
                time.sleep(0.1)
            mark = w.event_mark()

            def look_around() -> None:
                """Turn a little more than once around at 1.2 rad/s, then press Build map (again, after a failure
                to answer, up to 3 times): the robot cells of every map she builds are counted, the most kept."""
                base.twist(0.0, 1.2)
                time.sleep(2 * math.pi / 1.2 + 1.5)
                base.twist(0.0, 0.0)
                time.sleep(0.5)
                for attempt in range(3):
                    try:
                        built = base.build_map()
                        break
                    except Exception as exc:  # a loaded compute peer that did not answer: she presses it again
                        res["errors"].append(f"build: {exc}"[:300])
                        if attempt == 2:
                            raise
                        time.sleep(2.0)
                at_build = {rid: (float(p.position[0]), float(p.position[1])) for rid, p in poses.items()}
                cells = robot_cells(built, [Footprint(x, y, RADIUS) for x, y in at_build.values()], margin=0.0)
                res["robot_cells"] = max(cells, res["robot_cells"] or 0)
                res["robots_seen"] = len(at_build)
                res["builds"] = res.get("builds", 0) + 1
                res["map"] = {
                    "resolution": float(built.resolution),
                    "origin": [float(v) for v in built.origin[:2]],
                    "shape": list(built.cells.shape),
                }
                np.save(Path(out).with_suffix(".map.npy"), np.asarray(built.cells))  # beside her results, to look at

            look_around()
            my_map = keys.user_map("map", w.user)
            deadline = time.monotonic() + 150.0
            direction = "default"
            for _ in range(ATTEMPTS):
                t = time.perf_counter()
                try:
                    path = base.plan_to(*goal, map_name=my_map, direction=direction)
                except Exception as exc:  # refused: counted, and she tries again after a moment
                    res["errors"].append(f"plan: {exc}"[:300])
                    if reverse_when_asked and "allow reversing?" in str(exc) and direction != "both":
                        direction = "both"
                        res["notes"].append(f"base{index}: planning again with reversing allowed")
                    elif "cannot drive away" in str(exc) or "unknown space" in str(exc):
                        res["notes"].append(
                            f"base{index}: her map holds no way out: looking around and building it again"
                        )
                        look_around()  # what she sees in the console: her map has walls or unknown all around her
                    time.sleep(2.0)
                    continue
                res["plans"].append(time.perf_counter() - t)
                if base.plan_note:
                    res["notes"].append(base.plan_note[:200])
                since = w.event_mark()
                base.follow(path, wait=False)
                outcome = ""
                while time.monotonic() < deadline and not outcome:
                    time.sleep(0.1)
                    if _at(base.pose, goal):
                        outcome = "reached"
                    else:
                        outcome = _stopped(w.events[since:], base.id)
                if outcome == "reached":
                    break
                res["blocked"] += outcome == "blocked"
                if not outcome:
                    break  # out of time
                time.sleep(
                    1.0
                )  # she reads what it said (and its pose catches up), then plans again from where it stands
                if _at(base.pose, goal):
                    break
            p = base.pose
            if p is not None:
                d = math.hypot(p.position[0] - goal[0], p.position[1] - goal[1])
                res["final"], res["reached"] = d, d < REACHED
            mine = [e for e in w.events[mark:] if e.object == base.id]
            res["stops"] = sum(e.kind == EventKind.OBSTACLE_STOP and e.reason == "waiting" for e in mine)
            res["said"] = [
                f"{base.id} {e.reason}: {e.data.get('detail', '')}"[:200]
                for e in mine
                if e.kind in (EventKind.OBSTACLE_STOP, EventKind.COLLISION)
            ][:8]
            res["collisions"] = sum(e.kind == EventKind.COLLISION for e in mine)
            base.stop()
    except Exception as exc:
        res["errors"].append(f"{type(exc).__name__}: {exc}"[:300])
    Path(out).write_text(json.dumps(res))


# ---------------------------------------------------------------------- one class


def run_one(n: int, tmp: Path, reverse_when_asked: bool = True) -> dict[str, Any]:
    """A class of ``n`` students on a fresh world; the row's figures."""
    from robofabric.testing import ProcessGroup, client, free_port, robofabric_cmd, wait_until
    from fabric import keys
    from fabric.interfaces import Pose

    world = f"cnav{uuid.uuid4().hex[:6]}"
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    logs = tmp / f"n{n}"
    logs.mkdir(parents=True, exist_ok=True)
    with ProcessGroup(logs) as procs:
        router = procs.start(robofabric_cmd("router", "--world", world, "--listen", ep), name="router")
        wait_until(
            lambda: "listening" in procs.output(router),
            timeout=60,
            what="the router",
            seen=lambda: procs.output(router),
        )
        robots = [
            x
            for i, (px, py, yaw) in enumerate(placements(n))
            for x in ("--robot", f"reeman:base{i}@{px:g},{py:g},{math.degrees(yaw):g}")
        ]
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
        compute = procs.start(
            robofabric_cmd("compute", "--world", world, "--connect", ep, "--id", "compute"), name="compute"
        )
        with client(world, port, kind="tool", peer_id="probe") as fab:
            seen: set[str] = set()
            fab.subscribe(
                keys.robot_stream_all(world, "pose"), lambda k, m: seen.add(keys.parse(k).subject), expected=Pose
            )
            wait_until(
                lambda: len(seen) >= n, timeout=180, what="every base's pose", seen=lambda: procs.output(sim)[-1500:]
            )
            outs = [logs / f"s{i}.json" for i in range(n)]
            t0 = time.monotonic()
            policy = "reverse-when-asked" if reverse_when_asked else "forward-only"
            students = [
                procs.start([*STUDENT, world, ep, str(i), str(n), str(out), policy], name=f"s{i}")
                for i, out in enumerate(outs)
            ]
            wait_until(
                lambda: all(p.poll() is not None for p in students),
                timeout=400,
                interval=0.5,
                what="every student done",
                seen=lambda: [procs.output(p)[-300:] for p in students if p.poll() is None][:2],
            )
            seconds = time.monotonic() - t0
        for p in (compute, sim, router):
            end_process(p)
        results = [json.loads(o.read_text()) if o.exists() else dict(NO_RESULT) for o in outs]
    return summary(n, results, seconds)


NO_RESULT: dict[str, Any] = {
    "plans": [],
    "reached": False,
    "stops": 0,
    "collisions": 0,
    "blocked": 0,
    "robot_cells": None,
    "errors": ["no result"],
    "final": None,
    "notes": [],
}
"""What a student who wrote nothing counts for: not reached, her map's cells unknown."""


def summary(n: int, results: list[dict[str, Any]], seconds: float) -> dict[str, Any]:
    """A class's row from its ``n`` students' results (pure: the students' JSON in, the figures out)."""
    plans = [t for r in results for t in r["plans"]]
    cells = [r["robot_cells"] for r in results]
    return {
        "n": n,
        "reached": sum(bool(r["reached"]) for r in results),
        "plans": len(plans),
        "plan_p50": pct(plans, 50),
        "plan_p99": pct(plans, 99),
        "stops": sum(r["stops"] for r in results),
        "blocked": sum(r["blocked"] for r in results),
        "collisions": sum(r["collisions"] for r in results),
        "cells": cells,
        "finals": [r["final"] for r in results],
        "seconds": seconds,
        "errors": [e for r in results for e in r["errors"]][:6],
        "notes": [x for r in results for x in r["notes"]][:4],
        "said": [x for r in results for x in r.get("said", ())],
    }


def verdict(r: dict[str, Any]) -> str:
    """The budget line: "met" when every base reached its goal, none bumped and no map holds a robot's cell;
    otherwise what missed it. A map not measured (its student wrote nothing) is no pass."""
    missed = []
    if r["reached"] < r["n"]:
        missed.append(f"{r['n'] - r['reached']} of {r['n']} short of their goals")
    if r["collisions"]:
        missed.append(f"{r['collisions']} collisions")
    if any(c is None or c > 0 for c in r["cells"]):
        missed.append("robot cells in a map (or a map not measured)")
    return f"{r['n']} bases: budget " + ("met" if not missed else "not met: " + ", ".join(missed))


def header() -> list[str]:
    return [
        "| bases | reached within 0.1 m | plans, time p50 / p99 (s) | stops for something in the way | blocked "
        "| collisions (bumper) | robot cells in each map | final distance to goal (m) | wall time (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]


def row(r: dict[str, Any]) -> str:
    finals = ", ".join("-" if f is None else f"{f:.3f}" for f in r["finals"])
    cells = ", ".join("-" if c is None else str(c) for c in r["cells"])
    return (
        f"| {r['n']} | {r['reached']}/{r['n']} | {r['plans']}, {r['plan_p50']:.2f} / {r['plan_p99']:.2f} | {r['stops']} | "
        f"{r['blocked']} | {r['collisions']} | {cells} | {finals} | {r['seconds']:.0f} |"
    )


def command(
    bases: Annotated[
        str, typer.Option("--bases", help="Comma-separated class sizes (each student: one base).")
    ] = "4,8",
    out: TableOut = None,
    logs: Annotated[
        Optional[Path], typer.Option(help="Keep every process's output and the students' JSON here.")
    ] = None,
    reverse_when_asked: Annotated[
        bool,
        typer.Option(
            help="A student whose plan is refused with 'allow reversing?' plans again with reversing allowed, as the "
            "console's reverse box lets her; --no-reverse-when-asked keeps her forwards only."
        ),
    ] = True,
) -> None:
    """N students (processes) do Test B at once in the warehouse: reached within 0.1 m, plan time p50/p99, stops for
    something in the way, collisions, and the robot cells left in each student's map."""
    from fabric.cli_common import UserError

    try:
        sizes = [int(x) for x in bases.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"--bases {bases!r}: expected sizes like 4,8") from None
    if not sizes or min(sizes) < 1 or max(sizes) > 8:
        raise UserError("--bases: each size within 1..8 (a row across the warehouse holds 8)")
    flag = "" if reverse_when_asked else " --no-reverse-when-asked"
    lines = [
        f"Command: `robofabric bench class-nav --bases {bases}{flag}`",
        f"Machine: {machine()}; load average at start {os.getloadavg()[0]:.1f}",
        "",
        *header(),
    ]
    print("\n".join(lines), flush=True)
    verdicts: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            r = run_one(n, logs or Path(tmp), reverse_when_asked)
            lines.append(row(r))
            print(lines[-1], flush=True)
            for e in r["errors"] + r["notes"] + r["said"]:
                print(f"    {e}", flush=True)
            verdicts.append(verdict(r))
    lines += ["", *verdicts]
    print("\n".join(verdicts), flush=True)
    lines.append(f"Load average at the end {os.getloadavg()[0]:.1f}.")
    append(out, "\n".join(lines))


def _main(argv: list[str]) -> None:
    if argv and argv[0] == "student":
        student(argv[1], argv[2], int(argv[3]), int(argv[4]), argv[5], argv[6:7] != ["forward-only"])
    else:
        raise SystemExit(
            "usage: python -m robofabric.bench.class_nav student WORLD ENDPOINT INDEX N OUT.json [reverse-when-asked|forward-only]"
        )


if __name__ == "__main__":
    _main(sys.argv[1:])


__all__ = ["command", "goal_of", "placements", "row", "run_one", "student", "summary", "verdict"]
