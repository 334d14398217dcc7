"""The recorder library: writing key streams into MCAP files and reading them back.

``Recorder`` writes every sample of some key expressions into an MCAP file
(one channel per key, the fabric message type as schema name, msgpack as
message encoding, receive time as log time, header wall time as publish
time; zstd chunks that reach the disk every half second, so a killed
recorder leaves a readable file). ``read_info``, ``iter_messages`` and
``read_samples`` read files back, finished or not. This is core: a peer
records (``World.record``) and exports (``robofabric export`` reads files), so
it sits on the ground floor. The tools built on it live a floor above, in
:mod:`robofabric.recording`: the replayer, the live conversion, the load
generator and the CLI (``record``, ``info``, ``replay``); see docs/recording.md.
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
    from fabric.recording.sink import McapSink

__all__ = [
    "Recorder",
    "RecorderStats",
    "McapSink",
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
    """The package's names load on first use: ``robofabric --help`` imports :mod:`robofabric.recording.cli`, and
    with it this package, and must not pay for the session and numpy a recorder needs."""
    if name not in __all__:
        raise AttributeError(f"module 'fabric.recording' has no attribute {name!r}")
    from fabric.recording import format, reader, recorder, sink

    for mod in (format, reader, recorder, sink):
        if hasattr(mod, name):
            return getattr(mod, name)
    raise AttributeError(f"module 'fabric.recording' has no attribute {name!r}")
