"""The soak's nemesis: faults at random (seeded), one at a time, each undone before the next, each logged.

Kinds (:data:`KINDS`), every fault the lab knows:

* ``pause``: SIGSTOP then SIGCONT of a sim (the primary or its standby), the compute peer or a student, 1-10 s;
* ``kill``: SIGKILL and restart of one of them (a sim comes back as a standby);
* ``partition``: a student's or a sim's cable pulled for 1-8 s;
* ``router``: the router SIGKILLed and started again on its address;
* ``skew``: a student restarted with her wall clock shifted (libfaketime), which she keeps;
* ``hog``: two busy processes on a host for 2-10 s (the machine's cores, everyone's);
* ``replay``: a delayed duplicate of a command: the owner of an arm, an epoch she no longer holds, and a
  target nobody asks for; a sim must refuse it (the checker's ``applied`` invariant).

A fault that takes a sim (pause, kill, partition) is only chosen while the world has a primary and a standby
following it, so the world always has a sim that knows its state: the nemesis tests fail-over, not the loss
of the whole world. The schedule is bounded: one fault at a time, gaps of ``gap_s`` between them, and every
fault undone (thawed, plugged back, restarted) before the next one starts or the run ends.

The nemesis acts through a :class:`Cluster` (the soak's class in the lab), which it reads and drives only
through the methods that protocol names.
"""

from __future__ import annotations

import random
import threading
import time
from typing import Callable, Mapping, Protocol, Sequence

from robofabric.soak.history import Fault

__all__ = ["KINDS", "VICTIMS", "Cluster", "Nemesis", "POISON", "parse_victims"]

KINDS = ("pause", "kill", "partition", "router", "skew", "hog", "replay")
VICTIMS = ("sim", "compute", "student")
"""What pause, kill and partition may take (``--victims``; skew takes students, hog loads any host)."""


def parse_victims(text: str) -> dict[str, float]:
    """``--victims``: kinds among :data:`VICTIMS`, comma-separated, each with an optional weight (``sim=0.25``: a sim
    is picked a quarter as often as a student or the compute peer, so sim incarnations live long enough for their
    memory to be judged while fail-overs still come). Raises :class:`ValueError` naming what is expected."""
    out: dict[str, float] = {}
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        name, _, weight = part.partition("=")
        name = name.strip()
        try:
            w = float(weight) if weight.strip() else 1.0
        except ValueError:
            w = -1.0
        if name not in VICTIMS or not 0.0 < w <= 100.0:
            raise ValueError(
                f"--victims {text!r}: expected some of {', '.join(VICTIMS)}, each with an optional weight "
                "(sim=0.25), a number in (0, 100]"
            )
        out[name] = w
    if not out:
        raise ValueError(f"--victims {text!r}: expected some of {', '.join(VICTIMS)}")
    return out


SKEWS = ("-30", "-5", "+3", "+20")
"""Wall-clock offsets a skewed student runs with (libfaketime's syntax)."""
POISON = [-0.6, 0.0, 0.0, 0.0, -0.3, 0.0]
"""The target of a replayed command: joint 1 at -0.6 rad, where no student ever goes."""


class Cluster(Protocol):
    """What the nemesis may do to the class (implemented by :class:`robofabric.soak.run.Soak`)."""

    def roles(self, kind: str) -> list[str]: ...  # "sim" (the primary first), "compute", "student"
    def sims_healthy(self) -> bool: ...
    def freeze(self, role: str) -> None: ...
    def thaw(self, role: str) -> None: ...
    def kill_restart(self, role: str, *, clock_offset: str | None = None) -> None: ...
    def cut(self, role: str) -> None: ...
    def restore(self, role: str) -> None: ...
    def restart_router(self) -> None: ...
    def hog(self, role: str, seconds: float) -> None: ...
    def replay(self, poison: Sequence[float]) -> str | None: ...
    def wait_sims_healthy(self, timeout: float) -> bool: ...


