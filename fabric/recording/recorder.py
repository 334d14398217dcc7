"""The recorder: every sample on some key expressions, into one MCAP file.

Zenoh calls the subscriber callback on its own threads; the callback only
stamps the receive time and queues the bytes, so the network is never held up
by compression or disk. One writer thread owns the :class:`McapSink`. The
stamp and the enqueue happen under one lock, so file order is receive order
and a replay can stream the file without sorting it.

Bounded: the queue holds at most ``max_queue_bytes`` of payload, the file gets
at most ``max_keys`` channels, and an optional ``quota_bytes`` caps what is written; what
does not fit is dropped and counted (``RecorderStats.dropped``, ``dropped_bytes``), never
silently: the progress line and the final report say so. A 60 x 10 MB junk flood once took
an unbounded recorder from 163 to 712 MB of memory and wrote 629 MB in 2 s.
"""

from __future__ import annotations

import functools
import logging
import queue
import threading
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

import msgpack
import zenoh

from fabric import keys
from fabric.codec import encode
from fabric.exit import at_exit
from fabric.interfaces import WorldInfo
from fabric.worldview import union
from fabric.recording.format import LIVELINESS_SCHEMA, RAW_SCHEMA
from fabric.recording.sink import STALE, McapSink
from fabric.session import undeclare_all

log = logging.getLogger("robofabric.recording")

__all__ = ["Recorder", "RecorderStats"]

_SIMS_OF_EVERY_WORLD = f"{keys.PREFIX}/*/peer/sim/*"


DESCRIBE_WAITS_S = (0.2, 1.0, 2.0, 4.0, 8.0, 15.0)
"""Waits before each ask for a world's description when a sim comes (about 30 s of asking, each ask given 3 s):
one ask 0.2 s after the token missed it on a loaded box (a recording with no description, whose export then needs
``--scene``)."""

MAX_DESCRIBING = 8
"""Worlds whose description is being asked for at once (a thread each, for up to half a minute)."""


@dataclass(frozen=True, slots=True)
class _SimToken:
    """A sim peer's liveliness token came or went: queued with the samples, so the sink's fence
    resets in receive order (after the last sample heard from the world's last sim)."""

    world: str
    peer_id: str
    alive: bool


_Sample = tuple[str, bytes, int, "str | None"]
"""A queued sample: key, payload, wall-clock ns, and its schema (None: the key's message type; else ``liveliness``)."""


def _sim_token_exprs(exprs: Iterable[str]) -> list[str]:
    """Where the sims of the recorded worlds keep their liveliness tokens: the named worlds', or every
    world's when an expression leaves the world open (``rf/**``, ``rf/*/robot/**``, ``**``)."""
    worlds: set[str] = set()
    for e in exprs:
        parts = e.split("/")
        first = parts[0]
        if first != keys.PREFIX and "*" not in first and "$" not in first:
            continue  # not fabric keys: nothing in them is fenced
        if first != keys.PREFIX or len(parts) < 2:
            return [_SIMS_OF_EVERY_WORLD]
        try:
            worlds.add(keys.validate_id(parts[1], what="world"))
        except ValueError:
            return [_SIMS_OF_EVERY_WORLD]
    return [keys.peers_all(w, "sim") for w in sorted(worlds)]


