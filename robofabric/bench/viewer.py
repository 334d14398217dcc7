"""``robofabric bench viewer``: what drawing costs the Rerun viewer, per message and for a class world at full rate.

In this process, no network: :class:`user_peer.rerun_log.WorldLogger` (the code behind ``robofabric view``
and ``export``) draws synthetic messages of the ``combined`` scene's robot types into an ``.rrd`` file,
with no thinning (``max_hz=0``), so every message is drawn. It is flushed once per 0.1 s of stream
time, as the live viewer does (``user_peer.viewer``: the messages of a window are drawn as columns), so
a message's cost is its ``log`` call plus its share of the flushes and of Rerun's own threads (the
process's CPU time over the run, the file written included).

1. Per type: a Meca500 JointState (plots, the arm's joint transforms, skeleton), a base's Pose, its wheels'
   JointState, a 240-ray Scan (hits and rays in the world frame) and a 400 x 400 OccupancyGrid (an image),
   each stream alone at its sim rate. The messages change every call (joints sweep, the base drives,
   ranges vary), so nothing is served from a cache that a live stream would miss.
2. A class world: ``--arms`` arms and ``--bases`` bases at the sim's default rates (joints 100 Hz, an arm's
   flange pose 100 Hz, a base's pose 50 Hz, wheels 100 Hz, LIDAR and sonar 20 Hz) for ``--seconds`` of world
   time, interleaved as they arrive: the CPU seconds per second of world time are the share of one core
   the viewer needs to draw that world at full rate.

3. ``--live S``: the same class world for real: a router, ``robofabric sim --scene warehouse --no-scene-robots``
   with the arms and bases, and ``robofabric view --save FILE.rrd --max-hz 0 --duration S`` as its own
   process; its own count of messages logged and dropped, its lag, and its CPU (from /proc) per second.

4. ``--pages N``: N headless Chromium pages (plus ``--stalled`` paused ones) on one ``view --serve-web`` of the
   ``combined`` world, each page's lag read from the page itself (robofabric/bench/viewer_web.py).

For a before/after comparison the same command runs against another checkout's ``user_peer`` (put it first
on ``PYTHONPATH``): a WorldLogger without ``flush`` draws row by row in ``log``, and is measured the same way.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path
from typing import Annotated, Any, Callable, Iterator

import numpy as np
import typer

from robofabric.bench.common import TableOut, append, machine

__all__ = ["measure", "measure_world", "format_table", "command"]

WORLD = "benchview"
WINDOW_NS = 100_000_000  # the live viewer's drawing window
RATES = {"joints": 100.0, "flange": 100.0, "pose": 50.0, "wheels": 100.0, "scan": 20.0, "sonar": 20.0, "grid": 2.0}


class _Streams:
    """Synthetic messages of the scene's robot types, built on demand (their cost is not timed)."""

    def __init__(self, seed: int) -> None:
        import robots

        self.rng = np.random.default_rng(seed)
        self.arm = robots.load("meca500")
        self.lo, self.hi = np.asarray(self.arm.lower), np.asarray(self.arm.upper)
        self.wheels = robots.load("reeman").joint_names

    def make(self, kind: str, rid: str, i: int, t_ns: int) -> tuple[str, Any]:
        from fabric import keys
        from fabric.interfaces import Header, JointState, OccupancyGrid, Pose, Scan

        h = Header(stamp=t_ns * 1e-9 + 1e-3, wall_ns=1_700_000_000_000_000_000 + t_ns, seq=i, source="bench")
        phase = (hash(rid) % 100) / 10
        if kind == "joints":
            s = 0.5 + 0.5 * math.sin(i / 50 + phase)
            q = self.lo + (self.hi - self.lo) * (s * 0.8 + 0.1)
            return keys.robot_joints(WORLD, rid), JointState(self.arm.joint_names, q, np.full(self.arm.dof, 0.1), h)
        if kind == "flange":
            return keys.robot_pose(WORLD, rid), Pose(np.array([0.2, 0.1 * math.sin(i / 30), 0.3]), header=h)
        if kind == "wheels":
            return keys.robot_joints(WORLD, rid), JointState(
                self.wheels, np.array([i * 0.05, i * 0.06]), np.array([5.0, 6.0]), h
            )
        if kind == "pose":
            yaw = i * 0.01 + phase
            return keys.robot_pose(WORLD, rid), Pose(
                np.array([math.cos(yaw), math.sin(yaw), 0.0]),
                np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]),
                np.array([0.3, 0.0, 0.0]),
                np.array([0.0, 0.0, 0.3]),
                header=h,
            )
        if kind == "scan":
            ranges = self.rng.uniform(0.2, 14.0, 240)  # some beyond 12 m: misses, as in a real room
            return keys.robot_scan(WORLD, rid), Scan.from_ranges(
                ranges, angle_min=-1.178, angle_increment=2.356 / 239, range_max=12.0, header=h
            )
        if kind == "sonar":
            return keys.robot_stream(WORLD, rid, "sonar"), Scan.from_ranges(
                self.rng.uniform(0.1, 3.5, 8), angle_min=0.0, angle_increment=math.pi / 4, range_max=3.0, header=h
            )
        if kind == "grid":
            cells = np.full((400, 400), 255, np.uint8)
            cells[: 40 + i % 300, :] = 0
            cells[self.rng.integers(0, 400, 2000), self.rng.integers(0, 400, 2000)] = 100
            return keys.map_key(WORLD, "map"), OccupancyGrid(0.05, np.array([-10.0, -10.0, 0.0]), cells, h)
        raise ValueError(kind)


