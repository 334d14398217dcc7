"""``robofabric record | info | replay``.

Every user mistake (missing or non-MCAP file, empty selection, unknown world,
bad window) becomes a :class:`fabric.cli_common.UserError`: one line, exit 2.
"""

from __future__ import annotations

import json
import sys
import threading
import time
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from fabric import keys
from fabric.cli_common import Joining, NothingThere, UserError, join_flags, print_table
from robofabric.complete import complete_formats, complete_keys, complete_keys_or_recordings

__all__ = ["register", "record", "info", "replay"]


def _resolve(expr: str, world: str) -> str:
    """Full (``rf/demo/robot/**``) or world-relative (``robot/*/pose``) key expression, validated."""
    try:
        return keys.in_world(expr, world)
    except ValueError as exc:
        raise UserError(str(exc)) from None


# --------------------------------------------------------------------------- record


@join_flags()
def record(
    output: Annotated[Path, typer.Option("--output", "-o", help="The MCAP file to write (overwritten if it exists).")],
    keyexprs: Annotated[
        Optional[list[str]],
        typer.Argument(
            help="Key expressions to record, full or world-relative (default: the whole world, rf/WORLD/**).",
            autocompletion=complete_keys,
        ),
    ] = None,
    duration: Annotated[
        Optional[float], typer.Option(help="Stop after S seconds (default: until Ctrl-C / SIGTERM).")
    ] = None,
    liveliness: Annotated[
        bool, typer.Option("--liveliness", help="Also record peers' liveliness tokens appearing and going.")
    ] = False,
    compression: Annotated[str, typer.Option(help="Chunk compression: zstd, lz4 or none.")] = "zstd",
    chunk_size: Annotated[int, typer.Option(help="Close a chunk once it holds this many bytes.")] = 1 << 20,
    flush_interval: Annotated[
        float,
        typer.Option(help="Close the open chunk and hand it to the OS at least this often (s): what a crash can lose."),
    ] = 0.5,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress line.")] = False,
    to: Annotated[
        Optional[str],
        typer.Option(
            "--to",
            help="Write another format live instead of the fabric's own: foxglove or ros2 (see `robofabric export`).",
            autocompletion=complete_formats,
        ),
    ] = None,
    scene: Annotated[
        Optional[str], typer.Option(help="With --to: the scene being recorded (places the arms, draws the walls).")
    ] = None,
    max_queue_mb: Annotated[
        float,
        typer.Option(
            "--max-queue-mb", help="Payload waiting for the disk at most; beyond, samples are dropped and counted."
        ),
    ] = 256.0,
    quota_mb: Annotated[
        Optional[float],
        typer.Option(
            "--quota-mb", help="Write at most this many MB of payload; later samples are dropped and counted."
        ),
    ] = None,
    join: Joining = Joining(),
) -> None:
    """Record every sample on the selected keys into an MCAP file (one channel per key, zstd chunks).

    With --to foxglove|ros2 the file is written in that format as the samples arrive (decoded
    messages only; replay and info need the fabric's own format, which `export --to` converts from).
    """
    from fabric.recording.recorder import Recorder
    from fabric.recording.sink import COMPRESSIONS
    from fabric.session import shutdown_event

    if duration is not None and not duration > 0:
        raise UserError("--duration must be positive")
    if compression not in COMPRESSIONS:
        raise UserError(f"--compression must be one of {', '.join(COMPRESSIONS)}, got {compression!r}")
    if chunk_size < 1024:
        raise UserError("--chunk-size must be at least 1024 bytes")
    if not flush_interval > 0:
        raise UserError("--flush-interval must be positive")
    if not max_queue_mb > 0 or (quota_mb is not None and not quota_mb > 0):
        raise UserError("--max-queue-mb and --quota-mb must be positive")
    if output.is_dir():
        raise UserError(f"{output} is a directory; give a file name such as {output / 'run.mcap'}")
    if not output.parent.exists():
        raise UserError(f"directory {output.parent} does not exist")
    cfg = join.config()
    exprs = [_resolve(e, cfg.world) for e in keyexprs] if keyexprs else [keys.world_all(cfg.world)]
    stop = shutdown_event()
    tty = sys.stderr.isatty()
    if to is not None:
        _record_as(to, output, exprs, duration, quiet, scene, cfg, join, stop, tty)
        return
    from fabric.heap import HeapTrimmer, limit_arenas

    limit_arenas()  # before the session's threads: what they free through hours of recording goes back (fabric.heap)
    with join.open("recorder", cfg) as fab, HeapTrimmer():
        try:
            rec = Recorder(
                fab,
                output,
                exprs,
                liveliness=liveliness,
                compression=compression,
                chunk_size=chunk_size,
                flush_interval=flush_interval,
                max_queue_bytes=int(max_queue_mb * 1e6),
                quota_bytes=None if quota_mb is None else int(quota_mb * 1e6),
            )
            rec.start()
        except OSError as exc:
            raise UserError(f"cannot write {output}: {exc.strerror or exc}") from None
        print(f"recording {', '.join(exprs)} to {output}; Ctrl-C to stop", file=sys.stderr, flush=True)
        stats = _run_until_done(rec, output, duration, stop, quiet, tty)
    print(f"recorded {stats.line()} -> {output}", file=sys.stderr, flush=True)
    if stats.dropped:
        why = "the disk quota was reached" if stats.quota_reached else "the queue to the disk was full or too many keys"
        print(
            f"warning: {stats.dropped} samples ({stats.dropped_bytes} bytes) were not recorded: {why}",
            file=sys.stderr,
            flush=True,
        )
    _say_missed(stats)
    if stats.messages == 0:  # exit 1: the world had nothing there
        raise NothingThere(
            f"nothing was recorded on {', '.join(exprs)} (unknown world or no publisher?); {output} is an empty recording"
        )


