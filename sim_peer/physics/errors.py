"""The sim's domain error."""

from __future__ import annotations


class WorldError(ValueError):
    """A world cannot be built as asked (unknown robot type, duplicate id, bad spec); the text says why."""


__all__ = ["WorldError"]
