"""``robofabric bench record``: recording throughput and replay timing.

Throughput: a router (this process), a recorder (``robofabric record``, its own
process) and a synthetic world publisher (``python -m robofabric.bench.record
pub``, its own process): 10 robots x (joints 100 Hz + pose 50 Hz + 240-ray
scan 20 Hz) at each ``--scales`` multiple. Reported: messages and MB/s written,
loss (sent minus found in the file, per key), and the recorder's CPU use as a
fraction of one core (from /proc, over the publishing window).

Replay timing: the scale-1 file replayed at speed 1 through the router into a
second world while a second recorder process records it: scheduling error
(put time minus due time, in the replayer) and end-to-end error (re-recorded
receive offset minus original receive offset, same host clock).
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path
from typing import Annotated, Optional

import typer

from robofabric.stats import percentiles
from robofabric.bench.common import TablesOut, append, end_process, proc_cpu_s

WORLD = "benchrec"


def _drained(pid: int, idle: float = 0.05, timeout: float = 20.0) -> tuple[float, float]:
    """Wait until a process uses under ``idle`` of a core over 0.3 s; return (its CPU s, the time)."""
    deadline = time.monotonic() + timeout
    c, t = proc_cpu_s(pid), time.monotonic()
    while time.monotonic() < deadline:
        time.sleep(0.3)
        c2, t2 = proc_cpu_s(pid), time.monotonic()
        if (c2 - c) / (t2 - t) < idle:
            return c2, t2
        c, t = c2, t2
    return c, t


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "robofabric.cli", *args]


def _wait_token(fab, expr: str, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if fab.live_tokens(expr, timeout=0.5):
            return
        time.sleep(0.05)
    raise RuntimeError(f"no live token on {expr} after {timeout:.0f} s")


def _start_recorder(out: Path, world: str, ep: str, log: Path) -> subprocess.Popen:
    return subprocess.Popen(
        _cli("record", "-o", str(out), "-q", "--world", world, "--connect", ep, "--id", f"rec-{out.stem}"),
        stdout=open(log, "wb"),
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )


def _throughput(router, ep: str, tmp: Path, scale: float, robots: int, duration: float, precompute: int = 0) -> dict:
    from user_peer.recordings import iter_messages, read_info

    tag = f"x{scale:g}" + ("p" if precompute else "")
    out = tmp / f"rec-{tag}.mcap"
    rec = _start_recorder(out, WORLD, ep, tmp / f"rec-{tag}.log")
    try:
        _wait_token(router, f"rf/{WORLD}/peer/recorder/rec-{out.stem}", 30)
        pub = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "robofabric.bench.record",
                "pub",
                "--endpoint",
                ep,
                "--world",
                WORLD,
                "--robots",
                str(robots),
                "--scale",
                str(scale),
                "--duration",
                str(duration),
                "--precompute",
                str(precompute),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            start_new_session=True,
        )
        # The publisher waits for the recorder's subscription, then prints "go" and starts.
        line = pub.stdout.readline().decode().strip()
        if line != "go":
            raise RuntimeError(f"publisher failed: {line} {pub.stderr.read().decode()[-500:]}")
        c0, t0 = proc_cpu_s(rec.pid), time.monotonic()
        res = json.loads(pub.stdout.readline().decode())
        pub.wait(timeout=30)
        # let the recorder drain what is in flight (its CPU use falls to idle), and count that work too
        c1, t1 = _drained(rec.pid)
    finally:
        code = end_process(rec, signal.SIGINT, 30.0)
    info = read_info(out)
    got: Counter[str] = Counter()
    nbytes = 0
    for m in iter_messages(out):
        got[m.key] += 1
        nbytes += len(m.payload)
    sent = Counter(res["sent"])
    lost = sum(max(0, sent[k] - got[k]) for k in sent)
    n = sum(sent.values())
    return {
        "scale": scale,
        "precomputed": bool(precompute),
        "robots": robots,
        "streams": len(sent),
        "offered_hz": res["offered_hz"],
        "sent_hz": n / res["elapsed"],
        "sent": n,
        "recorded": sum(got[k] for k in sent),
        "lost": lost,
        "loss_pct": 100.0 * lost / n if n else 0.0,
        "msgs_per_s": sum(got[k] for k in sent) / res["elapsed"],
        "mb_per_s": nbytes / res["elapsed"] / 1e6,
        "file_mb_per_s": info.file_bytes / res["elapsed"] / 1e6,
        "ratio": nbytes / info.file_bytes if info.file_bytes else 0.0,
        "cpu_core": (c1 - c0) / (t1 - t0),
        "complete": info.complete,
        "recorder_exit": code,
        "file": str(out),
    }


def _replay_timing(router, ep: str, tmp: Path, source: Path) -> dict:
    from user_peer.recordings import iter_messages
    from robofabric.recording.replayer import Replayer, plan_replay

    target = "benchreplay"
    out = tmp / "replayed.mcap"
    rec = _start_recorder(out, target, ep, tmp / "replayed.log")
    try:
        _wait_token(router, f"rf/{target}/peer/recorder/rec-{out.stem}", 30)
        # the whole file: at load its messages spread over more than the run's duration (the suite's run of
        # 2026-11-30 replayed 165 of 170, the last ones past it), and the smoke checks that every one was replayed
        plan = plan_replay(source, remap_world=target)
        rp = Replayer(router, plan, wait_for_subscribers=5.0)
        try:
            stats = rp.run()
        finally:
            rp.close()
        _drained(rec.pid)  # what is in flight reaches the file before the stop (a fixed 0.5 s lost 4 of 170 at load)
    finally:
        end_process(rec, signal.SIGINT, 30.0)
    # end to end: per (key, seq order), offset from the first message, original vs replayed
    orig: dict[str, list[int]] = defaultdict(list)
    for m in iter_messages(source, end_ns=plan.end_ns):
        orig[m.key.replace(f"rf/{WORLD}/", f"rf/{target}/", 1)].append(m.log_time)
    again: dict[str, list[int]] = defaultdict(list)
    for m in iter_messages(out):
        again[m.key].append(m.log_time)
    o0 = min(v[0] for v in orig.values())
    a0 = min(v[0] for v in again.values()) if again else 0
    errs = []
    for k, ts in orig.items():
        for t_o, t_a in zip(ts, again.get(k, [])):
            errs.append(((t_a - a0) - (t_o - o0)) / 1e6)
    # the first replayed message fixes a0, so errors are relative to it; report the spread around the median
    errs.sort()
    med = errs[len(errs) // 2] if errs else 0.0
    dev = [abs(e - med) for e in errs]
    p = percentiles(dev, (50, 99))
    return {
        "messages": stats.messages,
        "expected": plan.messages,
        "received": sum(len(v) for v in again.values()),
        "sched_p50_ms": stats.late_p50_ms,
        "sched_p99_ms": stats.late_p99_ms,
        "sched_max_ms": stats.late_max_ms,
        "e2e_p50_ms": p["p50"],
        "e2e_p99_ms": p["p99"],
        "e2e_max_ms": max(dev) if dev else 0.0,
    }


def run_bench(
    scales: list[float],
    robots: int,
    duration: float,
    replay: bool,
    keep: Path | None = None,
    fast_scales: list[float] = (),
) -> dict:
    from fabric.session import Fabric
    from robofabric.testing import free_port, router_config

    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    results: dict = {"throughput": [], "replay": None}
    with tempfile.TemporaryDirectory(prefix="bench-record-") as d:
        tmp = keep or Path(d)
        tmp.mkdir(parents=True, exist_ok=True)
        with Fabric(router_config(WORLD, port), kind="router", peer_id="bench-router") as router:
            for s in scales:
                results["throughput"].append(_throughput(router, ep, tmp, s, robots, duration))
            for s in fast_scales:
                results["throughput"].append(_throughput(router, ep, tmp, s, robots, duration, precompute=200))
            if replay:
                src = next(
                    (Path(r["file"]) for r in results["throughput"] if r["scale"] == 1.0),
                    Path(results["throughput"][0]["file"]),
                )
                results["replay"] = _replay_timing(router, ep, tmp, src)
    return results


def format_tables(res: dict) -> str:
    lines = [
        "| robots | load | offered msg/s | sent msg/s | sent | recorded | loss % | msg/s written | payload MB/s | file MB/s | zstd ratio | recorder CPU (cores) | file |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in res["throughput"]:
        lines.append(
            f"| {r['robots']} | x{r['scale']:g}{' pre-encoded' if r.get('precomputed') else ''} | {r['offered_hz']:.0f} | "
            f"{r.get('sent_hz', 0):.0f} | {r['sent']} | {r['recorded']} | {r['loss_pct']:.2f} | "
            f"{r['msgs_per_s']:.0f} | {r['mb_per_s']:.3f} | {r['file_mb_per_s']:.3f} | {r['ratio']:.1f} | {r['cpu_core']:.2f} | "
            f"{'complete' if r['complete'] else 'UNFINISHED'} |"
        )
    rp = res.get("replay")
    if rp:
        lines += [
            "",
            "| replay (speed 1) | messages | received | sched p50 (ms) | sched p99 (ms) | sched max (ms) | e2e p50 (ms) | e2e p99 (ms) | e2e max (ms) |",
            "|---|---|---|---|---|---|---|---|---|",
            f"| x1 file | {rp['messages']} | {rp['received']} | {rp['sched_p50_ms']:.3f} | {rp['sched_p99_ms']:.3f} | {rp['sched_max_ms']:.3f} | "
            f"{rp['e2e_p50_ms']:.3f} | {rp['e2e_p99_ms']:.3f} | {rp['e2e_max_ms']:.3f} |",
        ]
    return "\n".join(lines)


def command(
    scales: Annotated[
        str, typer.Option(help="Comma-separated load multiples of the default rates (1 = 10 robots at 100/50/20 Hz).")
    ] = "1,4",
    robots: Annotated[int, typer.Option(help="Robots in the synthetic world.")] = 10,
    duration: Annotated[float, typer.Option(help="Seconds of publishing per load.")] = 10.0,
    fast: Annotated[
        str,
        typer.Option(
            help="Extra loads whose publisher cycles pre-encoded payloads (to find the recorder's ceiling, not the publisher's); '' for none."
        ),
    ] = "",
    replay: Annotated[
        bool, typer.Option("--replay/--no-replay", help="Also measure replay timing on the x1 file.")
    ] = True,
    as_json: Annotated[bool, typer.Option("--json")] = False,
    out: TablesOut = None,
    keep: Annotated[Optional[Path], typer.Option(help="Keep the recordings in this directory.")] = None,
) -> None:
    """Recording throughput (msgs/s, MB/s, loss, recorder CPU) and replay timing error, in separate processes."""
    from fabric.cli_common import UserError

    try:
        scale_list = [float(x) for x in scales.split(",") if x.strip()]
        fast_list = [float(x) for x in fast.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"--scales {scales!r} / --fast {fast!r}: expected numbers like 1,4,8") from None
    if not scale_list or any(s <= 0 for s in scale_list + fast_list) or duration <= 0 or robots <= 0:
        raise UserError("--scales, --fast and --duration must be positive, --robots at least 1")
    res = run_bench(scale_list, robots, duration, replay, keep, fast_list)
    if as_json:
        print(json.dumps(res))
        return
    table = format_tables(res)
    print(table)
    append(out, table)


# --------------------------------------------------------------------------- child: the synthetic world


def _child_pub(a: argparse.Namespace) -> None:
    import zenoh

    from fabric.config import FabricConfig
    from fabric.matching import wait_matched
    from robofabric.recording.load import robot_streams, run_load
    from fabric.session import Fabric

    streams = robot_streams(a.world, a.robots, scale=a.scale, precompute=a.precompute)
    with Fabric(FabricConfig(world=a.world, connect=(a.endpoint,)), kind="sim", peer_id="bench-world") as fab:
        # raw publishers: the load is pre-encoded bytes put as fast as the recorder under test can take them
        pubs = {
            s.key: fab.session.declare_publisher(s.key, congestion_control=zenoh.CongestionControl.BLOCK)
            for s in streams
        }
        if not wait_matched(pubs.values(), 20, every=True):
            print("error: no subscriber matched the world's keys", flush=True)
            sys.exit(1)
        print("go", flush=True)
        sent, elapsed = run_load(lambda k, b: pubs[k].put(b), streams, duration=a.duration)
        print(
            json.dumps({"sent": dict(sent), "elapsed": elapsed, "offered_hz": sum(s.hz for s in streams)}), flush=True
        )


def _main() -> None:
    ap = argparse.ArgumentParser(prog="python -m robofabric.bench.record")
    ap.add_argument("role", choices=("pub",))
    ap.add_argument("--endpoint", required=True)
    ap.add_argument("--world", default=WORLD)
    ap.add_argument("--robots", type=int, default=10)
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--precompute", type=int, default=0)
    _child_pub(ap.parse_args())


if __name__ == "__main__":
    _main()
