"""A LAN of hosts made of Linux network namespaces, for proving the fabric's promises across stacks.

::

    with Lab() as lab:
        router = lab.add_host("router")
        sim = lab.add_host("sim", clock_offset="-5")     # this host's clock runs 5 s behind
        router.start(["router", "--listen", f"tcp/{router.ip}:7447"], name="router")
        sim.start(["sim", "--connect", f"tcp/{router.ip}:7447"], name="sim")
        lab.cut(sim); lab.restore(sim)                   # pull and replug sim's cable

Layout: one namespace per host, each joined by a veth pair (``eth0`` in the host, ``hN`` in the
lab namespace) to the bridge ``br0`` that lives in a namespace of the lab's own. Addresses come
from one private /24 that exists only inside the lab; hosts have no default route, so nothing in
the lab can reach the machine's network, and the machine cannot reach the lab. Names carry the
pid and a per-process counter, so parallel runs never clash.

Everything the lab made (processes, by pid; namespaces, with their links) is removed by
``close()``, which the context manager, pytest fixtures and an ``atexit`` hook all call; it is
idempotent and tolerates pieces that are already gone.
"""

from __future__ import annotations

import atexit
import glob
import ipaddress
import itertools
import json
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Any, Callable, Sequence

from robofabric.lab.netns import LabError, ip, netns_list

__all__ = ["Lab", "Host", "LabProcess", "RemoteError", "RemotePython", "faketime_library", "DEFAULT_SUBNET"]

DEFAULT_SUBNET = "10.77.0.0/24"
_COUNTER = itertools.count(1)
_LIVE: "set[Lab]" = set()
_LIVE_LOCK = threading.Lock()


def faketime_library() -> str | None:
    """Path of Debian's libfaketime (multi-threaded variant), or None when the package is missing."""
    for pattern in (
        "/usr/lib/*/faketime/libfaketimeMT.so.1",
        "/usr/lib/faketime/libfaketimeMT.so.1",
        "/usr/lib/*/faketime/libfaketime.so.1",
        "/usr/local/lib/faketime/libfaketimeMT.so.1",
    ):
        found = sorted(glob.glob(pattern))
        if found:
            return found[0]
    return None


def _close_all_at_exit() -> None:
    with _LIVE_LOCK:
        labs = list(_LIVE)
    for lab in labs:
        lab.close()


atexit.register(_close_all_at_exit)


class LabProcess:
    """A process the lab started inside a host; it leads its own process group (pgid = pid).

    Signals go to the group, so a command that forks (``robofabric up``) is frozen or killed whole.
    """

    def __init__(self, popen: subprocess.Popen, host: "Host", name: str, log_path: Path) -> None:
        self.popen = popen
        self.host = host
        self.name = name
        self.log_path = log_path

    @property
    def pid(self) -> int:
        return self.popen.pid

    def alive(self) -> bool:
        return self.popen.poll() is None

    def output(self) -> str:
        """Everything the process printed so far (stdout and stderr)."""
        try:
            return self.log_path.read_text(errors="replace")
        except FileNotFoundError:
            return ""

    def send_signal(self, sig: int) -> None:
        if self.popen.poll() is None:
            try:
                os.killpg(self.popen.pid, sig)
            except ProcessLookupError:
                pass

    def freeze(self) -> None:
        """SIGSTOP: the process stops answering, its sockets stay open (a hung machine)."""
        self.send_signal(signal.SIGSTOP)

    def thaw(self) -> None:
        self.send_signal(signal.SIGCONT)

    def kill(self, sig: int = signal.SIGKILL, *, timeout: float = 10.0) -> int | None:
        """Send ``sig`` (SIGKILL by default) and wait for the process to end; returns its exit code."""
        if sig not in (signal.SIGKILL, signal.SIGCONT):
            self.send_signal(signal.SIGCONT)  # a frozen process must run to act on it
        self.send_signal(sig)
        try:
            return self.popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.send_signal(signal.SIGKILL)
            return self.popen.wait(timeout=10)

    def stop(self, *, grace: float = 5.0) -> None:
        """SIGINT (a clean exit), then SIGTERM, then SIGKILL."""
        if self.popen.poll() is not None:
            return
        self.send_signal(signal.SIGCONT)
        for sig, wait in ((signal.SIGINT, grace), (signal.SIGTERM, 2.0), (signal.SIGKILL, 10.0)):
            self.send_signal(sig)
            try:
                self.popen.wait(timeout=wait)
                return
            except subprocess.TimeoutExpired:
                continue

    def __repr__(self) -> str:
        return f"<LabProcess {self.name} pid={self.pid} on {self.host.name} {'alive' if self.alive() else 'ended'}>"