def _schedule(streams: list[tuple[str, str]], seconds: float) -> Iterator[tuple[int, str, str, int]]:
    """(time ns, kind, robot, index) of every message of ``streams`` (kind, robot) at their rates, in time order."""
    events = []
    for n, (kind, rid) in enumerate(streams):
        period = int(1e9 / RATES[kind])
        offset = (n * 7_919_000) % period  # streams do not tick together
        events.extend((offset + i * period, kind, rid, i) for i in range(int(seconds * RATES[kind])))
    events.sort()
    return iter(events)


def _run(
    streams: list[tuple[str, str]], seconds: float, seed: int, tmp: Path, clock: Callable[[], float] = time.process_time
) -> dict[str, Any]:
    """Draw every message of ``streams`` for ``seconds`` of world time; CPU seconds of log calls and flushes."""
    import rerun as rr

    from user_peer.catalog import RobotCatalog
    from user_peer.rerun_log import WorldLogger

    gen = _Streams(seed)
    msgs = [(t, *gen.make(kind, rid, i, t), kind, rid) for t, kind, rid, i in _schedule(streams, seconds)]
    rec = rr.RecordingStream("robofabric-bench-viewer")
    rec.save(str(tmp / f"bench-{len(streams)}-{seed}.rrd"))
    logger = WorldLogger(rec, drawing=RobotCatalog(scene="combined").drawing, max_hz=0)
    flush = getattr(logger, "flush", None)  # None: a row-by-row logger (an older checkout) draws in log()
    # the first message of each stream sets up static geometry and Rerun's caches: drawn, not timed
    seen: set[tuple[str, str]] = set()
    first = []
    for m in msgs:
        if (m[3], m[4]) not in seen:
            seen.add((m[3], m[4]))
            first.append(m)
    for t, key, msg, _kind in ((m[0], m[1], m[2], m[3]) for m in first):
        logger.log(key, msg, t)
    if flush is not None:
        flush()
    firsts = {id(m) for m in first}
    rec.flush()
    n = 0
    next_flush = WINDOW_NS
    c0 = clock()
    for m in msgs:
        if id(m) in firsts:
            continue
        t, key, msg = m[0], m[1], m[2]
        if flush is not None and t >= next_flush:
            flush()
            next_flush = (t // WINDOW_NS + 1) * WINDOW_NS
        if not logger.log(key, msg, t):
            raise RuntimeError(f"the viewer did not draw {key}")
        n += 1
    if flush is not None:
        flush()
    rec.flush()  # Rerun's own threads (batching, encoding, the file) count too
    cost = clock() - c0
    return {
        "n": n,
        "cpu_s": cost,
        "us_per_msg": cost / max(n, 1) * 1e6,
        "per_s": n / cost if cost > 0 else float("inf"),
    }


def measure(n: int = 2000, grids: int = 200, seed: int = 0) -> dict[str, dict]:
    """Per message type, each stream alone at its rate: messages drawn, mean cost (us, log + share of the
    flushes), messages per CPU second."""
    kinds = {
        "JointState": [("joints", "arm1")],
        "Pose": [("pose", "base1")],
        "wheels": [("wheels", "base1")],
        "Scan": [("scan", "base1")],
        "OccupancyGrid": [("grid", "map")],
    }
    result: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="bench-viewer-") as tmp:
        for name, streams in kinds.items():
            count = grids if name == "OccupancyGrid" else n
            kind = streams[0][0]
            result[name] = _run(streams, count / RATES[kind], seed, Path(tmp))
    return result


