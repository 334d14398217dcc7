"""``robofabric bench failover``: take-over time and state error of replicated authority (issue 16).

Real processes on loopback: an in-process router, a primary sim and a standby (``robofabric sim
--standby``), and this process as a user that owns the arm and keeps it moving slowly. Each round
SIGKILLs the current authority while the arm moves; the standby takes over; a fresh standby is started
for the next round, so the terms climb 1, 2, 3... Per round:

- take-over time: from the SIGKILL to the first joints sample of the new term arriving here;
- stream gap: from the last sample of the old term to the first of the new one (what a user sees);
- state error at take-over: the new authority's first joints (and flange pose) minus the old one's
  last, less the motion the old velocity explains over the sim time between them (rad, mm).
"""

from __future__ import annotations

import signal
import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Annotated, Optional

import numpy as np
import typer

from robofabric.bench.common import machine, write


def command(
    kills: Annotated[int, typer.Option(help="Take-overs to measure (each one SIGKILLs the current authority).")] = 5,
    out: Annotated[Optional[Path], typer.Option(help="Write the markdown table to this file.")] = None,
) -> None:
    """Time from the primary's SIGKILL to the new authority's first state, and the state error at take-over."""
    from fabric import keys
    from fabric.codec import DecodeError, decode
    from fabric.interfaces import Command, Event, JointTarget
    from fabric.session import Fabric
    from fabric.testing import ProcessGroup, client, free_port, robofabric_cmd, router_config, wait_until
    from ownership import OwnershipClient

    if kills < 1:
        raise typer.BadParameter("--kills must be at least 1")
    world = f"bench{int(time.time()) % 100000}"
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    rows: list[dict[str, float]] = []
    samples: list[tuple[float, str, object]] = []
    lock = threading.Lock()

    def on_sample(sample) -> None:
        try:
            msg = decode(sample.payload.to_bytes())
        except DecodeError:
            return
        with lock:
            samples.append((time.monotonic(), str(sample.key_expr), msg))

    def of(stream: str, term: int) -> list:
        with lock:
            return [(t, m) for t, k, m in samples if k.endswith(f"/arm1/{stream}") and m.header.term == term]

    with tempfile.TemporaryDirectory() as tmp, ProcessGroup(Path(tmp)) as procs, \
            Fabric(router_config(world, port), kind="router", peer_id="router") as _router, \
            client(world, port, kind="user", peer_id="bench") as fab:
        for stream in ("joints", "pose"):
            fab.subscribe_raw(keys.robot_stream_all(world, stream), on_sample)
        events: list = []
        fab.subscribe(keys.event_all(world), lambda k, e: events.append(e), expected=Event)

        def sim(pid: str, *extra: str):
            return procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep, "--id", pid, *extra),
                               name=pid)

        current = sim("sim-00")
        standby = sim("sim-01", "--standby")
        own = OwnershipClient(fab, "bench", renew_s=0.2, timeout=10.0).start()
        wait_until(lambda: own.record("arm1") is not None and of("joints", 1), timeout=120, what="the primary's joints")
        if not own.request("arm1", timeout=10).granted:
            raise typer.Exit(f"could not own arm1: {own.record('arm1')}")
        epoch = own.epoch("arm1")
        poses = [np.radians([60.0, 30.0, -40.0, 30.0, 50.0, -30.0]), np.radians([-60.0, -20.0, 30.0, -30.0, -50.0, 30.0])]
        for i in range(kills):
            term = i + 1
            wait_until(lambda: f"following sim-{i:02d} (term {term})" in procs.output(standby), timeout=120,
                       what=f"standby {i + 1} following", seen=lambda: procs.output(standby)[-800:])
            cmd = Command("bench", epoch, JointTarget(poses[i % 2], speed_scale=0.05))

            t_cmd = time.monotonic()

            def moving() -> bool:  # toward this round's target (the last round's motion may still be going)
                js = [m for t, m in of("joints", term) if t > t_cmd + 0.05]
                if len(js) >= 2 and np.abs(js[-1].dq).max() > 0.01 and \
                        np.abs(js[-1].q - cmd.body.q).max() < np.abs(js[0].q - cmd.body.q).max():
                    return True
                fab.publish(keys.robot_cmd(world, "arm1", "joints", "bench"), cmd)
                return False

            wait_until(moving, timeout=30, interval=0.3, what="the arm moving",
                       seen=lambda: (own.record("arm1"), [(e.kind, e.reason, e.header.source) for e in events[-4:]],
                                     procs.output(current)[-600:]))
            time.sleep(0.3)  # some way into the motion (a measurement pause, not a synchronisation)
            t_kill = time.monotonic()
            procs.kill(current, signal.SIGKILL)
            wait_until(lambda: of("joints", term + 1) and of("pose", term + 1), timeout=30, what=f"term {term + 1} state")
            (t_old, old), (t_new, new) = of("joints", term)[-1], of("joints", term + 1)[0]
            dt = new.header.stamp - old.header.stamp
            err_q = float(np.abs(new.q - (old.q + old.dq * dt)).max())
            (_, po), (_, pn) = of("pose", term)[-1], of("pose", term + 1)[0]
            err_mm = 1000 * float(np.linalg.norm(pn.position - (po.position + po.linear * (pn.header.stamp - po.header.stamp))))
            rows.append({"takeover_ms": 1000 * (t_new - t_kill), "gap_ms": 1000 * (t_new - t_old), "err_rad": err_q, "err_mm": err_mm,
                         "sim_dt_ms": 1000 * dt})
            r = rows[-1]
            print(f"kill {i + 1}: take-over {r['takeover_ms']:.0f} ms, stream gap {r['gap_ms']:.0f} ms, "
                  f"error {r['err_rad']:.5f} rad / {r['err_mm']:.3f} mm", flush=True)
            current, standby = standby, sim(f"sim-{i + 2:02d}", "--standby")
            if own.epoch("arm1") != epoch or not own.owns("arm1"):
                print(f"  ownership changed! {own.record('arm1')}", flush=True)
                epoch = own.epoch("arm1")
        own.close()

    def med_max(key: str, fmt: str) -> str:
        vals = [r[key] for r in rows]
        return f"{fmt.format(statistics.median(vals))} / {fmt.format(max(vals))}"

    lines = [
        f"Command: `robofabric bench failover --kills {kills}`",
        f"Machine: {machine()}; "
        "processes on loopback through one router, lease 2 s",
        "",
        "| measurement (median / max) | result |",
        "|---|---|",
        f"| SIGKILL of the authority → first joints of the new term, here | {med_max('takeover_ms', '{:.0f}')} ms |",
        f"| last sample of the old term → first of the new (stream gap) | {med_max('gap_ms', '{:.0f}')} ms |",
        f"| joint error at take-over, motion-compensated | {med_max('err_rad', '{:.5f}')} rad |",
        f"| flange error at take-over, motion-compensated | {med_max('err_mm', '{:.3f}')} mm |",
        f"| sim time between the two samples | {med_max('sim_dt_ms', '{:.0f}')} ms |",
    ]
    text = "\n".join(lines)
    print(text)
    write(out, text)


__all__ = ["command"]