class Host:
    """One machine of the lab: a network namespace with ``eth0`` on the lab's bridge."""

    def __init__(self, lab: "Lab", name: str, index: int, ip_addr: str, clock_offset: str | None) -> None:
        self.lab = lab
        self.name = name
        self.index = index
        self.ip = ip_addr
        self.ns = f"{lab.name}-{name}"
        self.port = f"h{index}"  # its veth end in the lab namespace (the switch port)
        self.clock_offset = clock_offset
        self.processes: list[LabProcess] = []

    def __repr__(self) -> str:
        return f"<Host {self.name} {self.ip} ns={self.ns}{' clock ' + self.clock_offset if self.clock_offset else ''}>"

    def endpoint(self, port: int = 7447) -> str:
        return f"tcp/{self.ip}:{port}"

    def _argv(self, argv: Sequence[str], clock_offset: str | None) -> tuple[list[str], dict[str, str]]:
        env: dict[str, str] = {}
        offset = clock_offset if clock_offset is not None else self.clock_offset
        if offset:
            lib = faketime_library()
            if lib is None:
                raise LabError("a shifted clock needs Debian's faketime (apt-get install faketime)")
            # LD_PRELOAD rather than the faketime wrapper: the wrapper forks, the pid would not be the program's.
            # Only the wall clock moves (a machine whose clock is wrong still has a sound monotonic clock).
            env.update(LD_PRELOAD=lib, FAKETIME=offset, FAKETIME_DONT_FAKE_MONOTONIC="1", FAKETIME_DONT_RESET="1")
            argv = list(argv)
            if len(argv) > 2 and argv[0] == sys.executable and argv[1] == "-m":
                argv[1:2] = ["-m", "robofabric.lab.skewed"]  # works around libfaketime's time.sleep (see skewed.py)
        return ["ip", "netns", "exec", self.ns, *argv], env

    def spawn(
        self,
        argv: Sequence[str],
        *,
        name: str | None = None,
        env: dict[str, str] | None = None,
        clock_offset: str | None = None,
        stdin: Any = subprocess.DEVNULL,
    ) -> LabProcess:
        """Start any program in this host (its own session; output to the lab's log directory)."""
        self.lab.ensure_open()
        full, fenv = self._argv(argv, clock_offset)
        name = name or Path(argv[0]).name
        log_path = self.lab.log_dir / f"{self.name}.{name}.{len(self.processes)}.log"
        with open(log_path, "wb") as out:
            popen = subprocess.Popen(
                full,
                stdout=out,
                stderr=subprocess.STDOUT,
                stdin=stdin,
                start_new_session=True,
                env={**os.environ, "PYTHONUNBUFFERED": "1", **fenv, **(env or {})},
            )
        proc = LabProcess(popen, self, name, log_path)
        self.processes.append(proc)
        self.lab.processes.append(proc)
        return proc

    def start(
        self,
        args: Sequence[str],
        *,
        name: str | None = None,
        env: dict[str, str] | None = None,
        clock_offset: str | None = None,
    ) -> LabProcess:
        """Start ``robofabric ARGS`` in this host (with this interpreter: no reliance on PATH)."""
        return self.spawn(
            [sys.executable, "-m", "robofabric.cli", *args], name=name or args[0], env=env, clock_offset=clock_offset
        )

    def run(
        self,
        argv: Sequence[str],
        *,
        timeout: float = 60.0,
        clock_offset: str | None = None,
        env: dict[str, str] | None = None,
    ) -> subprocess.CompletedProcess:
        """Run a program in this host to completion; returns its output (never raises on a non-zero exit)."""
        self.lab.ensure_open()
        full, fenv = self._argv(argv, clock_offset)
        return subprocess.run(
            full,
            capture_output=True,
            text=True,
            timeout=timeout,
            env={**os.environ, "PYTHONUNBUFFERED": "1", **fenv, **(env or {})},
        )

    def robofabric(self, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
        """Run ``robofabric ARGS`` in this host to completion (``ps``, ``own list``, ``call``...)."""
        return self.run([sys.executable, "-m", "robofabric.cli", *args], timeout=timeout)

    def python(
        self, *, name: str = "py", clock_offset: str | None = None, env: dict[str, str] | None = None
    ) -> "RemotePython":
        """A Python interpreter in this host that runs snippets on request (see :class:`RemotePython`)."""
        proc = self.spawn(
            [sys.executable, "-m", "robofabric.lab.agent"],
            name=name,
            env=env,
            clock_offset=clock_offset,
            stdin=subprocess.PIPE,
        )
        return RemotePython(proc)


class RemotePython:
    """Drive a Python process inside a host: ``submit(code)`` runs it in a thread there; the value of its
    last expression comes back as JSON. One namespace per process, so state (a ``World``) lives between calls::

        alice = lab.host("alice").python(name="alice")
        alice.call("import user_peer; w = user_peer.connect('demo', 'tcp/10.77.0.1:7447', 'alice')")
        epoch = alice.call("w.robot('arm1').request()")
    """

    def __init__(self, proc: LabProcess) -> None:
        self.proc = proc
        self._ids = itertools.count(1)
        self._replies: dict[int, dict] = {}
        self._cond = threading.Condition()
        self._write_lock = threading.Lock()
        self._pos = 0

    def submit(self, code: str) -> Callable[..., Any]:
        """Start ``code``; returns ``wait(timeout=60)`` giving its last expression's value (or raising RemoteError)."""
        rid = next(self._ids)
        line = json.dumps({"id": rid, "code": code}) + "\n"
        with self._write_lock:
            assert self.proc.popen.stdin is not None
            try:
                self.proc.popen.stdin.write(line.encode())
                self.proc.popen.stdin.flush()
            except (BrokenPipeError, ValueError):
                raise LabError(
                    f"{self.proc.name} on {self.proc.host.name} has ended (exit {self.proc.popen.poll()}); "
                    f"its output:\n{self.proc.output()[-3000:]}"
                ) from None

        def wait(timeout: float = 60.0) -> Any:
            deadline = time.monotonic() + timeout
            while True:
                self._read_replies()
                with self._cond:
                    if rid in self._replies:
                        reply = self._replies.pop(rid)
                        break
                if not self.proc.alive():
                    self._read_replies()
                    with self._cond:
                        if rid in self._replies:
                            reply = self._replies.pop(rid)
                            break
                    raise LabError(
                        f"{self.proc.name} on {self.proc.host.name} ended (exit {self.proc.popen.returncode}) "
                        f"before answering; its output:\n{self.proc.output()[-3000:]}"
                    )
                if time.monotonic() > deadline:
                    raise TimeoutError(
                        f"{self.proc.name} on {self.proc.host.name}: no answer within {timeout:.0f} s to\n{code}\n"
                        f"its output:\n{self.proc.output()[-3000:]}"
                    )
                time.sleep(0.02)
            if not reply["ok"]:
                raise RemoteError(reply["error"])
            return reply.get("value")

        return wait

    def call(self, code: str, timeout: float = 60.0) -> Any:
        return self.submit(code)(timeout)

    def _read_replies(self) -> None:
        """Collect the replies the agent has printed since the last look (other output is left in the log)."""
        marker = b"\x1eLAB "
        with self._cond:
            try:
                with open(self.proc.log_path, "rb") as f:
                    f.seek(self._pos)
                    data = f.read()
            except FileNotFoundError:
                return
            end = data.rfind(b"\n") + 1  # only whole lines
            self._pos += end
            for line in data[:end].splitlines():
                if line.startswith(marker):
                    reply = json.loads(line[len(marker) :])
                    self._replies[reply["id"]] = reply

    def close(self) -> None:
        try:
            if self.proc.popen.stdin is not None:
                self.proc.popen.stdin.close()
        except OSError:
            pass
        self.proc.stop(grace=3.0)


class RemoteError(Exception):
    """A snippet raised in the remote interpreter; the text is its traceback."""


class Lab:
    """A LAN of namespaces with a bridge; a context manager whose ``close()`` removes all it made."""

    def __init__(
        self, *, subnet: str = DEFAULT_SUBNET, log_dir: str | Path | None = None, name: str | None = None
    ) -> None:
        self.name = name or f"rflab{os.getpid()}x{next(_COUNTER)}"
        self.net = ipaddress.ip_network(subnet)
        if not self.net.is_private or self.net.prefixlen != 24:
            raise LabError(f"the lab's subnet must be a private /24, got {subnet}")
        self.ns = f"{self.name}-lan"
        self.hosts: dict[str, Host] = {}
        self.processes: list[LabProcess] = []
        self._namespaces: list[str] = []
        self._closed = False
        self._lock = threading.Lock()
        self.log_dir = Path(log_dir) if log_dir is not None else Path("/tmp") / f"{self.name}-{uuid.uuid4().hex[:6]}"
        self.log_dir.mkdir(parents=True, exist_ok=True)
        with _LIVE_LOCK:
            _LIVE.add(self)
        try:
            self._add_ns(self.ns)
            ip("-n", self.ns, "link", "add", "br0", "type", "bridge")
            ip("-n", self.ns, "link", "set", "br0", "up")
        except BaseException:
            self.close()
            raise

    def ensure_open(self) -> None:
        if self._closed:
            raise LabError(f"lab {self.name} is closed")

    def _add_ns(self, ns: str) -> None:
        ip("netns", "add", ns)
        self._namespaces.append(ns)
        ip("-n", ns, "link", "set", "lo", "up")

    # ------------------------------------------------------------------ building

    def add_host(self, name: str, *, clock_offset: str | None = None) -> Host:
        """A new host on the LAN with the next address of the subnet; ``clock_offset`` as libfaketime
        reads it (``"-5"``: five seconds behind) applies to every process started in it."""
        self.ensure_open()
        if not name.replace("-", "").replace("_", "").isalnum() or name in self.hosts:
            raise LabError(f"host name {name!r} is not a fresh name of letters, digits, - and _")
        index = len(self.hosts) + 1
        if index > 250:
            raise LabError("a lab has at most 250 hosts")
        addr = str(self.net.network_address + index)
        host = Host(self, name, index, addr, clock_offset)
        self._add_ns(host.ns)
        ip("-n", self.ns, "link", "add", host.port, "type", "veth", "peer", "name", "eth0", "netns", host.ns)
        ip("-n", self.ns, "link", "set", host.port, "master", "br0")
        ip("-n", self.ns, "link", "set", host.port, "up")
        ip("-n", host.ns, "addr", "add", f"{addr}/{self.net.prefixlen}", "dev", "eth0")
        ip("-n", host.ns, "link", "set", "eth0", "up")
        self.hosts[name] = host
        return host

    def host(self, name: str) -> Host:
        try:
            return self.hosts[name]
        except KeyError:
            raise LabError(f"no host {name!r} in the lab (hosts: {', '.join(self.hosts)})") from None

    # ------------------------------------------------------------------ faults

    def cut(self, host: Host | str) -> None:
        """Unplug ``host``'s cable at the switch: its ``eth0`` loses carrier, nothing reaches it or leaves it.
        Its processes keep running and their sockets stay open (TCP finds out only by timeouts)."""
        h = self.host(host) if isinstance(host, str) else host
        ip("-n", self.ns, "link", "set", h.port, "down")

    def restore(self, host: Host | str) -> None:
        """Plug the cable back in."""
        h = self.host(host) if isinstance(host, str) else host
        ip("-n", self.ns, "link", "set", h.port, "up")

    def link_up(self, host: Host | str) -> bool:
        h = self.host(host) if isinstance(host, str) else host
        out = ip("-n", self.ns, "-j", "link", "show", h.port).stdout
        return "UP" in json.loads(out)[0].get("flags", []) if out.strip() else False

    # ------------------------------------------------------------------ teardown

    def close(self) -> None:
        """End every process the lab started (by pid: SIGCONT, SIGTERM, then SIGKILL) and delete every
        namespace it made (their veths and the bridge go with them). Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        for proc in self.processes:
            if proc.alive():
                proc.send_signal(signal.SIGCONT)
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + 5.0
        for proc in self.processes:
            try:
                proc.popen.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.send_signal(signal.SIGKILL)
                try:
                    proc.popen.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    pass
            if proc.popen.stdin is not None:
                try:
                    proc.popen.stdin.close()
                except OSError:
                    pass
        existing = set(netns_list())
        for ns in reversed(self._namespaces):
            if ns in existing:
                ip("netns", "del", ns, check=False)
        with _LIVE_LOCK:
            _LIVE.discard(self)

    def __enter__(self) -> "Lab":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<Lab {self.name} {self.net} hosts={list(self.hosts)}>"
