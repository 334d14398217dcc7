"""The MCAP file a recorder writes: channels per key, chunks that reach the disk regularly.

Crash safety comes from the layout, not from luck: every chunk is a
self-contained record (its schemas and channels travel inside the first chunk
that uses them), and :meth:`McapSink.maybe_flush` closes the open chunk and
hands it to the OS at least every ``flush_interval`` seconds. A recorder
killed with SIGKILL therefore leaves a file whose complete chunks any MCAP
reader can stream; only the last ``flush_interval`` of data is lost, and the
missing footer tells :func:`user_peer.recordings.read_info` the file is
unfinished.

Fenced like a session (:mod:`fabric.fencing`): per world, authority state of a lower
term than one already written is left out. The recorder tells the sink when a world's
sim peers come and go (:meth:`McapSink.sim_seen`, :meth:`McapSink.sim_left`): when the last one
goes the world's fence resets, so a world restarted from scratch at term 1 after a take-over is
recorded again, and late samples of a departed sim cannot fence the new one out.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from mcap.writer import CompressionType

from fabric import keys
from fabric.fencing import SimFence, fenced_scopes
from fabric.recording.mcap_file import McapFile, mcap_writer
from fabric.recording.gaps import SeqGaps
from fabric.recording.format import MESSAGE_ENCODING, METADATA_NAME, PROFILE, peek, schema_data

STALE = "stale"
"""What :meth:`McapSink.write` returns for a sample it left out: authority state of a lower term."""

__all__ = ["McapSink", "COMPRESSIONS", "STALE"]

COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


class McapSink(McapFile):
    """Writes samples to one MCAP file. Not thread-safe: one writer thread owns it.

    ``close()`` finishes the file (summary, footer) and is idempotent.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        compression: str = "zstd",
        chunk_size: int = 1 << 20,
        flush_interval: float = 0.5,
        metadata: dict[str, str] | None = None,
        fsync: bool = False,
    ) -> None:
        if compression not in COMPRESSIONS:
            raise ValueError(f"unknown compression {compression!r}; expected one of {', '.join(COMPRESSIONS)}")
        super().__init__(
            path, mcap_writer(PROFILE, compression=COMPRESSIONS[compression], chunk_size=chunk_size), fsync=fsync
        )
        self.flush_interval = float(flush_interval)
        if metadata:
            self.writer.add_metadata(METADATA_NAME, {str(k): str(v) for k, v in metadata.items()})
        self.file.flush()
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._last_flush = time.monotonic()
        self.messages = 0
        self.fences: dict[str, SimFence] = {}  # per world: its sims and its fence
        # key -> (its world, the scopes that fence it) when it is an authority key, else None; one parse per key
        self._fenced: dict[str, tuple[str, tuple[str, ...]] | None] = {}
        self.stale = 0
        self.payload_bytes = 0
        self.gaps = SeqGaps()  # what the publishers numbered and never reached this file (fabric/recording/gaps.py)

    # ------------------------------------------------------------------ writing

    def _schema_id(self, name: str) -> int:
        sid = self._schemas.get(name)
        if sid is None:
            encoding, data = schema_data(name)
            sid = self._schemas[name] = self.writer.register_schema(name, encoding, data)
        return sid

    def channel(self, key: str, schema: str) -> int:
        """The channel of (key, schema); a key whose type changes gets a second channel on the same topic."""
        cid = self._channels.get((key, schema))
        if cid is None:
            cid = self._channels[(key, schema)] = self.writer.register_channel(
                key, MESSAGE_ENCODING, self._schema_id(schema)
            )
        return cid

    def write(self, key: str, payload: bytes, log_time_ns: int) -> str:
        """Write one sample; publish time and sequence come from its header when it has one. Returns the schema name,
        or ``stale`` for authority state of a lower term than one already written in its world, or
        stamped by a sim that has left (not written)."""
        p = peek(payload)
        if (p.term or self.fences) and not self._believe(key, p.term, p.source):
            self.stale += 1
            return STALE
        if p.wall_ns is not None:  # a fabric message with a header: its publisher numbered it
            self.gaps.seen(key, p.source, p.seq or 0)
        self.write_with(
            key, p.schema, payload, log_time_ns, p.wall_ns if p.wall_ns is not None else log_time_ns, p.seq or 0
        )
        return p.schema

    def _believe(self, key: str, term: int, source: str) -> bool:
        if key not in self._fenced:
            scopes = fenced_scopes(key)
            self._fenced[key] = None if scopes is None else (keys.parse(key).world, scopes)
        fenced = self._fenced[key]
        if fenced is None:
            return True
        world, scopes = fenced
        fence = self.fences.get(world)
        if fence is None:
            if not term:
                return True
            fence = self.fences[world] = SimFence()
        return fence.believe(term, source, scopes)

    # ------------------------------------------------------------------ the world's sims

    def sim_seen(self, world: str, peer_id: str) -> None:
        """A sim peer of ``world`` is alive (its liveliness token appeared)."""
        self.fences.setdefault(world, SimFence()).sim_seen(peer_id)

    def sim_left(self, world: str, peer_id: str) -> None:
        """A sim peer of ``world`` is gone; when it was the last one, the world's fence resets."""
        fence = self.fences.get(world)
        if fence is not None:
            fence.sim_left(peer_id)

    @property
    def fence_resets(self) -> int:
        """How often a world's fence was reset (its last sim left)."""
        return sum(f.resets for f in self.fences.values())

    def write_with(
        self, key: str, schema: str, payload: bytes, log_time_ns: int, publish_time_ns: int, seq: int = 0
    ) -> None:
        self.writer.add_message(
            self.channel(key, schema),
            log_time=log_time_ns,
            data=payload,
            publish_time=publish_time_ns,
            sequence=seq & 0xFFFFFFFF,
        )
        self.messages += 1
        self.payload_bytes += len(payload)

    def maybe_flush(self, now: float | None = None) -> bool:
        """Close the open chunk and hand it to the OS if ``flush_interval`` has passed; True if it did."""
        now = time.monotonic() if now is None else now
        if now - self._last_flush < self.flush_interval:
            return False
        self.flush(now)
        return True

    def flush(self, now: float | None = None) -> None:
        self.writer.flush()
        if self.fsync:
            os.fsync(self.file.fileno())
        self._last_flush = time.monotonic() if now is None else now

    @property
    def file_bytes(self) -> int:
        """Bytes handed to the file so far (the open chunk is not counted until it is flushed)."""
        return self.file.tell()
