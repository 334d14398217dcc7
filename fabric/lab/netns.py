"""The ``ip`` commands behind the lab: namespaces, a bridge, veth pairs, addresses, link state.

Every command names its namespace explicitly (``ip -n NS ...``, ``ip netns exec NS ...``), and
links are created inside the lab's own namespace, so the lab never adds, renames or removes
anything in the machine's own network stack; deleting a namespace deletes its links.
"""

from __future__ import annotations

import os
import shutil
import subprocess
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
        raise LabError(f"ip {' '.join(args)}: {proc.stderr.strip() or proc.stdout.strip() or f'exit {proc.returncode}'}")
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
        return False, f"cannot create a network namespace here (ip netns add: {proc.stderr.strip()}); the lab needs root or CAP_SYS_ADMIN"
    subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=30)
    return True, ""


def sweep_stale(prefix: str = "rflab") -> list[str]:
    """Delete lab namespaces left by runs that died without cleaning up (SIGKILL, a power cut).

    Only names of the form ``{prefix}{PID}x{N}-...`` whose PID is no longer alive and that hold no
    process are touched: a live run's lab, or anything else on the machine, is never removed.
    """
    removed = []
    for ns in netns_list():
        if not ns.startswith(prefix):
            continue
        pid_part = ns[len(prefix):].split("x", 1)[0]
        if not pid_part.isdigit() or os.path.exists(f"/proc/{pid_part}") or netns_pids(ns):
            continue
        if ip("netns", "del", ns, check=False).returncode == 0:
            removed.append(ns)
    return removed
