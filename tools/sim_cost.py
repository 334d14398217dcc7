"""The sim's CPU per robot per second of sim time, for one or more source trees side by side.

    python tools/sim_cost.py --robots 32 --trees /tmp/before,. --rounds 3
    python tools/sim_cost.py --robots 2 --compute --trees /tmp/before,.   # and an idle compute peer's CPU

For each tree (a checkout of robofabric: ``git worktree add /tmp/before COMMIT``) it starts a router and a
``robofabric sim --scene warehouse --no-scene-robots`` with N/2 Meca500 arms and N/2 Reeman bases from that
tree (``python -m robofabric.cli`` run inside it), lets it settle, then reads the sim's CPU time (/proc) and its
sim time (the joints headers of arm0) over ``--seconds``. Trees alternate round by round, so a busy machine
weighs on each alike; the medians and the ratio to the first tree are printed. Nobody owns or commands the
robots: this is the cost of simulating and publishing them. With ``--compute`` a compute peer of the same tree
joins the world, and its CPU over the same window is printed too (nobody asks it anything: the cost of listening
to the world and mapping its scans).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path


def _cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _listening(port: int) -> bool:
    import socket

    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def measure(
    tree: Path, robots: int, seconds: float, settle: float, compute: bool = False
) -> tuple[float, float, float, float]:
    """(sim CPU in cores, real-time factor, arm0's joints rate in Hz, the compute peer's CPU in cores or NaN) of one
    run of ``tree``'s sim with ``robots`` robots. The joints rate (100 Hz asked) tells a sim that kept up from one
    that thinned its streams."""
    from fabric import keys
    from fabric.interfaces import JointState
    from robofabric.testing import client, free_port, wait_until

    world, port = f"cost{uuid.uuid4().hex[:6]}", free_port()
    ep = f"tcp/127.0.0.1:{port}"
    env = {**os.environ, "PYTHONPATH": str(tree)}
    cli = [sys.executable, "-m", "robofabric.cli"]

    def start(args: list[str]) -> subprocess.Popen:
        """A process of ``tree``'s, quiet."""
        return subprocess.Popen(args, cwd=tree, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    router = start([*cli, "router", "--world", world, "--listen", ep])
    specs = [x for i in range(robots // 2) for x in ("--robot", f"meca500:arm{i}", "--robot", f"reeman:base{i}")]
    sim = peer = None
    try:
        wait_until(lambda: _listening(port), timeout=60, what="the router's port")  # a loaded box: seconds
        sim = start(
            [
                *cli,
                "sim",
                "--scene",
                "warehouse",
                "--no-scene-robots",
                *specs,
                "--world",
                world,
                "--connect",
                ep,
                "--id",
                "sim",
            ]
        )
        if compute:
            peer = start([*cli, "compute", "--world", world, "--connect", ep])
        stamps: list[tuple[float, float]] = []
        lock = threading.Lock()

        def on(key: str, js: JointState) -> None:
            with lock:
                stamps.append((time.monotonic(), js.header.stamp))

        with client(world, port, kind="tool", peer_id="cost") as fab:
            fab.subscribe(keys.robot_joints(world, "arm0"), on, expected=JointState)
            wait_until(lambda: len(stamps) > 10, timeout=120, what="the sim's joints")
            time.sleep(settle)  # past the start-up (model compile, first publishers)
            if peer is not None:
                wait_until(lambda: fab.live_peers("compute"), timeout=120, what="the compute peer")
                time.sleep(settle)  # its imports and its first look at the world
            c0, p0, t0 = _cpu_s(sim.pid), _cpu_s(peer.pid) if peer else 0.0, time.monotonic()
            time.sleep(seconds)  # the measurement window
            c1, p1, t1 = _cpu_s(sim.pid), _cpu_s(peer.pid) if peer else 0.0, time.monotonic()
            with lock:
                pts = [(w, s) for w, s in stamps if t0 <= w <= t1]
        rtf = (pts[-1][1] - pts[0][1]) / (pts[-1][0] - pts[0][0]) if len(pts) > 1 else float("nan")
        peer_cores = (p1 - p0) / (t1 - t0) if peer is not None else float("nan")
        return (c1 - c0) / (t1 - t0), rtf, len(pts) / (t1 - t0), peer_cores
    finally:
        for p in (peer, sim, router):
            if p is not None:
                p.terminate()
                try:
                    p.wait(10)
                except subprocess.TimeoutExpired:
                    p.kill()


def main() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the measuring client: this checkout's fabric
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", type=int, default=32, help="robots in the world (half arms, half bases)")
    ap.add_argument("--trees", default=".", help="comma-separated source trees, the first is the reference")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--settle", type=float, default=5.0)
    ap.add_argument("--compute", action="store_true", help="a compute peer joins too; its CPU is printed")
    args = ap.parse_args()
    trees = [Path(t).resolve() for t in args.trees.split(",") if t]
    res: dict[Path, list[tuple[float, float, float, float]]] = {t: [] for t in trees}
    for r in range(args.rounds):
        for t in trees:
            cores, rtf, hz, peer = measure(t, args.robots, args.seconds, args.settle, args.compute)
            res[t].append((cores, rtf, hz, peer))
            print(
                f"round {r + 1} {t}: sim {cores:.2f} cores, real-time factor {rtf:.3f}, arm0 joints {hz:.0f} Hz"
                + (f", compute peer {peer:.3f} cores" if args.compute else "")
                + f" (load average {os.getloadavg()[0]:.1f})",
                flush=True,
            )
    ref = ref_peer = None
    print(
        "\n| tree | sim CPU (cores) | real-time factor | arm0 joints (Hz) | CPU per robot per sim second (ms) | "
        f"vs {trees[0].name} | compute peer (cores) | vs {trees[0].name} |\n|---|---|---|---|---|---|---|---|"
    )
    for t in trees:
        cores = statistics.median(c for c, _, _, _ in res[t])
        rtf = statistics.median(x for _, x, _, _ in res[t])
        hz = statistics.median(h for _, _, h, _ in res[t])
        peer = statistics.median(p for _, _, _, p in res[t])
        per = cores / args.robots / rtf * 1e3
        ref = per if ref is None else ref
        ref_peer = peer if ref_peer is None else ref_peer
        print(
            f"| {t} | {cores:.2f} | {rtf:.3f} | {hz:.0f} | {per:.2f} | {per / ref:.2f}x | {peer:.3f} | "
            f"{peer / ref_peer:.2f}x |"
        )


if __name__ == "__main__":
    main()