def measure_world(arms: int = 8, bases: int = 8, seconds: float = 20.0, seed: int = 0) -> dict[str, Any]:
    """A class world at the sim's default rates: messages, CPU s, us per message, share of one core."""
    streams = [(k, f"arm{i}") for i in range(arms) for k in ("joints", "flange")]
    streams += [(k, f"base{i}") for i in range(bases) for k in ("pose", "wheels", "scan", "sonar")]
    with tempfile.TemporaryDirectory(prefix="bench-viewer-") as tmp:
        r = _run(streams, seconds, seed, Path(tmp))
    r.update(arms=arms, bases=bases, seconds=seconds, rate=r["n"] / seconds, core=r["cpu_s"] / seconds)
    return r


LABELS = {
    "JointState": "JointState (Meca500: 6+6 plots, joint transforms, skeleton), 100 Hz",
    "Pose": "Pose (mobile base: transform, plots, Eq. 8 age), 50 Hz",
    "wheels": "JointState (a base's two wheels: plot), 100 Hz",
    "Scan": "Scan (240 rays: hits as points + rays as lines, world frame), 20 Hz",
    "OccupancyGrid": "OccupancyGrid 400x400 (image), 2 Hz",
}


def measure_live(arms: int, bases: int, seconds: float) -> dict[str, Any]:
    """A real sim world and a real ``view --save --max-hz 0`` process: the viewer's counts, lag and CPU share."""
    import re
    import uuid

    from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, wait_until
    from robofabric.bench.common import end_process, proc_cpu_s

    world = f"bv{uuid.uuid4().hex[:6]}"
    ep = f"tcp/127.0.0.1:{free_port()}"
    robots = [x for i in range(arms) for x in ("--robot", f"meca500:arm{i}")]
    robots += [x for i in range(bases) for x in ("--robot", f"reeman:base{i}")]
    with tempfile.TemporaryDirectory(prefix="bench-viewer-live-") as tmp, ProcessGroup(Path(tmp)) as procs:
        router = procs.start(robofabric_cmd("router", "--world", world, "--listen", ep), name="router")
        wait_until(
            lambda: "listening" in procs.output(router),
            timeout=60,
            what="the router",
            seen=lambda: procs.output(router),
        )
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
        wait_until(
            lambda: "Ctrl-C to stop" in procs.output(sim),
            timeout=180,
            what="the sim",
            seen=lambda: procs.output(sim)[-1500:],
        )
        view = procs.start(
            robofabric_cmd(
                "view",
                "--save",
                str(Path(tmp) / "live.rrd"),
                "--max-hz",
                "0",
                "--duration",
                str(seconds),
                "--world",
                world,
                "--connect",
                ep,
            ),
            name="view",
        )
        wait_until(
            lambda: "viewer on world" in procs.output(view),
            timeout=120,
            what="the viewer",
            seen=lambda: procs.output(view)[-1500:],
        )
        cpu0, t0 = proc_cpu_s(view.pid), time.monotonic()
        cpu1, t1 = cpu0, t0
        while view.poll() is None and time.monotonic() < t0 + seconds + 120:
            if time.monotonic() < t0 + seconds:  # its drawing, not its closing flush
                cpu1, t1 = proc_cpu_s(view.pid), time.monotonic()
            time.sleep(0.5)
        out = procs.output(view)
        for p in (view, sim, router):
            end_process(p)
    m = re.search(
        r"viewer: (\d+) messages logged, (\d+) dropped, (\d+) thinned(?:; lag p50 (\d+) ms, max (\d+) ms)?", out
    )
    if m is None:
        raise RuntimeError(f"the viewer said no summary: {out[-1500:]}")
    logged, dropped = int(m.group(1)), int(m.group(2))
    return {
        "arms": arms,
        "bases": bases,
        "seconds": seconds,
        "logged": logged,
        "dropped": dropped,
        "rate": logged / seconds,
        "lag_p50": float(m.group(4) or "nan"),
        "lag_max": float(m.group(5) or "nan"),
        "core": (cpu1 - cpu0) / max(t1 - t0, 1e-9),
    }


