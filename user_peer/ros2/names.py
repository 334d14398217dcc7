"""Frame ids under a namespace: ``--namespace class1`` makes ``base1/laser`` ``class1/base1/laser``.

ROS users with several robots (or, here, several classes' worlds on one DDS domain) expect each namespace's frames
to carry its prefix, as robot_state_publisher's ``frame_prefix`` and Nav2's multi-robot launch give them: two
bridges' trees then never share a frame, where two worlds' ``base1/base_link`` (or ``map``) would otherwise be one
frame in tf2 and jump between two places. Every frame is prefixed, the root ``map`` too (two classes' worlds are two
unrelated trees); without a namespace the frames are the export's, unchanged.
"""

from __future__ import annotations

from typing import Any

__all__ = ["frame_prefix", "prefixed", "prefix_headers"]


def frame_prefix(namespace: str) -> str:
    """``"class1"`` (or ``"/class1/"``) -> ``"class1/"``; no namespace -> ``""``."""
    ns = namespace.strip("/")
    return f"{ns}/" if ns else ""


def prefixed(prefix: str, frame: str) -> str:
    """``frame`` under ``prefix`` (an empty frame, ROS's "none", stays empty)."""
    return prefix + frame if frame and prefix else frame


def prefix_headers(msg: Any, prefix: str) -> Any:
    """``msg`` with its header's frame, its ``child_frame_id`` and each pose's header (a Path's) under ``prefix``,
    in place: for the messages filled from the export's dicts (maps, paths), which carry the export's frames."""
    if not prefix:
        return msg
    header = getattr(msg, "header", None)
    if header is not None:
        header.frame_id = prefixed(prefix, header.frame_id)
    if hasattr(msg, "child_frame_id"):
        msg.child_frame_id = prefixed(prefix, msg.child_frame_id)
    for pose in getattr(msg, "poses", ()):
        pose.header.frame_id = prefixed(prefix, pose.header.frame_id)
    return msg