def _say_missed(stats: Any) -> None:
    """A warning for samples their publishers numbered and that never came (fabric/recording/gaps.py)."""
    if stats.missed:
        print(
            f"warning: {stats.missed} samples ({stats.holes} stretches) numbered by their publishers never reached this "
            "recorder: lost on the way (best-effort streams drop what a starved or paused process cannot take), or "
            "held back by their publisher (a sim muzzled after a freeze)",
            file=sys.stderr,
            flush=True,
        )


def _run_until_done(
    worker: Any, output: Path, duration: float | None, stop: threading.Event, quiet: bool, tty: bool
) -> Any:
    """Run a recorder or live converter until ``duration``, Ctrl-C or its error, showing its progress line
    (in place on a terminal, every 5 s otherwise); returns its final stats."""
    t0 = last_line = time.monotonic()
    while True:
        left = None if duration is None else duration - (time.monotonic() - t0)
        if left is not None and left <= 0:
            break
        if stop.wait(0.5 if left is None else min(0.5, left)) or worker.error is not None:
            break
        now = time.monotonic()
        if not quiet and (tty or now - last_line >= 5.0):
            last_line = now
            line = worker.stats.line()
            print(f"\r{line}\x1b[K" if tty else line, end="" if tty else "\n", file=sys.stderr, flush=True)
    try:
        stats = worker.close()
    except RuntimeError as exc:
        raise UserError(f"recording to {output} failed: {exc}") from None
    finally:
        if tty and not quiet:
            print(file=sys.stderr)
    return stats


def _record_as(to, output, exprs, duration, quiet, scene, cfg, join: Joining, stop, tty) -> None:
    """``record --to FORMAT``: decode live samples into another format's writer (robofabric.recording.live_convert)."""
    from robofabric.recording.live_convert import LiveConverter, open_exporter

    if output.suffix != ".mcap":
        raise UserError(f"--output {output}: a {to} recording is an MCAP file and must end in .mcap")
    with join.open("recorder", cfg) as fab:
        try:
            sink = open_exporter(to, output, scene=scene)
        except KeyError as exc:
            raise UserError(str(exc.args[0])) from None
        except OSError as exc:
            raise UserError(f"cannot write {output}: {exc.strerror or exc}") from None
        conv = LiveConverter(fab, sink, exprs).start()
        print(f"recording {', '.join(exprs)} as {to} to {output}; Ctrl-C to stop", file=sys.stderr, flush=True)
        stats = _run_until_done(conv, output, duration, stop, quiet, tty)
    print(f"recorded {stats.line()} -> {output} ({to})", file=sys.stderr, flush=True)
    _say_missed(stats)
    if stats.written == 0:
        raise NothingThere(
            f"nothing was recorded on {', '.join(exprs)} (unknown world or no publisher?); {output} is empty"
        )


