"""Reading recordings back, finished or not.

The fabric's recorder library (:mod:`fabric.recording`) writes; reading is a user's need, not a running
peer's: ``robofabric export`` and the exporters here in :mod:`user_peer` read recordings, and so do the
tools a floor above (``info``, ``replay``, the benchmarks), while no sim or compute peer ever opens one.
So the reader lives in the lowest package that reads (docs/architecture.md, "The house").

The reader walks the file record by record (mcap's record classes, chunks
opened lazily here) instead of trusting the summary at the end, because the
file we most need to read is the one whose recorder was killed before it
could write a summary. A file with a footer is
``complete``; one without is ``unfinished``: everything up to its last whole
chunk is read and the torn tail is reported, not raised. Only a file that is
not MCAP at all, or has no readable header, is refused
(:class:`RecordingError`).
"""

from __future__ import annotations

import io
import struct
import zlib
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import lz4.frame
import zenoh
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import MAGIC_SIZE

from fabric.recording.format import LIVELINESS_SCHEMA, METADATA_NAME, world_of

__all__ = [
    "RecordingError",
    "RecordedMessage",
    "ChannelInfo",
    "RecordingInfo",
    "read_info",
    "iter_messages",
    "read_samples",
    "key_filter",
]

_MAGIC = bytes([137, 77, 67, 65, 80, 48, 13, 10])


class RecordingError(ValueError):
    """A file cannot be used as a recording; the text (one line) says why."""


@dataclass(frozen=True, slots=True)
class RecordedMessage:
    """One recorded sample: its key, receive time and header time (ns since the epoch), and the exact bytes."""

    key: str
    log_time: int
    publish_time: int
    payload: bytes
    schema: str = ""
    sequence: int = 0


@dataclass(frozen=True, slots=True)
class ChannelInfo:
    key: str
    schema: str
    messages: int
    bytes: int
    first_ns: int
    last_ns: int

    @property
    def rate_hz(self) -> float:
        """Messages per second over this channel's own span (0 for fewer than two messages)."""
        span = (self.last_ns - self.first_ns) / 1e9
        return (self.messages - 1) / span if self.messages > 1 and span > 0 else 0.0


@dataclass(frozen=True, slots=True)
class RecordingInfo:
    """What ``robofabric info`` shows. ``complete`` is False for a file whose recorder never finished it."""

    path: str
    file_bytes: int
    complete: bool
    status: str
    detail: str
    messages: int
    payload_bytes: int
    start_ns: int
    end_ns: int
    chunks: int
    compression: tuple[str, ...]
    channels: tuple[ChannelInfo, ...]
    metadata: dict = field(default_factory=dict)
    library: str = ""
    profile: str = ""

    @property
    def duration_s(self) -> float:
        return max(0, self.end_ns - self.start_ns) / 1e9

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(sorted({c.key for c in self.channels}))

    @property
    def worlds(self) -> tuple[str, ...]:
        return tuple(sorted({w for c in self.channels if (w := world_of(c.key))}))

    @property
    def schemas(self) -> tuple[str, ...]:
        return tuple(sorted({c.schema for c in self.channels}))

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["compression"] = list(self.compression)
        d["duration_s"] = self.duration_s
        d["keys"] = list(self.keys)
        d["worlds"] = list(self.worlds)
        d["schemas"] = list(self.schemas)
        d["rate_hz"] = (self.messages - 1) / self.duration_s if self.messages > 1 and self.duration_s > 0 else 0.0
        d["bytes_per_s"] = self.payload_bytes / self.duration_s if self.duration_s > 0 else 0.0
        d["channels"] = [{**asdict(c), "rate_hz": c.rate_hz} for c in self.channels]
        return d


# --------------------------------------------------------------------------- the walk


@dataclass
class _Walk:
    """State of one pass over a file: what was seen, and how the pass ended."""

    path: Path
    file_bytes: int = 0
    good_end: int = 0
    complete: bool = False
    tail_error: str = ""
    header: Header | None = None
    chunks: int = 0
    compression: set[str] = field(default_factory=set)
    metadata: dict[str, str] = field(default_factory=dict)
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)


def _open_checked(path: str | Path):
    p = Path(path)
    if not p.exists():
        raise RecordingError(f"{p}: no such file")
    if not p.is_file():
        raise RecordingError(f"{p}: not a file")
    size = p.stat().st_size
    if size == 0:
        raise RecordingError(f"{p}: empty file, not an MCAP recording")
    f = open(p, "rb")
    magic = f.read(MAGIC_SIZE)
    if magic != _MAGIC:
        f.close()
        if _MAGIC.startswith(magic):
            raise RecordingError(f"{p}: truncated beyond repair ({size} bytes, not even a whole MCAP header)")
        raise RecordingError(f"{p}: not an MCAP file (bad magic bytes)")
    f.seek(0)
    return f, size


