"""``robofabric bench flood``, the flood harness: an owner commands a robot while other clients flood the world.

Real processes over loopback: a router, a sim peer and a compute peer (each a ``robofabric``
child process with its log in a file; the router apart from alice, so that forwarding the flood
does not take her process's time), the owner ``alice`` (a session in this
process: she owns ``arm1``, renews her lease and sends a joint target every ``period_s``), and
a flooder child process (:mod:`robofabric.bench.flooder`) that sends, as fast as it can:
commands to unique robot ids, junk payloads on every key the peers subscribe to, large
payloads, fake joint streams for the compute peer and forged ownership requests.

How a command is known to be applied, from outside: alice moves only the last joint, towards
+/-2.5 rad alternately, at a speed scale that encodes the command's number (mod 60). The sim's
controller moves a joint at ``max_speed * speed_scale`` towards its target, so the first
published JointState whose last-joint velocity has that sign and magnitude shows that command
applied; the latency is from alice's send to the sim's publish stamp on that message (one host,
one clock): when the sim applied it, not when the flooded joint stream brought the news to alice.

What it measures: alice's command latency (p50/p99, commands never seen), whether her lease
ever lapsed, resident memory (VmRSS) and CPU of the sim and compute processes, and their log
sizes. Counts are a :class:`Load`, bounded; everything started is ended by pid.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
import time
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from fabric import keys
from fabric.interfaces import Command, JointState, JointTarget, ServiceError, Stop
from fabric.session import Fabric
from robofabric.testing import client, free_port, robofabric_cmd, wait_until
from ownership.client import OwnershipClient
from robofabric.bench.common import end_processes, pct, proc_cpu_s, proc_rss_mb
from user_peer.reliable import resend_until

__all__ = ["Load", "FloodResult", "run_flood", "report", "command"]

JOINT = 5  # the last joint of the arm: the one alice moves
SCALES = 60  # command numbers are told apart modulo this
AMPLITUDE = 2.5
FAR_SPEED = 0.02  # the mid-flood stop's slow target: below the 0.05 speed scale the latency code reads


@dataclass(frozen=True, slots=True)
class Load:
    """What the flooder sends (the issue's test counts by default) and how long alice goes on."""

    unique_commands: int = 20_000
    junk_per_key: int = 10_000
    big_payloads: int = 100
    big_bytes: int = 5_000_000
    fake_joint_streams: int = 1_000
    forged_requests: int = 1_000
    warm_s: float = 3.0
    settle_s: float = 5.0
    period_s: float = 0.05

    def scaled(self, factor: float) -> "Load":
        """The same load times ``factor`` (counts only)."""
        f = float(factor)
        return Load(
            int(self.unique_commands * f),
            int(self.junk_per_key * f),
            int(self.big_payloads * f),
            self.big_bytes,
            int(self.fake_joint_streams * f),
            int(self.forged_requests * f),
            self.warm_s,
            self.settle_s,
            self.period_s,
        )


@dataclass
class FloodResult:
    """What one run measured. Latencies in seconds; memory in MB; CPU in seconds of the flood phase."""

    flooded: bool
    commands: int = 0
    applied: int = 0
    latencies: list[float] = field(default_factory=list)
    lapses: list[str] = field(default_factory=list)
    rss_before: dict[str, float] = field(default_factory=dict)
    rss_peak: dict[str, float] = field(default_factory=dict)
    cpu_s: dict[str, float] = field(default_factory=dict)
    log_bytes: dict[str, int] = field(default_factory=dict)
    flood_s: float = 0.0
    phase_s: float = 0.0
    flooder: dict[str, Any] = field(default_factory=dict)
    slowest: list[tuple[float, float]] = field(default_factory=list)  # (sent at, s after the flood began; latency s)
    stop: dict[str, Any] = field(
        default_factory=dict
    )  # the mid-flood stop: moving, done, sends, seconds, effect_s, short_by
    sim_counts: dict[str, int] = field(default_factory=dict)  # the sim's own count of commands received and rejected

    def pct(self, q: float) -> float:
        """The ``q``-th percentile of the latencies, s (NaN when none was measured)."""
        return pct(self.latencies, q)

    @property
    def not_applied(self) -> int:
        """Commands never seen themselves (superseded by a later one, or lost)."""
        return self.commands - self.applied

    def growth(self, name: str) -> float:
        return self.rss_peak.get(name, 0.0) - self.rss_before.get(name, 0.0)

    def summary(self) -> dict[str, Any]:
        out = asdict(self)
        out.pop("latencies")
        out.update(
            p50_ms=self.pct(50) * 1e3,
            p99_ms=self.pct(99) * 1e3,
            not_applied=self.not_applied,
            growth_mb={k: round(self.growth(k), 1) for k in self.rss_peak},
        )
        return out


class _Owner:
    """Alice: owns arm1, renews, sends a coded joint target every period, sees each applied."""

    def __init__(self, fab: Fabric, world: str, vmax: float, dof: int) -> None:
        self.fab, self.world, self.vmax, self.dof = fab, world, vmax, dof
        self.own = OwnershipClient(fab, "alice", renew_s=0.4).start()
        self.sent: dict[int, tuple[float, int, float]] = {}  # k -> (send time monotonic, sign, send time wall)
        self.seen: dict[int, float] = {}  # k -> wall time the sim published the first JointState showing it
        self.lapses: list[str] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._k = 0
        self._key = keys.robot_cmd(world, "arm1", "joints", "alice")
        self.paused = threading.Event()
        self.still_since: float | None = None  # arrival time of the first still JointState after motion
        self.still_at: tuple[float, float] = (0.0, 0.0)  # (sim's publish wall time, last joint) of that JointState
        self.last: JointState | None = None
        fab.subscribe(keys.robot_joints(world, "arm1"), self._on_joints, expected=JointState)
        self.own.on_change(self._on_record)
        self._thread: threading.Thread | None = None

    def take(self) -> None:
        wait_until(
            lambda: self.own.request("arm1").granted or self.own.owns("arm1"), timeout=30, what="alice owns arm1"
        )

    def _on_record(self, rec) -> None:
        if rec.object == "arm1" and rec.owner != "alice" and not self._stop.is_set() and self._thread is not None:
            self.lapses.append(f"owner became {rec.owner or 'nobody'} (epoch {rec.epoch})")

    def _on_joints(self, key: str, js: JointState) -> None:
        now = time.monotonic()
        if js.dq.shape[0] <= JOINT:
            return
        still = float(np.max(np.abs(js.dq))) < 1e-9
        with self._lock:
            self.last = js
            if not still:
                self.still_since = None
            elif self.still_since is None:
                self.still_since = now
                self.still_at = (js.header.wall_ns * 1e-9, float(js.q[JOINT]))
        v = float(js.dq[JOINT])
        scale = abs(v) / self.vmax
        if scale < 0.05:
            return
        sign = 1 if v > 0 else -1
        m = int(round((scale - 0.1) / 0.015)) % SCALES
        with self._lock:
            # the latest command sent with this code: if its sign matches and it is new, it is applied now
            k = self._k - ((self._k - m) % SCALES)
            if k in self.sent and k not in self.seen and self.sent[k][1] == sign:
                # the sim's publish stamp (same host, same clock), not the arrival here: the joint stream
                # is flooded too, and what is measured is when the sim applied the command
                self.seen[k] = js.header.wall_ns * 1e-9

    def latency(self, k: int) -> float:
        """Send to first sight; a command never seen was superseded (the sim keeps the latest target), so
        its effect was there, at the latest, when a later command was first seen: that bound is its latency."""
        t = self.seen.get(k)
        if t is None:
            later = [self.seen[j] for j in self.seen if j > k]
            if not later:
                return float("inf")
            t = min(later)
        return t - self.sent[k][2]

    def send_one(self) -> None:
        with self._lock:
            self._k += 1
            k = self._k
            sign = 1 if k % 2 else -1
            self.sent[k] = (time.monotonic(), sign, time.time())
        q = np.zeros(self.dof)
        q[JOINT] = sign * AMPLITUDE
        self.fab.publish(
            self._key, Command("alice", self.own.epoch("arm1"), JointTarget(q, 0.1 + 0.015 * (k % SCALES)))
        )

    def start(self, period: float) -> None:
        def loop() -> None:
            nxt = time.monotonic()
            while not self._stop.is_set():
                try:
                    if not self.paused.is_set():
                        self.send_one()
                except Exception:
                    pass
                nxt += period
                self._stop.wait(max(0.0, nxt - time.monotonic()))

        self._thread = threading.Thread(target=loop, name="alice", daemon=True)
        self._thread.start()

    def stop_robot(self, timeout: float) -> dict[str, Any]:
        """Pause the commands, set the last joint off slowly towards a target ~15 s away, and once it moves
        send ``cmd/stop`` again every 0.1 s until arm1's joints show it still.

        Only a stop that arrived stops it short of that target: a lost stop leaves it moving past
        ``timeout`` (with alice's own targets, the arm reached them within ~6 s and was still anyway).
        ``effect_s``: from the first stop sent to the sim's publish stamp of the first still JointState."""
        self.paused.set()
        with self._lock:
            here = float(self.last.q[JOINT]) if self.last is not None else 0.0
        target = -AMPLITUDE if here > 0 else AMPLITUDE
        q = np.zeros(self.dof)
        q[JOINT] = target
        far = Command("alice", self.own.epoch("arm1"), JointTarget(q, FAR_SPEED))
        speed = FAR_SPEED * self.vmax

        def moving() -> bool:
            with self._lock:
                v = float(self.last.dq[JOINT]) if self.last is not None else 0.0
            return v * (target - here) > 0 and 0.5 * speed <= abs(v) <= 1.5 * speed

        went = resend_until(lambda: self.fab.publish(self._key, far), moving, interval=0.2, timeout=timeout)
        key = keys.robot_cmd(self.world, "arm1", "stop", "alice")
        t0, wall0 = time.monotonic(), time.time()

        def send() -> None:
            self.fab.publish(key, Command("alice", self.own.epoch("arm1"), Stop()))

        def still() -> bool:
            with self._lock:
                return self.still_since is not None and self.still_since > t0

        r = resend_until(send, still, interval=0.1, timeout=timeout)
        with self._lock:
            stamp, at = self.still_at
        return {
            "moving": went.done,
            "done": r.done,
            "sends": r.sends,
            "seconds": round(r.seconds, 3),
            "effect_s": round(stamp - wall0, 3) if r.done else None,
            "target": target,
            "short_by": round(abs(target - at), 3) if r.done else None,
        }

    def score(self, result: FloodResult, *, since: float, t0: float) -> None:
        """Fill ``result`` with the commands sent from ``since`` (monotonic) to a second before the last one
        (those may not have been published yet): their latencies, the slowest (sent at, s after ``t0``), how
        many were seen themselves, and the lease lapses."""
        with self._lock:
            last = max((t for t, _, _ in self.sent.values()), default=0.0)
            measured = [k for k, (t, _, _) in self.sent.items() if since <= t <= last - 1.0]
            lat = {k: self.latency(k) for k in measured}
            slow = sorted(((self.sent[k][0] - t0, v) for k, v in lat.items()), key=lambda x: -x[1])
            result.commands = len(measured)
            result.latencies = sorted(lat.values())
            result.slowest = [(round(a, 3), round(b, 3)) for a, b in slow[:8]]
            result.applied = sum(1 for k in measured if k in self.seen)
        result.lapses = list(self.lapses)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)

    def close(self) -> None:
        self.stop()
        self.own.close()


