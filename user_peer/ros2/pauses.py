"""The interpreter's garbage-collection pauses, timed: one cause of a late message that a profile averages away.

A full collection walks every tracked object (a process that imported rclpy, zenoh and numpy holds about 80,000)
and stops every Python thread meanwhile, so each message in flight through the bridge then waits for it.
``robofabric bench ros2`` records them (the bridge's ``--trace``) to tell such pauses from the rest of the tail.
"""

from __future__ import annotations

import gc
import time
from typing import Any

__all__ = ["GcPauses"]


class GcPauses:
    """Each collection's (generation, start, end), ``time.time_ns()``, from construction until ``close()``."""

    def __init__(self) -> None:
        self.pauses: list[tuple[int, int, int]] = []
        self._start = 0
        gc.callbacks.append(self._on)

    def _on(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._start = time.time_ns()
        else:
            self.pauses.append((int(info["generation"]), self._start, time.time_ns()))

    def close(self) -> None:
        """Stop recording (idempotent)."""
        if self._on in gc.callbacks:
            gc.callbacks.remove(self._on)