@dataclass(frozen=True, slots=True)
class RecorderStats:
    """A snapshot of a recorder: what it wrote, how fast, and whether the writer keeps up (``queued``)."""

    messages: int
    payload_bytes: int
    file_bytes: int
    keys: int
    elapsed_s: float
    queued: int
    raw: int
    liveliness: int
    dropped: int = 0
    dropped_bytes: int = 0
    quota_reached: bool = False
    queued_bytes: int = 0  # payload bytes heard and not yet written (bounded by ``max_queue_bytes``)
    missed: int = 0  # samples their publishers numbered that never reached this recorder (fabric/recording/gaps.py)
    holes: int = 0  # in how many stretches

    @property
    def rate_hz(self) -> float:
        return self.messages / self.elapsed_s if self.elapsed_s > 0 else 0.0

    @property
    def bytes_per_s(self) -> float:
        return self.payload_bytes / self.elapsed_s if self.elapsed_s > 0 else 0.0

    def line(self) -> str:
        """The progress line: messages, bytes, rates."""
        return (
            f"{self.messages} msgs  {_human(self.payload_bytes)}  ({self.rate_hz:.0f} msg/s, {_human(self.bytes_per_s)}/s)"
            f"  {self.keys} keys  file {_human(self.file_bytes)}  {self.elapsed_s:.1f} s"
            + (f"  backlog {self.queued}" if self.queued > 100 else "")
            + (f"  DROPPED {self.dropped} msgs ({_human(self.dropped_bytes)})" if self.dropped else "")
            + (
                f"  MISSED {self.missed} msgs on the way (in {self.holes} hole{'s' if self.holes != 1 else ''})"
                if self.missed
                else ""
            )
            + ("  disk quota reached" if self.quota_reached else "")
        )


def _human(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if abs(n) < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} GB"


