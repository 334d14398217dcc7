"""A peer's resources from /proc: resident memory, threads, open file descriptors (and its log's size).

Read by pid, so it works for processes in any network namespace of the lab (they share the machine's
process namespace). A process that is gone, or whose files vanish mid-read, gives None.
"""

from __future__ import annotations

import os
from pathlib import Path

from robofabric.soak.history import ProcSample

__all__ = ["sample"]


def sample(t: float, name: str, pid: int, log_path: Path | None = None) -> ProcSample | None:
    """``pid``'s resources at ``t`` (the caller's clock), or None when it is gone."""
    rss_kb, threads = 0, 0
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    rss_kb = int(line.split()[1])
                elif line.startswith("Threads:"):
                    threads = int(line.split()[1])
        fds = len(os.listdir(f"/proc/{pid}/fd"))
    except (OSError, ValueError, IndexError):
        return None
    try:
        log_bytes = log_path.stat().st_size if log_path is not None else 0
    except OSError:
        log_bytes = 0
    return ProcSample(t, name, pid, round(rss_kb / 1024.0, 2), threads, fds, log_bytes)
