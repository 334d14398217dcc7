"""The live Rerun view inside a notebook, fed by the user's own world session.

``user_peer.notebook.show(world)`` draws what ``robofabric view`` draws (robots, scans, maps, paths,
target and goal, ownership, plots) in an inline Rerun viewer under the cell. It needs the notebook
extra (``pip install 'robofabric[notebook]'``: rerun's notebook widget); without it,
:func:`available` is False and a notebook can skip the view. Nothing here blocks on a display, and
nothing keeps the kernel alive: the drawing thread is a daemon and the subscription ends with the world.
"""

from __future__ import annotations

import importlib.util
import logging
import queue
import threading
import time
from typing import Any

import rerun as rr

from fabric import keys
from user_peer.api import World
from user_peer.catalog import RobotCatalog
from user_peer.rerun_log import WorldLogger, blueprint
from user_peer.viewer import APP_ID, log_scene

log = logging.getLogger("robofabric.viewer")

__all__ = ["available", "NotebookView", "show"]


def available() -> bool:
    """True when rerun's notebook widget (the ``notebook`` extra) is installed."""
    return importlib.util.find_spec("rerun_notebook") is not None


class NotebookView:
    """A world drawn into a Rerun recording; ``display()`` shows it inline. ``close()`` stops it."""

    def __init__(self, world: World, *, max_hz: float = 15.0, queue_size: int = 5000) -> None:
        self.world = world
        self.rec = rr.RecordingStream(APP_ID)
        self.catalog = RobotCatalog(world.info())
        self.logger = WorldLogger(self.rec, drawing=self.catalog.drawing, max_hz=max_hz, clock=time.time_ns)
        info = self.catalog.world_info
        if info is not None and info.scene:
            log_scene(self.logger, info.scene)
        self.queue: queue.Queue[tuple[str, Any, int]] = queue.Queue(maxsize=queue_size)
        self.dropped = 0
        self.drawn = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._drain, name="notebook-view", daemon=True)
        self._thread.start()
        self._sub = world.fabric.subscribe(keys.world_all(world.name), self._enqueue, history=True)

    def _enqueue(self, key: str, msg: Any) -> None:
        try:
            self.queue.put_nowait((key, msg, time.time_ns()))
        except queue.Full:  # a slow widget must never slow the world down
            self.dropped += 1

    def _drain(self) -> None:
        flushed = time.monotonic()
        while not self._stop.is_set():
            try:
                key, msg, t = self.queue.get(timeout=0.05)
            except queue.Empty:
                key = None
            if key is not None:
                try:
                    if self.logger.log(key, msg, t):
                        self.drawn += 1
                except Exception:
                    log.debug("could not draw %s", key, exc_info=True)
            if time.monotonic() - flushed >= 0.1:  # the logger draws what it filed once per window
                flushed = time.monotonic()
                try:
                    self.logger.flush()
                except Exception:
                    log.debug("could not draw a window", exc_info=True)

    def display(self, *, width: int | None = None, height: int = 600) -> None:
        """The inline viewer under the current cell (the ``notebook`` extra)."""
        self.rec.notebook_show(width=width, height=height, blueprint=blueprint())

    def close(self) -> None:
        self._stop.set()
        try:
            self._sub.undeclare()
        except Exception:
            pass


def show(world: World, *, width: int | None = None, height: int = 600, max_hz: float = 15.0) -> NotebookView:
    """Draw ``world`` live in an inline Rerun viewer under this cell; returns the view (``close()`` stops it)."""
    view = NotebookView(world, max_hz=max_hz)
    view.display(width=width, height=height)
    return view
