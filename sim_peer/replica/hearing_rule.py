"""Whether a sim hears its world, and when its view of the live sims may be trusted: a pure core.

:class:`sim_peer.replica.roles.Roles` feeds it what the process observes (its own heartbeat's ticks, the link's state,
its own token, when each sim was last heard) with the time passed in; it answers with values, no zenoh, no lock, no
clock, so the same code runs in the sim and in hypothesis property tests.

The decisions:

- **a freeze** (:func:`tick`, :func:`frozen`): a gap between two heartbeats longer than half a lease is a freeze
  (SIGSTOP, a starved process). A standby paused past the lease wakes with a link the router dropped and a stale
  state; the tokens it sees go before its session reconnects, and it must not read that as its leader's death. The
  distrust lasts a lease and as long again as the freeze was (up to five leases): a session that slept through the
  router dropping it reads its link's news late (a standby paused 4 s read its leader's token gone more than a
  lease after it woke, link up, and took the world over from no state).
- **a cut** (:func:`cut`): the link is down, or the router no longer holds this sim's own token (for
  :data:`OWN_TOKEN_S` at most: a link that is up hears the router again). A freeze alone is not a cut.
- **a lost token judged** (:func:`unlinked_since`): a sim's token lost while this sim's own link went down (or its
  own token went) at about the same time went with the link, not with the sim.
- **the wait after deafness** (:func:`recheck`): once the link and the own token are back, a window of
  :data:`RECHECK_LEASES` leases (and half a second) for the live sims' tokens to come back, started again by a new
  cut.
- **the audible sims** (:func:`audible`): those heard within :data:`AUDIBLE_S`, while the view of the tokens may
  still be arriving, and a leader heard whose token was never seen.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace

__all__ = [
    "Heartbeat",
    "tick",
    "frozen",
    "cut",
    "unlinked_since",
    "recently_unlinked",
    "recheck",
    "recheck_window",
    "audible",
    "gone_since",
    "AUDIBLE_S",
    "RECHECK_LEASES",
    "freeze_words",
    "OWN_TOKEN_S",
    "TICK_S",
    "NOT_YET",
]

AUDIBLE_S = 1.0
"""How recently a sim was heard (its term on a stream or ``srv/state``) for it to count as alive, whatever its
token, while this host's view of the tokens is fresh (:func:`audible`). A live leader's streams (joints at the
sim's rate, about 100 a second, and ``srv/state`` every 50 ms) speak well inside it, even on a loaded machine."""
RECHECK_LEASES = 3
"""Leases a sim whose link came back waits for the others' tokens before the election looks: after a router's
restart every client reconnects on its own schedule (seconds apart), the leader's token among them."""
OWN_TOKEN_S = 10.0
"""How long our own token's absence, with the link up, still counts as deafness (its return is the usual end)."""
TICK_S = 0.1
"""The heartbeat's period."""
NOT_YET = float("inf")
"""The end of a recheck window that has not started (this sim does not hear yet)."""

_NEVER = float("-inf")


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """This process's own heartbeat: when it last ticked, when it last came back from a freeze and how long that
    was, when a tick last found the link down (all monotonic seconds; -inf: never)."""

    last_tick: float = _NEVER
    thawed_at: float = _NEVER
    late_s: float = 0.0
    unlinked_at: float = _NEVER


def tick(beat: Heartbeat, now: float, *, gap: float, connected: bool) -> Heartbeat:
    """One heartbeat at ``now``: a gap since the last longer than ``gap`` (half a lease) is a freeze that ended now;
    a tick that finds the link down marks when."""
    if now - beat.last_tick > gap and beat.last_tick != _NEVER:
        beat = replace(beat, thawed_at=now, late_s=now - beat.last_tick)
    beat = replace(beat, last_tick=now)
    return beat if connected else replace(beat, unlinked_at=now)


def frozen(beat: Heartbeat, now: float, lease: float) -> bool:
    """Whether this process was frozen just now: its heartbeat is late (more than half a lease), or came back from a
    gap within the last lease plus as long again as the gap was (up to five leases). Never before the first tick."""
    if beat.last_tick == _NEVER:
        return False
    return now - beat.last_tick > lease / 2 or now - beat.thawed_at < lease + min(beat.late_s, 5 * lease)


def freeze_words(beat: Heartbeat, now: float, lease: float) -> str:
    """Why :func:`frozen` holds, in a log's words ('' : it does not): the heartbeat late now, or lately back from a
    gap. A standby that reads a token loss then waits before it takes over; its log must say it froze, not that it
    was cut off (a starved heir read as "its link or its own token gone" for 7 s, its link up all along)."""
    if not frozen(beat, now, lease):
        return ""
    if now - beat.last_tick > lease / 2:
        return f"frozen: its heartbeat is {now - beat.last_tick:.1f} s late"
    return f"frozen: its heartbeat came {beat.late_s:.1f} s late {now - beat.thawed_at:.1f} s ago"


def cut(*, connected: bool, own_token_seen: bool, own_gone_at: float, now: float) -> str:
    """Why this sim's link is gone now ('' : it is not): the link is down, or the router no longer holds its own
    token (which counts for :data:`OWN_TOKEN_S` at most)."""
    if not connected:
        return "its link is down"
    mine = own_token_seen or now - own_gone_at > OWN_TOKEN_S
    return "" if mine else "the router no longer holds its token"


def unlinked_since(beat: Heartbeat, own_gone_at: float, lost_at: float) -> bool:
    """Whether the link went down, or this sim's own token went, since about ``lost_at`` (two heartbeats before it):
    a sim's token lost then went with this sim's link, not with that sim."""
    return max(beat.unlinked_at, own_gone_at) >= lost_at - 2 * TICK_S


def recently_unlinked(beat: Heartbeat, now: float) -> bool:
    """Whether a heartbeat found the link down within the last two heartbeats."""
    return now - beat.unlinked_at < 2 * TICK_S


def recheck_window(lease: float) -> float:
    """How long a sim that hears again waits for the live sims' tokens before the election looks."""
    return RECHECK_LEASES * lease + 0.5


def recheck(back: float, now: float, *, deaf: bool, window: float) -> float:
    """The end of the wait after deafness, as of ``now``: :data:`NOT_YET` while this sim is deaf (again), else the end
    already set, or ``now + window`` when it just began to hear. The wait is over when ``now >= back``."""
    if deaf:
        return NOT_YET
    return now + window if back == NOT_YET else back


def audible(
    heard_at: Mapping[str, float],
    now: float,
    *,
    fresh_until: float,
    relooking: bool,
    unseen: Iterable[str] = (),
) -> frozenset[str]:
    """The sims heard within :data:`AUDIBLE_S`, while the tokens seen may still be arriving (``now`` before
    ``fresh_until``, or a leader already found missing but heard: ``relooking``); else only those of ``unseen``
    (a leader whose token this sim never saw since it follows it: a fresh session's first view can lack a live
    sim's token that has not reached it yet, and a token never seen says nothing of a death), and a token's loss
    is trusted at once."""
    heard = frozenset(p for p, t in heard_at.items() if now - t < AUDIBLE_S)
    if now > fresh_until and not relooking:
        return heard & frozenset(unseen)
    return heard


def gone_since(live: Iterable[str], gone_at: Mapping[str, float], began: float) -> frozenset[str]:
    """The sims alive now or whose token went at ``began`` or later (was it there when this sim froze?)."""
    return frozenset(live) | {p for p, t in gone_at.items() if t >= began}
