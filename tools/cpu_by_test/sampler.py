"""Every process's CPU on the machine, by kind, while a run goes: the whole box, Chromium and killed peers included.

    python3 tools/cpu_by_test/sampler.py /tmp/cpu.json &   # then make test; then kill %1 (SIGTERM) for the totals
    python3 tools/cpu_by_test/sampler.py --report /tmp/cpu.json

``sitecustomize`` (beside it) counts a Python process at its exit, so it misses Chromium, processes killed by
SIGKILL, and the kernel's own threads. This reads ``/proc/PID/stat`` of every process every ``--interval``
seconds instead and adds each one's CPU since the last look to its kind: ``rf sim``, ``rf compute`` (a
``robofabric`` subcommand), ``py -m robofabric.lab.agent``, ``pytest worker``, ``chromium``... A process is known
by its pid and start time (pids wrap at 32,768 here, and a whole run starts more). What a process did after its
last look before it ended is lost: at most ``--interval`` seconds of it. The file holds the totals and, per
interval, the six heaviest kinds.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import signal
import sys
import time

TICK = os.sysconf("SC_CLK_TCK")


def kind(argv: list[str]) -> str:
    """What a process is, from its argv."""
    if not argv:
        return "kernel thread"
    joined = " ".join(argv[:4])
    if "-m" in argv[:-1]:
        i = argv.index("-m")
        module = argv[i + 1]
        if module == "robofabric.cli":
            return "rf " + (argv[i + 2] if i + 2 < len(argv) else "")
        if module.startswith("robofabric") or module == "pytest":
            return "py -m " + module
    for i, arg in enumerate(argv[:2]):
        if arg.endswith(("/robofabric", "robofabric/cli.py")):
            return "rf " + (argv[i + 1] if i + 1 < len(argv) else "")
    if "chromium" in joined:
        return "chromium"
    if "execnet" in joined or argv[:3] == [argv[0], "-u", "-c"]:
        return "pytest worker"
    base = os.path.basename(argv[0])
    if base.startswith("python") and len(argv) > 1:
        return f"{base} {os.path.basename(argv[1])}"
    return base


def _argv(pid: str) -> list[str] | None:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return [a.decode(errors="replace") for a in f.read().split(b"\0") if a]
    except OSError:
        return None


def sample(seen: dict[tuple[int, str], list], totals: collections.Counter) -> collections.Counter:
    """One look at every process: the CPU seconds each kind used since the last look (added to ``totals``)."""
    now: collections.Counter = collections.Counter()
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/stat") as f:
                stat = f.read()
        except OSError:
            continue  # ended meanwhile
        fields = stat[stat.rindex(")") + 2 :].split()
        ticks, started = int(fields[11]) + int(fields[12]), fields[19]
        ident = (int(pid), started)
        if ident not in seen:
            argv = _argv(pid)
            if argv is None:
                continue
            seen[ident] = [kind(argv), 0]
        name, before = seen[ident]
        if ticks > before:
            used = (ticks - before) / TICK
            totals[name] += used
            now[name] += used
            seen[ident][1] = ticks
    return now


def record(path: str, interval: float) -> None:
    """Sample until SIGTERM or SIGINT, then write the totals and the timeline to ``path``."""
    running = [True]

    def stop(*_: object) -> None:
        running[0] = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    seen: dict[tuple[int, str], list] = {}
    totals: collections.Counter = collections.Counter()
    sample(seen, totals)  # what ran before the start is not the run's
    totals.clear()
    timeline = []
    while running[0]:
        time.sleep(interval)
        now = sample(seen, totals)
        timeline.append((round(time.time(), 1), {k: round(v, 2) for k, v in now.most_common(6)}))
    with open(path, "w") as f:
        json.dump({"interval": interval, "total": dict(totals.most_common()), "timeline": timeline}, f)


def report(path: str, top: int) -> None:
    with open(path) as f:
        doc = json.load(f)
    total = sum(doc["total"].values())
    span = len(doc["timeline"]) * doc["interval"]
    print(f"{total:.0f} CPU s in {span:.0f} s of wall ({total / max(span, 1e-9):.2f} cores on average)")
    for name, cpu in list(doc["total"].items())[:top]:
        print(f"{cpu:8.1f} s {100 * cpu / total:5.1f} %  {name}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("path", help="the JSON file written at the end (or read, with --report)")
    ap.add_argument("--interval", type=float, default=2.0, help="seconds between two looks")
    ap.add_argument("--report", action="store_true", help="print a file's totals by kind")
    ap.add_argument("--top", type=int, default=20)
    args = ap.parse_args()
    if args.report:
        report(args.path, args.top)
    else:
        record(args.path, args.interval)


if __name__ == "__main__":
    sys.exit(main())
