"""A goal typed into the base panel's x and y fields, read as a student means it, refused in plain words.

Clicking the map is not the only way to place a goal: a student who knows where it is (the paper's Test B gives
the goal in metres), or who cannot use a mouse, types it. What she typed is read leniently (a comma for the
decimal point, a trailing ``m``, spaces) and refused only with what to type instead: an empty field, something
that is no number, a point off the map. Pure: the text and the map's frame in, a goal or the reasons out.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from fabric.text import one_line
from user_peer.console.topview import Frame

__all__ = ["TypedGoal", "typed_goal", "read_metres"]

_UNIT = re.compile(r"\s*m(etres?|eters?)?\s*$", re.IGNORECASE)


@dataclass(frozen=True, slots=True)
class TypedGoal:
    """What the fields said: ``xy`` when both are good, else one plain message per bad field (``field``, ``why``)."""

    xy: tuple[float, float] | None
    errors: tuple[tuple[str, str], ...] = ()

    def message(self) -> str:
        """Every refusal on one line, for the page's status."""
        return " · ".join(why for _, why in self.errors)


def read_metres(text: str) -> float | None:
    """``text`` as metres: ``-2.5``, ``-2,5``, `` 3 m``; None when it is no finite number."""
    t = _UNIT.sub("", (text or "").strip()).replace(",", ".").replace("\u2212", "-")  # a typographic minus too
    try:
        v = float(t)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def _field(name: str, text: str, lo: float, hi: float) -> tuple[float | None, str | None]:
    shown = (text or "").strip()
    if not shown:
        return None, f"Goal {name} is empty: type a number of metres, e.g. {(lo + hi) / 2:.1f}"
    v = read_metres(shown)
    if v is None:
        return (
            None,
            f"Goal {name} '{one_line(shown, 20)}' is not a number: type metres with a point, e.g. {(lo + hi) / 2:.1f}",
        )
    if not lo <= v <= hi:
        return None, f"Goal {name} {v:.2f} m is off the map: type a number from {lo:.2f} to {hi:.2f}"
    return v, None


def typed_goal(x_text: str, y_text: str, frame: Frame) -> TypedGoal:
    """The goal the two fields give, on ``frame`` (the whole map, not a zoomed part of it), or why not."""
    x, ex = _field("x", x_text, frame.xmin, frame.xmax)
    y, ey = _field("y", y_text, frame.ymin, frame.ymax)
    errors = tuple((f, e) for f, e in (("x", ex), ("y", ey)) if e is not None)
    return TypedGoal(None if errors else (float(x), float(y)), errors)  # type: ignore[arg-type]
