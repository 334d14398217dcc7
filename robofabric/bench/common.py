"""Helpers the benchmarks share: where tables go, the machine line, a process's CPU and memory, ending children.

Pure or /proc-reading functions, the ending of children by pid, and the ``--out`` flag every benchmark
takes (:data:`TableOut`); no benchmark logic. :func:`pct` is
the tables' percentile (NaN where nothing was measured); the replayer and ``robofabric hz`` summarise
with :func:`robofabric.stats.percentiles`.
"""

from __future__ import annotations

import os
import platform
import signal
import subprocess
import time
from pathlib import Path
from typing import Annotated, Optional

import typer

__all__ = [
    "TableOut",
    "TablesOut",
    "append",
    "write",
    "pct",
    "cpus",
    "machine",
    "proc_cpu_s",
    "proc_sched_s",
    "proc_waited_s",
    "box_idle_s",
    "proc_rss_mb",
    "end_process",
    "end_processes",
]

TableOut = Annotated[Optional[Path], typer.Option("--out", help="Append the markdown table to this file.")]
"""``--out FILE`` of a benchmark that prints one table: the one definition of the flag and its help."""
TablesOut = Annotated[Optional[Path], typer.Option("--out", help="Append the markdown tables to this file.")]
"""``--out FILE`` of a benchmark that prints several tables."""


def append(out: Path | str | None, text: str) -> None:
    """Append ``text`` and a newline to ``out`` (``--out FILE`` of a benchmark); nothing when ``out`` is None."""
    if out is not None:
        with open(out, "a", encoding="utf-8") as f:
            f.write(text + "\n")


def write(out: Path | str | None, text: str) -> None:
    """Replace ``out`` with ``text`` and a newline; nothing when ``out`` is None."""
    if out is not None:
        Path(out).write_text(text + "\n", encoding="utf-8")


def pct(values, q: float, scale: float = 1.0) -> float:
    """The ``q``-th percentile of ``values`` times ``scale`` (1e3: seconds to ms); NaN when there are none,
    so a table shows a row that measured nothing instead of failing."""
    import numpy as np

    arr = np.asarray(list(values), dtype=np.float64)
    return float(np.percentile(arr, q) * scale) if arr.size else float("nan")


def cpus() -> int:
    """CPUs this process may run on (its affinity), which is what a benchmark gets on a shared machine."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 0)


def machine() -> str:
    """One line naming the machine, for the head of a result table."""
    proc = platform.processor() or ""
    return f"{platform.machine()} {proc}".strip() + f" ({cpus()} CPUs visible), Python {platform.python_version()}"


def proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds a process used so far, from /proc/PID/stat (NaN when it is gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def proc_sched_s(pid: int) -> tuple[float, float] | None:
    """(ran, waited): seconds the threads of a process ran on a CPU and spent runnable but waiting for one so far,
    summed over its threads (/proc/PID/task/*/schedstat, its first two fields); None once it is gone. Two processes
    can use the same CPU time, one on an idle box and one on a full box: what they waited for it tells them apart."""
    ran = waited = 0
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return None
    for tid in tasks:
        try:
            with open(f"/proc/{pid}/task/{tid}/schedstat") as f:
                fields = f.read().split()
            ran, waited = ran + int(fields[0]), waited + int(fields[1])
        except (OSError, IndexError, ValueError):
            continue  # a thread that ended meanwhile
    return ran / 1e9, waited / 1e9


def proc_waited_s(pid: int) -> float:
    """Seconds the threads of a process spent waiting for a CPU so far (:func:`proc_sched_s`); NaN when it is gone."""
    sched = proc_sched_s(pid)
    return float("nan") if sched is None else sched[1]


def box_idle_s() -> tuple[float, float]:
    """(all CPU seconds, idle CPU seconds) of the machine so far, summed over its CPUs (/proc/stat's first line;
    idle includes waiting for I/O): between two readings, how full the box was."""
    with open("/proc/stat") as f:
        fields = [int(x) for x in f.readline().split()[1:]]
    tick = os.sysconf("SC_CLK_TCK")
    return sum(fields) / tick, (fields[3] + fields[4]) / tick


def proc_rss_mb(pid: int, field: str = "VmRSS") -> float:
    """Resident memory of a process, from /proc/PID/status (``VmRSS``, or ``RssAnon``, ``RssShmem``...), in MB."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    return 0.0


def end_process(proc: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int:
    """Send ``sig`` to a child (by pid) unless it has exited, wait ``timeout``, then SIGKILL; its exit code."""
    _signal(proc, sig)
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait(timeout=10)


def end_processes(procs: list[subprocess.Popen], sig: int = signal.SIGTERM, timeout: float = 10.0) -> list[int]:
    """End several children together: ``sig`` to each first, then each waited for (``timeout`` in all before
    the stragglers get SIGKILL); their exit codes, in order."""
    for proc in procs:
        _signal(proc, sig)
    deadline = time.monotonic() + timeout
    return [end_process(proc, sig, max(0.1, deadline - time.monotonic())) for proc in procs]


def _signal(proc: subprocess.Popen, sig: int) -> None:
    """``sig`` to a child that has not exited (by pid; one gone meanwhile is no error)."""
    if proc.poll() is None:
        try:
            os.kill(proc.pid, sig)
        except ProcessLookupError:
            pass