class Nemesis:
    """Runs faults on a daemon thread until :meth:`stop`; each one is handed to ``log`` as a :class:`Fault`."""

    def __init__(
        self,
        cluster: Cluster,
        log: Callable[[Fault], None],
        *,
        seed: int,
        kinds: Sequence[str] = KINDS,
        gap_s: tuple[float, float] = (2.0, 6.0),
        clock: Callable[[], float] = time.monotonic,
        victims: Sequence[str] = VICTIMS,
        weights: Mapping[str, float] | None = None,
    ) -> None:
        bad = [k for k in kinds if k not in KINDS]
        if bad or not kinds:
            raise ValueError(f"unknown fault kinds {bad} (known: {', '.join(KINDS)})" if bad else "no fault kinds")
        if not victims or any(v not in VICTIMS for v in victims):
            raise ValueError(f"victims {list(victims)}: expected some of {', '.join(VICTIMS)}")
        self.cluster, self.log, self.kinds, self.gap_s, self.clock = cluster, log, tuple(kinds), gap_s, clock
        self.victims = tuple(victims)
        self.weights = {k: float(v) for k, v in (weights or {}).items()}  # victim kind -> weight (1 when not named)
        self.rng = random.Random(seed)
        self.count = 0
        self.errors: list[str] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="nemesis", daemon=True)

    def start(self) -> "Nemesis":
        self._thread.start()
        return self

    def stop(self, timeout: float = 120.0) -> None:
        """Ask it to stop after the fault under way is undone, and wait for that."""
        self._stop.set()
        self._thread.join(timeout)

    def _run(self) -> None:
        while not self._stop.wait(self.rng.uniform(*self.gap_s)):
            kind = self.rng.choice(self.kinds)
            t0 = self.clock()
            try:
                detail = getattr(self, f"_{kind}")()
            except Exception as exc:  # a fault that could not be made is reported, and the run goes on
                self.errors.append(f"{kind}: {type(exc).__name__}: {exc}")
                continue
            if detail is None:
                continue  # not applicable now (no standby following, nothing to replay)
            target, what = detail
            self.count += 1
            self.log(Fault(t0, kind, target, self.clock(), what))

    def _sleep(self, seconds: float) -> None:
        time.sleep(seconds)  # a fault lasts its time (at most 10 s), even when the run is ending

    def _victim(self, kinds: Sequence[str] = VICTIMS) -> str | None:
        """A process to fault, among the kinds asked for (sims only while a standby follows the primary)."""
        pool = [
            (r, k) for k in ("student", "compute") if k in kinds and k in self.victims for r in self.cluster.roles(k)
        ]
        if "sim" in kinds and "sim" in self.victims and self.cluster.sims_healthy():
            pool += [(r, "sim") for r in self.cluster.roles("sim")]
        if not pool:
            return None
        if all(self.weights.get(k, 1.0) == 1.0 for _, k in pool):
            return self.rng.choice(pool)[0]  # unweighted: the schedule a seed gave before weights existed
        return self.rng.choices(pool, weights=[self.weights.get(k, 1.0) for _, k in pool])[0][0]

    def _pause(self) -> tuple[str, str] | None:
        role = self._victim()
        if role is None:
            return None
        secs = self.rng.uniform(1.0, 10.0)
        self.cluster.freeze(role)
        try:
            self._sleep(secs)
        finally:
            self.cluster.thaw(role)
        self._settle(role)
        return role, f"{secs:.1f} s"

    def _kill(self) -> tuple[str, str] | None:
        role = self._victim()
        if role is None:
            return None
        self.cluster.kill_restart(role)
        self._settle(role)
        return role, "SIGKILL, restarted"

    def _partition(self) -> tuple[str, str] | None:
        role = self._victim(("student", "sim"))
        if role is None:
            return None
        secs = self.rng.uniform(1.0, 8.0)
        self.cluster.cut(role)
        try:
            self._sleep(secs)
        finally:
            self.cluster.restore(role)
        self._settle(role)
        return role, f"{secs:.1f} s"

    def _router(self) -> tuple[str, str]:
        self.cluster.restart_router()
        self.cluster.wait_sims_healthy(60.0)
        return "router", "SIGKILL, restarted"

    def _skew(self) -> tuple[str, str] | None:
        students = self.cluster.roles("student")
        if not students:
            return None
        role, offset = self.rng.choice(students), self.rng.choice(SKEWS)
        self.cluster.kill_restart(role, clock_offset=offset)
        return role, f"clock {offset} s"

    def _hog(self) -> tuple[str, str]:
        role = self.rng.choice(self.cluster.roles("sim") + self.cluster.roles("student"))
        secs = self.rng.uniform(2.0, 10.0)
        self.cluster.hog(role, secs)
        return role, f"{secs:.1f} s"

    def _replay(self) -> tuple[str, str] | None:
        what = self.cluster.replay(POISON)
        return None if what is None else ("wire", what)

    def _settle(self, role: str) -> None:
        if role.startswith("sim"):
            self.cluster.wait_sims_healthy(90.0)
