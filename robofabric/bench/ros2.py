"""``robofabric bench ros2``: N mobile robots at full rate through the ROS 2 bridge, against zenoh's own delivery.

A router, one sim of N bases (warehouse, LIDAR each), the bridge (``robofabric ros2``) and a plain rclpy node
(:mod:`robofabric.bench.ros2_listen`) in processes of their own, on a ROS domain of the run's own with discovery
kept on this machine. This process subscribes to the same streams over zenoh. Each message that reached both is
matched by its stamp (the sim's time, which the bridge's header stamps carry): the bridge's added latency is its ROS
arrival minus its zenoh arrival (one clock, one machine). Lost: messages zenoh delivered within the window (its
first ``SETTLE_S`` seconds left out, for discovery) that the ROS node never got. CPU: the bridge's, over the window.

Where the added latency goes: the bridge runs with ``--trace`` and notes each message's entry into its zenoh callback
and the return of its ``publish``, on the same clock, so each matched message's added latency splits into three
parts that sum to it: zenoh to the bridge (the bridge's zenoh delivery, its wait for the GIL and its decode, against
this process's delivery), in the bridge (conversion and rclpy's publish, DDS's write included) and DDS to the ROS
node's callback (the transport and the node's executor).
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from robofabric.bench.common import append, end_process, machine, pct, proc_cpu_s

__all__ = ["command", "run_one", "header", "row"]

STREAMS = {"scan": "scan", "pose": "odom", "joints": "joint_states"}
"""Fabric stream -> the bridge's topic leaf (a base's pose is its odometry)."""
SETTLE_S = 3.0
"""Seconds at the window's start left out of the loss count: the ROS node's discovery of the bridge's topics."""
TAIL_S = 1.0
"""Seconds at the window's end left out: messages still in flight when the node stops listening."""