def format_table(
    result: dict[str, dict], world: dict[str, Any] | None = None, live: dict[str, Any] | None = None
) -> str:
    lines = [
        "| message | drawn | mean cost (us of process CPU per message) | throughput (msg per CPU s) |",
        "|---|---|---|---|",
    ]
    for kind, r in result.items():
        lines.append(f"| {LABELS[kind]} | {r['n']} | {r['us_per_msg']:.0f} | {r['per_s']:.0f} |")
    if world is not None:
        w = world
        lines += [
            "",
            f"Class world, {w['arms']} arms + {w['bases']} bases at full rate ({w['rate']:.0f} msg/s) for {w['seconds']:g} s "
            f"of world time: {w['n']} messages drawn in {w['cpu_s']:.2f} CPU s: **{w['us_per_msg']:.0f} us per message, "
            f"{w['core'] * 100:.0f} % of one core**.",
        ]
    if live is not None:
        v = live
        lines += [
            "",
            f"Live: `robofabric sim` with {v['arms']} arms + {v['bases']} bases, `robofabric view --save --max-hz 0` for "
            f"{v['seconds']:g} s: **{v['logged']} messages logged ({v['rate']:.0f}/s), {v['dropped']} dropped**, viewer lag "
            f"p50 {v['lag_p50']:.0f} ms, max {v['lag_max']:.0f} ms, viewer process {v['core'] * 100:.0f} % of one core.",
        ]
    return "\n".join(lines)


def command(
    n: Annotated[int, typer.Option("--n", help="Messages per type (JointState, Pose, wheels, Scan).")] = 2000,
    grids: Annotated[int, typer.Option(help="Occupancy grids (400x400) to draw.")] = 200,
    arms: Annotated[int, typer.Option(help="Arms in the class world (0 with --bases 0: no world run).")] = 8,
    bases: Annotated[int, typer.Option(help="Mobile bases in the class world.")] = 8,
    seconds: Annotated[float, typer.Option(help="World time of the class world (s).")] = 20.0,
    seed: Annotated[int, typer.Option(help="Seed of the synthetic scans and grids.")] = 0,
    live: Annotated[
        float,
        typer.Option(
            help="Also run the class world for real for this many seconds (a sim and a view process; 0: not)."
        ),
    ] = 0.0,
    out: TableOut = None,
    pages: Annotated[
        int,
        typer.Option(
            help="Also open this many browser pages (headless chromium) on `view --serve-web` and read each one's lag from the page (0: not)."
        ),
    ] = 0,
    stalled: Annotated[int, typer.Option(help="With --pages: further pages, paused once they show the world.")] = 1,
    page_seconds: Annotated[float, typer.Option(help="With --pages: how long their lag is sampled (s).")] = 60.0,
    page_width: Annotated[int, typer.Option(help="With --pages: page width in pixels (height 5/8 of it).")] = 640,
    page_window: Annotated[float, typer.Option(help="With --pages: the viewer's --window.")] = 0.5,
    page_max_hz: Annotated[float, typer.Option(help="With --pages: the viewer's --max-hz.")] = 5.0,
) -> None:
    """Cost of drawing in the Rerun viewer (WorldLogger to an .rrd file): per message type, and a class world at full rate."""
    from fabric.cli_common import UserError

    if n < 2 or grids < 2:
        raise UserError("--n and --grids must be at least 2 (the first of each stream is not timed)")
    if arms < 0 or bases < 0 or seconds <= 0:
        raise UserError("--arms and --bases at least 0, --seconds positive")
    world = measure_world(arms, bases, seconds, seed) if arms + bases else None
    real = measure_live(arms, bases, live) if live > 0 and arms + bases else None
    table = f"{machine()}\n\n" + format_table(measure(n, grids, seed), world, real)
    if pages > 0:  # browsers on one served viewer (robofabric/bench/viewer_web.py)
        from robofabric.bench import viewer_web

        r = viewer_web.run(
            pages,
            stalled,
            page_seconds,
            page_width,
            ["--window", f"{page_window:g}", "--max-hz", f"{page_max_hz:g}"],
            log=lambda *a: None,
        )
        s = viewer_web.summary(r)
        table += (
            f"\n\nBrowsers: {pages} live pages + {stalled} paused on one `view --serve-web --window {page_window:g} "
            f"--max-hz {page_max_hz:g}`, {page_width}x{page_width * 5 // 8}: all showing the world after {r['ready_s']:.0f} s; "
            f"lag read from each page over {page_seconds:g} s: p50 {s['p50']:.1f} s, p90 {s['p90']:.1f} s, max {s['max']:.1f} s; "
            f"{min(r['fps']):.1f}-{max(r['fps']):.1f} frames/s per page; paused pages cut off by the relay: {len(r['cut'])}; "
            f"'sender blocked' reports: {r['blocked']}."
        )
    print(table)
    append(out, table)
