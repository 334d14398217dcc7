"""``robofabric bench failover``: take-over time and state error of replicated authority.

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
from typing import TYPE_CHECKING, Annotated, Any, Optional

import numpy as np
import typer

from robofabric.bench.common import machine, write

if TYPE_CHECKING:
    from fabric.session import Fabric
    from robofabric.testing import ProcessGroup
    from ownership import OwnershipClient

__all__ = ["command", "measure", "report"]

#: the two joint targets the arm moves between, one per round, slowly (speed scale 0.05)
ERR_SAY_RAD = 0.005
"""A take-over's joint error above which the bench prints the two samples and what the heir said (the
test allows 0.01; a whole run once measured 0.0196 rad, 2026-12-02, with nothing else to go on)."""

POSES = (np.radians([60.0, 30.0, -40.0, 30.0, 50.0, -30.0]), np.radians([-60.0, -20.0, 30.0, -30.0, -50.0, 30.0]))


def command(
    kills: Annotated[int, typer.Option(help="Take-overs to measure (each one SIGKILLs the current authority).")] = 5,
    out: Annotated[Optional[Path], typer.Option(help="Write the markdown table to this file.")] = None,
) -> None:
    """Time from the primary's SIGKILL to the new authority's first state, and the state error at take-over."""
    if kills < 1:
        raise typer.BadParameter("--kills must be at least 1")
    text = report(measure(kills), kills)
    print(text)
    write(out, text)


class _Samples:
    """arm1's joints and pose samples as they arrive here: (arrival time, key, message), any term."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._samples: list[tuple[float, str, Any]] = []

    def on_sample(self, sample: Any) -> None:
        from fabric.codec import DecodeError, decode

        try:
            msg = decode(sample.payload.to_bytes())
        except DecodeError:
            return
        with self._lock:
            self._samples.append((time.monotonic(), str(sample.key_expr), msg))

    def of(self, stream: str, term: int) -> list[tuple[float, Any]]:
        """(arrival, message) of ``stream`` published in ``term``, in arrival order."""
        with self._lock:
            return [(t, m) for t, k, m in self._samples if k.endswith(f"/arm1/{stream}") and m.header.term == term]


def measure(kills: int) -> list[dict[str, float]]:
    """Set up the world (router, primary, standby, this process owning arm1), then ``kills`` rounds; a row each."""
    from fabric import keys
    from fabric.interfaces import Event
    from fabric.session import Fabric
    from robofabric.testing import ProcessGroup, SimRoles, client, free_port, router_config, wait_until
    from ownership import OwnershipClient

    world = f"bench{int(time.time()) % 100000}"
    port = free_port()
    samples = _Samples()
    rows: list[dict[str, float]] = []
    with (
        tempfile.TemporaryDirectory() as tmp,
        ProcessGroup(Path(tmp)) as procs,
        Fabric(router_config(world, port), kind="router", peer_id="router"),
        client(world, port, kind="user", peer_id="bench") as fab,
    ):
        for stream in ("joints", "pose"):
            fab.subscribe_raw(keys.robot_stream_all(world, stream), samples.on_sample)
        events: list = []
        fab.subscribe(keys.event_all(world), lambda k, e: events.append(e), expected=Event)
        roles = SimRoles(fab)  # the role each sim shows (its role token), not its log
        sims = _Sims(procs, world, f"tcp/127.0.0.1:{port}")
        current, standby = sims.start(0), sims.start(1, standby=True)
        own = OwnershipClient(fab, "bench", renew_s=0.2, timeout=10.0).start()
        try:
            wait_until(
                lambda: own.record("arm1") is not None and samples.of("joints", 1),
                timeout=120,
                what="the primary's joints",
            )
            if not own.request("arm1", timeout=10).granted:
                raise typer.Exit(f"could not own arm1: {own.record('arm1')}")
            epoch = own.epoch("arm1")
            for i in range(kills):
                roles.wait(
                    f"sim-{i + 1:02d}",
                    "standby",
                    term=i + 1,
                    leader=f"sim-{i:02d}",
                    timeout=120,
                    seen=lambda: procs.output(standby)[-800:],
                )
                _set_moving(
                    fab,
                    own,
                    samples,
                    i,
                    epoch,
                    seen=lambda: (
                        [(e.kind, e.reason, e.header.source) for e in events[-4:]],
                        procs.output(current)[-600:],
                    ),
                )
                rows.append(_take_over(procs, current, samples, term=i + 1))
                _print_row(i, rows[-1])
                if rows[-1]["err_rad"] > ERR_SAY_RAD:  # what the heir said it took over from, to look into
                    said = [ln for ln in procs.output(standby).splitlines() if "took over the world" in ln]
                    print(f"  the heir: {said[-1] if said else '(said nothing of its take-over)'}", flush=True)
                current, standby = standby, sims.start(i + 2, standby=True)
                if own.epoch("arm1") != epoch or not own.owns("arm1"):
                    print(f"  ownership changed! {own.record('arm1')}", flush=True)
                    epoch = own.epoch("arm1")
        finally:
            own.close()
    return rows


