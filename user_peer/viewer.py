"""The Rerun viewer peer: subscribe to a world, log everything it shows to Rerun.

Zenoh callbacks only append ``(message, receive time)`` to their stream's queue (one per key); one
thread, once per window (``window_s``, 0.1 s), takes everything queued, in arrival order, files it in a
:class:`~user_peer.rerun_log.WorldLogger` and flushes it: one ``send_columns`` per entity and window. So
the logger needs no locks and a slow sink never stalls Zenoh.

Never behind: a sample that waited longer than ``max_lag_s`` (0.5 s) when its window is drawn is dropped,
oldest first, per stream, and counted, but never a stream's newest sample (a robot's last state is
always drawn), so the view stays within about ``max_lag_s`` of the world however slow the drawing.
The viewer plots its own lag (``plots/viewer/lag_ms``: how long the oldest sample of a window waited)
and drops (``plots/viewer/dropped``), and says so in the event log when it starts dropping.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from fabric import keys
from fabric.config import FabricConfig
from fabric.exit import at_exit
from fabric.interfaces import ServiceError, WorldInfo
from fabric.session import Fabric
from user_peer import services
from user_peer.catalog import RobotCatalog
from user_peer.rerun_log import WorldLogger, blueprint, framing

log = logging.getLogger("robofabric.viewer")

__all__ = [
    "ViewerOptions",
    "Viewer",
    "make_recording",
    "query_world_info",
    "log_scene",
    "web_urls",
    "default_advertise",
]

APP_ID = "robofabric"


@dataclass(frozen=True, slots=True)
class ViewerOptions:
    """Where the view goes: any combination of a spawned viewer, a remote viewer, a web viewer, a file."""

    spawn: bool = False
    connect_url: str | None = None
    serve_web: bool = False
    web_port: int = 9090
    bind: str = "0.0.0.0"  # the interface --serve-web's page and data ports listen on (default: every one)
    advertise: str | None = None  # the host name or address other machines reach this one by (--serve-web)
    grpc_port: int = 9876
    save: Path | None = None
    max_hz: float = 30.0
    window_s: float = 0.1  # drawing window: what arrived in it goes out as one chunk per entity
    max_lag_s: float = 0.5  # a sample older than this when drawn is dropped (never a stream's newest)
    # what Rerun's gRPC server keeps for pages that join late, in bytes: the scene (static) and the blueprint always,
    # and the newest data up to this (at the combined world's ~0.3 MB/s, the last ~100 s). A page that joins is
    # sent it at once, behind the live feed; the relay holds twice this for each page (RelayLimits.max_queue_bytes)
    web_history: int = 32 << 20


def default_advertise() -> str:
    """The name other machines are most likely to reach this one by: its host name."""
    import socket

    return socket.gethostname() or "localhost"


def web_urls(host: str, web_port: int, grpc_port: int) -> tuple[str, str]:
    """(page URL for a browser, gRPC URL the page streams from), both naming ``host``.

    The web viewer Rerun serves does not know where the data is: the page must be told with
    ``?url=``. A page opened on another machine with a ``127.0.0.1`` data URL would look for the
    data on that other machine, which is why ``host`` must be this machine's name as others see it.
    """
    from urllib.parse import quote

    h = f"[{host}]" if ":" in host and not host.startswith("[") else host  # IPv6 literals
    grpc = f"rerun+http://{h}:{grpc_port}/proxy"
    return f"http://{h}:{web_port}/?url={quote(grpc, safe='')}", grpc


def make_recording(
    opts: ViewerOptions, *, recording_id: str | None = None, grpc_server_port: int | None = None
) -> rr.RecordingStream:
    """A recording stream with the requested sinks and the default blueprint.

    ``grpc_server_port``: with ``serve_web``, Rerun's gRPC server listens there on loopback only, behind
    the per-page relay (user_peer/web_relay.py) on ``grpc_port``; None: on ``grpc_port``, every interface."""
    rec = rr.RecordingStream(APP_ID, recording_id=recording_id)
    sinks: list[Any] = []
    if opts.save is not None:
        opts.save.parent.mkdir(parents=True, exist_ok=True)
        sinks.append(rr.FileSink(str(opts.save)))
    if opts.spawn:
        rr.spawn(port=opts.grpc_port, connect=False)
        sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{opts.grpc_port}/proxy"))
    if opts.connect_url:
        sinks.append(rr.GrpcSink(opts.connect_url))
    if opts.serve_web:
        # All interfaces, and the web page's origin on any host name allowed to stream (Rerun's default
        # CORS list holds only localhost and rerun.io, so a page from http://HOST:WEB_PORT would be refused).
        server = rr.GrpcServerSink(
            bind_ip="0.0.0.0" if grpc_server_port is None else "127.0.0.1",
            port=opts.grpc_port if grpc_server_port is None else grpc_server_port,
            # a page that joins gets the live feed first and the history behind it: it shows now at once
            # instead of ingesting the whole session first (at a software-rendered page's pace, minutes)
            newest_first=True,
            server_memory_limit=f"{opts.web_history}B",
            cors_allow_origin=[f"http://*:{opts.web_port}", f"https://*:{opts.web_port}"],
        )
        sinks.append(server)
    if not sinks:
        raise ValueError("nowhere to show the world: give --spawn, --connect URL, --serve-web or --save FILE.rrd")
    rec.set_sinks(*sinks, default_blueprint=blueprint())
    return rec


def log_scene(logger: WorldLogger, scene: str) -> bool:
    """Draw a scene's static geometry from robots/ (nothing if the scene is unknown here)."""
    try:
        import robots
        from user_peer.scene_geometry import static_boxes

        logger.log_scene(static_boxes(robots.scene(scene).mjcf_path))
        return True
    except Exception as exc:
        log.info("no static geometry for scene %r: %s", scene, exc)
        return False