class Recorder:
    """Record the samples of ``keyexprs`` (default: the fabric's whole world) seen by ``fabric`` into ``path``.

    A context manager: ``with Recorder(fab, "run.mcap"): ...`` starts on entry and finishes the file
    on exit. ``close()`` is idempotent and returns the final :class:`RecorderStats`; a script that
    never calls it still gets a finished file, as ``close()`` runs when the interpreter exits. With
    ``liveliness=True`` the appearance and loss of peers' liveliness tokens under the same key
    expressions is recorded too (schema ``liveliness``; replay skips those by default).

    Authority state of a lower term than one already recorded is left out; the
    recorder follows the recorded worlds' sim tokens so that, like a session's, a world's fence resets
    when its last sim goes and a world restarted from scratch is recorded again.
    """

    def __init__(
        self,
        fabric: Any,
        path: str | Path,
        keyexprs: Iterable[str] | None = None,
        *,
        liveliness: bool = False,
        compression: str = "zstd",
        chunk_size: int = 1 << 20,
        flush_interval: float = 0.5,
        metadata: dict[str, str] | None = None,
        max_queue_bytes: int = 256 * 1024 * 1024,
        max_keys: int = 4096,
        quota_bytes: int | None = None,
    ) -> None:
        if max_queue_bytes < 1 or max_keys < 1 or (quota_bytes is not None and quota_bytes < 1):
            raise ValueError("max_queue_bytes, max_keys and quota_bytes must be positive")
        self.max_queue_bytes = int(max_queue_bytes)
        self.max_keys = int(max_keys)
        self.quota_bytes = quota_bytes
        self.fabric = fabric
        self.path = Path(path)
        exprs = list(keyexprs) if keyexprs else [keys.world_all(fabric.world)]
        for e in exprs:
            zenoh.KeyExpr(e)  # raises on an invalid expression before anything is opened
        self.keyexprs = tuple(exprs)
        self.liveliness = liveliness
        self._open_sink = functools.partial(
            McapSink, compression=compression, chunk_size=chunk_size, flush_interval=flush_interval
        )
        self._metadata = {
            "world": fabric.world,
            "keyexprs": ",".join(self.keyexprs),
            "recorder": getattr(fabric, "peer_id", ""),
            "started_ns": "",
            "liveliness": str(bool(liveliness)).lower(),
            **(metadata or {}),
        }
        self._q: queue.SimpleQueue[_Sample | _SimToken | None] = queue.SimpleQueue()  # None: stop
        self._lock = threading.Lock()
        self._subs: list[Any] = []
        self._thread: threading.Thread | None = None
        self._sink: McapSink | None = None
        self._t0 = 0.0
        self._t_end: float | None = None
        self._queued = 0
        self._queued_bytes = 0
        self._dropped = 0
        self._dropped_bytes = 0
        self._quota_reached = False
        self._accepted_keys: set[str] = set()
        self._written = 0
        self._raw = 0
        self._live = 0
        self._keys: Counter[str] = Counter()
        self._first_match: dict[str, int] = {}
        self._describing: set[str] = set()
        self.described = 0
        """World descriptions recorded (``srv/world`` answers, one each time a sim came)."""
        self._started = False
        self._stopped = False
        self._cancel_exit: Callable[[], None] | None = None
        self.error: BaseException | None = None

    # ------------------------------------------------------------------ lifecycle

    def __enter__(self) -> "Recorder":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> "Recorder":
        if self._started:
            return self
        self._started = True
        self._metadata["started_ns"] = str(time.time_ns())
        self._sink = self._open_sink(self.path, metadata=self._metadata)
        # before the session's own closer (newest first): the file gets its footer at exit
        self._cancel_exit = at_exit(self.close)
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._write_loop, name="recorder-writer", daemon=True)
        self._thread.start()
        for i, expr in enumerate(self.keyexprs):
            self._subs.append(self.fabric.subscribe_raw(expr, self._on_sample_for(i)))
            if self.liveliness:
                self._subs.append(self.fabric.watch_tokens(expr, self._on_token_for(i)))
        for expr in _sim_token_exprs(self.keyexprs):
            self._subs.append(self.fabric.watch_tokens(expr, self._on_sim_token, every_going=True))
        return self

    def close(self) -> "RecorderStats":
        """Stop listening, write what is queued, finish the file (summary + footer). Idempotent."""
        if not self._started or self._stopped:
            return self.stats
        self._stopped = True
        if self._cancel_exit is not None:
            self._cancel_exit()
        undeclare_all(self._subs)
        self._subs.clear()
        self._t_end = time.monotonic()
        self._q.put(None)
        if self._thread is not None:
            self._thread.join()
        assert self._sink is not None
        self._sink.close()
        if self.error is not None:
            raise RuntimeError(f"recorder writer failed: {self.error}") from self.error
        return self.stats

    @property
    def stats(self) -> RecorderStats:
        end = self._t_end if self._t_end is not None else time.monotonic()
        sink = self._sink
        return RecorderStats(
            messages=self._written,
            payload_bytes=sink.payload_bytes if sink else 0,
            file_bytes=sink.file_bytes
            if sink and not self._stopped
            else (self.path.stat().st_size if self.path.exists() else 0),
            keys=len(self._keys),
            elapsed_s=(end - self._t0) if self._started else 0.0,
            queued=max(0, self._queued - self._written),
            raw=self._raw,
            liveliness=self._live,
            dropped=self._dropped,
            dropped_bytes=self._dropped_bytes,
            quota_reached=self._quota_reached,
            queued_bytes=self._queued_bytes,
            # the holes less what it dropped itself (each a numbered sample its sink never saw): on the way
            missed=max(0, sink.gaps.missed - self._dropped) if sink else 0,
            holes=sink.gaps.holes if sink else 0,
        )

    @property
    def sink(self) -> McapSink | None:
        """The MCAP file being written (its fences, its byte counts); None before :meth:`start`."""
        return self._sink

    # ------------------------------------------------------------------ receiving (zenoh threads)

    def _owns(self, i: int, key: str) -> bool:
        """With overlapping expressions a sample reaches several subscribers: only the first one records it."""
        if len(self.keyexprs) == 1:
            return True
        first = self._first_match.get(key)
        if first is None:
            first = next((j for j, e in enumerate(self.keyexprs) if zenoh.KeyExpr(e).intersects(key)), i)
            if len(self._first_match) < self.max_keys:
                self._first_match[key] = first
        return first == i

    def _admit(self, key: str, size: int) -> bool:
        """Room for one more sample (called with the lock held)? Counts what it turns away."""
        if (
            self._quota_reached
            or self._queued_bytes + size > self.max_queue_bytes
            or (key not in self._accepted_keys and len(self._accepted_keys) >= self.max_keys)
        ):
            self._dropped += 1
            self._dropped_bytes += size
            return False
        self._accepted_keys.add(key)
        self._queued_bytes += size
        self._queued += 1
        return True

    def _on_sample_for(self, i: int) -> Callable[[zenoh.Sample], None]:
        def on_sample(sample: zenoh.Sample) -> None:
            if sample.kind != zenoh.SampleKind.PUT:
                return
            key = str(sample.key_expr)
            if not self._owns(i, key):
                return
            payload = sample.payload.to_bytes()
            with self._lock:
                if self._admit(key, len(payload)):
                    self._q.put((key, payload, time.time_ns(), None))

        return on_sample

    def _on_token_for(self, i: int) -> Callable[[str, bool], None]:
        def on_token(key: str, alive: bool) -> None:
            if not self._owns(i, key):
                return
            payload = msgpack.packb({"alive": alive})
            with self._lock:
                if self._admit(key, len(payload)):
                    self._q.put((key, payload, time.time_ns(), LIVELINESS_SCHEMA))

        return on_token

    def _on_sim_token(self, key: str, alive: bool) -> None:
        try:
            p = keys.parse(key)
        except ValueError:
            return
        if p.category == "peer" and p.subject == "sim":
            self._q.put(_SimToken(p.world, p.leaf, alive))
            if alive:
                self._describe(p.world)

    def _describe(self, world: str) -> None:
        """Record the world's description (the union of the sims' ``srv/world`` answers, :mod:`fabric.worldview`,
        on its key) whenever a sim comes: export and
        replay place robots from it, with no ``--scene``. One query at a time per world (made-up sim tokens
        must not make a thread each)."""
        with self._lock:
            if world in self._describing or self._stopped or len(self._describing) >= MAX_DESCRIBING:
                return  # made-up sim tokens of many worlds get a few threads, not one each
            self._describing.add(world)

        def ask() -> None:
            key = keys.srv(world, "world")
            try:
                for wait in DESCRIBE_WAITS_S:  # a sim's token comes before its queryable, and a loaded one answers late
                    time.sleep(wait)
                    with self._lock:
                        if self._stopped:
                            return
                    try:
                        replies = self.fabric.rpc.query(key, timeout=3.0, expected=WorldInfo, all_replies=True)
                        info = union((rep.source, rep.message) for rep in replies)  # every sim's part: one world
                    except Exception:  # no answer yet (or a standby alone, access control): asked again, then not
                        log.debug("no description of world %s to record yet", world, exc_info=True)
                        continue
                    payload = encode(info)
                    with self._lock:
                        if not self._stopped and self._admit(key, len(payload)):
                            self._q.put((key, payload, time.time_ns(), None))
                            self.described += 1
                    return
                log.info("no description of world %s recorded: no sim answered srv/world", world)
            finally:
                with self._lock:
                    self._describing.discard(world)

        threading.Thread(target=ask, name=f"recorder-describe-{world}", daemon=True).start()

    # ------------------------------------------------------------------ writing (one thread)

    def _write_loop(self) -> None:
        sink = self._sink
        assert sink is not None
        q = self._q
        try:
            while True:
                try:
                    item = q.get(timeout=0.05)
                except queue.Empty:
                    sink.maybe_flush()
                    continue
                if item is None:
                    break
                self._write(sink, item)
                # drain what is already queued before looking at the clock again
                for _ in range(1000):
                    try:
                        item = q.get_nowait()
                    except queue.Empty:
                        break
                    if item is None:
                        return
                    self._write(sink, item)
                sink.maybe_flush()
        except BaseException as exc:  # a full disk must not pass silently
            self.error = exc

    def _write(self, sink: McapSink, item: _Sample | _SimToken) -> None:
        if isinstance(item, _SimToken):
            (sink.sim_seen if item.alive else sink.sim_left)(item.world, item.peer_id)
            return
        key, payload, t_ns, schema = item
        with self._lock:
            self._queued_bytes -= len(payload)
            if (
                self.quota_bytes is not None
                and not self._quota_reached
                and sink.payload_bytes + len(payload) > self.quota_bytes
            ):
                self._quota_reached = True
            if self._quota_reached:
                self._dropped += 1
                self._dropped_bytes += len(payload)
                self._queued -= 1
                return
        if schema is None:
            written = sink.write(key, payload, t_ns)
            if written == STALE:
                return  # a primary that lost the world, heard after its successor (counted by the sink)
            if written == RAW_SCHEMA:
                self._raw += 1
        else:
            sink.write_with(key, schema, payload, t_ns, t_ns)
            self._live += 1
        self._written += 1
        self._keys[key] += 1