_READERS = {
    Opcode.HEADER: Header.read,
    Opcode.SCHEMA: Schema.read,
    Opcode.CHANNEL: Channel.read,
    Opcode.METADATA: Metadata.read,
    Opcode.FOOTER: Footer.read,
}
_MSG_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_REC_HEAD = struct.Struct("<BQ")  # opcode, length


def _decompress(chunk: Chunk) -> bytes:
    if chunk.compression == "zstd":
        data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    elif chunk.compression == "lz4":
        data = lz4.frame.decompress(chunk.data)
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise ValueError(f"unsupported chunk compression {chunk.compression!r}")
    if len(data) != chunk.uncompressed_size:
        raise ValueError(f"chunk decompresses to {len(data)} bytes, header says {chunk.uncompressed_size}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ValueError("chunk CRC mismatch")
    return data


def _chunk_records(data: bytes) -> Iterator[Any]:
    """The records inside a decompressed chunk, parsed one at a time.

    Lazy on purpose: a replay parses a message just before it is due instead of stalling on a
    whole chunk (mcap's ``breakup_chunk`` parses ~1000 records at once, several milliseconds).
    """
    pos, end = 0, len(data)
    while pos < end:
        if end - pos < 9:
            raise ValueError("chunk ends inside a record header")
        op, length = _REC_HEAD.unpack_from(data, pos)
        body = pos + 9
        pos = body + length
        if pos > end:
            raise ValueError("chunk ends inside a record")
        if op == Opcode.MESSAGE:
            cid, seq, log_t, pub_t = _MSG_HEAD.unpack_from(data, body)
            yield Message(channel_id=cid, sequence=seq, log_time=log_t, publish_time=pub_t, data=data[body + 22 : pos])
        elif op in (Opcode.SCHEMA, Opcode.CHANNEL):
            yield _READERS[op](ReadDataStream(io.BytesIO(data[body:pos])))


def _messages(w: _Walk) -> Iterator[tuple[Channel, Message]]:
    """Stream every (channel, message) of ``w.path`` in file order, filling ``w`` as records go by.

    Records are parsed here (with mcap's record classes) rather than by ``StreamReader`` so that
    index records are skipped unread and chunks are opened lazily. Stops quietly at a torn or
    corrupt tail (``w.tail_error`` says what); ``w.complete`` is True only once the footer and the
    closing magic have been read.
    """
    f, size = _open_checked(w.path)
    w.file_bytes = size
    with f:
        f.seek(MAGIC_SIZE)
        stream = ReadDataStream(f)
        pos = MAGIC_SIZE
        w.good_end = pos
        while True:
            head = f.read(9)
            if len(head) == 0:
                w.tail_error = f"file ends after byte {pos} without a footer"
                break
            if len(head) < 9:
                w.tail_error = f"file ends inside a record header after byte {pos}"
                break
            op, length = _REC_HEAD.unpack(head)
            nxt = pos + 9 + length
            if nxt > size:
                w.tail_error = f"file ends inside a record after byte {pos} ({nxt - size} byte(s) missing)"
                break
            if w.header is None and op != Opcode.HEADER:
                raise RecordingError(f"{w.path}: truncated beyond repair (no MCAP header record)")
            try:
                if op == Opcode.CHUNK:
                    chunk = Chunk.read(stream)
                    data = _decompress(chunk)
                    w.chunks += 1
                    w.compression.add(chunk.compression or "none")
                    f.seek(nxt)
                    pos = w.good_end = nxt
                    for r in _chunk_records(data):
                        if isinstance(r, Message):
                            ch = w.channels.get(r.channel_id)
                            if ch is not None:
                                yield ch, r
                        else:
                            _note(w, r)
                    continue
                if op == Opcode.MESSAGE:
                    rec = Message.read(stream, length)
                elif op in _READERS:
                    rec = _READERS[op](stream)
                else:
                    rec = None  # indexes, statistics, attachments: not needed to read messages
            except Exception as exc:  # a corrupt record: read nothing past it
                w.tail_error = f"unreadable record after byte {pos} ({type(exc).__name__}: {exc})"
                break
            f.seek(nxt)
            pos = w.good_end = nxt
            if isinstance(rec, Message):
                ch = w.channels.get(rec.channel_id)
                if ch is not None:
                    yield ch, rec
            elif rec is not None:
                _note(w, rec)
                if isinstance(rec, Footer):
                    if f.read(MAGIC_SIZE) != _MAGIC:
                        w.complete = False
                        w.tail_error = "footer not followed by the closing magic bytes"
                    break
    if w.header is None:
        raise RecordingError(f"{w.path}: truncated beyond repair (no readable MCAP header)")


def _note(w: _Walk, rec: Any) -> None:
    if isinstance(rec, Header):
        w.header = rec
    elif isinstance(rec, Schema):
        w.schemas[rec.id] = rec
    elif isinstance(rec, Channel):
        w.channels[rec.id] = rec
    elif isinstance(rec, Metadata) and rec.name == METADATA_NAME:
        w.metadata.update(rec.metadata)
    elif isinstance(rec, Footer):
        w.complete = True


def _schema_name(w: _Walk, ch: Channel) -> str:
    s = w.schemas.get(ch.schema_id)
    return s.name if s is not None else ""


# --------------------------------------------------------------------------- public helpers


def key_filter(exprs: Iterable[str] | str | None) -> Callable[[str], bool]:
    """A predicate on concrete keys: True if any expression includes the key (all keys when None).

    Invalid expressions raise :class:`RecordingError` naming them.
    """
    if exprs is None:
        return lambda _key: True
    if isinstance(exprs, str):
        exprs = [exprs]
    kes = []
    for e in exprs:
        try:
            kes.append(zenoh.KeyExpr(e))
        except Exception as exc:
            raise RecordingError(f"{e!r} is not a valid key expression: {exc}") from None
    cache: dict[str, bool] = {}

    def match(key: str) -> bool:
        hit = cache.get(key)
        if hit is None:
            try:
                hit = any(ke.intersects(key) for ke in kes)
            except Exception:
                hit = False
            cache[key] = hit
        return hit

    return match


def read_info(path: str | Path, *, progress: Callable[[int, int], None] | None = None) -> RecordingInfo:
    """Summarise a recording by reading it through; works on unfinished files (see module doc).

    ``progress(bytes_read, file_bytes)`` is called as the reading goes (for a progress bar).
    """
    counts: Counter[int] = Counter()
    sizes: Counter[int] = Counter()
    first: dict[int, int] = {}
    last: dict[int, int] = {}

    w = _Walk(Path(path))
    seen = 0
    for ch, m in _messages(w):
        seen += 1
        if progress is not None and seen % 2000 == 0:
            progress(w.good_end, w.file_bytes)
        cid = ch.id
        counts[cid] += 1
        sizes[cid] += len(m.data)
        t = m.log_time
        if cid not in first or t < first[cid]:
            first[cid] = t
        if cid not in last or t > last[cid]:
            last[cid] = t
    chans = tuple(
        sorted(
            (
                ChannelInfo(ch.topic, _schema_name(w, ch), counts[cid], sizes[cid], first.get(cid, 0), last.get(cid, 0))
                for cid, ch in w.channels.items()
                if counts[cid]
            ),
            key=lambda c: (c.key, c.schema),
        )
    )
    if progress is not None:
        progress(w.file_bytes, w.file_bytes)
    n = sum(counts.values())
    start = min(first.values()) if first else 0
    end = max(last.values()) if last else 0
    if w.complete:
        status, detail = "complete", "finished cleanly (footer and summary present)"
    else:
        torn = w.file_bytes - w.good_end
        status = "unfinished"
        detail = (
            f"truncated: the recorder did not finish this file; read up to the last complete chunk, "
            f"{torn} byte(s) of torn tail ignored" + (f" ({w.tail_error})" if w.tail_error else "")
        )
    return RecordingInfo(
        path=str(path),
        file_bytes=w.file_bytes,
        complete=w.complete,
        status=status,
        detail=detail,
        messages=n,
        payload_bytes=sum(sizes.values()),
        start_ns=start,
        end_ns=end,
        chunks=w.chunks,
        compression=tuple(sorted(w.compression)),
        channels=chans,
        metadata=dict(w.metadata),
        library=w.header.library if w.header else "",
        profile=w.header.profile if w.header else "",
    )


def iter_messages(
    path: str | Path,
    keys: Iterable[str] | str | None = None,
    *,
    start_ns: int | None = None,
    end_ns: int | None = None,
    liveliness: bool = False,
) -> Iterator[RecordedMessage]:
    """Yield recorded samples in file order (receive order), optionally filtered.

    ``keys``: key expressions (any intersecting key is kept); ``start_ns``/``end_ns``: a half-open
    window on log time; liveliness changes (``--liveliness`` recordings) only when asked.
    Reading stops quietly at the torn tail of an unfinished file.
    """
    match = key_filter(keys)
    w = _Walk(Path(path))
    for ch, m in _messages(w):
        if start_ns is not None and m.log_time < start_ns:
            continue
        if end_ns is not None and m.log_time >= end_ns:
            continue
        schema = _schema_name(w, ch)
        if schema == LIVELINESS_SCHEMA and not liveliness:
            continue
        if match(ch.topic):
            yield RecordedMessage(ch.topic, m.log_time, m.publish_time, bytes(m.data), schema, m.sequence)


def read_samples(
    path: str | Path, keys: Iterable[str] | str | None = None, *, start_ns: int | None = None, end_ns: int | None = None
) -> Iterator[tuple[str, int, int, bytes]]:
    """``(key, log_time, publish_time, payload)`` of every recorded sample, for scripts that want plain tuples."""
    for m in iter_messages(path, keys, start_ns=start_ns, end_ns=end_ns):
        yield m.key, m.log_time, m.publish_time, m.payload
