"""A soak: a class in the lab for M minutes under the nemesis, its history, then the checker.

The class, each piece on a host of its own (a network namespace, :mod:`robofabric.lab`):

* a router; two sims of the world, ``sim-a`` (the primary) and ``sim-b`` (its standby), with one Meca500
  arm per student; a compute peer;
* on an ``obs`` host the nemesis never touches: ``robofabric record`` (an MCAP of the run) and the observer
  (:mod:`robofabric.soak.observer`), which writes the wire's half of the history;
* N students (:mod:`robofabric.soak.student`), each on her own host, owning and moving her arm, giving it up
  now and then, queueing for her neighbour's.

Meanwhile the nemesis (:mod:`robofabric.soak.nemesis`) makes faults and a monitor samples every peer's
memory, threads, fds and log from /proc (and restarts, after logging it, a peer that ended by itself).
At the end everything is ended by pid, both halves of the history are read, and
:func:`robofabric.soak.checker.check` judges them.

``plant``: a defect planted in the sims for this run (their hidden ``--plant``, :mod:`fabric.plant`), to show
the checker catches it.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

from robofabric.lab import Host, Lab, LabError, LabProcess, RemotePython
from robofabric.soak import checker, procs
from robofabric.soak.history import Fault, Mark, ProcExit, Record, Writer, read
from robofabric.soak.nemesis import KINDS, VICTIMS, Nemesis
from robofabric.testing import RemoteRoles

__all__ = ["SoakConfig", "SoakResult", "Soak", "after_look", "run_soak"]

SIMS = ("sim-a", "sim-b")
READY = {
    "router": "listening",
    "sim-a": "Ctrl-C to stop",
    "sim-b": "Ctrl-C to stop",
    "compute": "Ctrl-C to stop",
    "student": "joined",
}
"""What a restarted peer prints once it is up: a fault is over only then (a router restarted while a peer was still
starting would fail its first connection, which is no fault of the peer's)."""
HOG = "import time\ne = time.monotonic() + {secs}\nwhile time.monotonic() < e:\n    pass\n"


UNTIL_CHECK_S = 3.0
"""How often a run with ``until`` reads its history so far (it is a few thousand lines a minute)."""

UNTIL_AFTER_S = 3.0
"""How long a run with ``until`` goes on after the catch: the observer's last lines reach the file."""


def after_look(broken: bool, caught: bool, now: float, end: float, planned: float) -> tuple[float, bool, str]:
    """A run with ``until`` after a look at its history so far (``broken``: whether it breaks the invariant now):
    (its end, whether the invariant is caught, what to say; "" for nothing). A catch ends the run only once the next
    look (:data:`UNTIL_CHECK_S` on, with that moment's lines in the files) still finds it: the history read in the
    middle of a run can break an invariant that the whole one keeps ("applied": an owner's command for the same
    target, or the record that allowed it, written to its file later). A run of the planted stale command ended 10 s
    in on such a catch, and its verdict found nothing (run 6 of the twenty-fourth session). A catch taken back lets
    the run go on to its ``planned`` end."""
    if broken and not caught:
        return min(planned, now + UNTIL_CHECK_S + UNTIL_AFTER_S), True, "broken: ending early once the next look agrees"
    if broken:
        return min(end, now + UNTIL_AFTER_S), True, "still broken: ending early"
    if caught:
        return planned, False, "not broken in the history read since: going on"
    return end, False, ""


@dataclass(frozen=True, slots=True)
class SoakConfig:
    minutes: float
    log_dir: Path
    students: int = 3
    seed: int = 1
    plant: str = ""
    kinds: tuple[str, ...] = KINDS
    sample_s: float = 10.0
    gap_s: tuple[float, float] = (2.0, 6.0)
    victims: tuple[str, ...] = VICTIMS
    weights: tuple[tuple[str, float], ...] = ()  # victim kind -> how often it is picked (--victims sim=0.25)
    until: str = ""
    """An invariant (:data:`checker.INVARIANTS`): the run ends early, :data:`UNTIL_AFTER_S` after the history so far
    first breaks it. For a planted defect, whose proof is that it is caught: a run past the catch only burns CPU. The
    verdict is still the whole history's, read after the end; the early look only decides when the end is."""


@dataclass(frozen=True, slots=True)
class SoakResult:
    history: tuple[Record, ...]
    violations: tuple[checker.Violation, ...]
    bad_lines: tuple[str, ...]
    nemesis_errors: tuple[str, ...]
    summary: tuple[str, ...]
    started: float
    extra: dict = field(default_factory=dict)


def _wait(pred: Any, timeout: float, what: str, seen: Any = None) -> None:
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            raise TimeoutError(
                f"soak: {what} did not happen within {timeout:.0f} s" + (f"; seen:\n{seen()}" if seen else "")
            )
        time.sleep(0.2)


def _sim_roles(watch: RemoteRoles | None) -> dict[str, str]:
    """The role each sim shows now on the fabric, as the observer's session sees its role token
    (:class:`robofabric.testing.SimRoles`): ``primary``, ``standby``, or ``""`` (none: starting, killed, cut off,
    paused past the lease, or the observer's own link down)."""
    try:
        assert watch is not None
        return watch.roles(SIMS)
    except Exception:  # the observer busy or ending: nothing is known
        return {s: "" for s in SIMS}


class Soak:
    """The class in the lab, and what the nemesis may do to it (:class:`robofabric.soak.nemesis.Cluster`)."""

    def __init__(self, cfg: SoakConfig) -> None:
        self.cfg = cfg
        self.world = f"soak{uuid.uuid4().hex[:6]}"
        cfg.log_dir.mkdir(parents=True, exist_ok=True)
        self.lab = Lab(log_dir=cfg.log_dir / "lab")
        self.writer = Writer(cfg.log_dir / "soak.jsonl")
        self.wire_path = cfg.log_dir / "wire.jsonl"
        self.procs: dict[str, LabProcess] = {}
        self.hosts: dict[str, Host] = {}
        self.frozen: set[str] = set()
        self.cut_off: set[str] = set()
        self.expected: set[int] = set()
        self.reported: set[int] = set()
        self.ending = False
        self.observer: RemotePython | None = None
        self.sim_watch: RemoteRoles | None = None  # the roles the sims show, watched from the observer's process
        self.nemesis: Nemesis | None = None
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self.restarts = 0

    # ------------------------------------------------------------------ building

    def _start(self, role: str, *, clock_offset: str | None = None, standby: bool = True) -> LabProcess:
        host, world, ep = self.hosts[role], self.world, self.hosts["router"].endpoint()
        if role == "router":
            p = host.start(["router", "--world", world, "--listen", ep], name="router")
        elif role in SIMS:
            robots = [x for i in range(self.cfg.students) for x in ("--robot", f"meca500:arm{i}")]
            plant = ["--plant", self.cfg.plant] if self.cfg.plant else []  # a test-only defect (fabric/plant.py)
            p = host.start(
                [
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
                    role,
                    *(["--standby"] if standby else []),
                    *plant,
                ],
                name=role,
            )
        elif role == "compute":
            p = host.start(["compute", "--world", world, "--connect", ep, "--id", "compute"], name="compute")
        elif role == "recorder":
            p = host.start(
                ["record", "-o", str(self.cfg.log_dir / "soak.mcap"), "-q", "--world", world, "--connect", ep],
                name="recorder",
            )
        else:
            index = int(role[1:])
            p = host.spawn(
                [
                    sys.executable,
                    "-m",
                    "robofabric.soak.student",
                    world,
                    ep,
                    str(index),
                    str(self.cfg.students),
                    str(self.cfg.seed),
                ],
                name=role,
                clock_offset=clock_offset,
            )
        with self._lock:
            self.procs[role] = p
        return p

    def build(self) -> None:
        """Every host and peer, each waited for; the observer's history last, so it starts with a served world (its process
        first: it watches the roles the sims show)."""
        self.hosts["router"] = self.lab.add_host("router")
        for role, host in (("sim-a", "sa"), ("sim-b", "sb"), ("compute", "cp"), ("recorder", "obs")):
            self.hosts[role] = self.lab.hosts.get(host) or self.lab.add_host(host)
        router = self._start("router")
        _wait(lambda: "listening" in router.output(), 120, "the router listening", lambda: router.output()[-800:])
        # the observer's process first: it watches the roles the sims show (their role tokens) from the start
        self.observer = self.hosts["recorder"].python(name="observer")
        self.procs["observer"] = self.observer.proc
        self.sim_watch = RemoteRoles(self.observer, self.world, self.hosts["router"].endpoint())
        primary = self._start("sim-a", standby=False)
        _wait(
            lambda: _sim_roles(self.sim_watch)["sim-a"] == "primary",
            240,
            "the primary sim",
            lambda: primary.output()[-1500:],
        )
        standby = self._start("sim-b")
        _wait(
            lambda: _sim_roles(self.sim_watch)["sim-b"] == "standby",
            240,
            "the standby following",
            lambda: standby.output()[-1500:],
        )
        self._start("compute")
        self._start("recorder")
        self.observer.call(
            "from robofabric.soak.observer import Observer\n"
            f"ob = Observer({self.world!r}, {self.hosts['router'].endpoint()!r}, {str(self.wire_path)!r}); None",
            timeout=120,
        )
        for i in range(self.cfg.students):
            role = f"s{i:02d}"
            self.hosts[role] = self.lab.add_host(role)
            self._start(role)

    # ------------------------------------------------------------------ the Cluster protocol

    def roles(self, kind: str) -> list[str]:
        if kind == "sim":
            shown = _sim_roles(self.sim_watch)
            return sorted(SIMS, key=lambda r: shown[r] != "primary")
        with self._lock:
            if kind == "compute":
                return ["compute"]
            return sorted(r for r in self.procs if r.startswith("s") and r[1:].isdigit())

    def sims_healthy(self) -> bool:
        with self._lock:
            if any(r in self.frozen or r in self.cut_off or not self.procs[r].alive() for r in SIMS):
                return False
        return sorted(_sim_roles(self.sim_watch).values()) == ["primary", "standby"]

    def wait_sims_healthy(self, timeout: float) -> bool:
        try:
            _wait(self.sims_healthy, timeout, "a primary and a following standby")
            return True
        except TimeoutError:
            return False

    def freeze(self, role: str) -> None:
        with self._lock:
            self.frozen.add(role)
            self.procs[role].freeze()

    def thaw(self, role: str) -> None:
        with self._lock:
            self.procs[role].thaw()
            self.frozen.discard(role)

    def kill_restart(self, role: str, *, clock_offset: str | None = None) -> None:
        with self._lock:
            if self.ending:
                return  # the run is over (or interrupted): nothing is started again
            p = self.procs[role]
            self.expected.add(p.pid)
        code = p.kill()
        self._exited(role, p, code if code is not None else -9, expected=True)
        new = self._start(role, clock_offset=clock_offset)
        ready = READY.get("student" if role not in READY else role)
        try:
            _wait(lambda: ready in new.output() or not new.alive(), 180, f"{role} up again")
        except TimeoutError:
            pass  # the monitor reports it if it ends; the run goes on

    def cut(self, role: str) -> None:
        with self._lock:
            self.cut_off.add(role)
        self.lab.cut(self.hosts[role])

    def restore(self, role: str) -> None:
        self.lab.restore(self.hosts[role])
        with self._lock:
            self.cut_off.discard(role)

    def restart_router(self) -> None:
        self.kill_restart("router")

    def hog(self, role: str, seconds: float) -> None:
        host = self.hosts[role]
        hogs = [host.spawn([sys.executable, "-c", HOG.format(secs=seconds)], name="hog") for _ in range(2)]
        for h in hogs:
            try:
                h.popen.wait(timeout=seconds + 20)
            except subprocess.TimeoutExpired:
                h.kill()

    def replay(self, poison: Sequence[float]) -> str | None:
        assert self.observer is not None
        owned = self.observer.call("ob.owned()", timeout=30)
        choices = sorted((o, u, e) for o, (u, e) in owned.items() if e >= 2 and o.startswith("arm"))
        if not choices:
            return None
        obj, user, epoch = choices[int(time.monotonic() * 1000) % len(choices)]
        self.observer.call(f"ob.replay({obj!r}, {user!r}, {epoch - 1}, {list(poison)!r}); None", timeout=30)
        return f"{obj} as {user} at epoch {epoch - 1} (current {epoch})"

    # ------------------------------------------------------------------ the monitor

    def _exited(self, role: str, p: LabProcess, code: int, *, expected: bool) -> None:
        with self._lock:
            if p.pid in self.reported:
                return
            self.reported.add(p.pid)
        tail = "" if expected else p.output()[-600:]
        self.writer.write(ProcExit(time.monotonic(), role, p.pid, code, expected, tail))

    def _monitor(self) -> None:
        while not self._stop.wait(self.cfg.sample_s):
            with self._lock:
                items = list(self.procs.items())
            for role, p in items:
                s = procs.sample(time.monotonic(), role, p.pid, p.log_path)
                if s is not None and p.alive():
                    self.writer.write(s)
                    continue
                code = p.popen.poll()
                if code is None:
                    continue
                with self._lock:
                    expected = p.pid in self.expected or self.ending
                    current = self.procs.get(role) is p
                self._exited(role, p, code, expected=expected)
                if not expected and current and role != "observer" and not self.ending:
                    self.restarts += 1
                    self._start(role)  # the run goes on; the exit is a violation already

    # ------------------------------------------------------------------ the run

    def run(self) -> SoakResult:
        cfg = self.cfg
        started = time.monotonic()
        self.writer.write(
            Mark(
                started,
                "start",
                f"world {self.world}, {cfg.students} students, seed {cfg.seed}"
                + (f", plant {cfg.plant}" if cfg.plant else ""),
            )
        )
        self.build()
        monitor = threading.Thread(target=self._monitor, name="soak-monitor", daemon=True)
        monitor.start()
        t0 = time.monotonic()
        end = t0 + cfg.minutes * 60.0
        warm = t0 + min(600.0, max(30.0, 0.15 * cfg.minutes * 60.0))
        nemesis = self.nemesis = Nemesis(
            self,
            self.writer.write,
            seed=cfg.seed,
            kinds=cfg.kinds,
            gap_s=cfg.gap_s,
            victims=cfg.victims,
            weights=dict(cfg.weights),
        ).start()
        self.writer.write(Mark(t0, "class", "every peer started; the nemesis begins"))
        warmed = False
        look = t0 + UNTIL_CHECK_S
        planned, caught = end, False
        while time.monotonic() < end:
            if not warmed and time.monotonic() >= warm:
                self.writer.write(Mark(time.monotonic(), "warm"))
                warmed = True
            if cfg.until and time.monotonic() >= look:
                look = time.monotonic() + UNTIL_CHECK_S
                was = caught
                end, caught, said = after_look(self._broken(cfg.until), caught, time.monotonic(), end, planned)
                if said:
                    self.writer.write(Mark(time.monotonic(), "caught", f"{cfg.until} {said}"))
                if was and caught:
                    look = end  # confirmed: once is enough
            time.sleep(min(1.0, max(0.0, end - time.monotonic())))
        nemesis.stop()
        self.writer.write(Mark(time.monotonic(), "end", f"{nemesis.count} faults"))
        self.close()
        monitor.join(timeout=30)
        history, bad = read([self.wire_path, cfg.log_dir / "soak.jsonl"])
        violations = checker.check(history)
        return SoakResult(
            tuple(history),
            tuple(violations),
            tuple(bad),
            tuple(nemesis.errors),
            tuple(checker.summary(history, violations)),
            started,
            {"restarts": self.restarts},
        )

    def _broken(self, invariant: str) -> bool:
        """Whether the history so far breaks ``invariant`` (its files are whole lines, flushed as written)."""
        history, _ = read([self.wire_path, self.cfg.log_dir / "soak.jsonl"])
        return bool(checker.INVARIANTS[invariant](history, checker.Limits()))

    def close(self) -> None:
        """End every peer by pid (students first, so their leaving is not the world's), then the lab. The nemesis
        stops first (after undoing its fault under way), when the run was interrupted before its end."""
        with self._lock:
            self.ending = True
        if self.nemesis is not None:
            self.nemesis.stop(timeout=60.0)
        with self._lock:
            for role in list(self.frozen):
                self.procs[role].thaw()
            for role in list(self.cut_off):
                try:
                    self.lab.restore(self.hosts[role])
                except LabError:
                    pass
        self._stop.set()
        students = [self.procs[r] for r in self.roles("student")]
        for p in students:
            p.send_signal(signal.SIGTERM)
        for p in students:
            try:
                p.popen.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
        if self.observer is not None:
            try:
                self.observer.call("ob.close(); None", timeout=30)
            except Exception:
                pass
            self.observer.close()
        rec = self.procs.get("recorder")
        if rec is not None:
            rec.stop(grace=15.0)
        for role in ("compute", "sim-b", "sim-a", "router"):
            p = self.procs.get(role)
            if p is not None:
                p.stop(grace=5.0)
        with self._lock:
            items = list(self.procs.items())
        for role, p in items:
            code = p.popen.poll()
            self._exited(role, p, code if code is not None else 0, expected=True)
        self.lab.close()
        self.writer.close()

    def __enter__(self) -> "Soak":
        return self

    def __exit__(self, *exc: object) -> None:
        if not self.ending:
            self.close()
        else:
            self.lab.close()


def run_soak(cfg: SoakConfig) -> SoakResult:
    with Soak(cfg) as soak:
        return soak.run()


def memory_series(history: Sequence[Record]) -> dict[str, list[tuple[float, float]]]:
    """Each peer role's (minute since the first sample, RSS MB), every incarnation in one series."""
    from robofabric.soak.history import ProcSample

    ss = [r for r in history if isinstance(r, ProcSample)]
    if not ss:
        return {}
    t0 = ss[0].t
    out: dict[str, list[tuple[float, float]]] = {}
    for s in ss:
        out.setdefault(s.name, []).append((round((s.t - t0) / 60.0, 3), s.rss_mb))
    return out


def fault_counts(history: Sequence[Record]) -> dict[str, int]:
    counts: dict[str, int] = {}
    for r in history:
        if isinstance(r, Fault):
            counts[r.kind] = counts.get(r.kind, 0) + 1
    return dict(sorted(counts.items()))
