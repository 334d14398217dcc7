"""Helpers for tests and benchmarks that run real sessions and real processes (every package's tests, the
benchmarks in :mod:`robofabric.bench`). No peer needs them at run time, so they sit on the top floor, not in
:mod:`fabric`.

Waiting is always on a condition with a deadline (:func:`wait_until`), never a
fixed sleep; every process started through :class:`ProcessGroup` is ended by
its pid when the group closes, SIGTERM first, then SIGKILL.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from fabric import keys
from fabric.config import FabricConfig
from fabric.session import Fabric


EPHEMERAL_RANGE_FILE = "/proc/sys/net/ipv4/ip_local_port_range"
PORTS_BELOW_EPHEMERAL = 16_000  # how many ports under the kernel's ephemeral range free_port deals from

_ports_lock = threading.Lock()
_ports_handed: set[int] = set()
_ports_next: int | None = None


def port_slice(env: dict[str, str] | None = None, ephemeral_low: int | None = None) -> tuple[int, int]:
    """The ports (first, how many) :func:`free_port` deals in this process: the :data:`PORTS_BELOW_EPHEMERAL`
    under the kernel's ephemeral range, cut in one slice per pytest-xdist worker and one for processes outside
    the workers, so that two workers never pick the same port."""
    env = os.environ if env is None else env
    if ephemeral_low is None:
        try:
            with open(EPHEMERAL_RANGE_FILE) as f:
                ephemeral_low = int(f.read().split()[0])
        except (OSError, ValueError, IndexError):
            ephemeral_low = 32768
    top = min(ephemeral_low, 65536)
    bottom = max(1024, top - PORTS_BELOW_EPHEMERAL)
    count = int(env.get("PYTEST_XDIST_WORKER_COUNT", "0") or 0)
    worker = env.get("PYTEST_XDIST_WORKER", "")
    index = int(worker[2:]) if worker[:2] == "gw" and worker[2:].isdigit() and int(worker[2:]) < count else count
    size = (top - bottom) // (count + 1)
    return bottom + index * size, size


def free_port() -> int:
    """A TCP port on loopback, free now and never handed out before by this process.

    Not one the kernel picks (``bind(0)``): those come from its ephemeral range, where every outgoing connection
    takes its local port, and a whole run's viewer once found the port it was given taken that way ("Address
    already in use"). Ports come from :func:`port_slice`, in turn from a place set by this process's pid (a
    benchmark a test starts deals from its worker's slice too)."""
    global _ports_next
    first, size = port_slice()
    with _ports_lock:
        if _ports_next is None:
            _ports_next = (os.getpid() * 7919) % size
        for _ in range(size):
            port, _ports_next = first + _ports_next, (_ports_next + 1) % size
            if port in _ports_handed:
                continue
            with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
                try:
                    s.bind(("127.0.0.1", port))
                except OSError:
                    continue
            _ports_handed.add(port)
            return port
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:  # every port of the slice handed out: the kernel's
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_until(
    predicate: Callable[[], Any],
    *,
    timeout: float = 10.0,
    interval: float = 0.02,
    what: str = "condition",
    seen: Callable[[], Any] | None = None,
) -> Any:
    """Poll ``predicate`` until it returns something truthy; on timeout fail saying what was seen."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            detail = f"; last seen: {seen()!r}" if seen is not None else f"; last value: {value!r}"
            raise AssertionError(f"timed out after {timeout:.1f} s waiting for {what}{detail}")
        time.sleep(interval)


def router_config(world: str, port: int) -> FabricConfig:
    """An embedded (router) profile listening on loopback ``port``, scouting off.

    ``scouting/delay`` 0: a router opens after waiting that long for peers to scout (zenoh's default 500 ms),
    and with multicast off and nothing to connect to there is nothing to wait for; at half a second per test
    that wait was most of the fast suite's time.
    """
    return FabricConfig(
        world=world, profile="embedded", listen=(f"tcp/127.0.0.1:{port}",), extra=(("scouting/delay", "0"),)
    )


def client_config(world: str, port: int) -> FabricConfig:
    return FabricConfig(world=world, profile="client", connect=(f"tcp/127.0.0.1:{port}",))


def client(world: str, port: int, *, kind: str = "tool", peer_id: str | None = None) -> Fabric:
    return Fabric(client_config(world, port), kind=kind, peer_id=peer_id)


def robofabric_cmd(*args: str) -> list[str]:
    """The argv that runs the CLI with this interpreter (no reliance on PATH)."""
    return [sys.executable, "-m", "robofabric.cli", *args]


class ProcessGroup:
    """Child processes of one test; ``close()`` ends them all by pid."""

    def __init__(self, log_dir: Path | None = None) -> None:
        self.procs: list[subprocess.Popen] = []
        self.log_dir = log_dir

    def start(self, argv: list[str], *, name: str = "proc", env: dict[str, str] | None = None) -> subprocess.Popen:
        out: Any = subprocess.DEVNULL
        log_path = None
        if self.log_dir is not None:
            log_path = self.log_dir / f"{name}-{len(self.procs)}.log"
            out = open(log_path, "wb")
        full_env = {**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})}
        proc = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT, env=full_env, start_new_session=True)
        if log_path is not None:
            out.close()  # the child holds its own descriptor
        proc.name = name  # type: ignore[attr-defined]
        proc.log_path = log_path  # type: ignore[attr-defined]
        self.procs.append(proc)
        return proc

    def output(self, proc: subprocess.Popen) -> str:
        """Everything the process printed so far (stdout and stderr)."""
        path = getattr(proc, "log_path", None)
        if path is None or not path.exists():
            return ""
        return path.read_text(errors="replace")

    def kill(self, proc: subprocess.Popen, sig: int = signal.SIGKILL) -> None:
        if proc.poll() is None:
            os.kill(proc.pid, sig)
        proc.wait(timeout=10)

    def close(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                try:
                    os.kill(proc.pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + 5
        for proc in self.procs:
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait(timeout=5)

    def __enter__(self) -> "ProcessGroup":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def example_robot_urdf(relative: str) -> Path:
    """A URDF of the ``example-robot-data`` distribution (the test extra: real robots' descriptions, meshes
    included), e.g. ``"ur_description/urdf/ur5_robot.urdf"``; found through the distribution's file list, as its
    wheel installs them under ``cmeel.prefix/share/example-robot-data/robots``."""
    import importlib.metadata

    for f in importlib.metadata.files("example-robot-data") or ():
        if str(f).endswith("example-robot-data/robots/" + relative):
            return Path(str(f.locate())).resolve()
    raise FileNotFoundError(f"example-robot-data has no robots/{relative}")


@dataclass(frozen=True, slots=True)
class SimRole:
    """A role a sim shows on the fabric (its token ``peer/sim/{id}/{role}/{term}/{leader}``, :mod:`sim_peer.replica.role_token`)."""

    sim: str
    role: str  # primary | standby
    term: int
    leader: str  # who leads its shard: itself when primary, the sim it follows when standby


class SimRoles:
    """The roles a world's sims show, as one session sees their tokens: what each shows now, and every role any of
    them showed since this watch began (``shown``, in order). Tests and the soak read a sim's role here, never in
    its log. A sim killed, cut off or paused past the lease shows none (its tokens go with its session)."""

    def __init__(self, fab: Fabric) -> None:
        self._lock = threading.Lock()
        self._live: dict[str, list[SimRole]] = {}  # sim -> its tokens alive now, oldest first (two, for a moment)
        self.shown: list[SimRole] = []
        fab.watch_tokens(keys.sim_roles_all(fab.world), self._on_token)

    def _on_token(self, key: str, alive: bool) -> None:
        try:
            p = keys.parse(key)
        except ValueError:
            return  # a made-up token under peer/sim/: nobody's role
        if p.category != "sim_role":
            return
        r = SimRole(p.subject, p.leaf, int(p.rest[0]), p.rest[1])
        with self._lock:
            now = self._live.setdefault(r.sim, [])
            if r in now:
                now.remove(r)
            if alive:
                now.append(r)
                self.shown.append(r)

    def now(self, sim: str) -> SimRole | None:
        """What ``sim`` shows now (its newest token), None when it shows no role."""
        with self._lock:
            now = self._live.get(sim)
            return now[-1] if now else None

    def role(self, sim: str) -> str:
        """``primary``, ``standby``, or ``""`` when ``sim`` shows no role now."""
        r = self.now(sim)
        return r.role if r else ""

    def ever(self, sim: str, role: str, term: int | None = None) -> bool:
        """Whether ``sim`` showed ``role`` (under ``term``, if given) since this watch began."""
        with self._lock:
            return any(r.sim == sim and r.role == role and term in (None, r.term) for r in self.shown)

    def shows(self, sim: str, role: str, *, term: int | None = None, leader: str | None = None) -> SimRole | None:
        """What ``sim`` shows now if it is ``role`` (under ``term``, led by ``leader``, if given), else None."""
        r = self.now(sim)
        ok = r is not None and r.role == role and term in (None, r.term) and leader in (None, r.leader)
        return r if ok else None

    def wait(
        self,
        sim: str,
        role: str,
        *,
        term: int | None = None,
        leader: str | None = None,
        timeout: float = 60.0,
        seen: Callable[[], Any] | None = None,
    ) -> SimRole:
        """Wait until ``sim`` shows ``role`` (under ``term``, following ``leader``, if given); what it shows then."""

        def showing() -> SimRole | None:
            return self.shows(sim, role, term=term, leader=leader)

        what = (
            f"{sim} showing {role}"
            + (f" (term {term})" if term is not None else "")
            + (f" of {leader}" if leader else "")
        )
        return wait_until(
            showing,
            timeout=timeout,
            interval=0.05,
            what=what,
            seen=lambda: (self.now(sim), seen() if seen is not None else None),
        )


class RemoteRoles:
    """:class:`SimRoles` in another process: a Python a lab host runs (:class:`robofabric.lab.RemotePython`), for
    tests and the soak whose sims live in the lab's network, where this process has no route. Each question is one
    call into that process."""

    def __init__(self, py: Any, world: str, endpoint: str, *, peer_id: str = "roles") -> None:
        self.py = py
        py.call(
            "from fabric.config import FabricConfig\nfrom fabric.session import Fabric\n"
            "from robofabric.testing import SimRoles\n"
            f"roles = SimRoles(Fabric(FabricConfig.resolve(world={world!r}, connect=[{endpoint!r}]), kind='tool', "
            f"peer_id={peer_id!r})); None",
            timeout=120,
        )

    def role(self, sim: str, *, timeout: float = 30.0) -> str:
        return self.py.call(f"roles.role({sim!r})", timeout=timeout)

    def roles(self, sims: Any, *, timeout: float = 30.0) -> dict[str, str]:
        """The role each of ``sims`` shows now (``""``: none), in one call."""
        return self.py.call(f"{{s: roles.role(s) for s in {tuple(sims)!r}}}", timeout=timeout)

    def ever(self, sim: str, role: str, term: int | None = None) -> bool:
        return self.py.call(f"roles.ever({sim!r}, {role!r}, {term!r})")

    def wait(
        self,
        sim: str,
        role: str,
        *,
        term: int | None = None,
        leader: str | None = None,
        timeout: float = 60.0,
        seen: Callable[[], Any] | None = None,
    ) -> None:
        """Wait until ``sim`` shows ``role`` (under ``term``, following ``leader``, if given)."""
        ask = f"roles.shows({sim!r}, {role!r}, term={term!r}, leader={leader!r}) is not None"
        what = (
            f"{sim} showing {role}"
            + (f" (term {term})" if term is not None else "")
            + (f" of {leader}" if leader else "")
        )
        wait_until(
            lambda: self.py.call(ask),
            timeout=timeout,
            interval=0.2,
            what=what,
            seen=lambda: (self.role(sim), seen() if seen is not None else None),
        )
