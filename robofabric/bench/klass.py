"""``robofabric bench class``: a class of N students on one world, each a process owning an arm and a base.

Per class size N, a fresh world: a router, one ``robofabric sim --scene warehouse --no-scene-robots`` with
N Meca500 arms and N Reeman bases, a compute peer, and N student processes (``python -m
robofabric.bench.klass student ...``). Each student joins through the user API, requests ``armI`` and
``baseI``, then for ``--seconds`` turns its base with ``twist`` and moves its arm back and forth with
``move_joints(wait=True)``, and writes what it saw to a JSON file. Meanwhile this process probes the world:
the sim's real-time factor (sim time in the joints headers against the wall clock), the ownership
authority's answer time (a record query every 0.1 s), the messages per second the world publishes (what a
wildcard subscriber receives over a few seconds), and the CPU of the router, the sim and the compute peer.

A robot is *lost* when its owner was told it passed to someone else or became free (``on_lost``); a
*refused* command is one that raised (a rejection, a timeout). Both should be 0 at every size.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from robofabric.bench.common import TableOut, append, end_process, machine, pct, proc_cpu_s

STUDENT = [sys.executable, "-m", "robofabric.bench.klass", "student"]
TARGETS_DEG = ([25.0, 15.0, -15.0, 0.0, 20.0, 0.0], [-25.0, -10.0, 10.0, 0.0, -20.0, 0.0])
"""The two arm poses a student alternates between (well inside the Meca500's limits)."""
STALL_LOSES_S = 1.5
"""A renewal round this late, by the owner's own account, loses her lease on its own: the authority's 2 s lease less
the 0.5 s between rounds (ownership's defaults). A robot lost so went with its owner's stall, not on the way."""


# ---------------------------------------------------------------------- a student (child process)


def student(world: str, endpoint: str, index: int, seconds: float, out: str) -> None:
    """Join, own armI and baseI, drive and move for ``seconds``, write the results to ``out`` (JSON)."""
    import numpy as np

    from user_peer.api import connect
    from user_peer.errors import NotOwner

    t0 = time.monotonic()
    res: dict[str, Any] = {"index": index, "moves": [], "refused": 0, "errors": [], "lost": [], "join_s": None}
    lost: list[str] = []
    try:
        with connect(world, endpoint, user=f"s{index:02d}", timeout=10.0, join_timeout=120.0) as w:
            w.ownership.on_lost(lambda obj, rec: lost.append(f"{obj}: owner {rec.owner or 'none'} epoch {rec.epoch}"))
            arm, base = w.robot(f"arm{index}"), w.robot(f"base{index}")
            arm.request(timeout=30.0)
            base.request(timeout=30.0)
            res["join_s"] = time.monotonic() - t0
            end = time.monotonic() + seconds
            k = 0
            while time.monotonic() < end:
                try:
                    base.twist(0.0, 0.4 if k % 2 else -0.4)
                    t = time.monotonic()
                    arm.move_joints(np.radians(TARGETS_DEG[k % 2]), wait=True, tol=2e-3, timeout=20.0)
                    res["moves"].append(time.monotonic() - t)
                except Exception as exc:  # a refusal or a timeout: counted, and the class goes on
                    res["refused"] += 1
                    if isinstance(exc, NotOwner):  # hers no longer: a lease lost (to her own stall, or not)
                        res["not_owner"] = res.get("not_owner", 0) + 1
                    if len(res["errors"]) < 5:
                        res["errors"].append(f"{type(exc).__name__}: {exc}")
                    time.sleep(0.2)
                k += 1
            try:
                base.twist(0.0, 0.0)
            except Exception:
                pass
            res["renewals_late_s"] = w.ownership.client.renewal.latest_late_s
    except Exception as exc:
        res["errors"].append(f"{type(exc).__name__}: {exc}")
    res["lost"] = lost
    Path(out).write_text(json.dumps(res))


# ---------------------------------------------------------------------- the probe (this process)


class Probe:
    """What this process measures of the world while the class runs (see the module docstring)."""

    def __init__(self, fab: Any, echo: Any, world: str) -> None:
        from fabric import keys
        from fabric.interfaces import JointState, OwnershipRecord

        self.fab, self.world = fab, world
        self.stamps: list[tuple[float, float]] = []  # (wall, sim time) of arm0's joints
        self.own_ms: list[float] = []
        self.count = 0
        self.counting = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        fab.subscribe(keys.robot_joints(world, "arm0"), self._on_joints, expected=JointState)
        # the same round trip to an idle queryable of this process's own second session, through the router:
        # what the machine and the router add, apart from the sim
        self.echo_ms: list[float] = []
        self.echo_key = f"{keys.world_root(world)}/bench/echo"
        self._echo = echo
        echo.rpc.serve(self.echo_key, lambda key, req: OwnershipRecord("echo"))
        self._thread = threading.Thread(target=self._ask_ownership, name="probe-own", daemon=True)

    def _on_joints(self, key: str, js: Any) -> None:
        with self._lock:
            self.stamps.append((time.monotonic(), js.header.stamp))

    def _on_any(self, sample: Any) -> None:
        if self.counting:
            self.count += 1

    def start(self) -> "Probe":
        self._thread.start()
        return self

    def _ask_ownership(self) -> None:
        from fabric import keys
        from fabric.interfaces import ServiceError

        while not self._stop.wait(0.1):
            for key, into in ((keys.own(self.world, "arm0"), self.own_ms), (self.echo_key, self.echo_ms)):
                t = time.perf_counter()
                try:
                    self.fab.rpc.call(key, timeout=5.0)
                except ServiceError:
                    into.append(5000.0)  # unanswered: counted as the time limit
                    continue
                into.append((time.perf_counter() - t) * 1e3)

    def count_messages(self, seconds: float) -> float:
        """Messages per second the world publishes, from a wildcard subscriber over ``seconds``."""
        from fabric import keys

        sub = self.fab.subscribe_raw(keys.world_all(self.world), self._on_any)
        self.count, self.counting = 0, True
        t = time.monotonic()
        time.sleep(seconds)  # the measurement window
        self.counting = False
        n, dt = self.count, time.monotonic() - t
        try:
            sub.undeclare()
        except Exception:
            pass
        return n / dt

    def real_time_factor(self, since: float, until: float) -> float:
        with self._lock:
            pts = [(w, s) for w, s in self.stamps if since <= w <= until]
        if len(pts) < 2 or pts[-1][0] <= pts[0][0]:
            return float("nan")
        return (pts[-1][1] - pts[0][1]) / (pts[-1][0] - pts[0][0])

    def close(self) -> None:
        self._stop.set()
        self._thread.join(6.0)


# ---------------------------------------------------------------------- one class size


def _children_cpu_s() -> float:
    """CPU seconds of this process's children that have ended and been waited for."""
    import resource

    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run_one(n: int, seconds: float, tmp: Path, *, extra: int = 0) -> dict[str, Any]:
    """A class of ``n`` students on a fresh world (plus ``extra`` arms and bases nobody owns, to load the sim);
    the row's figures."""
    from robofabric.testing import ProcessGroup, client, free_port, robofabric_cmd, wait_until

    world = f"class{uuid.uuid4().hex[:6]}"
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
        robots = [x for i in range(n + extra) for x in ("--robot", f"meca500:arm{i}", "--robot", f"reeman:base{i}")]
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
        with (
            client(world, port, kind="tool", peer_id="probe") as fab,
            client(world, port, kind="tool", peer_id="echo") as echo,
        ):
            probe = Probe(fab, echo, world)
            wait_until(
                lambda: len(probe.stamps) > 50,
                timeout=180,
                what="the sim's joints",
                seen=lambda: procs.output(sim)[-1500:],
            )
            probe.start()
            outs = [logs / f"s{i}.json" for i in range(n)]
            cpu0 = {name: proc_cpu_s(p.pid) for name, p in (("router", router), ("sim", sim), ("compute", compute))}
            kids0 = _children_cpu_s()
            t0 = time.monotonic()
            students = [
                procs.start([*STUDENT, world, ep, str(i), str(seconds), str(out)], name=f"s{i}")
                for i, out in enumerate(outs)
            ]
            wait_until(
                lambda: time.monotonic() > t0 + min(20.0, seconds / 2),
                timeout=seconds + 60,
                interval=0.5,
                what="the middle of the class",
            )
            msgs = probe.count_messages(3.0)
            wait_until(
                lambda: all(p.poll() is not None for p in students),
                timeout=seconds + 240,
                interval=0.5,
                what="every student done",
                seen=lambda: [procs.output(p)[-300:] for p in students if p.poll() is None][:2],
            )
            t1 = time.monotonic()
            cpu1 = {name: proc_cpu_s(p.pid) for name, p in (("router", router), ("sim", sim), ("compute", compute))}
            cpu1["students"], cpu0["students"] = (
                _children_cpu_s(),
                kids0,
            )  # the students, reaped by now: the others are not
            probe.close()
            rtf = probe.real_time_factor(t0 + 5.0, t1 - 1.0)
            own_ms, echo_ms = list(probe.own_ms), list(probe.echo_ms)
        for p in (compute, sim, router):
            end_process(p)
        results = [
            json.loads(o.read_text())
            if o.exists()
            else {"moves": [], "refused": 0, "lost": [], "errors": ["no result"], "join_s": None}
            for o in outs
        ]
        why: list[str] = []  # a robot lost, in the peers' own words: the sim's expiry, its owner's renewals
        if any(r["lost"] for r in results):
            why = [line for line in procs.output(sim).splitlines() if "expired" in line][-3:]
            for r, p in zip(results, students):
                if r["lost"]:
                    why += [line for line in procs.output(p).splitlines() if "renewal" in line][-4:]
    moves = [m for r in results for m in r["moves"]]
    joins = [r["join_s"] for r in results if r["join_s"] is not None]
    return {
        "n": n,
        "robots": 2 * (n + extra),
        "joined": len(joins),
        "join_p50": pct(joins, 50),
        "join_max": pct(joins, 100),
        "move_p50": pct(moves, 50),
        "move_p95": pct(moves, 95),
        "moves": len(moves),
        "fewest_moves": min((len(r["moves"]) for r in results), default=0),
        "lost": sum(len(r["lost"]) for r in results),
        # robots whose owner said her own renewals stalled long enough to lose them (STALL_LOSES_S)
        "lost_to_stalls": sum(len(r["lost"]) for r in results if r.get("renewals_late_s", 0.0) >= STALL_LOSES_S),
        "refused": sum(r["refused"] for r in results),
        # of them, commands refused as no longer hers by a student whose own stall lost her robots (she goes on
        # driving what the lease took back: the lease's doing, as the loss itself)
        "refused_after_stalls": sum(
            r.get("not_owner", 0) for r in results if r["lost"] and r.get("renewals_late_s", 0.0) >= STALL_LOSES_S
        ),
        "errors": [e for r in results for e in r["errors"]][:5],
        "lost_detail": [x for r in results for x in r["lost"]][:5] + why,
        "rtf": rtf,
        "own_p50": pct(own_ms, 50),
        "own_p99": pct(own_ms, 99),
        "own_n": len(own_ms),
        "echo_p50": pct(echo_ms, 50),
        "echo_p99": pct(echo_ms, 99),
        "cpu": {k: (cpu1[k] - cpu0[k]) / (t1 - t0) for k in cpu0},
        "msgs": msgs,
    }


def header() -> list[str]:
    return [
        "| students (robots) | joined, p50 / max (s) | move p50 / p95 (s) | vs 1 student | robots lost | refused commands "
        "| sim real-time factor | ownership answer p50 / p99 (ms) | idle echo p50 / p99 (ms) | CPU router / sim / compute / all "
        "students (cores) | messages/s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]


def row(r: dict[str, Any], base: float) -> str:
    ratio = r["move_p50"] / base if base and base == base else float("nan")
    c = r["cpu"]
    return (
        f"| {r['n']} ({r['robots']}) | {r['joined']}/{r['n']}, {r['join_p50']:.1f} / {r['join_max']:.1f} | "
        f"{r['move_p50']:.3f} / {r['move_p95']:.3f} | {ratio:.2f}x | {r['lost']} | {r['refused']} | {r['rtf']:.2f} | "
        f"{r['own_p50']:.1f} / {r['own_p99']:.1f} | {r['echo_p50']:.1f} / {r['echo_p99']:.1f} | {c['router']:.2f} / {c['sim']:.2f} / {c['compute']:.2f} / {c['students']:.2f} | {r['msgs']:.0f} |"
    )


def command(
    students: Annotated[
        str, typer.Option("--students", help="Comma-separated class sizes (each student: one arm, one base).")
    ] = "1,4,8,16,32",
    seconds: Annotated[float, typer.Option("--seconds", help="How long each student drives and moves (s).")] = 40.0,
    extra_robots: Annotated[
        int, typer.Option("--extra-robots", help="Arms and bases (as many of each) nobody owns, to load the sim.")
    ] = 0,
    out: TableOut = None,
    logs: Annotated[
        Optional[Path], typer.Option(help="Keep every process's output and the students' JSON here.")
    ] = None,
) -> None:
    """A class of N students (processes), each owning an arm and a base: join and move times, robots lost,
    refused commands, the sim's real-time factor, ownership answer times, CPU and message rates."""
    from fabric.cli_common import UserError

    try:
        sizes = [int(x) for x in students.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"--students {students!r}: expected sizes like 1,4,8,16,32") from None
    if not sizes or min(sizes) < 1 or seconds <= 0 or extra_robots < 0:
        raise UserError("--students: each size at least 1; --seconds positive; --extra-robots at least 0")
    rows: list[dict[str, Any]] = []
    more = f" --extra-robots {extra_robots}" if extra_robots else ""
    lines = [
        f"Command: `robofabric bench class --students {students} --seconds {seconds:g}{more}`",
        f"Machine: {machine()}; load average at start {os.getloadavg()[0]:.1f}",
        "",
        *header(),
    ]
    print("\n".join(lines), flush=True)
    base = float("nan")
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            r = run_one(n, seconds, logs or Path(tmp), extra=extra_robots)
            rows.append(r)
            if n == 1 or base != base:
                base = r["move_p50"] if n == 1 else base
            lines.append(row(r, base))
            print(lines[-1], flush=True)
            for e in r["errors"] + r["lost_detail"]:
                print(f"    {e}", flush=True)
            if r["lost_to_stalls"]:
                print(f"    of the robots lost, {r['lost_to_stalls']} with their owner's own stall", flush=True)
    per = [r for r in rows if r["n"] > 1 and r["rtf"] == r["rtf"]]
    if per:
        big = max(per, key=lambda r: r["n"])
        cost = big["cpu"]["sim"] / (2 * big["n"]) / max(big["rtf"], 1e-9)
        lines += [
            "",
            f"Sim CPU per robot per second of sim time at {big['n']} students: {cost * 1e3:.1f} ms "
            f"(sim {big['cpu']['sim']:.2f} cores at real-time factor {big['rtf']:.2f} for {2 * big['n']} robots).",
        ]
        print(lines[-1], flush=True)
    append(out, "\n".join(lines))


def _main(argv: list[str]) -> None:
    if argv and argv[0] == "student":
        student(argv[1], argv[2], int(argv[3]), float(argv[4]), argv[5])
    else:
        raise SystemExit("usage: python -m robofabric.bench.klass student WORLD ENDPOINT INDEX SECONDS OUT.json")


if __name__ == "__main__":
    _main(sys.argv[1:])


__all__ = ["command", "student", "run_one"]
