"""Recording and replaying key streams with MCAP.

``Recorder`` writes every sample of some key expressions into an MCAP file
(one channel per key, the fabric message type as schema name, msgpack as
message encoding, receive time as log time, header wall time as publish
time; zstd chunks that reach the disk every half second, so a killed
recorder leaves a readable file). ``read_info``, ``iter_messages`` and
``read_samples`` read files back, finished or not; ``plan_replay`` + ``Replayer`` republish the
exact bytes on the recorded timeline, optionally filtered, windowed, sped up
and remapped into another world. The CLI (``record``, ``info``, ``replay``)
is in :mod:`fabric.recording.cli` (``bench record``: robofabric/bench/record.py); see docs/recording.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fabric.recording.format import LIVELINESS_SCHEMA, MESSAGE_ENCODING, RAW_SCHEMA, Peek, peek, remap_world, world_of
    from fabric.recording.reader import (
        ChannelInfo,
        RecordedMessage,
        RecordingError,
        RecordingInfo,
        iter_messages,
        key_filter,
        read_info,
        read_samples,
    )
    from fabric.recording.recorder import Recorder, RecorderStats
    from fabric.recording.replayer import Replayer, ReplayPlan, ReplayStats, due_time, plan_replay
    from fabric.recording.sink import McapSink

__all__ = [
    "Recorder",
    "RecorderStats",
    "McapSink",
    "Replayer",
    "ReplayPlan",
    "ReplayStats",
    "plan_replay",
    "due_time",
    "RecordingError",
    "RecordingInfo",
    "ChannelInfo",
    "RecordedMessage",
    "read_info",
    "iter_messages",
    "read_samples",
    "key_filter",
    "peek",
    "Peek",
    "remap_world",
    "world_of",
    "MESSAGE_ENCODING",
    "RAW_SCHEMA",
    "LIVELINESS_SCHEMA",
]


def __getattr__(name: str) -> Any:
    """The package's names load on first use: ``robofabric --help`` imports :mod:`fabric.recording.cli`, and with
    it this package, and must not pay for the session and numpy a recorder needs."""
    if name not in __all__:
        raise AttributeError(f"module 'fabric.recording' has no attribute {name!r}")
    from fabric.recording import format, reader, recorder, replayer, sink

    for mod in (format, reader, recorder, replayer, sink):
        if hasattr(mod, name):
            return getattr(mod, name)
    raise AttributeError(f"module 'fabric.recording' has no attribute {name!r}")