# --------------------------------------------------------------------------- info


def _size(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} GB"


@join_flags()
def info(
    target: Annotated[
        str,
        typer.Argument(
            help="A recording (FILE.mcap) or a live key (robot/arm1/joints, rf/demo/map/map).",
            autocompletion=complete_keys_or_recordings,
        ),
    ],
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help=(
                'One JSON document instead of tables. A live key: {"key", "latched", "subscribers", "subscribed_by", "declarations_visible", '
                '"services": [{key, request, reply, servers}], "keys": [{key, type, publishers, messages, rate_hz, bytes_per_s, last_bytes, latched}], '
                '"types": {TYPE: [field names]}}; a recording: its summary (path, complete, duration_s, messages, channels, ...).'
            ),
        ),
    ] = False,
    duration: Annotated[float, typer.Option(help="Live key: seconds to watch it.")] = 2.0,
    join: Joining = Joining(),
) -> None:
    """A recording's summary (duration, keys, counts, rates, sizes, schemas, complete or not), or a live key's.

    TARGET ending in .mcap or naming an existing file is a recording; anything else is a key of the
    world (type and fields, publishers, rate, subscribers), as ``ros2 topic info`` gives.
    """
    path = Path(target)
    if target.endswith(".mcap") or path.is_file():
        _recording_info(path, as_json)
        return
    from robofabric.introspect_cli import key_info

    key_info(target, as_json=as_json, duration=duration, join=join)


LONG_INFO_BYTES = 20_000_000
"""``info`` reads a recording through (it must, for unfinished files): a progress bar above this size."""


def _recording_info(file: Path, as_json: bool) -> None:
    from user_peer.recordings import RecordingError, read_info

    big = not as_json and file.is_file() and file.stat().st_size > LONG_INFO_BYTES
    try:
        if big:
            from rich.console import Console
            from rich.progress import BarColumn, DownloadColumn, Progress, TextColumn, TimeRemainingColumn

            with Progress(
                TextColumn("reading"),
                BarColumn(),
                DownloadColumn(),
                TimeRemainingColumn(),
                console=Console(stderr=True),
                transient=True,
            ) as bar:
                task = bar.add_task("info", total=file.stat().st_size)
                inf = read_info(file, progress=lambda done, total: bar.update(task, completed=done, total=total))
        else:
            inf = read_info(file)
    except RecordingError as exc:
        raise UserError(str(exc)) from None
    if as_json:
        print(json.dumps(inf.to_json()))
        return
    from rich.console import Console

    con = Console()
    state = "[green]complete[/]" if inf.complete else f"[bold red]UNFINISHED[/] - {inf.detail}"
    con.print(f"[bold]{inf.path}[/]: {state}")
    ratio = inf.payload_bytes / inf.file_bytes if inf.file_bytes else 0.0
    rate = (inf.messages - 1) / inf.duration_s if inf.messages > 1 and inf.duration_s > 0 else 0.0
    con.print(
        f"duration {inf.duration_s:.3f} s   messages {inf.messages} ({rate:.1f}/s)   payload {_size(inf.payload_bytes)}   "
        f"file {_size(inf.file_bytes)} ({ratio:.1f}x, {inf.chunks} chunk(s), {', '.join(inf.compression) or 'none'})"
    )
    con.print(f"worlds: {', '.join(inf.worlds) or '-'}   schemas: {', '.join(inf.schemas) or '-'}")
    if inf.metadata:
        con.print("recorded by " + ", ".join(f"{k}={v}" for k, v in sorted(inf.metadata.items()) if v))
    print_table(
        f"{len(inf.channels)} channel(s)",
        ("key", "schema", "messages", "rate Hz", "bytes", "avg B"),
        [
            (c.key, c.schema, str(c.messages), f"{c.rate_hz:.1f}", _size(c.bytes), f"{c.bytes / c.messages:.0f}")
            for c in inf.channels
        ],
        numeric=("messages", "rate Hz", "bytes", "avg B"),
    )


