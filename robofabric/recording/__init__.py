"""The recording tools: replay, live conversion, the recorded-load generator and the ``record``/``info``/``replay`` CLI.

They stand on the recorder library in :mod:`fabric.recording` (writing and reading MCAP files), which
stays on the ground floor because peers use it at run time; nothing here is imported by a peer.
``plan_replay`` + ``Replayer`` republish a recording's exact bytes on its timeline, optionally filtered,
windowed, sped up and remapped into another world (docs/recording.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from robofabric.recording.replayer import Replayer, ReplayPlan, ReplayStats, due_time, plan_replay

__all__ = ["Replayer", "ReplayPlan", "ReplayStats", "plan_replay", "due_time"]


def __getattr__(name: str) -> Any:
    """Loaded on first use: ``robofabric --help`` imports :mod:`robofabric.recording.cli`, and with it this package."""
    if name not in __all__:
        raise AttributeError(f"module 'robofabric.recording' has no attribute {name!r}")
    from robofabric.recording import replayer

    return getattr(replayer, name)