def _start(argv: list[str], log_path: Path) -> subprocess.Popen:
    """A ``robofabric`` child in a session of its own, its output in ``log_path`` (the log sizes are measured)."""
    out = open(log_path, "wb")
    try:
        return subprocess.Popen(
            argv,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
    finally:
        out.close()


class _Rig:
    """What one run starts: a router, alice's session, the sim and compute peers, alice herself (and the flooder).

    ``close()`` ends everything it started, the children by pid, whatever step failed."""

    def __init__(self, out_dir: Path) -> None:
        self.out_dir = out_dir
        self.world = f"flood{uuid.uuid4().hex[:6]}"
        self.port = free_port()
        self.ep = f"tcp/127.0.0.1:{self.port}"
        self.procs: list[subprocess.Popen] = []
        self.peers: dict[str, subprocess.Popen] = {}
        self.fab: Fabric | None = None
        self.owner: _Owner | None = None

    def start(self, name: str, argv: list[str]) -> subprocess.Popen:
        proc = _start(argv, self.out_dir / f"{name}.log")
        self.procs.append(proc)
        return proc

    def set_up(self) -> _Owner:
        """Router, then alice's session (peers connect once, at start: the router must listen first), the
        sim and compute peers; alice owns arm1 when it returns."""
        w, ep = self.world, self.ep
        self.start("router", robofabric_cmd("router", "--listen", ep, "--world", w))
        fab = self.fab = wait_until(
            lambda: _try_client(w, self.port), timeout=90, interval=0.5, what="the router to accept alice"
        )
        self.peers = {
            "sim": self.start(
                "sim", robofabric_cmd("sim", "--scene", "combined", "--world", w, "--connect", ep, "--id", "sim-flood")
            ),
            "compute": self.start(
                "compute", robofabric_cmd("compute", "--world", w, "--connect", ep, "--id", "compute-flood")
            ),
        }
        info = wait_until(lambda: _world_info(fab, w), timeout=90, interval=0.5, what="the sim's srv/world")
        arm = next(r for r in info.robots if r.id == "arm1")
        self.owner = _Owner(fab, w, float(arm.max_speed[JOINT]), len(arm.joint_names))
        wait_until(lambda: fab.live_peers("compute"), timeout=90, interval=0.5, what="the compute peer")
        self.owner.take()
        return self.owner

    def start_flooder(self, load: Load) -> subprocess.Popen:
        return self.start(
            "flooder",
            [sys.executable, "-m", "robofabric.bench.flooder", self.world, str(self.port), json.dumps(asdict(load))],
        )

    def memory(self) -> dict[str, float]:
        """Each peer's resident memory now, MB: ``sim`` (VmRSS) and its parts (``sim:RssAnon``, ...)."""
        out: dict[str, float] = {}
        for n, p in self.peers.items():
            out[n] = proc_rss_mb(p.pid)
            for fld in ("RssAnon", "RssShmem", "RssFile"):
                out[f"{n}:{fld}"] = proc_rss_mb(p.pid, fld)
        return out

    def cpu(self) -> dict[str, float]:
        return {n: proc_cpu_s(p.pid) for n, p in self.peers.items()}

    def close(self) -> None:
        if self.owner is not None:
            self.owner.close()
        if self.fab is not None:
            self.fab.close()
        end_processes(self.procs)

    def __enter__(self) -> "_Rig":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_flood(load: Load, out_dir: Path, *, flood: bool = True, stop_at: float | None = 2.0) -> FloodResult:
    """One run: set up, warm up, flood (or not) and settle, then what was measured. Logs go to ``out_dir``.

    ``stop_at``: seconds after the flood began, alice stops sending targets and stops the arm with
    :func:`user_peer.reliable.resend_until` (re-sent until her joint stream shows it still), then goes on."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    result = FloodResult(flooded=flood)
    with _Rig(out_dir) as rig:
        owner = rig.set_up()
        owner.start(load.period_s)
        time.sleep(load.warm_s)  # a measurement phase of fixed length, not a wait for a condition
        t0 = _flood_phase(rig, load, result, flood=flood, stop_at=stop_at)
        owner.stop()
        if flood:
            result.flooder = _flooder_report(out_dir / "flooder.log")
        owner.score(result, since=t0 - load.warm_s, t0=t0)  # from the start of warm-up
    _read_logs(out_dir, result)
    return result


def _flood_phase(rig: _Rig, load: Load, result: FloodResult, *, flood: bool, stop_at: float | None) -> float:
    """Flood (or not), stop the arm ``stop_at`` s in, go on ``load.settle_s`` after the flooder ended, sampling
    the peers' memory every 0.1 s; fills the phase's figures and returns when it began (monotonic)."""
    owner = rig.owner
    assert owner is not None
    result.rss_before = rig.memory()
    cpu0 = rig.cpu()
    peak = dict(result.rss_before)
    t0 = time.monotonic()
    flooder = rig.start_flooder(load) if flood else None
    end = None
    stopped = stop_at is None
    while True:
        if not stopped and time.monotonic() - t0 >= stop_at:
            result.stop = {
                **owner.stop_robot(timeout=10.0),
                "flooder_running": flooder is not None and flooder.poll() is None,
            }
            owner.paused.clear()
            stopped = True
        peak = {k: max(peak.get(k, 0.0), v) for k, v in rig.memory().items()}
        now = time.monotonic()
        if end is None and (flooder is None or flooder.poll() is not None):
            result.flood_s = now - t0
            end = now + load.settle_s
        if end is not None and now >= end:
            break
        if now - t0 > 600:
            raise RuntimeError("the flooder ran for more than 600 s")
        time.sleep(0.1)
    result.phase_s = time.monotonic() - t0
    cpu1 = rig.cpu()
    result.cpu_s = {n: cpu1[n] - cpu0[n] for n in cpu0}
    result.rss_peak = peak
    return t0


def _flooder_report(log: Path) -> dict[str, Any]:
    """What the flooder says it sent (its last line, JSON), else the tail of its output."""
    try:
        return json.loads(log.read_text().strip().splitlines()[-1])
    except (ValueError, IndexError):
        return {"output": log.read_text(errors="replace")[-2000:]}


def _read_logs(out_dir: Path, result: FloodResult) -> None:
    """The peers' log sizes and the sim's own command counts, once they have stopped."""
    result.log_bytes = {
        n: (out_dir / f"{n}.log").stat().st_size for n in ("sim", "compute") if (out_dir / f"{n}.log").exists()
    }
    result.sim_counts = sim_counts(
        (out_dir / "sim.log").read_text(errors="replace") if (out_dir / "sim.log").exists() else ""
    )


_SIM_STOPPED = re.compile(
    r"sim stopped at .*: (?P<steps>\d+) steps, (?P<commands>\d+) commands \((?P<accepted>\d+) accepted, "
    r"(?P<rejected>\d+) rejected"
)


def sim_counts(log_text: str) -> dict[str, int]:
    """The sim's own counts from its last line (printed when it stops): what of the flood reached it."""
    found = list(_SIM_STOPPED.finditer(log_text))
    return {k: int(v) for k, v in found[-1].groupdict().items()} if found else {}


def _try_client(world: str, port: int) -> Fabric | None:
    try:
        return client(world, port, kind="user", peer_id="alice")
    except Exception:  # the router child is not listening yet
        return None


def _world_info(fab: Fabric, world: str) -> Any:
    try:
        return fab.rpc.call(keys.srv(world, "world"), timeout=2.0)
    except ServiceError:
        return None


def command(
    scale: Annotated[
        float,
        typer.Option(
            "--scale",
            help="Times the issue's flood (20k unique-id commands, 10k junk per key, 100 x 5 MB, 1k fake streams, 1k forged requests).",
        ),
    ] = 2.0,
    out: Annotated[Path, typer.Option("--out", help="Folder for the peers' logs.")] = Path("out/bench-flood"),
    settle: Annotated[float, typer.Option("--settle", help="Seconds alice goes on after the flood.")] = 5.0,
) -> None:
    """An owner commands arm1 every 50 ms while other clients flood the world: her command latency, lease,
    each peer's memory, CPU and log size, side by side with no flood (real sim and compute processes)."""
    import dataclasses

    load = dataclasses.replace(Load().scaled(scale), settle_s=settle)
    rows = [
        ("no flood", run_flood(load, out / "quiet", flood=False)),
        (f"flood x{scale:g}", run_flood(load, out / "flood", flood=True)),
    ]
    print(report(rows))


def report(rows: list[tuple[str, FloodResult]]) -> str:
    """The runs side by side (a markdown table), then per run its lapses, the mid-flood stop and the sim's
    counts, and what the flooder of the last run sent."""
    lines = [
        "| run | alice p50 / p99 (ms) | commands (never seen) | lease lapses | sim RSS before -> peak (MB) | compute RSS before -> peak (MB) "
        "| sim / compute CPU (s) | phase (s) | sim / compute log (bytes) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in rows:
        lines.append(
            f"| {name} | {r.pct(50) * 1e3:.1f} / {r.pct(99) * 1e3:.1f} | {r.commands} ({r.not_applied}) | {len(r.lapses)} "
            f"| {r.rss_before['sim']:.0f} -> {r.rss_peak['sim']:.0f} | {r.rss_before['compute']:.0f} -> {r.rss_peak['compute']:.0f} "
            f"| {r.cpu_s['sim']:.1f} / {r.cpu_s['compute']:.1f} | {r.phase_s:.1f} | {r.log_bytes.get('sim', 0)} / {r.log_bytes.get('compute', 0)} |"
        )
    for name, r in rows:
        if r.lapses:
            lines.append(f"{name}: lease lapses: {'; '.join(r.lapses[:5])}")
        st = r.stop
        lines.append(
            f"{name}: a stop 2 s in (the last joint slowly on its way to {st.get('target')} rad), resent every 0.1 s: "
            f"{'seen still' if st.get('done') else 'NOT seen still'} after {st.get('sends')} send(s), {st.get('seconds')} s; "
            f"took effect {st.get('effect_s')} s after the first send, {st.get('short_by')} rad short of the target "
            f"(flooder {'running' if st.get('flooder_running') else 'idle'})"
        )
        lines.append(
            f"{name}: the sim counted {r.sim_counts.get('commands', '?')} commands, {r.sim_counts.get('rejected', '?')} rejected"
        )
    flooder = rows[-1][1].flooder
    lines.append("flooder sent: " + ", ".join(f"{k}={v}" for k, v in flooder.items() if not k.startswith("t_")))
    return "\n".join(lines)
