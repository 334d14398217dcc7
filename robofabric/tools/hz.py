"""``robofabric hz``: rate, jitter and bandwidth of the keys matching an expression (like ``ros2 topic hz`` and ``bw``)."""

from __future__ import annotations

import json
import sys
import threading
import time
from typing import Annotated, Optional

import typer
import zenoh

from fabric.cli_common import Joining, NothingThere, join_flags, say
from robofabric.terminal import print_folded
from robofabric.complete import complete_keys
from robofabric.tools.common import open_world, resolve_key


@join_flags()
def hz(
    key: Annotated[
        str,
        typer.Argument(help="Key expression; each matching key is measured separately.", autocompletion=complete_keys),
    ],
    duration: Annotated[
        Optional[float], typer.Option(help="Measure for S seconds, then print the summary and exit.")
    ] = None,
    window: Annotated[int, typer.Option(help="Intervals kept per key for the running statistics.")] = 10_000,
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help='Print only the final summary, as one JSON document: {"key", "streams": {KEY: {count, rate_hz, jitter_ms, min_ms, max_ms, bytes, bytes_per_s}}}.',
        ),
    ] = False,
    join: Joining = Joining(),
) -> None:
    """Rate, jitter and bandwidth of the keys matching KEY (like ``ros2 topic hz`` and ``bw``)."""
    from fabric.session import shutdown_event
    from robofabric.stats import StreamStats

    stop = shutdown_event()
    stats: dict[str, StreamStats] = {}
    lock = threading.Lock()
    with open_world("tool", join, key=key) as fab:
        full = resolve_key(key, fab.world)

        def on_sample(sample: zenoh.Sample) -> None:
            now = time.monotonic()
            k = str(sample.key_expr)
            with lock:
                st = stats.get(k)
                if st is None:
                    st = stats[k] = StreamStats(window=window)
                st.add(now, len(sample.payload))

        fab.subscribe_raw(full, on_sample)
        start = time.monotonic()
        end = None if duration is None else start + duration
        while not stop.is_set():
            left = 1.0 if end is None else min(1.0, end - time.monotonic())
            if left <= 0 or stop.wait(left):
                break
            if not as_json:
                with lock:
                    snap = {k: s.summary() for k, s in stats.items()}
                print_folded(*(_hz_line(k, s) for k, s in sorted(snap.items())))  # as wide as the terminal
                if not snap and not say(f"no messages on {full} yet", stop=stop):
                    break
    with lock:
        final = {k: s.summary() for k, s in sorted(stats.items())}
    if as_json:
        say(json.dumps({"key": full, "streams": final}))
    elif final:
        say("summary:")
        print_folded(*(_hz_line(k, s) for k, s in final.items()))
    elif stop.is_set():
        print(f"no messages on {full}", file=sys.stderr)
    if not final and not stop.is_set():  # --duration ran out with nothing to measure (Ctrl-C: asked to stop, 0)
        raise NothingThere(f"no messages on {full} in {duration:g} s")


def _hz_line(key: str, s: dict) -> str:
    return (
        f"{key}: {s['rate_hz']:.1f} Hz  jitter {s['jitter_ms']:.3f} ms  min {s['min_ms']:.3f} ms  "
        f"max {s['max_ms']:.3f} ms  {s['bytes_per_s'] / 1000:.1f} kB/s  n={s['count']}"
    )