# --------------------------------------------------------------------------- replay


@join_flags()
def replay(
    file: Annotated[
        Path, typer.Argument(help="An MCAP recording (unfinished ones replay up to their last complete chunk).")
    ],
    speed: Annotated[float, typer.Option(help="Time scale: 2 plays twice as fast, 0.5 at half speed.")] = 1.0,
    loop: Annotated[bool, typer.Option("--loop", help="Start again at the end, until Ctrl-C.")] = False,
    start: Annotated[Optional[float], typer.Option(help="Begin S seconds into the recording.")] = None,
    end: Annotated[Optional[float], typer.Option(help="Stop S seconds into the recording.")] = None,
    key_exprs: Annotated[
        Optional[list[str]],
        typer.Option("--keys", "-k", help="Only keys matching this expression, full or world-relative (repeatable)."),
    ] = None,
    remap_world: Annotated[
        Optional[str], typer.Option("--remap-world", help="Publish into this world instead of the recorded one.")
    ] = None,
    wait: Annotated[float, typer.Option(help="Wait up to S seconds for a subscriber before starting.")] = 2.0,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
    join: Joining = Joining(),
) -> None:
    """Republish a recording's exact bytes on the recorded timeline (scaled by --speed), optionally into another world.

    --world selects which recorded world to replay (default: every world in the file).
    """
    from user_peer.recordings import RecordingError
    from robofabric.recording.replayer import Replayer, plan_replay
    from fabric.session import shutdown_event

    if wait < 0:
        raise UserError("--wait must be >= 0")
    exprs = None
    if key_exprs:
        scope = join.world or "*"
        exprs = []
        for e in key_exprs:
            full = e if e.startswith(keys.PREFIX + "/") else f"{keys.PREFIX}/{scope}/{e.lstrip('/')}"
            exprs.append(_check_expr(e, full))
    try:
        plan = plan_replay(
            file, speed=speed, start=start, end=end, keys=exprs, world=join.world, remap_world=remap_world
        )
    except RecordingError as exc:
        raise UserError(str(exc)) from None
    target_world = remap_world or join.world or (plan.worlds[0] if plan.worlds else None)
    cfg = join.config(world=target_world)
    stop = shutdown_event()
    with join.open("tool", cfg) as fab:
        into = f" into world {remap_world!r}" if remap_world else ""
        print(
            f"replaying {plan.messages} msgs on {len(plan.keys)} key(s) from {file}{into} at {speed:g}x"
            + (" (loop)" if loop else ""),
            file=sys.stderr,
            flush=True,
        )
        rp = Replayer(fab, plan, loop=loop, wait_for_subscribers=wait)
        try:
            stats = _run_with_progress(rp, plan.messages, loop, stop, quiet)
        finally:
            rp.close()
    if rp.error is not None:
        raise UserError(f"replay of {file} failed: {rp.error}")
    print(stats.line(), flush=True)


def _run_with_progress(rp, total: int, loop: bool, stop, quiet: bool):
    """Run the replayer on its thread with a rich progress bar on stderr (messages sent of the recording's)."""
    rp.start()
    if quiet:
        while not rp.done and not stop.wait(0.2):
            pass
        rp.close()  # ends it when stopped (Ctrl-C), else only undeclares
        return rp.stats
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(
        TextColumn("replay"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
    ) as bar:
        task = bar.add_task("replay", total=None if loop else total)
        while not rp.done and not stop.wait(0.2):
            bar.update(task, completed=rp.stats.messages)
        rp.close()
        bar.update(task, completed=rp.stats.messages)
    return rp.stats


def _check_expr(given: str, full: str) -> str:
    import zenoh

    try:
        zenoh.KeyExpr(full)
    except Exception as exc:
        raise UserError(f"{given!r} is not a valid key expression: {exc}") from None
    return full


def register(app: typer.Typer) -> None:
    app.command("record")(record)
    app.command("info")(info)
    app.command("replay")(replay)
