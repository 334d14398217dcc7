"""Text from the network, made safe to show: one line, no control characters, a bounded length.

Ids, kinds, reasons and names come from any login (a decode report's fields are its writer's say-so; a key
expression may hold a newline). Shown as they are, a newline in a kind forged a whole "trusted" line in every
console page's event log, one in a liveliness token's key forged lines of ``robofabric router --audit``, 2,000
newlines in a reason became 2,000 log lines per event in a page, and an escape sequence could drive a terminal.
Every place that shows such text (the console, the terminal UI, the CLI's tables, the router's audit) passes it
through :func:`one_line` first: what was sent is still readable, but it is data, never layout.
"""

from __future__ import annotations

__all__ = ["one_line", "escape", "CAP", "CUT"]

CAP = 200
"""The default length of a shown field, in characters after escaping."""

CUT = "…"
"""What ends a field cut at its cap (one character: a cut field is exactly the cap long)."""


def escape(text: str) -> str:
    """``text`` with every character that is not printable written as Python writes it in a string literal
    (``\\n``, ``\\x1b``, ``\\u202e``): control characters, line and paragraph separators, format characters
    (bidirectional overrides) and unassigned code points. Printable text, spaces included, is unchanged."""
    if text.isprintable():
        return text
    return "".join(ch if ch.isprintable() else ascii(ch)[1:-1] for ch in text)


def one_line(value: object, cap: int = CAP) -> str:
    """``str(value)`` escaped (:func:`escape`) and, when longer than ``cap`` characters, cut to ``cap`` with
    :data:`CUT` last. The result is one line of printable characters at most ``cap`` long (``cap`` >= 1)."""
    if cap < 1:
        raise ValueError(f"cap must be at least 1, got {cap}")
    out = escape(str(value)[: cap + 1])  # each character escapes to one or more: what is past cap + 1 is cut anyway
    return out if len(out) <= cap else out[: cap - 1] + CUT
