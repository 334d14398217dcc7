"""A focusable horizontal slider for the terminal: a joint target between its limits.

Textual has no slider; this one is a single-line widget. ``left``/``right``
(or ``-``/``+``) step the value, ``shift``-variants step ten times as far,
``home``/``end`` jump to the limits, a click sets the value at the clicked
column. Every change posts :class:`JointSlider.Changed`.
"""

from __future__ import annotations

import math

from rich.text import Text
from textual import events
from textual.binding import Binding
from textual.message import Message
from textual.reactive import reactive
from textual.widget import Widget

__all__ = ["JointSlider"]


class JointSlider(Widget, can_focus=True):
    DEFAULT_CSS = """
    JointSlider { height: 1; width: 1fr; min-width: 20; }
    JointSlider:focus { background: $boost; }
    JointSlider:disabled { color: $text-disabled; }
    """

    BINDINGS = [
        Binding("right,plus,equals_sign", "step(1)", "+", show=False),
        Binding("left,minus", "step(-1)", "-", show=False),
        Binding("shift+right", "step(10)", "++", show=False),
        Binding("shift+left", "step(-10)", "--", show=False),
        Binding("home", "jump(-1)", "min", show=False),
        Binding("end", "jump(1)", "max", show=False),
    ]

    value: reactive[float] = reactive(0.0)
    actual: reactive[float | None] = reactive(None)

    class Changed(Message):
        def __init__(self, slider: "JointSlider", value: float) -> None:
            super().__init__()
            self.slider = slider
            self.value = value

        @property
        def control(self) -> "JointSlider":
            return self.slider

    def __init__(
        self,
        name: str,
        lo: float,
        hi: float,
        *,
        value: float = 0.0,
        step: float = math.radians(1.0),
        id: str | None = None,
    ) -> None:
        super().__init__(id=id)
        self.joint = name
        self.lo, self.hi, self.step_size = float(lo), float(hi), float(step)
        self.set_reactive(JointSlider.value, min(max(value, self.lo), self.hi))

    def set_value(self, value: float, *, notify: bool = True) -> None:
        v = min(max(float(value), self.lo), self.hi)
        if v != self.value:
            self.value = v
            if notify:
                self.post_message(self.Changed(self, v))

    def action_step(self, n: int) -> None:
        self.set_value(self.value + n * self.step_size)

    def action_jump(self, direction: int) -> None:
        self.set_value(self.hi if direction > 0 else self.lo)

    def on_click(self, event: events.Click) -> None:
        width = max(1, self._bar_width())
        frac = min(max((event.x - self._bar_start()) / (width - 1 if width > 1 else 1), 0.0), 1.0)
        self.set_value(self.lo + frac * (self.hi - self.lo))

    def _bar_start(self) -> int:
        return 10

    def _bar_width(self) -> int:
        return max(5, self.size.width - 10 - 18)

    def render(self) -> Text:
        width = self._bar_width()
        frac = 0.0 if self.hi == self.lo else (self.value - self.lo) / (self.hi - self.lo)
        pos = round(frac * (width - 1))
        bar = ["─"] * width
        if self.actual is not None and self.hi != self.lo:
            a = round(min(max((self.actual - self.lo) / (self.hi - self.lo), 0.0), 1.0) * (width - 1))
            bar[a] = "┃"
        bar[pos] = "●"
        text = Text(f"{self.joint[:9]:<10}", style="bold")
        text.append("".join(bar), style="cyan" if not self.disabled else "dim")
        act = f"{math.degrees(self.actual):7.1f}" if self.actual is not None else "      -"
        text.append(f" {math.degrees(self.value):7.1f}°{act}°")
        return text