FIRST_LOOK_S = 30.0
"""How long a viewer that knows no world yet asks a sim that came for its description (a loaded sim's token can come
seconds before its service answers)."""


def query_world_info(fab: Fabric, timeout: float = 2.0) -> WorldInfo | None:
    """The sim peer's world description, or None when no sim answers (the viewer then guesses types)."""
    try:
        return services.world_info(fab, timeout=timeout)
    except ServiceError as exc:  # Refused (e.g. a reply that is no WorldInfo) or NoReply
        log.info("no world description (%s); robot types are guessed from joint names", exc)
        return None


class Viewer:
    """A viewer peer on one world. ``run(stop, duration)`` blocks; ``close()`` flushes the sinks."""

    def __init__(
        self, config: FabricConfig, opts: ViewerOptions, *, peer_id: str | None = None, queue_size: int = 5000
    ) -> None:
        self.opts = opts
        self.fab = Fabric(config, kind="viewer", peer_id=peer_id)
        self.page = None
        self.relay = None
        if opts.serve_web:
            # the pages stream through the relay, one queue per page (user_peer/web_relay.py), from Rerun's
            # gRPC server on a loopback port; the page itself comes from this machine alone (user_peer/web_page.py)
            from user_peer import web_page
            from user_peer.web_relay import Relay, RelayLimits

            try:
                inner = web_page.free_loopback_port()
                limits = RelayLimits(max_queue_bytes=max(RelayLimits().max_queue_bytes, 2 * opts.web_history))
                self.relay = Relay(("127.0.0.1", inner), opts.grpc_port, bind=opts.bind, limits=limits)
                self.rec = make_recording(opts, grpc_server_port=inner)
                self.page = web_page.serve(opts.web_port, opts.grpc_port, bind=opts.bind)
            except Exception:
                if self.relay is not None:
                    self.relay.close()
                self.fab.close()
                raise
        else:
            self.rec = make_recording(opts)
        # one queue per key: dropping happens per stream, so a busy stream never pushes out another's samples
        self.queue_size = queue_size
        self._streams: dict[str, deque[tuple[Any, int]]] = {}
        self._lock = threading.Lock()
        self.dropped = 0  # samples dropped, every stream together
        self.dropped_per_stream: dict[str, int] = {}
        self.received = 0
        self.lags_ms: deque[float] = deque(maxlen=10_000)  # per window: how long its oldest sample waited
        self._warned_ns = 0
        self.catalog = RobotCatalog(None)
        # the clock that stamps arrivals in receive: Eq. 8 ages are measured on it alone
        self.logger = WorldLogger(self.rec, drawing=self.catalog.drawing, max_hz=opts.max_hz, clock=time.time_ns)
        self._closed = False
        self._sims: set[str] = set()
        self._sims_lock = threading.Lock()
        self._world_seen = False  # "is back" only after the world was there and went
        self._stopped = threading.Event()  # set at close: background looks at the world end
        # a script that never closes the viewer still flushes its sinks, then its session closes (fabric/exit.py)
        self._cancel_exit = at_exit(self.close)

    def receive(self, key: str, msg: Any) -> None:
        """Zenoh's callback: file the sample under its key. A stream holding ``queue_size`` samples (the drawing
        thread stalled) loses its oldest."""
        item = (msg, time.time_ns())
        with self._lock:
            d = self._streams.get(key)
            if d is None:
                d = self._streams[key] = deque()
            if len(d) >= self.queue_size:
                d.popleft()
                self._count_drop(key, 1)
            d.append(item)
            self.received += 1

    def _count_drop(self, key: str, n: int) -> None:
        self.dropped += n
        self.dropped_per_stream[key] = self.dropped_per_stream.get(key, 0) + n

    def take(self, now_ns: int | None = None) -> list[tuple[int, str, Any]]:
        """Everything queued, as (arrival ns, key, message) in arrival order, less what waited longer than
        ``max_lag_s`` by ``now_ns``: dropped and counted, except each stream's newest."""
        now_ns = time.time_ns() if now_ns is None else now_ns
        oldest_kept = now_ns - int(self.opts.max_lag_s * 1e9)
        out: list[tuple[int, str, Any]] = []
        with self._lock:
            batches = [(key, list(d)) for key, d in self._streams.items() if d]
            for d in self._streams.values():
                d.clear()
            for key, items in batches:
                keep = [it for it in items[:-1] if it[1] >= oldest_kept]
                if len(keep) < len(items) - 1:
                    self._count_drop(key, len(items) - 1 - len(keep))
                keep.append(items[-1])  # the stream's latest state is always drawn
                out.extend((t, key, msg) for msg, t in keep)
        out.sort(key=lambda x: x[0])
        return out

    def start(self) -> None:
        """Learn the world, subscribe, and ask for the state a late joiner missed (ownership, maps)."""
        info = self.catalog.world_info = query_world_info(self.fab)
        if info is not None:
            self._draw_world(info)
        self.fab.subscribe(
            keys.world_all(self.fab.world), self.receive, history=True
        )  # maps, paths, objects set before we joined
        self.fab.watch_peers(self._on_sim, kind="sim")  # "world gone" when the last sim peer leaves
        self._ask_records()

    def _draw_world(self, info: WorldInfo) -> None:
        """The scene, and a first view that shows every robot, not the scene's bounds (shelves and walls)."""
        if info.scene:
            log_scene(self.logger, info.scene)
        frame = framing([tuple(float(v) for v in r.pose[:3]) for r in info.robots])
        if frame is not None:
            self.rec.send_blueprint(blueprint(frame), make_active=True, make_default=True)

    def _ask_records(self) -> None:
        """Every ownership record, asked: a record is published only when it changes, so one published before
        our subscription reached its sim would otherwise never be drawn."""
        try:
            for rep in self.fab.rpc.query(keys.own_all(self.fab.world), timeout=1.0, all_replies=True):
                self.receive(rep.key, rep.message)
        except ServiceError:
            pass

    def _on_sim(self, kind: str, peer_id: str, alive: bool) -> None:
        """Say when the world goes (its last sim peer left: died, or cut off) and when it comes back:
        on the terminal and in the view's event log; the robots keep their last drawn state."""
        with self._sims_lock:
            was = bool(self._sims)
            new = alive and peer_id not in self._sims
            (self._sims.add if alive else self._sims.discard)(peer_id)
            now = bool(self._sims)
            first, self._world_seen = now and not self._world_seen, self._world_seen or now
        # a sim joining the world (a shard) describes robots of its own; the first one does too when the look at start
        # found no sim (a viewer started before its sim, or one too loaded to answer in time: the clock-skew lab's
        # viewer drew nothing for its whole run so)
        if new:
            threading.Thread(target=self._learn_world, args=(peer_id,), name="viewer-world", daemon=True).start()
        if now == was:
            return
        text = (
            f"world {self.fab.world!r}: served by sim peer {peer_id}"
            if first
            else f"world {self.fab.world!r} is back: sim peer {peer_id}"
            if now
            else f"world {self.fab.world!r} gone: its sim peer {peer_id} left (died, or cut off)"
        )
        print(f"viewer: {text}", flush=True)
        try:
            self.rec.log("events", rr.TextLog(text, level="INFO" if now else "WARN"))
        except Exception:
            log.debug("could not log the world's state", exc_info=True)

    def _learn_world(self, sim: str, wait_s: float = 5.0) -> None:
        """Ask the world's description again (the union of every sim's part), off Zenoh's callback threads, until
        it has robots of ``sim`` (its token comes before its service) or ``wait_s`` pass (a standby has none)."""
        deadline = time.monotonic() + (wait_s if self.catalog.world_info is not None else FIRST_LOOK_S)
        while not self._stopped.is_set():
            try:
                info = query_world_info(self.fab)
            except Exception:  # the session closed under it
                return
            if info is not None:
                first = self.catalog.world_info is None
                self.catalog.world_info = info
                if first:
                    self._draw_world(info)
                if any(r.sim == sim for r in info.robots):
                    self._ask_records()  # its ownership records too (its authority serves before its world does)
                    return
            if time.monotonic() > deadline:
                return
            self._stopped.wait(0.2)

    def draw(self) -> int:
        """One window: file everything queued (less what is too old) and flush it; returns how many were logged."""
        dropped_before = self.dropped
        items = self.take()
        n = 0
        for t, key, msg in items:
            try:
                self.logger.log(key, msg, t)
            except Exception:
                log.exception("could not log %s", key)
            n += 1
        try:
            self.logger.flush()
        except Exception:
            log.exception("could not draw a window")
        if items:
            self._show_health(items[0][0], self.dropped - dropped_before)
        return n

    def _show_health(self, oldest_ns: int, dropped_now: int) -> None:
        """Plot how long this window's oldest sample waited (the view's lag) and the drops; a line in the event
        log when dropping starts (at most one per 5 s)."""
        now = time.time_ns()
        lag_ms = (now - oldest_ns) / 1e6
        self.lags_ms.append(lag_ms)
        try:
            self.rec.reset_time()
            self.rec.set_time("wall_time", timestamp=np.datetime64(now, "ns"))
            self.rec.log("plots/viewer/lag_ms", rr.Scalars(lag_ms))
            self.rec.log("plots/viewer/dropped", rr.Scalars(float(self.dropped)))
            if dropped_now and now - self._warned_ns > 5e9:
                self._warned_ns = now
                self.rec.log(
                    "events",
                    rr.TextLog(
                        f"viewer behind: dropped {self.dropped} samples so far that waited over {self.opts.max_lag_s:g} s "
                        "(the oldest of each stream; every robot's latest state is drawn)",
                        level="WARN",
                    ),
                )
        except Exception:
            log.debug("could not log the viewer's health", exc_info=True)

    def run(self, stop: threading.Event, duration: float | None = None) -> int:
        self.start()
        t_end = time.monotonic() + duration if duration is not None else None
        n = 0
        window = max(0.01, self.opts.window_s)
        next_at = time.monotonic() + window
        while not stop.is_set():
            left = next_at - time.monotonic()
            if t_end is not None:
                left = min(left, t_end - time.monotonic())
            if left > 0:
                stop.wait(left)
            n += self.draw()
            next_at = max(next_at + window, time.monotonic() + window / 4)  # behind: draw again soon, not at once
            if t_end is not None and time.monotonic() >= t_end:
                break
        return n

    def lag_summary(self) -> str:
        """'lag p50 X ms, max Y ms' over the windows drawn ('' before any)."""
        if not self.lags_ms:
            return ""
        arr = np.asarray(self.lags_ms)
        return f"lag p50 {np.percentile(arr, 50):.0f} ms, max {arr.max():.0f} ms"

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._stopped.set()
        self._cancel_exit()
        self.fab.close()
        # Whatever is already queued still goes to the sinks.
        try:
            self.draw()
        except Exception:
            log.debug("could not draw the last window", exc_info=True)
        self.rec.flush(timeout_sec=10.0)
        self.rec.disconnect()
        if self.page is not None:
            self.page.close()
        if self.relay is not None:
            self.relay.close()
            k = self.relay.counters()
            print(
                f"web relay: {k.refused_requests} requests refused (only reads are relayed), {k.refused_connections} "
                f"connections refused, {k.cut} pages cut off; at most {k.peak_queued_bytes / 1e6:.1f} MB queued "
                f"for every page together (budget {self.relay.limits.max_total_bytes / 1e6:.0f} MB)",
                flush=True,
            )

    def __enter__(self) -> "Viewer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