class _Sims:
    """Starts the sims of the world: ``sim-00`` the primary, each later one a standby."""

    def __init__(self, procs: "ProcessGroup", world: str, ep: str) -> None:
        self.procs, self.world, self.ep = procs, world, ep

    def start(self, n: int, *, standby: bool = False):
        from robofabric.testing import robofabric_cmd

        pid = f"sim-{n:02d}"
        extra = ("--standby",) if standby else ()
        return self.procs.start(
            robofabric_cmd(
                "sim", "--scene", "combined", "--world", self.world, "--connect", self.ep, "--id", pid, *extra
            ),
            name=pid,
        )


def _set_moving(fab: "Fabric", own: "OwnershipClient", samples: _Samples, i: int, epoch: int, *, seen) -> None:
    """Command round ``i``'s target (again, until the joints of the current term show the arm on its way to it:
    the last round's motion may still be going), then let it get some way into the motion."""
    from fabric import keys
    from fabric.interfaces import Command, JointTarget
    from robofabric.testing import wait_until

    term = i + 1
    cmd = Command("bench", epoch, JointTarget(POSES[i % 2], speed_scale=0.05))
    t_cmd = time.monotonic()

    def moving() -> bool:
        js = [m for t, m in samples.of("joints", term) if t > t_cmd + 0.05]
        if (
            len(js) >= 2
            and np.abs(js[-1].dq).max() > 0.01
            and np.abs(js[-1].q - cmd.body.q).max() < np.abs(js[0].q - cmd.body.q).max()
        ):
            return True
        fab.publish(keys.robot_cmd(fab.world, "arm1", "joints", "bench"), cmd)
        return False

    wait_until(moving, timeout=30, interval=0.3, what="the arm moving", seen=lambda: (own.record("arm1"), seen()))
    time.sleep(0.3)  # some way into the motion (a measurement pause, not a synchronisation)


def _take_over(procs: "ProcessGroup", current, samples: _Samples, *, term: int) -> dict[str, float]:
    """SIGKILL the authority of ``term``; once the next term's joints and pose arrive, what the take-over cost."""
    from robofabric.testing import wait_until

    t_kill = time.monotonic()
    procs.kill(current, signal.SIGKILL)
    wait_until(
        lambda: samples.of("joints", term + 1) and samples.of("pose", term + 1),
        timeout=30,
        what=f"term {term + 1} state",
    )
    (t_old, old), (t_new, new) = samples.of("joints", term)[-1], samples.of("joints", term + 1)[0]
    dt = new.header.stamp - old.header.stamp
    err_q = float(np.abs(new.q - (old.q + old.dq * dt)).max())
    if err_q > ERR_SAY_RAD:
        print(
            f"  term {term}'s last joints (t={old.header.stamp:.3f}, seq {old.header.seq}): q {np.round(old.q, 4)}, "
            f"dq {np.round(old.dq, 4)}; term {term + 1}'s first (t={new.header.stamp:.3f}, seq {new.header.seq}): "
            f"q {np.round(new.q, 4)}, dq {np.round(new.dq, 4)}",
            flush=True,
        )
    (_, po), (_, pn) = samples.of("pose", term)[-1], samples.of("pose", term + 1)[0]
    err_mm = 1000 * float(np.linalg.norm(pn.position - (po.position + po.linear * (pn.header.stamp - po.header.stamp))))
    return {
        "takeover_ms": 1000 * (t_new - t_kill),
        "gap_ms": 1000 * (t_new - t_old),
        "err_rad": err_q,
        "err_mm": err_mm,
        "sim_dt_ms": 1000 * dt,
    }


def _print_row(i: int, r: dict[str, float]) -> None:
    print(
        f"kill {i + 1}: take-over {r['takeover_ms']:.0f} ms, stream gap {r['gap_ms']:.0f} ms, "
        f"error {r['err_rad']:.5f} rad / {r['err_mm']:.3f} mm",
        flush=True,
    )


def report(rows: list[dict[str, float]], kills: int) -> str:
    """The markdown table of the rounds: median / max of each figure, with the command and the machine."""

    def med_max(key: str, fmt: str) -> str:
        vals = [r[key] for r in rows]
        return f"{fmt.format(statistics.median(vals))} / {fmt.format(max(vals))}"

    lines = [
        f"Command: `robofabric bench failover --kills {kills}`",
        f"Machine: {machine()}; processes on loopback through one router, lease 2 s",
        "",
        "| measurement (median / max) | result |",
        "|---|---|",
        f"| SIGKILL of the authority → first joints of the new term, here | {med_max('takeover_ms', '{:.0f}')} ms |",
        f"| last sample of the old term → first of the new (stream gap) | {med_max('gap_ms', '{:.0f}')} ms |",
        f"| joint error at take-over, motion-compensated | {med_max('err_rad', '{:.5f}')} rad |",
        f"| flange error at take-over, motion-compensated | {med_max('err_mm', '{:.3f}')} mm |",
        f"| sim time between the two samples | {med_max('sim_dt_ms', '{:.0f}')} ms |",
    ]
    return "\n".join(lines)
