"""How the tools' text meets a terminal: docstrings as plain help, and long lines folded at its edge.

Only the top floor's commands print help pages and folded listings (``--help``, ``interfaces``, ``info``,
``ps``, ``hz``); the peers' commands print through :func:`fabric.cli_common.say` and
:func:`fabric.cli_common.print_table`, so these stay up here.
"""

from __future__ import annotations

import re

from fabric.cli_common import console

__all__ = ["plain_doc", "print_folded"]

_ROLE = re.compile(r":[a-z]+(?::[a-z]+)?:`~?([^`<]*?)(?:\s*<[^>]*>)?`")
_LITERAL = re.compile(r"``(.+?)``")


def plain_doc(text: str) -> str:
    """A docstring as a terminal shows it: reStructuredText markup gone (``x`` -> x, :class:`~a.B` -> B), and
    each paragraph's lines joined, so the terminal wraps it at its own width (a list or an indented block
    keeps its lines)."""
    import inspect

    text = _LITERAL.sub(
        r"\1", _ROLE.sub(lambda m: m.group(1).rsplit(".", 1)[-1] if "~" in m.group(0) else m.group(1), text)
    )
    paragraphs = []
    for para in inspect.cleandoc(text).split("\n\n"):
        lines = para.splitlines()
        listed = any(line.lstrip().startswith(("- ", "* ", "\b")) or line.startswith(" ") for line in lines)
        paragraphs.append(para if listed else " ".join(line.strip() for line in lines))
    return "\n\n".join(paragraphs)


def print_folded(*lines: str, stderr: bool = False) -> None:
    """Lines wrapped to the terminal's width, a word longer than a line (a key) folded, never cut."""
    out = console(stderr=stderr)
    for line in lines:
        out.print(line, overflow="fold")
