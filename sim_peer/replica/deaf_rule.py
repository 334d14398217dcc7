"""When a primary that hears no one holds its robots, and when it lets them go: a pure core.

:class:`sim_peer.replica.deaf_stop.DeafStop` looks every few tens of milliseconds and feeds each look to :func:`step`
(:class:`Look`: whether the robots are held now, whether this sim is cut off or was just frozen, its heartbeat, the
time); :func:`step` answers with the new :class:`DeafState` and the effects to carry out (:class:`Hold`,
:class:`Resume`, :class:`WasLate`). No zenoh, no lock, no clock: the one question that needs the network, whether
this sim's router answers, is asked by the shell only when :func:`must_ask` says so, and its answer comes back in
the look (``answered_at``).

The rules (docs/sim.md, "A primary that hears no one"):

- a primary cut off (:func:`sim_peer.replica.hearing_rule.cut`: its link down, or its own token gone) holds its robots;
- one that was only late (:func:`sim_peer.replica.hearing_rule.frozen`) holds them only if its router does not answer: an
  answer proves the link for the freeze it follows (a new freeze, a new cut or the own token going again needs a
  new one), and while the heartbeat is late right now, for :data:`PROOF_S` only;
- a held primary that hears again resumes (its robots stay where they stopped);
- a freeze that ended with the router answering, nothing held, is told once (:class:`WasLate`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from sim_peer.replica.hearing_rule import Heartbeat

__all__ = [
    "DeafState",
    "Look",
    "Hold",
    "Resume",
    "WasLate",
    "DeafEffect",
    "PROOF_S",
    "proven",
    "must_ask",
    "why",
    "step",
]

PROOF_S = 0.5
"""How long a router's answer proves the link while the heartbeat is late right now (a starved process)."""

_NEVER = float("-inf")


@dataclass(frozen=True, slots=True)
class DeafState:
    """What the deaf stop remembers: how many times it held the robots, how many freezes ended with the router
    answering (nothing held), when the router last answered, and which freeze (its ``thawed_at``) was last told."""

    holds: int = 0
    lates: int = 0
    proven_at: float = _NEVER
    told_thaw: float = _NEVER


@dataclass(frozen=True, slots=True)
class Look:
    """One look of a serving primary at itself, at ``now`` (monotonic seconds)."""

    now: float
    held: bool
    """Whether its robots are held now (its command pipeline refuses commands)."""
    cut: str
    """Why its link is gone ('' : it is not; :func:`sim_peer.replica.hearing_rule.cut`)."""
    frozen: bool
    """Whether it was just frozen (:func:`sim_peer.replica.hearing_rule.frozen`)."""
    beat: Heartbeat
    own_gone_at: float
    """When the router last dropped its own token (-inf: never)."""
    lease: float
    """The transport lease, seconds."""
    answered_at: float | None = None
    """When its router answered, if it was asked (:func:`must_ask`) and answered; None otherwise."""


@dataclass(frozen=True, slots=True)
class Hold:
    """Stop every robot as a release does and refuse commands, because ``why``."""

    why: str


@dataclass(frozen=True, slots=True)
class Resume:
    """Take commands again (the robots stay where they stopped)."""


@dataclass(frozen=True, slots=True)
class WasLate:
    """A freeze of ``late_s`` seconds ended with the router answering: nothing was held; say so."""

    late_s: float


DeafEffect = Hold | Resume | WasLate


def proven(s: DeafState, look: Look) -> bool:
    """Whether the router answered since the last freeze, the last cut and the own token's last loss (within
    :data:`PROOF_S` while the heartbeat is late right now)."""
    beat = look.beat
    since = max(beat.thawed_at, beat.unlinked_at, look.own_gone_at)
    if look.now - beat.last_tick > look.lease / 2:
        since = max(since, look.now - PROOF_S)
    return s.proven_at > since


def must_ask(s: DeafState, look: Look) -> bool:
    """Whether the router must be asked before :func:`step` decides: not cut, just frozen, and not proven yet."""
    return not look.cut and look.frozen and not proven(s, look)


def why(s: DeafState, look: Look) -> str:
    """Why this primary hears no one now ('' : it hears): cut off, or late and its router did not answer."""
    if look.cut:
        return look.cut
    if must_ask(s, look) and look.answered_at is None:
        return f"frozen or starved {look.beat.late_s:.1f} s, and its router does not answer"
    return ""


def step(s: DeafState, look: Look) -> tuple[DeafState, list[DeafEffect]]:
    """Apply one look: hold the robots if this primary hears no one and they are not held, resume them if it hears
    and they are, tell a freeze that ended with the router answering once."""
    reason = why(s, look)
    if must_ask(s, look) and look.answered_at is not None:
        s = replace(s, proven_at=look.answered_at)  # the router holds it: nobody took the world meanwhile
    thaw = look.beat.thawed_at
    if reason and not look.held:
        return replace(s, holds=s.holds + 1), [Hold(reason)]
    if look.held and not reason:
        return replace(s, told_thaw=thaw), [Resume()]
    if not reason and thaw > s.told_thaw and s.proven_at > thaw:
        return replace(s, told_thaw=thaw, lates=s.lates + 1), [WasLate(look.beat.late_s)]
    return s, []
