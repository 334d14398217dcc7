"""``robofabric record --to FORMAT``: write a live world straight into another format (Foxglove, ROS 2).

Kept apart from :mod:`fabric.recording.recorder` (which writes the fabric's own MCAP byte for byte):
here each sample is decoded and handed to a writer found through the entry-point group
``robofabric.exporters`` (``user_peer.openfmt`` declares ``foxglove`` and ``ros2``), so ``fabric``
imports no peer package. Zenoh callbacks only stamp and enqueue; one thread decodes and writes.
The queue is bounded: when the writer falls behind, the oldest samples are dropped and counted
(the converter must never hold the world up), and the count is reported.
"""

from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Callable, Iterable

import zenoh

from fabric.codec import DecodeError, decode, load_plugins
from fabric.exit import at_exit
from fabric.limits import put_dropping_oldest
from fabric.recording.gaps import SeqGaps
from fabric.session import undeclare_all

__all__ = ["EXPORTERS", "exporters", "LiveConverter", "LiveStats"]

EXPORTERS = "robofabric.exporters"


def exporters() -> dict[str, Callable[..., Any]]:
    """Installed writers by format name: each ``factory(path, scene=None)`` returns ``write``/``close``."""
    return {ep.name: ep for ep in entry_points(group=EXPORTERS)}  # type: ignore[misc]


@dataclass(frozen=True, slots=True)
class LiveStats:
    received: int
    written: int  # fabric messages handed to the writer
    bad: int  # payloads that did not decode (not fabric messages)
    dropped: int  # oldest samples dropped because the writer fell behind
    elapsed_s: float
    missed: int = 0  # samples their publishers numbered that never reached this converter (fabric/recording/gaps.py)
    holes: int = 0  # in how many stretches

    def line(self) -> str:
        return (
            f"{self.written} msgs converted  {self.bad} undecodable  {self.dropped} dropped  "
            f"({self.written / self.elapsed_s if self.elapsed_s > 0 else 0:.0f} msg/s)  {self.elapsed_s:.1f} s"
            + (
                f"  MISSED {self.missed} msgs on the way (in {self.holes} hole{'s' if self.holes != 1 else ''})"
                if self.missed
                else ""
            )
        )


class LiveConverter:
    """Subscribe to ``keyexprs`` on ``fabric`` and write every decodable message with ``sink``.

    A context manager like :class:`~fabric.recording.recorder.Recorder`: ``with LiveConverter(fab, sink,
    exprs): ...`` starts on entry and finishes the file on exit. The converter owns ``sink`` from the
    start: ``close()`` (idempotent) closes it. A script that never calls ``close()`` still gets a finished
    file: it runs when the interpreter exits, before the session closes.
    """

    def __init__(self, fabric: Any, sink: Any, keyexprs: Iterable[str], *, queue_size: int = 20_000) -> None:
        self.fabric = fabric
        self.sink = sink
        self.keyexprs = tuple(keyexprs)
        self._q: queue.Queue = queue.Queue(maxsize=queue_size)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._subs: list[Any] = []
        self._lock = threading.Lock()
        self.received = self.written = self.bad = self.dropped = 0
        self.error: BaseException | None = None
        self.gaps = SeqGaps()
        self._t0 = 0.0
        self._t_end: float | None = None
        self._started = False
        self._stopped = False
        self._cancel_exit: Any = None

    def __enter__(self) -> "LiveConverter":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> "LiveConverter":
        """Start the writer thread and listen. Idempotent; refused after ``close()`` (the file is finished)."""
        if self._stopped:
            raise RuntimeError("this converter was stopped: its file is finished")
        if self._started:
            return self
        self._started = True
        load_plugins()
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._loop, name="convert-writer", daemon=True)
        self._thread.start()
        # before the session's own closer (newest first): the file gets its footer at exit
        self._cancel_exit = at_exit(self.close)
        for expr in self.keyexprs:
            # history: the latest map, path and scene objects published before we joined
            self._subs.append(self.fabric.subscribe_raw(expr, self._on_sample, history=True))
        return self

    def _on_sample(self, sample: zenoh.Sample) -> None:
        if sample.kind != zenoh.SampleKind.PUT:
            return
        item = (str(sample.key_expr), sample.payload.to_bytes(), time.time_ns())
        with self._lock:
            self.received += 1
            self.dropped += put_dropping_oldest(self._q, item)

    def _loop(self) -> None:
        try:
            while not (self._stop.is_set() and self._q.empty()):
                try:
                    key, payload, t_ns = self._q.get(timeout=0.1)
                except queue.Empty:
                    continue
                try:
                    msg = decode(payload)
                except DecodeError:
                    self.bad += 1
                    continue
                header = getattr(msg, "header", None)
                wall = int(getattr(header, "wall_ns", 0) or 0)
                if header is not None:
                    self.gaps.seen(key, str(getattr(header, "source", "")), int(getattr(header, "seq", 0)))
                self.sink.write(key, msg, t_ns, wall or t_ns)
                self.written += 1
        except BaseException as exc:  # a full disk must not pass silently
            self.error = exc

    @property
    def stats(self) -> LiveStats:
        end = self._t_end if self._t_end is not None else time.monotonic()
        return LiveStats(
            self.received,
            self.written,
            self.bad,
            self.dropped,
            end - self._t0 if self._t0 else 0.0,
            max(0, self.gaps.missed - self.dropped),  # the holes less what it dropped itself: lost on the way
            self.gaps.holes,
        )

    def close(self) -> LiveStats:
        """Stop listening, write what is queued, finish the file. Idempotent."""
        if self._stopped:
            return self.stats
        self._stopped = True
        if self._cancel_exit is not None:
            self._cancel_exit()
        undeclare_all(self._subs)
        self._subs.clear()
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self._t_end = time.monotonic()
        self.sink.close()
        if self.error is not None:
            raise RuntimeError(f"converting writer failed: {self.error}") from self.error
        return self.stats


def open_exporter(name: str, path: Path, scene: str | None = None) -> Any:
    """The writer of format ``name`` at ``path``; ``KeyError`` naming the installed formats when unknown."""
    found = exporters()
    if name not in found:
        raise KeyError(f"no writer for format {name!r}; installed: {', '.join(sorted(found)) or 'none'}")
    factory = found[name].load()  # type: ignore[attr-defined]
    return factory(path, scene=scene)
