"""The ``ip`` commands behind the lab: namespaces, a bridge, veth pairs, addresses, link state.

Every command names its namespace explicitly (``ip -n NS ...``, ``ip netns exec NS ...``), and
links are created inside the lab's own namespace, so the lab never adds, renames or removes
anything in the machine's own network stack; deleting a namespace deletes its links.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
import uuid

__all__ = ["LabError", "ip", "namespaces_available", "netns_list", "netns_pids", "sweep_stale"]


class LabError(RuntimeError):
    """The lab could not be built or changed; the text says which command failed and why."""


def ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    """Run ``ip ARGS``; a failure raises :class:`LabError` with the command and its stderr."""
    if shutil.which("ip") is None:
        raise LabError("the `ip` command (iproute2) is not installed")
    proc = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if check and proc.returncode != 0:
        raise LabError(
            f"ip {' '.join(args)}: {proc.stderr.strip() or proc.stdout.strip() or f'exit {proc.returncode}'}"
        )
    return proc


def netns_list() -> list[str]:
    """Names of the network namespaces that ``ip netns`` knows."""
    out = ip("netns", "list", check=False).stdout
    return [line.split()[0] for line in out.splitlines() if line.strip()]


def netns_pids(ns: str) -> list[int]:
    """Pids of the processes running in namespace ``ns``."""
    out = ip("netns", "pids", ns, check=False).stdout
    return [int(p) for p in out.split() if p.isdigit()]


def namespaces_available() -> tuple[bool, str]:
    """(True, "") when this process may create network namespaces, else (False, why not).

    Tried for real: a namespace is added and deleted, so the answer holds for this machine and user.
    """
    if os.name != "posix" or not os.path.isdir("/proc/self/ns"):
        return False, "network namespaces need Linux"
    if shutil.which("ip") is None:
        return False, "the `ip` command (iproute2) is not installed"
    name = f"rfprobe-{os.getpid()}-{uuid.uuid4().hex[:6]}"
    proc = subprocess.run(["ip", "netns", "add", name], capture_output=True, text=True, timeout=30)
    if proc.returncode != 0:
        return (
            False,
            f"cannot create a network namespace here (ip netns add: {proc.stderr.strip()}); the lab needs root or CAP_SYS_ADMIN",
        )
    subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=30)
    return True, ""


def sweep_stale(prefix: str = "rflab", *, timeout: float = 10.0) -> list[str]:
    """Delete lab namespaces left by runs that died without cleaning up (SIGKILL, a power cut).

    Only names of the form ``{prefix}{PID}x{N}-...`` whose PID is no longer alive are touched: a live
    run's lab, or anything else on the machine, is never removed. The processes such a run started
    lead their own sessions, so they outlive it; every process still inside one of its namespaces is
    SIGKILLed first (a namespace whose processes do not go within ``timeout`` is left for next time).
    """
    stale = []
    for ns in netns_list():
        if not ns.startswith(prefix):
            continue
        pid_part = ns[len(prefix) :].split("x", 1)[0]
        if pid_part.isdigit() and not os.path.exists(f"/proc/{pid_part}"):
            stale.append(ns)
    for ns in stale:
        for pid in netns_pids(ns) + _entering(ns):
            _kill(pid)
    deadline = time.monotonic() + timeout
    removed = []
    for ns in stale:
        while (netns_pids(ns) or _entering(ns)) and time.monotonic() < deadline:
            time.sleep(0.05)
        if netns_pids(ns) or _entering(ns):
            continue
        if ip("netns", "del", ns, check=False).returncode == 0:
            removed.append(ns)
    return removed


def _entering(ns: str) -> list[int]:
    """Pids of ``ip netns exec NS ...`` processes not yet inside ``ns`` (one frozen right after it was
    started stops before its ``setns``): ``ip netns pids`` cannot see them, and they would never end."""
    want = ["netns", "exec", ns]
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                argv = f.read().decode(errors="replace").split("\0")
        except OSError:
            continue
        if os.path.basename(argv[0]) == "ip" and argv[1:4] == want:
            found.append(int(entry))
    return found


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)  # a frozen (SIGSTOPped) process dies of SIGKILL too
    except (ProcessLookupError, PermissionError):
        pass