def ros_env(domain: int) -> dict[str, str]:
    return {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_LOCALHOST_ONLY": "1"}


class _Zenoh:
    """Every robot's scan, pose and joints as zenoh delivers them: (robot, stream, stamp) -> arrival (ns)."""

    def __init__(self, fab: Any, world: str) -> None:
        from fabric import keys

        self._arrived: list[tuple[str, int, bytes]] = []  # list.append: one step under the GIL, no lock
        self.undecodable = 0
        # undecoded: the arrival is noted and the bytes kept, nothing more, while the window runs (the reference
        # must not be later than the bridge's own delivery for work of ours, and this process's decoding of 1,300
        # messages a second would take a share of the cores the bridge and the ROS node need); decoded afterwards
        self.subs = [fab.subscribe_raw(keys.robot_stream_all(world, s), self._on) for s in STREAMS]

    def _on(self, sample: Any) -> None:
        now = time.time_ns()
        self._arrived.append((str(sample.key_expr), now, sample.payload.to_bytes()))

    def window(self, t0_ns: int, t1_ns: int) -> dict[tuple[str, str, int], int]:
        from fabric.codec import DecodeError, decode
        from user_peer.openfmt.ros2 import sim_time_ns

        got: dict[tuple[str, str, int], int] = {}
        for key, now, payload in list(self._arrived):
            if not t0_ns <= now <= t1_ns:
                continue
            try:
                msg = decode(payload)
            except DecodeError:
                self.undecodable += 1
                continue
            parts = key.split("/")
            got[(parts[3], parts[4], sim_time_ns(msg))] = now
        return got


def domain_of(given: int | None, env: Mapping[str, str], pid: int) -> int:
    """The ROS domain of a run: ``--domain``, else the caller's ``ROS_DOMAIN_ID``, else one of the run's own (from
    its pid, 1-100: two benchmarks on one machine seldom meet)."""
    if given is not None:
        return given
    if env.get("ROS_DOMAIN_ID", "").strip().isdigit():
        return int(env["ROS_DOMAIN_ID"])
    return 1 + (pid * 13) % 100


def run_one(
    robots: int, seconds: float, tmp: Path, take: str = "raw", domain: int | None = None, port: int | None = None
) -> dict[str, Any]:
    """One world of ``robots`` bases bridged to ROS 2 for ``seconds``; the row's figures. ``take``: how the ROS
    node takes a message (:mod:`robofabric.bench.ros2_listen`): ``raw`` bytes, timed as zenoh's are, or ``message``.
    ``domain`` (:func:`domain_of`) and ``port`` (the router's, default a free one) as the caller gives them."""
    from robofabric.testing import ProcessGroup, client, free_port, robofabric_cmd, wait_until
    from robofabric.bench.shards import spots

    world = f"ros{uuid.uuid4().hex[:6]}"
    port = port or free_port()
    ep = f"tcp/127.0.0.1:{port}"
    env = ros_env(domain_of(domain, os.environ, os.getpid()))
    ids = [f"base{i}" for i in range(robots)]
    out_file = tmp / "ros.txt"
    trace_file = tmp / "bridge-trace.txt"
    with ProcessGroup(tmp) as procs:
        router = procs.start(robofabric_cmd("router", "--world", world, "--listen", ep), name="router")
        wait_until(
            lambda: "listening" in procs.output(router),
            timeout=60,
            what="the router",
            seen=lambda: procs.output(router),
        )
        specs = [x for s in spots(robots) for x in ("--robot", s)]
        sim = procs.start(
            robofabric_cmd(
                "sim", "--scene", "warehouse", "--no-scene-robots", *specs, "--world", world, "--connect", ep
            ),
            name="sim",
        )
        wait_until(
            lambda: "Ctrl-C to stop" in procs.output(sim),
            timeout=180,
            what="the sim",
            seen=lambda: procs.output(sim)[-1500:],
        )
        bridge = procs.start(
            robofabric_cmd("ros2", "--world", world, "--connect", ep, "--user", "bench", "--trace", str(trace_file)),
            name="bridge",
            env=env,
        )
        wait_until(
            lambda: "bridging world" in procs.output(bridge) or bridge.poll() is not None,
            timeout=60,
            what="the bridge",
            seen=lambda: procs.output(bridge)[-1500:],
        )
        if bridge.poll() is not None:
            raise RuntimeError(
                f"the bridge exited ({bridge.returncode}) before bridging: {procs.output(bridge)[-1500:]}"
            )
        with client(world, port, kind="tool", peer_id="probe") as fab:
            z = _Zenoh(fab, world)
            listen = procs.start(
                [
                    sys.executable,
                    "-m",
                    "robofabric.bench.ros2_listen",
                    "--robots",
                    ",".join(ids),
                    "--seconds",
                    str(seconds),
                    "--out",
                    str(out_file),
                    "--take",
                    take,
                ],
                name="listen",
                env=env,
            )
            wait_until(
                lambda: "ready" in procs.output(listen) or listen.poll() is not None,
                timeout=60,
                what="the ROS node",
                seen=lambda: procs.output(listen)[-1500:],
            )
            if listen.poll() is not None:
                raise RuntimeError(
                    f"the ROS node exited ({listen.returncode}) before it was ready: {procs.output(listen)[-1500:]}"
                )
            t0, cpu0, lcpu0 = time.time_ns(), proc_cpu_s(bridge.pid), proc_cpu_s(listen.pid)
            rest0 = [proc_cpu_s(sim.pid), proc_cpu_s(router.pid), time.process_time()]
            wait_until(
                lambda: time.time_ns() >= t0 + int(seconds * 1e9) or listen.poll() is not None,
                timeout=seconds + 60,
                what="the measured window",
            )
            t1, cpu1, lcpu1 = time.time_ns(), proc_cpu_s(bridge.pid), proc_cpu_s(listen.pid)
            rest1 = [proc_cpu_s(sim.pid), proc_cpu_s(router.pid), time.process_time()]
            listen.wait(timeout=60)
            zen = z.window(t0 + int(SETTLE_S * 1e9), t1 - int(TAIL_S * 1e9))
        summary_out = procs.output(bridge)
        end_process(bridge)
        end_process(sim)
        end_process(router)
        bridge_log = procs.output(bridge)[len(summary_out) :]
    leaf_to_stream = {v: k for k, v in STREAMS.items()}
    ros: dict[tuple[str, str, int], int] = {}
    node_gc: list[tuple[int, int, int]] = []
    for line in out_file.read_text().splitlines():
        if line.startswith("gc "):
            node_gc.append(tuple(int(x) for x in line.split()[1:]))  # type: ignore[arg-type]
            continue
        topic, stamp, arrival = line.split()
        _, rid, leaf = topic.split("/")
        ros[(rid, leaf_to_stream[leaf], int(stamp))] = int(arrival)
    out: dict[str, Any] = {
        "robots": robots,
        "seconds": seconds,
        "take": take,
        "cores": (cpu1 - cpu0) / ((t1 - t0) / 1e9),
        "listener_cores": (lcpu1 - lcpu0) / ((t1 - t0) / 1e9),
        "load": os.getloadavg()[0],
        # the rest of the benchmark's own processes: what it takes of the machine's cores itself
        "sim_router_bench_cores": [(b - a) / ((t1 - t0) / 1e9) for a, b in zip(rest0, rest1)],
        "summary": next((ln for ln in bridge_log.splitlines() if "messages published" in ln), ""),
    }
    bridge_at, bridge_gc = _read_trace(trace_file)
    for stream in STREAMS:
        keys_ = [k for k in zen if k[1] == stream]
        added = [(ros[k] - zen[k]) / 1e6 for k in keys_ if k in ros]
        out[stream] = {
            "zenoh": len(keys_),
            "lost": sum(1 for k in keys_ if k not in ros),
            "p50": pct(added, 50),
            "p99": pct(added, 99),
            "rate": len(keys_) / max(1e-9, (t1 - t0) / 1e9 - SETTLE_S - TAIL_S),
            "split": split([(zen[k], *bridge_at[k], ros[k]) for k in keys_ if k in ros and k in bridge_at]),
            "in_gc": in_gc([(zen[k], ros[k]) for k in keys_ if k in ros], bridge_gc, node_gc),
        }
    out["gc"] = {"bridge": gc_stats(bridge_gc, t0, t1), "node": gc_stats(node_gc, t0, t1)}
    return out


def _read_trace(path: Path) -> tuple[dict[tuple[str, str, int], tuple[int, int]], list[tuple[int, int, int]]]:
    """The bridge's ``--trace``: (robot, stream, stamp) -> (entry, published), and its garbage collections
    (generation, start, end); empty when it wrote none."""
    got: dict[tuple[str, str, int], tuple[int, int]] = {}
    pauses: list[tuple[int, int, int]] = []
    if not path.exists():
        return got, pauses
    for line in path.read_text().splitlines():
        if line.startswith("gc "):
            g, a, b = (int(x) for x in line.split()[1:])
            pauses.append((g, a, b))
            continue
        key, stamp, entry, published = line.split()
        parts = key.split("/")
        if len(parts) == 5 and parts[2] == "robot":
            got[(parts[3], parts[4], int(stamp))] = (int(entry), int(published))
    return got, pauses


def gc_stats(pauses: list[tuple[int, int, int]], t0: int, t1: int) -> dict[str, float]:
    """The garbage collections within [t0, t1]: how many, how many full (generation 2), the longest (ms)."""
    inside = [p for p in pauses if t0 <= p[1] <= t1]
    return {
        "n": len(inside),
        "full": sum(1 for p in inside if p[0] == 2),
        "max_ms": max(((b - a) / 1e6 for _, a, b in inside), default=0.0),
    }


def in_gc(spans: list[tuple[int, int]], *pauses: list[tuple[int, int, int]], over_ms: float = 1.0) -> float:
    """The share of the slowest 1% of messages (zenoh arrival, ROS arrival) that were in flight while the bridge or
    the node collected garbage for longer than ``over_ms`` (NaN when none was measured)."""
    if not spans:
        return float("nan")
    cut = pct([(b - a) for a, b in spans], 99)
    tail = [(a, b) for a, b in spans if b - a >= cut]
    long_ = [(a, b) for p in pauses for _, a, b in p if b - a >= over_ms * 1e6]
    return sum(1 for a, b in tail if any(pa <= b and pb >= a for pa, pb in long_)) / len(tail)


SPLIT = ("to bridge", "in bridge", "to ROS node")
"""The added latency's parts (module docstring), in order."""


def split(times: list[tuple[int, int, int, int]]) -> dict[str, Any]:
    """Per part of the added latency, from (zenoh, bridge entry, bridge published, ROS) arrivals in ns: its p50
    and p99 (ms) over every message, and its median over the slowest 1% (added at or above the p99), the tail."""
    cols = [[(t[i + 1] - t[i]) / 1e6 for t in times] for i in range(len(SPLIT))]
    added = [(t[-1] - t[0]) / 1e6 for t in times]
    cut = pct(added, 99)
    tail = [i for i, a in enumerate(added) if a >= cut]
    return {
        "n": len(times),
        **{
            name: {"p50": pct(c, 50), "p99": pct(c, 99), "tail": pct([c[i] for i in tail], 50)}
            for name, c in zip(SPLIT, cols)
        },
    }


def split_header() -> list[str]:
    return [
        "| robots | ROS node takes | stream | matched | zenoh to bridge p50 / p99 / tail (ms) | in bridge p50 / p99 / tail (ms) | DDS to ROS node p50 / p99 / tail (ms) | tail in a GC pause | GCs bridge / node (full, longest ms) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]


def split_row(r: dict[str, Any]) -> list[str]:
    """Where one run's added latency went, per stream (tail: the part's median over the slowest 1%)."""
    cell = lambda d: f"{d['p50']:.2f} / {d['p99']:.2f} / {d['tail']:.2f}"  # noqa: E731
    gcs = " / ".join(f"{g['n']} ({g['full']}, {g['max_ms']:.1f})" for g in (r["gc"]["bridge"], r["gc"]["node"]))
    return [
        f"| {r['robots']} | {r['take']} | {s} | {r[s]['split']['n']} | "
        + " | ".join(cell(r[s]["split"][p]) for p in SPLIT)
        + f" | {r[s]['in_gc']:.0%} | {gcs} |"
        for s in STREAMS
    ]


def header() -> list[str]:
    return [
        "| robots | ROS node takes | stream | msg/s (all robots) | added latency p50 / p99 (ms) | lost / delivered by zenoh | bridge CPU (cores) | ROS node CPU (cores) | load (1 min) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]


def row(r: dict[str, Any]) -> list[str]:
    return [
        f"| {r['robots']} | {r['take']} | {s} | {r[s]['rate']:.0f} | {r[s]['p50']:.2f} / {r[s]['p99']:.2f} | "
        f"{r[s]['lost']} / {r[s]['zenoh']} | {r['cores']:.2f} | {r['listener_cores']:.2f} | {r['load']:.1f} |"
        for s in STREAMS
    ]


def command(
    robots: Annotated[
        str, typer.Option("--robots", help="Comma-separated robot counts (mobile bases with LIDAR).")
    ] = "8",
    seconds: Annotated[float, typer.Option("--seconds", help="Measured window per count.")] = 20.0,
    out: Annotated[Optional[Path], typer.Option("--out", help="Append the markdown table to this file.")] = None,
    take: Annotated[
        str,
        typer.Option(
            "--take",
            help="How the ROS node takes each message: raw (bytes, timed at arrival as zenoh's are), message (rclpy's message built first), or both in turn (message, then raw) for each count.",
        ),
    ] = "raw",
    domain: Annotated[
        Optional[int],
        typer.Option(
            "--domain", help="The ROS domain of the run (default: $ROS_DOMAIN_ID when set, else one of the run's own)."
        ),
    ] = None,
    port: Annotated[
        Optional[int], typer.Option("--port", help="The zenoh router's port on 127.0.0.1 (default: a free one).")
    ] = None,
    convert: Annotated[
        bool,
        typer.Option("--convert", help="Only the Python cost of one message (decode, build, publish) in this process."),
    ] = False,
) -> None:
    """N mobile robots at full rate through the ROS 2 bridge (robofabric ros2) to a plain rclpy node: the latency
    the bridge adds to zenoh's delivery (p50, p99), the messages lost on the way, and the bridge's CPU."""
    try:
        import rclpy  # noqa: F401
    except ImportError:
        from fabric.cli_common import UserError
        from user_peer.ros2.cli import MISSING_RCLPY

        raise UserError(MISSING_RCLPY) from None
    if convert:
        from robofabric.bench.ros2_convert import measure, table

        text = (
            "\n".join(
                [
                    f"`robofabric bench ros2 --convert` on {machine()}, load {os.getloadavg()[0]:.1f}",
                    "",
                    *table(measure()),
                ]
            )
            + "\n"
        )
        print(text)
        append(out, text)
        return
    counts = [int(x) for x in robots.split(",") if x.strip()]
    if not counts or min(counts) < 1 or seconds <= SETTLE_S + TAIL_S:
        raise typer.BadParameter(f"--robots needs counts >= 1 and --seconds more than {SETTLE_S + TAIL_S:g}")
    takes = {"raw": ["raw"], "message": ["message"], "both": ["message", "raw"]}.get(take)
    if takes is None:
        raise typer.BadParameter(f"--take is raw, message or both, not {take!r}")
    lines = [
        f"`robofabric bench ros2 --robots {robots} --seconds {seconds:g} --take {take}` on {machine()}",
        "",
        *header(),
    ]
    summaries: list[str] = []
    splits = [
        "",
        "Where the added latency went (tail: each part's median over the slowest 1% of messages):",
        "",
        *split_header(),
    ]
    with tempfile.TemporaryDirectory(prefix="rf-ros2-") as tmp:
        for n in counts:
            for how in takes:
                d = Path(tmp) / f"n{n}-{how}"
                d.mkdir()
                r = run_one(n, seconds, d, how, domain, port)
                lines.extend(row(r))
                splits.extend(split_row(r))
                summaries.append(
                    f"{n} robots, ROS node takes {how}: the sim, router and this process used "
                    + " / ".join(f"{c:.2f}" for c in r["sim_router_bench_cores"])
                    + f" cores; bridge said: {r['summary']}"
                )
                print("\n".join(row(r)), flush=True)
    text = "\n".join([*lines, *splits, "", *summaries]) + "\n"
    print(text)
    append(out, text)
