"""Arrow keys to a twist, as the page's keyboard holds them: pure, so the rules are tested without a browser.

The base moves only while an arrow key is held (the twist is a deadman the page refreshes, see
:data:`REFRESH_S`); a release, a lost focus or space stops it. ``1``-``3`` pick the speed, as in
the terminal UI (:data:`user_peer.tui.SPEEDS`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Driver", "ARROWS", "REFRESH_S", "SPEEDS"]

SPEEDS = {1: (0.2, 0.4), 2: (0.5, 0.8), 3: (1.0, 1.5)}
"""Speed level -> (forward m/s, turn rad/s): the terminal UI's (``user_peer.tui.SPEEDS``, tested equal)."""

ARROWS = {"ArrowUp": (1, 0), "ArrowDown": (-1, 0), "ArrowLeft": (0, 1), "ArrowRight": (0, -1)}
"""Browser key names -> (forward sign, turn sign)."""

REFRESH_S = 0.1
"""How often the page sends the twist again while a key is held (the sim's twist is a deadman of ~0.5 s)."""


@dataclass
class Driver:
    """Which arrows are held and at what speed; :meth:`twist` is what to send now."""

    level: int = 1
    held: set[str] = field(default_factory=set)

    def key(self, name: str, down: bool) -> bool:
        """A key went down or up; True when it changes what the base should do (send :meth:`twist` now)."""
        if name in ARROWS:
            before = set(self.held)
            (self.held.add if down else self.held.discard)(name)
            return self.held != before
        if not down:
            return False
        if name in ("1", "2", "3"):
            self.level = int(name)
            return bool(self.held)
        if name == " ":
            return self.stop()
        return False

    def stop(self) -> bool:
        """Let go of every key (space, the page lost focus); True when the base was being driven."""
        was = bool(self.held)
        self.held.clear()
        return was

    @property
    def driving(self) -> bool:
        return bool(self.held)

    def twist(self) -> tuple[float, float]:
        """(v m/s, omega rad/s) for the keys held: opposite keys cancel."""
        v, w = SPEEDS[self.level]
        fwd = sum(ARROWS[k][0] for k in self.held)
        turn = sum(ARROWS[k][1] for k in self.held)
        return float(fwd * v), float(turn * w)
