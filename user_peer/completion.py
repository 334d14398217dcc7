"""Shell completion that needs no live world: prefix matching and the installed export formats.

With the user peer because its CLI offers them (``export --to``), and a peer imports no tool; the
completers that look at a live world are a tool (:mod:`robofabric.complete`), which uses these too.
Standard library only: completion runs at every Tab, so this module must not load zenoh or the codec.
"""

from __future__ import annotations

from typing import Iterable

__all__ = ["matching", "exporter_names", "complete_formats", "complete_export_formats"]


def matching(candidates: Iterable[str], incomplete: str) -> list[str]:
    """The candidates that start with what was typed, sorted, each once."""
    return sorted({c for c in candidates if c.startswith(incomplete)})


def exporter_names() -> list[str]:
    """The formats ``record --to`` writes: the names of the ``robofabric.exporters`` entry points."""
    from importlib.metadata import entry_points

    return sorted({ep.name for ep in entry_points(group="robofabric.exporters")})


def complete_formats(incomplete: str) -> list[str]:
    """``record --to``: foxglove, ros2 and any other installed exporter."""
    try:
        return matching(exporter_names(), incomplete)
    except Exception:
        return []


def complete_export_formats(incomplete: str) -> list[str]:
    """``export --to``: rrd (Rerun) and every installed exporter."""
    try:
        return matching(["rrd", *exporter_names()], incomplete)
    except Exception:
        return []
