"""Export a fabric recording to Foxglove's or ROS 2's MCAP, with progress; pick a writer by format name."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from fabric import keys
from fabric.codec import DecodeError, decode, load_plugins
from fabric.interfaces import WorldInfo
from user_peer.catalog import RobotCatalog
from user_peer.recordings import RecordingError, iter_messages, read_info

log = logging.getLogger("robofabric.user")

__all__ = ["FORMATS", "ExportStats", "ExportError", "open_sink", "export_recording", "recorded_world"]

FORMATS = ("foxglove", "ros2")
SKIPPED_SCHEMAS = ("raw", "liveliness")


class ExportError(ValueError):
    """The recording cannot be read or the format is unknown; the text says why (every export, Rerun's too)."""


@dataclass(frozen=True, slots=True)
class ExportStats:
    messages: int  # fabric messages read
    written: int  # messages written (a pose may become a PoseStamped and a TF message)
    bad: int  # payloads that did not decode
    skipped: int  # messages the format has no place for
    robots: tuple[str, ...]


def open_sink(to: str, path: Path, *, scene: str | None = None, catalog: RobotCatalog | None = None) -> Any:
    """A writer for format ``to`` ("foxglove" or "ros2") at ``path``: ``write(key, msg, log_ns, pub_ns)``, ``close()``."""
    if to == "foxglove":
        from user_peer.openfmt.foxglove import FoxgloveWriter

        return FoxgloveWriter(path, scene=scene, catalog=catalog)
    if to == "ros2":
        from user_peer.openfmt.ros2 import Ros2Writer

        return Ros2Writer(path, scene=scene, catalog=catalog)
    raise ExportError(f"unknown format {to!r}; expected one of {', '.join(FORMATS)}")


def export_recording(
    src: Path, dst: Path, to: str, *, scene: str | None = None, progress: Callable[[int, int], None] | None = None
) -> ExportStats:
    """Write ``dst`` in format ``to`` from the fabric recording ``src``; ``progress(done, total)`` as it goes."""
    try:
        total = read_info(src).messages
    except RecordingError as exc:
        raise ExportError(str(exc)) from None
    load_plugins()
    dst.parent.mkdir(parents=True, exist_ok=True)
    info = recorded_world(src)
    if info is None and scene is None:
        log.warning(
            "%s carries no world description (recorded before recorders kept one, or no sim answered): robots "
            "are placed by the scene that names them first; pass --scene NAME to place them by yours",
            src,
        )
    sink = open_sink(
        to,
        dst,
        scene=scene or (info.scene if info is not None else None),
        catalog=RobotCatalog(info, scene=scene or (info.scene if info is not None else None)),
    )
    n = bad = done = 0
    try:
        for m in iter_messages(src):
            done += 1
            if progress is not None and (done % 200 == 0 or done == total):
                progress(done, total)
            if m.schema in SKIPPED_SCHEMAS:
                continue
            try:
                msg = decode(m.payload)
            except DecodeError:
                bad += 1
                continue
            n += 1
            sink.write(m.key, msg, int(m.log_time), int(m.publish_time) or int(m.log_time))
    except RecordingError as exc:
        raise ExportError(str(exc)) from None
    finally:
        sink.close()
    if progress is not None:
        progress(total, total)
    return ExportStats(
        n, sink.written, bad, sink.skipped, tuple(sorted(r for r, i in sink.frames.robots.items() if i.kind))
    )


def recorded_world(src: Path) -> WorldInfo | None:
    """The last world description a recording holds (the recorder writes ``srv/world``'s answer when a sim
    comes), or None for a recording without one."""
    found = None
    for m in iter_messages(src, f"{keys.PREFIX}/*/srv/world"):
        try:
            msg = decode(m.payload)
        except DecodeError:
            continue
        if isinstance(msg, WorldInfo):
            found = msg
    return found


def foxglove_sink(path: Path, scene: str | None = None) -> Any:
    """Entry point ``robofabric.exporters:foxglove`` (for ``robofabric record --to foxglove``)."""
    return open_sink("foxglove", path, scene=scene)


def ros2_sink(path: Path, scene: str | None = None) -> Any:
    """Entry point ``robofabric.exporters:ros2`` (for ``robofabric record --to ros2``)."""
    return open_sink("ros2", path, scene=scene)
