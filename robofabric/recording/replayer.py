"""Replaying a recording: the same bytes on the same (or remapped) keys, on the recorded timeline.

Every message is due at ``t0 + (log_time - base) / speed`` on one absolute
timeline, never "sleep the gap since the previous one", so scheduling error
does not accumulate over a long replay; a message that comes due while the
replayer is behind goes out at once and its lateness is counted. The
replayer sleeps until shortly before a message is due and spins the last
fraction of a millisecond, which is what keeps the p99 error under 2 ms.

What is replayed is chosen up front (:class:`ReplayPlan`), so an empty
selection, an unknown world or a bad window is refused before anything is
published.
"""

from __future__ import annotations

import math
import threading
from array import array
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

import zenoh

from fabric.matching import wait_matched
from fabric.rate import Clock, MonotonicClock
from fabric.recording.format import LIVELINESS_SCHEMA, remap_world, world_of
from user_peer.recordings import RecordingError, RecordingInfo, iter_messages, key_filter, read_info
from fabric.publishers import declare_publisher
from robofabric.stats import percentiles

__all__ = ["Replayer", "ReplayPlan", "ReplayStats", "plan_replay", "due_time"]


def due_time(
    log_time_ns: int, base_ns: int, speed: float, t0: float, loop_index: int = 0, loop_len: float = 0.0
) -> float:
    """When (on the replayer's clock) a message recorded at ``log_time_ns`` must go out."""
    return t0 + loop_index * loop_len + (log_time_ns - base_ns) / 1e9 / speed


@dataclass(frozen=True, slots=True)
class ReplayPlan:
    """What a replay will publish: checked against the file before anything goes on the wire."""

    path: str
    info: RecordingInfo
    keys: tuple[str, ...]  # recorded keys selected
    worlds: tuple[str, ...]  # recorded worlds selected
    key_exprs: tuple[str, ...] | None
    base_ns: int  # the timeline's zero: recording start + start offset
    start_ns: int | None
    end_ns: int | None
    messages: int  # in the window, per loop
    first_ns: int
    last_ns: int
    speed: float
    remap_world: str | None

    def target(self, key: str) -> str:
        return remap_world(key, self.remap_world) if self.remap_world else key

    @property
    def loop_len_s(self) -> float:
        """One pass on the replayer's clock: the window, or the selection's span plus one mean gap."""
        if self.end_ns is not None:
            end = self.end_ns
        else:
            gap = (self.last_ns - self.first_ns) / (self.messages - 1) if self.messages > 1 else 1e8
            end = self.last_ns + max(int(gap), 1_000_000)
        return (end - self.base_ns) / 1e9 / self.speed


