"""Keeping a twist alive: the client's half of the sim's twist deadman.

A served base keeps a twist only ``--twist-timeout`` (0.5 s by default) without a fresh one, as ROS
teleop expects of ``cmd_vel``: a base whose driver went quiet (a crash, a closed laptop, a lost link)
brakes to a halt by itself. So a twist that should hold is repeated by the client while it drives:
:meth:`user_peer.mobile_base.Base.twist` hands its resend to the world's :class:`TwistKeeper`, which repeats
it every :data:`TWIST_REFRESH_S` until the next twist, a zero twist, a stop, a reset, a path, a release,
or the world's close; a resend that cannot go out (the robot was lost: another owner, a new epoch) ends
the hold. The keeper lives and dies with the program: that is the point.
"""

from __future__ import annotations

import logging
import threading
from typing import Callable

log = logging.getLogger("robofabric.user")

__all__ = ["TwistKeeper", "TWIST_REFRESH_S"]

TWIST_REFRESH_S = 0.1
"""How often a held twist is sent again: 10 Hz, five times within the sim's default 0.5 s deadman, so a
scheduling hiccup of a few hundred ms on a loaded machine does not stop the base."""


class TwistKeeper:
    """Resends each robot's held twist every ``interval`` s on one daemon thread (started at the first hold).

    ``hold(robot, send)``: ``send()`` goes out again every ``interval`` until :meth:`drop`, another hold of
    the same robot, or ``send`` raising (then the hold ends: it is logged, never raised here). ``close()``
    ends every hold and the thread; idempotent."""

    def __init__(self, interval: float = TWIST_REFRESH_S) -> None:
        if not interval > 0:
            raise ValueError(f"interval must be positive, got {interval}")
        self.interval = interval
        self._held: dict[str, Callable[[], None]] = {}
        self._lock = threading.Lock()
        # held while a resend goes out: a drop or a new hold waits for it, so that a resend of the old twist read
        # before the drop can never land after the caller's own next command (the full suite saw a stop's zero
        # twist followed by the old twist's resend: the base drove on until the sim's deadman)
        self._sending = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.resent = 0
        self.ended: dict[str, str] = {}  # robot -> why its last hold ended by itself (a failed resend)

    def hold(self, robot: str, send: Callable[[], None]) -> None:
        with self._sending, self._lock:
            if self._stop.is_set():
                return
            self._held[robot] = send
            self.ended.pop(robot, None)
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="twist-keeper", daemon=True)
                self._thread.start()

    def drop(self, robot: str) -> None:
        """End ``robot``'s hold; once this returns, no resend of it goes out (one under way has gone)."""
        with self._sending, self._lock:
            self._held.pop(robot, None)

    def holding(self, robot: str) -> bool:
        """Whether ``robot``'s twist is being repeated (False once it was dropped or could not be sent)."""
        with self._lock:
            return robot in self._held

    def close(self) -> None:
        with self._lock:
            self._stop.set()
            self._held.clear()
            thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            with self._lock:
                items = list(self._held.items())
            for robot, send in items:
                with self._sending:
                    with self._lock:
                        if self._held.get(robot) is not send:
                            continue  # dropped or replaced since the copy: its twist is not the robot's any more
                    try:
                        send()
                        self.resent += 1
                    except Exception as exc:  # lost the robot, or the session closed: the hold ends, the base stops
                        with self._lock:
                            if self._held.get(robot) is send:
                                del self._held[robot]
                                self.ended[robot] = str(exc)
                        log.info("stopped repeating the twist of %s: %s", robot, exc)
