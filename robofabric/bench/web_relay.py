"""Stalled readers against one ``robofabric view --serve-web``: the viewer's memory, and an honest reader's feed.

A router, ``robofabric sim --scene combined`` and ``robofabric view --serve-web`` run as child processes for
``--warmup`` seconds (the session's history grows), then one honest gRPC-web reader (as a page reads, from
127.0.0.2) starts, and ``--stalled`` connections ask for the stream and never read, each from an address of
its own (127.0.0.10 on: no per-address cap spares the relay the others). Reported: the viewer process's RSS
before and at most while they are held (sampled every 0.2 s for ``--seconds``), what the honest reader
received meanwhile and whether it was cut, and the viewer's relay counters (its closing line). Run it on an
older checkout to compare (``PYTHONPATH=OLD_TREE``: the children run that tree's code).
"""

from __future__ import annotations

import re
import socket
import time
from typing import Any

from robofabric.bench.grpc_web import WebReader, stalled_reader

__all__ = ["run", "main"]


def _rss_mb(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:")) / 1024
    except (OSError, StopIteration):
        return float("nan")


def run(stalled: int, warmup: float, seconds: float, log: Any = print) -> dict[str, Any]:
    import signal
    import tempfile
    import uuid
    from pathlib import Path

    from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, wait_until
    from robofabric.bench.viewer_web import VIEWER_URL, accepts

    world = f"benchrelay{uuid.uuid4().hex[:6]}"
    out: dict[str, Any] = {"stalled": stalled, "warmup_s": warmup, "seconds": seconds}
    with tempfile.TemporaryDirectory(prefix="bench-relay-") as tmp, ProcessGroup(Path(tmp)) as procs:
        ep = f"tcp/127.0.0.1:{free_port()}"
        router = procs.start(robofabric_cmd("router", "--listen", ep, "--world", world), name="router")
        wait_until(
            lambda: accepts(ep),
            timeout=30,
            interval=0.1,
            what="the router to listen",
            seen=lambda: procs.output(router),
        )
        procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep), name="sim")
        web, grpc = free_port(), free_port()
        view = procs.start(
            robofabric_cmd(
                "view",
                "--serve-web",
                "--advertise",
                "127.0.0.1",
                "--web-port",
                str(web),
                "--grpc-port",
                str(grpc),
                "--world",
                world,
                "--connect",
                ep,
            ),
            name="view",
        )
        wait_until(
            lambda: VIEWER_URL.search(procs.output(view)),
            timeout=90,
            interval=0.2,
            what="the viewer's URL",
            seen=lambda: procs.output(view)[-2000:],
        )
        time.sleep(warmup)  # a benchmark's session length, not a wait on a condition
        honest = WebReader(grpc, source="127.0.0.2")
        conns: list[socket.socket] = []
        try:
            wait_until(lambda: honest.received > 0, timeout=30, what="the honest reader to receive")
            out["rss_before_mb"] = _rss_mb(view.pid)
            log(f"session of {warmup:g} s; viewer RSS {out['rss_before_mb']:.0f} MB; {stalled} stalled readers connect")
            before = honest.received
            t0 = time.monotonic()
            for i in range(stalled):
                try:
                    conns.append(stalled_reader(grpc, source=f"127.0.{(10 + i) // 250}.{(10 + i) % 250 + 1}"))
                except OSError as exc:
                    out.setdefault("connect_errors", []).append(str(exc))
            peak = out["rss_before_mb"]
            received = []
            while time.monotonic() - t0 < seconds:  # bounded: --seconds
                peak = max(peak, _rss_mb(view.pid))
                received.append((time.monotonic() - t0, honest.received - before))
                time.sleep(0.2)
            out["rss_peak_mb"] = peak
            out["honest_mb"] = (honest.received - before) / 1e6
            # the longest the honest reader went without a byte while the stalled readers were held
            longest = run_s = 0.0
            for (ta, na), (tb, nb) in zip(received, received[1:]):
                run_s = run_s + (tb - ta) if nb == na else 0.0
                longest = max(longest, run_s)
            out["honest_longest_gap_s"] = longest
            out["honest_ended"] = honest.ended
        finally:
            for c in conns:
                c.close()
            honest.close()
            if view.poll() is None:
                view.send_signal(signal.SIGINT)  # its closing lines: the relay's counters
                try:
                    view.wait(timeout=20)
                except Exception:
                    pass
        text = procs.output(view)
        out["relay_line"] = next(iter(re.findall(r"web relay: \d+ requests refused.*", text)), "")
        out["cut"] = len(re.findall(r"web relay: page \S+ cut off", text))
        out["honest_cut"] = bool(re.search(r"web relay: page 127\.0\.0\.2:\d+ cut off", text))
    return out


def main(argv: list[str] | None = None) -> None:
    """``python -m robofabric.bench.web_relay --stalled 100 --warmup 120 --seconds 20``"""
    import argparse

    from robofabric.bench.common import machine

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stalled", type=int, default=100, help="connections that ask for the stream and never read")
    ap.add_argument("--warmup", type=float, default=120.0, help="seconds the session runs before (its history)")
    ap.add_argument("--seconds", type=float, default=20.0, help="how long the stalled readers are held")
    a = ap.parse_args(argv)
    r = run(a.stalled, a.warmup, a.seconds)
    print(machine())
    print(
        f"{a.stalled} stalled readers after a {a.warmup:g} s session, held {a.seconds:g} s: viewer RSS "
        f"{r['rss_before_mb']:.0f} MB -> peak {r['rss_peak_mb']:.0f} MB; honest reader got {r['honest_mb']:.1f} MB, "
        f"longest gap {r['honest_longest_gap_s']:.1f} s, cut: {r['honest_cut']}; pages cut {r['cut']}; "
        f"{r['relay_line'] or '(no relay line)'}"
    )


if __name__ == "__main__":
    main()