def plan_replay(
    path: str | Path,
    *,
    speed: float = 1.0,
    start: float | None = None,
    end: float | None = None,
    keys: Iterable[str] | str | None = None,
    world: str | None = None,
    remap_world: str | None = None,
) -> ReplayPlan:
    """Check a replay request against the file; raise :class:`RecordingError` with one line if it cannot work."""
    if not (isinstance(speed, (int, float)) and math.isfinite(speed) and speed > 0):
        raise RecordingError(f"--speed must be a positive number, got {speed}")
    if start is not None and (not math.isfinite(start) or start < 0):
        raise RecordingError(f"--start must be >= 0 seconds, got {start}")
    if end is not None and (not math.isfinite(end) or end <= (start or 0.0)):
        raise RecordingError(f"--end ({end}) must be after --start ({start or 0.0})")
    if remap_world is not None:
        from fabric import keys as fkeys

        try:
            fkeys.validate_id(remap_world, what="world")
        except ValueError as exc:
            raise RecordingError(f"--remap-world: {exc}") from None
    info = read_info(path)
    if info.messages == 0:
        raise RecordingError(f"{path}: the recording holds no messages ({info.status})")
    exprs = (keys,) if isinstance(keys, str) else (tuple(keys) if keys is not None else None)
    match = key_filter(exprs)
    if world is not None and world not in info.worlds:
        held = ", ".join(info.worlds) or "none"
        raise RecordingError(f"world {world!r} is not in {path} (it holds: {held})")
    chans = [
        c
        for c in info.channels
        if c.schema != LIVELINESS_SCHEMA
        and match(c.key)
        and (world is None or world_of(c.key) == world)
        and _valid(c.key)
    ]
    if not chans:
        what = ", ".join(exprs) if exprs else "any key"
        raise RecordingError(f"nothing in {path} matches {what}" + (f" in world {world!r}" if world else ""))
    base = info.start_ns + int(round((start or 0.0) * 1e9))
    start_ns = base if start else None
    end_ns = info.start_ns + int(round(end * 1e9)) if end is not None else None
    selected = {c.key for c in chans}
    n, first, last = 0, 0, 0
    for m in iter_messages(path, start_ns=start_ns, end_ns=end_ns):
        if m.key not in selected:
            continue
        if n == 0:
            first = m.log_time
        last = max(last, m.log_time)
        n += 1
    if n == 0:
        raise RecordingError(
            f"no selected message between {start or 0.0:.3f} s and {end if end is not None else info.duration_s:.3f} s "
            f"(the recording lasts {info.duration_s:.3f} s)"
        )
    return ReplayPlan(
        path=str(path),
        info=info,
        keys=tuple(sorted(selected)),
        worlds=tuple(sorted({w for k in selected if (w := world_of(k))})),
        key_exprs=exprs,
        base_ns=base,
        start_ns=start_ns,
        end_ns=end_ns,
        messages=n,
        first_ns=first,
        last_ns=last,
        speed=float(speed),
        remap_world=remap_world,
    )


def _valid(key: str) -> bool:
    """Channels of foreign MCAP files (``/camera``) are not zenoh keys: they cannot be replayed."""
    try:
        zenoh.KeyExpr(key)
    except Exception:
        return False
    return "*" not in key and "$" not in key


@dataclass(frozen=True, slots=True)
class ReplayStats:
    """What a replay did. ``late_*``: how long after its due time each message was handed to zenoh."""

    messages: int
    payload_bytes: int
    loops: int
    elapsed_s: float
    late_p50_ms: float
    late_p99_ms: float
    late_max_ms: float

    def line(self) -> str:
        return (
            f"replayed {self.messages} msgs ({self.payload_bytes} B) in {self.elapsed_s:.2f} s, {self.loops} pass(es); "
            f"timing error p50 {self.late_p50_ms:.3f} ms  p99 {self.late_p99_ms:.3f} ms  max {self.late_max_ms:.3f} ms"
        )


Publish = Callable[[str, bytes], None]


