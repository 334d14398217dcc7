"""The paper's Table 4 for robofabric: CPU and RSS of each application while Test A and Test B run.

One ``robofabric up`` of a launch file written here: the router (hosted by the launcher, as in the demo), the
sim (``combined``), the compute peer streaming arm1's IK, a viewer saving its recording, the console, and the
two scripted users, alice (Test A) and bob (Test B). Every second each process of the launch is read from
/proc (CPU % of one core over the second, resident memory); the rows are min and max over the seconds in
which both users were running, as the paper's Table 4 reports min and max per application. The launch ends
by itself when both users have finished (``up`` stops the services then); a cap ends it otherwise.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import shutil
import tempfile
import time
import uuid
from pathlib import Path

from robofabric.bench.common import end_process, proc_cpu_s, proc_rss_mb

__all__ = ["measure_resources", "PEERS"]

PEERS = ("router", "sim", "compute", "view", "console", "alice (Test A)", "bob (Test B)")


def _launch_file(world: str, router_port: int, console_port: int) -> str:
    return f"""[launch]
world = "{world}"
router = "tcp/127.0.0.1:{router_port}"

[[peer]]
name = "sim"
args = ["sim", "--scene", "combined"]
role = "service"

[[peer]]
name = "compute"
args = ["compute", "--stream", "arm1:target"]
role = "service"
after = ["sim"]

[[peer]]
name = "view"
args = ["view", "--save", "{{out}}/paper.rrd"]
role = "service"
after = ["sim"]

[[peer]]
name = "console"
args = ["console", "--listen", "127.0.0.1:{console_port}"]
role = "service"
after = ["sim"]

[[peer]]
name = "alice"
args = ["scenario", "test-a", "--user", "alice"]
role = "task"
after = ["sim", "compute", "view", "console"]

[[peer]]
name = "bob"
args = ["scenario", "test-b", "--user", "bob"]
role = "task"
after = ["sim", "compute", "view", "console"]
"""


def _children() -> dict[int, list[int]]:
    """ppid -> pids, from /proc."""
    out: dict[int, list[int]] = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        out.setdefault(ppid, []).append(int(d))
    return out


def _descendants(root: int) -> list[int]:
    kids = _children()
    seen, todo = [], [root]
    while todo:
        p = todo.pop()
        seen.append(p)
        todo.extend(kids.get(p, []))
    return seen


def _name(pid: int, launcher: int) -> str | None:
    """Which application ``pid`` is, from its command line; None for helpers (a browser's, a shell)."""
    if pid == launcher:
        return "router"
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            argv = f.read().split(b"\0")
    except OSError:
        return None
    words = [a.decode(errors="replace") for a in argv]
    if "scenario" in words:
        return "alice (Test A)" if "test-a" in words else "bob (Test B)"
    for peer in ("sim", "compute", "view", "console"):
        if peer in words:
            return peer
    return None


def _kept_logs(tmp: Path, tail: int = 1500) -> str:
    """The launch's peers' logs copied out of ``tmp`` (a failed run's cause is in them: one `bench paper` run's bob
    did not reach his path's end, and its logs went with the folder), and each one's last ``tail`` characters."""
    logs = tmp / "out" / "logs"
    if not logs.is_dir():
        return ""
    kept = Path(tempfile.mkdtemp(prefix="bench-paper-failed-"))
    words = [f"\n--- the launch's logs are kept in {kept}"]
    for f in sorted(logs.glob("*.log")):
        shutil.copy2(f, kept / f.name)
        words.append(f"--- {f.name}:\n{f.read_text(errors='replace')[-tail:]}")
    return "\n".join(words)


def measure_resources(cap_s: float = 600.0, progress=lambda s: print(s, file=sys.stderr, flush=True)) -> dict:
    """Run the launch once; ``{"rows": [{peer, cpu_min, cpu_max, rss_min_mb, rss_max_mb, samples}], ...}``."""
    from robofabric.testing import free_port

    world = f"paper{uuid.uuid4().hex[:6]}"
    with tempfile.TemporaryDirectory(prefix="bench-paper-res-") as tmp:
        launch = Path(tmp) / "paper.toml"
        launch.write_text(_launch_file(world, free_port(), free_port()))
        log = open(Path(tmp) / "up.log", "wb")
        proc = subprocess.Popen(
            [sys.executable, "-m", "robofabric", "up", str(launch), "--out", str(Path(tmp) / "out")],
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        log.close()
        samples: dict[str, list[tuple[float, float]]] = {p: [] for p in PEERS}
        last: dict[int, tuple[float, float]] = {}
        t0 = time.monotonic()
        both_seen = False
        try:
            while proc.poll() is None and time.monotonic() - t0 < cap_s:
                time.sleep(1.0)
                now = time.monotonic()
                named = {pid: n for pid in _descendants(proc.pid) if (n := _name(pid, proc.pid))}
                users = {n for n in named.values() if n.startswith(("alice", "bob"))}
                both = len(users) == 2
                both_seen = both_seen or both
                for pid, n in named.items():
                    cpu = proc_cpu_s(pid)
                    try:
                        rss = proc_rss_mb(pid)
                    except OSError:
                        continue
                    prev = last.get(pid)
                    last[pid] = (now, cpu)
                    if prev is not None and both and cpu == cpu:
                        samples[n].append((100.0 * (cpu - prev[1]) / (now - prev[0]), rss))
                if both_seen and not users:
                    progress("both users finished")
                    break
        finally:
            try:
                code = proc.wait(timeout=60 if both_seen else 0.1)  # up exits by itself once both users finished
            except subprocess.TimeoutExpired:
                code = end_process(proc, sig=signal.SIGINT, timeout=30)  # Ctrl-C: up stops its peers
            for pid in last:  # anything of the launch still alive (up killed before it stopped them): by pid
                if pid != proc.pid and _name(pid, proc.pid):
                    try:
                        os.kill(pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
            up_log = (Path(tmp) / "up.log").read_text(errors="replace")[-3000:]
            if code:  # the launch failed: keep its peers' logs, which go with the temporary folder, and say where
                up_log += _kept_logs(Path(tmp))
    rows = []
    for peer in PEERS:
        s = samples[peer]
        rows.append(
            {
                "peer": peer,
                "cpu_min": min((c for c, _ in s), default=float("nan")),
                "cpu_max": max((c for c, _ in s), default=float("nan")),
                "rss_min_mb": min((r for _, r in s), default=float("nan")),
                "rss_max_mb": max((r for _, r in s), default=float("nan")),
                "samples": len(s),
            }
        )
    return {"rows": rows, "seconds": time.monotonic() - t0, "up_exit": code, "up_log_tail": up_log if code else ""}
