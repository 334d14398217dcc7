"""How a key is published: its zenoh priority, and a cached publisher for latched keys.

Shared by the session, its services (a query travels at its key's priority) and the replayer, which
publishes recorded samples on their original keys with the same options.
"""

from __future__ import annotations

from typing import Any

import zenoh
import zenoh.ext

from fabric import keys

__all__ = ["priority_for", "declare_publisher"]


def priority_for(key: str) -> zenoh.Priority | None:
    """zenoh priority of what travels on ``key``: robot commands and ownership (records, requests,
    renewals, their replies) go ahead of data, so that a flood of data on any key (junk included:
    a flooder's samples carry the default priority) cannot queue an owner's command or renewal
    behind it in a router's per-priority queues. So do the events that explain ownership and refusals
    (``event/own/...``, ``event/reject/...``, the kept kinds of :func:`fabric.keys.cache_size`): at the
    default priority, a slow subscriber's queue full of scans dropped them while the record they explain,
    ahead in its own queue, arrived (a console told of no lease's end; the soak's checker saw a release
    nobody announced). They are few: one per ownership change, refusals at most a burst per interval
    (:mod:`fabric.reports`). None for everything else (zenoh's default)."""
    parts = key.split("/")
    if len(parts) >= 4 and (parts[2] == "own" or (parts[2] == "robot" and len(parts) >= 5 and parts[4] == "cmd")):
        return zenoh.Priority.INTERACTIVE_HIGH
    if len(parts) >= 4 and parts[2] == "event" and parts[3] in keys.KEPT_EVENT_KINDS:
        return zenoh.Priority.INTERACTIVE_HIGH
    return None


def declare_publisher(session: zenoh.Session, key: str, **options: Any) -> Any:
    """A publisher for ``key``; on a latched key (:func:`fabric.keys.is_latched`) one whose last sample
    stays in a cache for subscribers that join later and ask for history. Priority: :func:`priority_for`."""
    prio = priority_for(key)
    if prio is not None:
        options.setdefault("priority", prio)
    kept = keys.cache_size(key)
    if not kept:
        return session.declare_publisher(key, **options)
    if not keys.is_latched(key):  # events kept for a subscriber whose link was down (fabric.keys.cache_size)
        return zenoh.ext.declare_advanced_publisher(
            session,
            key,
            cache=zenoh.ext.CacheConfig(max_samples=kept),
            publisher_detection=True,
            sample_miss_detection=zenoh.ext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=None),
            **options,
        )
    # the cache and token are what fabric/history.py asks a late joiner's latest value of; the sequence
    # numbers let a zenoh advanced subscriber elsewhere (not ours) track each publisher on its own
    # state, not a stream: a full queue waits rather than dropping it (a dropped map is never resent)
    options.setdefault("congestion_control", zenoh.CongestionControl.BLOCK)
    return zenoh.ext.declare_advanced_publisher(
        session,
        key,
        cache=zenoh.ext.CacheConfig(max_samples=1),
        publisher_detection=True,
        sample_miss_detection=zenoh.ext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=None),
        **options,
    )