class Replayer:
    """Republish a :class:`ReplayPlan` through ``target``: a Fabric, a zenoh Session, or a ``publish(key, payload)``.

    ``run(stop)`` blocks until the replay ends (or ``stop`` is set) and returns :class:`ReplayStats`.
    ``start()`` (or ``with Replayer(...) as rp:``) runs it on a thread of its own, once; ``done`` says it
    ended; ``close()`` (or leaving the ``with``) ends it, waits for it and undeclares the publishers,
    idempotent; ``stats`` are the figures so far, or final once done. With a zenoh
    target, publishers for every selected key are declared first and the replay waits up to
    ``wait_for_subscribers`` seconds for someone to listen, so the first messages are not lost.
    """

    def __init__(
        self,
        target: Any,
        plan: ReplayPlan,
        *,
        loop: bool = False,
        clock: Clock | None = None,
        wait_for_subscribers: float = 2.0,
        spin_s: float = 0.0005,
    ) -> None:
        self.plan = plan
        self.loop = loop
        self.clock = clock or MonotonicClock(spin_s=spin_s)
        self.wait_for_subscribers = wait_for_subscribers
        self.spin_s = spin_s
        self._pubs: dict[str, Any] = {}
        self._session = None
        if callable(target) and not isinstance(target, zenoh.Session):
            self._publish: Publish = target
        else:
            # the raw session, not Fabric.publish: recorded bytes go out as they were (never decoded nor re-stamped),
            # on express publishers of its own, one per recorded key however many (a Fabric caches 1024)
            self._session = getattr(target, "session", target)
            self._publish = self._zenoh_put
        self._stop = threading.Event()
        self._ended = threading.Event()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._late = array("d")
        self._count = 0
        self._bytes = 0
        self._loops = 0
        self._elapsed = 0.0
        self.error: BaseException | None = None

    # ------------------------------------------------------------------ publishing

    def _zenoh_put(self, key: str, payload: bytes) -> None:
        pub = self._pubs.get(key)
        if pub is None:
            pub = self._declare(key)
        pub.put(payload)

    def _declare(self, key: str) -> Any:
        # latched keys (maps, paths, scene objects) keep their last replayed value for late joiners, as live
        pub = declare_publisher(self._session, key, congestion_control=zenoh.CongestionControl.BLOCK, express=True)
        self._pubs[key] = pub
        return pub

    def _prepare(self, stop: threading.Event) -> None:
        if self._session is None:
            return
        for k in self.plan.keys:
            self._declare(self.plan.target(k))
        # advanced publishers (latched keys) do not say whether anyone listens; the plain ones beside them do
        wait_matched(self._pubs.values(), self.wait_for_subscribers, stop=stop)

    def _undeclare(self) -> None:
        for pub in self._pubs.values():
            try:
                pub.undeclare()
            except Exception:
                pass
        self._pubs.clear()

    # ------------------------------------------------------------------ timing

    def _wait_until(self, due: float, stop: threading.Event) -> None:
        clock = self.clock
        while True:
            left = due - clock.now()
            if left <= 0:
                return
            if clock.wait(left, stop):
                return

    # ------------------------------------------------------------------ running

    def run(self, stop: threading.Event | None = None) -> ReplayStats:
        stop = stop or self._stop
        plan = self.plan
        selected = set(plan.keys)
        self._prepare(stop)
        loop_len = plan.loop_len_s
        t0 = self.clock.now()
        k = 0
        try:
            while not stop.is_set():
                for m in iter_messages(plan.path, start_ns=plan.start_ns, end_ns=plan.end_ns):
                    if m.key not in selected:
                        continue
                    due = due_time(m.log_time, plan.base_ns, plan.speed, t0, k, loop_len)
                    self._wait_until(due, stop)
                    if stop.is_set():
                        break
                    now = self.clock.now()
                    self._publish(plan.target(m.key), m.payload)
                    self._late.append(max(0.0, now - due))
                    self._count += 1
                    self._bytes += len(m.payload)
                else:
                    k += 1
                    self._loops = k
                    if self.loop:
                        continue
                break
        finally:
            self._elapsed = self.clock.now() - t0
            self._ended.set()
        return self.stats

    @property
    def stats(self) -> ReplayStats:
        if self._late:
            p = percentiles(self._late, (50, 99))
            p50, p99, mx = p["p50"] * 1e3, p["p99"] * 1e3, max(self._late) * 1e3
        else:
            p50 = p99 = mx = 0.0
        return ReplayStats(self._count, self._bytes, self._loops, self._elapsed, p50, p99, mx)

    def start(self) -> "Replayer":
        """Run the replay on a daemon thread (once: a second call, or one after ``close()``, does nothing);
        an exception it raises is kept in ``error``."""
        with self._lock:
            if self._thread is not None or self._stop.is_set():
                return self
            self._thread = threading.Thread(target=self._run_kept, name="replayer", daemon=True)
            self._thread.start()
        return self

    def _run_kept(self) -> None:
        try:
            self.run(self._stop)
        except BaseException as exc:
            self.error = exc
            self._ended.set()

    @property
    def done(self) -> bool:
        """Whether the replay has ended (its last message sent, stopped, or failed: see ``error``)."""
        return self._ended.is_set()

    def close(self, timeout: float = 5.0) -> None:
        """End the replay started by ``start()`` and wait up to ``timeout`` for it, then undeclare the
        publishers; idempotent. A ``run(stop)`` in the caller's thread is ended by its own ``stop``."""
        self._stop.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
        self._undeclare()

    def __enter__(self) -> "Replayer":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
