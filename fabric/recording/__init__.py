"""The recorder library: writing key streams into MCAP files.

``Recorder`` writes every sample of some key expressions into an MCAP file
(one channel per key, the fabric message type as schema name, msgpack as
message encoding, receive time as log time, header wall time as publish
time; zstd chunks that reach the disk every half second, so a killed
recorder leaves a readable file). This is core: a user's script records
through it, and the MCAP mapping (:mod:`fabric.recording.format`) and writer
base (:mod:`fabric.recording.mcap_file`) are what the exporters stand on. Reading
files back, finished or not (``read_info``, ``iter_messages``, ``read_samples``),
is :mod:`user_peer.recordings`, since only users and tools read recordings.
The tools built on both live a floor above, in :mod:`robofabric.recording`:
the replayer, the live conversion, the load generator and the CLI (``record``,
``info``, ``replay``); see docs/recording.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fabric.recording.format import (
        LIVELINESS_SCHEMA,
        MESSAGE_ENCODING,
        RAW_SCHEMA,
        Peek,
        peek,
        remap_world,
        world_of,
    )
    from fabric.recording.recorder import Recorder, RecorderStats
    from fabric.recording.sink import McapSink

__all__ = [
    "Recorder",
    "RecorderStats",
    "McapSink",
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
    from fabric.recording import format, recorder, sink

    for mod in (format, recorder, sink):
        if hasattr(mod, name):
            return getattr(mod, name)
    raise AttributeError(f"module 'fabric.recording' has no attribute {name!r}")
