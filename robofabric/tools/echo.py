"""``robofabric echo``: print the decoded messages on a key (like ``ros2 topic echo``)."""

from __future__ import annotations

import json
import sys
import threading
from typing import Annotated, Optional

import typer
import zenoh

from fabric.cli_common import Joining, NothingThere, UserError, join_flags, say, watch_reader
from fabric.text import escape
from robofabric.complete import complete_keys
from robofabric.tools.common import open_world, resolve_key


@join_flags()
def echo(
    key: Annotated[
        str,
        typer.Argument(
            help="Key expression, full (rf/demo/robot/arm1/joints) or world-relative (robot/*/pose).",
            autocompletion=complete_keys,
        ),
    ],
    count: Annotated[Optional[int], typer.Option("--count", "-n", help="Exit after N messages.")] = None,
    duration: Annotated[Optional[float], typer.Option(help="Exit after S seconds (exit 1 if nothing came).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object per line: {key, message}.")] = False,
    timeout: Annotated[
        Optional[float], typer.Option(help="Exit 1 with 'nothing on KEY in S s' when no message came within S seconds.")
    ] = None,
    latest: Annotated[
        bool,
        typer.Option(
            "--latest/--no-latest",
            help="First the latest value of latched keys (maps, paths, scene objects) set before echo started.",
        ),
    ] = True,
    join: Joining = Joining(),
) -> None:
    """Print decoded messages on a key; malformed payloads are reported on stderr and skipped."""
    from fabric.codec import DecodeError, decode, to_plain
    from fabric.session import shutdown_event

    if count is not None and count <= 0:
        raise UserError("--count must be positive")
    if timeout is not None and not timeout > 0:
        raise UserError("--timeout must be positive")
    stop = shutdown_event()
    watch_reader(stop)  # `echo KEY | head -3` ends with head, even on a key gone quiet
    printed = 0
    bad = 0
    lock = threading.Lock()
    with open_world("tool", join, key=key) as fab:
        full = resolve_key(key, fab.world)

        def on_sample(sample: zenoh.Sample) -> None:
            nonlocal printed, bad
            k = str(sample.key_expr)
            try:
                msg = decode(sample.payload.to_bytes())
            except DecodeError as exc:
                with lock:
                    bad += 1
                print(f"{k}: bad payload: {exc}", file=sys.stderr, flush=True)
                return
            with lock:
                if count is not None and printed >= count:
                    return
                printed += 1
                if as_json:
                    line = json.dumps({"key": k, "message": to_plain(msg)})
                else:
                    line = f"--- {escape(k)}\n{msg}"  # a key may hold a newline: escaped, never a line of its own
                say(line, stop=stop)  # a closed pipe (`| head -3`) ends echo with 0
                if count is not None and printed >= count:
                    stop.set()

        fab.subscribe_raw(full, on_sample, history=latest)
        early = timeout is not None and (duration is None or timeout < duration)
        stop.wait(timeout if early else duration)
        with lock:
            silent = printed == 0 and bad == 0
        if early and not silent and not stop.is_set():
            stop.wait(None if duration is None else duration - timeout)
        # set by Ctrl-C / SIGTERM (asked to stop: 0 even with nothing), --count or a closed pipe
        stopped = stop.is_set()
    if bad:
        print(f"{bad} malformed payload(s) skipped", file=sys.stderr)
    if silent and not stopped:  # --timeout or --duration ran out with nothing: the world had nothing there
        raise NothingThere(f"nothing on {full} in {timeout if early else duration:g} s")
