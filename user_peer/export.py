"""``robofabric export FILE.mcap -o FILE.rrd``: the live viewer's views, from a recording.

Messages are read with the standard ``mcap`` reader in log-time order and go
through the very :class:`~user_peer.rerun_log.WorldLogger` the live viewer
uses, with the receive time as the wall clock. Payloads that do not decode are
counted and skipped; a file that is not MCAP at all is an error.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import rerun as rr

from fabric.codec import DecodeError, decode, load_plugins
from user_peer.catalog import RobotCatalog
from user_peer.openfmt.convert import ExportError, recorded_world
from user_peer.rerun_log import WorldLogger, blueprint
from user_peer.viewer import APP_ID, log_scene

log = logging.getLogger("robofabric.user")

__all__ = ["RerunExportStats", "ExportError", "read_mcap", "export_mcap"]


SKIPPED_SCHEMAS = ("raw", "liveliness")
"""Recorded samples that are not fabric messages (see fabric/recording/format.py): nothing to draw."""


@dataclass(frozen=True, slots=True)
class RerunExportStats:
    """What an export to a Rerun file did (the other formats' counterpart: ``user_peer.openfmt.ExportStats``)."""

    messages: int
    drawn: int
    bad: int
    robots: tuple[str, ...]


def check_mcap(path: Path) -> None:
    """Raise :class:`ExportError` unless ``path`` is a readable MCAP file."""
    if not path.is_file():
        raise ExportError(f"{path}: no such file")
    with open(path, "rb") as f:
        if f.read(8)[:5] != b"\x89MCAP":
            raise ExportError(f"{path}: not an MCAP file")


def read_mcap(path: Path, counts: dict[str, int] | None = None) -> Iterator[tuple[str, object, int]]:
    """(key, decoded message, log time ns) of every fabric message of a recording, in file order.

    Reading goes through :func:`user_peer.recordings.iter_messages` (the ``mcap`` package underneath),
    which stops quietly at the torn tail of a recorder killed mid-write. Samples recorded as raw
    bytes or liveliness are skipped; payloads that do not decode are counted as ``bad``.
    """
    from user_peer.recordings import RecordingError, iter_messages

    check_mcap(path)
    load_plugins()  # the recording may hold any installed package's message types
    try:
        for m in iter_messages(path):
            if m.schema in SKIPPED_SCHEMAS:
                continue
            try:
                msg = decode(m.payload)
            except DecodeError:
                if counts is not None:
                    counts["bad"] = counts.get("bad", 0) + 1
                continue
            yield m.key, msg, int(m.log_time)
    except RecordingError as exc:
        raise ExportError(str(exc)) from None


def export_mcap(
    src: Path,
    dst: Path,
    *,
    max_hz: float = 0.0,
    scene: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RerunExportStats:
    """Write ``dst`` (.rrd) from the recording ``src``; every message is drawn unless ``max_hz`` thins it.

    Robots are placed by the world description the recording holds (the recorder writes ``srv/world``'s answer
    when a sim comes), else by ``scene``, else by the first scene placing each robot id (with a warning).
    """
    check_mcap(src)
    dst.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream(APP_ID, recording_id=f"export-{src.stem}")
    rec.save(str(dst), default_blueprint=blueprint())
    info = recorded_world(src)
    if info is None and scene is None:
        log.warning(
            "%s carries no world description: robots are placed by the scene that names them first; pass "
            "--scene NAME to place them by yours",
            src,
        )
    scene = scene or (info.scene if info is not None else None)
    catalog = RobotCatalog(info, scene=scene)
    logger = WorldLogger(rec, drawing=catalog.drawing, max_hz=max_hz)
    if scene:
        log_scene(logger, scene)
    counts: dict[str, int] = {}
    n = drawn = 0
    total = _count(src) if progress is not None else 0
    try:
        for key, msg, t in read_mcap(src, counts):
            n += 1
            if logger.log(key, msg, t):
                drawn += 1
            if progress is not None and n % 200 == 0:
                progress(n, total)
    finally:
        logger.flush()
        rec.flush(timeout_sec=30.0)
        rec.disconnect()
    if progress is not None:
        progress(n, n)
    return RerunExportStats(n, drawn, counts.get("bad", 0), tuple(sorted(logger.robots)))


def _count(src: Path) -> int:
    """Messages in the recording per its summary (0 when unknown: an unfinished file)."""
    from user_peer.recordings import RecordingError, read_info

    try:
        return read_info(src).messages
    except RecordingError:
        return 0
