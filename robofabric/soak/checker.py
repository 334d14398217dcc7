"""The soak's checker: reads a history (:mod:`robofabric.soak.history`) and lists what must never happen.

Pure: records in, violations out; time is the records' own ``t``. Each violation carries the shortest
excerpt of the history that shows it (two to four records), so a reader can judge it without the rest.

The observer is a client of the router like everyone else: while the router restarts it hears nothing live, and
catches up when its link is back on the ownership records and the ownership and reject events it missed (their
publishers keep the last ones: :func:`fabric.keys.cache_size`). Those stretches (:func:`blind`) are named in the
summary; an owner change across one is judged when its records all came (consecutive epochs: every change bumps
the epoch), and only one whose records were missed there (the authority that kept them gone with its process) is
not judged by ``handover`` nor ``queue`` (whose verdicts rest on events and the robot's motion then): it is counted
as not judged instead, and the summary says so; and ``reset`` allows a robot across a fail-over the motion it could make while the
observer was blind.

The wire's view is fenced as every consumer fences it: a record or a joint sample with a lower term than
one already seen for its object is a stale authority's (a primary that was paused or cut off and has not
stepped down yet), which consumers drop (:mod:`fabric.fencing`); the invariants are about what they act on.

Invariants (each a function ``(history, limits) -> violations``, named in :data:`INVARIANTS`):

* ``owners``: never two owners of one object at one epoch; an object's epoch never goes back;
* ``applied``: a robot never reaches a target that only a command its sender could not give asked for
  (a command whose (user, epoch) was not the record's when it came, with a target at least
  ``poison_gap`` from every target an owner asked for): such a command was applied;
* ``reset``: joints never jump: between two samples of one sim they move at most ``joint_speed`` times the
  time between them (the sim's or the observer's, the longer) plus ``joint_slack``; across a change of sim (a
  fail-over) at most ``joint_slack``;
* ``handover``: an owner loses her robot only when she released it, was gone past her grace (the
  authority's ``own_expired``, or a handover or release it made for her), or when the robot was still and
  someone took it over;
* ``queue``: users waiting for an object keep their order, and nobody is skipped who still waits;
* ``unowned_motion``: a robot does not move when nobody owns it (``settle_s`` after its owner went; a grant the
  observer heard after the joints it caused, as its owner's command at the new epoch heard about then shows, is not
  "nobody");
* ``resources``: after warm-up (the run's, and as long again for a peer restarted during it), each peer's memory grows at most ``mem_mb_per_h``, its threads and file
  descriptors at most ``thread_slack``/``fd_slack`` above their first half's peak, its log at most
  ``log_mb_per_h`` (judged on windows of at least ``min_window_s``);
* ``exits``: no peer ended unless the nemesis or the end of the run ended it.
"""

from __future__ import annotations

import bisect
from collections import Counter, defaultdict
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

from fabric.interfaces import EventKind
from robofabric.soak.history import Cmd, Fault, Joints, Mark, OwnEvent, OwnRec, ProcExit, ProcSample, Record

__all__ = [
    "Limits",
    "Violation",
    "INVARIANTS",
    "blind",
    "check",
    "fenced",
    "fmt",
    "memory_judged",
    "not_judged",
    "summary",
]


@dataclass(frozen=True, slots=True)
class Limits:
    """The checker's bounds (see the module docstring)."""

    joint_speed: float = 3.0
    joint_slack: float = 0.15
    settle_s: float = 2.0
    justify_s: float = 5.0
    poison_gap: float = 0.2
    poison_reach: float = 0.08
    poison_window_s: float = 30.0
    moving: float = 0.02
    mem_mb_per_h: float = 20.0
    thread_slack: int = 8
    fd_slack: int = 16
    log_mb_per_h: float = 10.0
    min_window_s: float = 600.0
    blind_margin_s: float = 0.5
    """How long after the observer hears the wire again (a router restarted) it may still miss what a peer sends:
    each of its subscriptions reaches the new router on its own."""
    restart_warm_s: float = 60.0
    """The least warm-up of a peer started during the run (a restart); it gets the run's own warm-up if longer."""
    order_s: float = 0.5
    """How much later than a robot's joints the observer may hear the grant that moved it (records, commands and
    joints come by different routes and priorities: the soak heard an owner's command at her new epoch, then the
    moving joints, then the record of her grant, in one 3 ms burst)."""


@dataclass(frozen=True, slots=True)
class Violation:
    invariant: str
    message: str
    excerpt: tuple[Record, ...]

    def __str__(self) -> str:
        lines = [f"VIOLATION {self.invariant}: {self.message}"]
        lines += [f"    {fmt(r)}" for r in self.excerpt]
        return "\n".join(lines)


def fmt(r: Record) -> str:
    """One line for a record in an excerpt."""
    if isinstance(r, OwnRec):
        q = f" queue={list(r.queue)}" if r.queue else ""
        return f"t={r.t:.3f} record {r.obj}: owner={r.owner or '-'} epoch={r.epoch}{q} {r.state} (by {r.source} term {r.term})"
    if isinstance(r, OwnEvent):
        return f"t={r.t:.3f} event {r.kind} {r.obj} user={r.user}: {r.reason}"
    if isinstance(r, Cmd):
        q = f" q={_q(r.q)}" if r.q else ""
        return f"t={r.t:.3f} command {r.name} to {r.robot} from {r.user} epoch {r.epoch}{q}"
    if isinstance(r, Joints):
        return f"t={r.t:.3f} joints {r.robot} q={_q(r.q)} sim time {r.s:.3f} (by {r.source} term {r.term})"
    if isinstance(r, Fault):
        return f"t={r.t:.3f} fault {r.kind} {r.target} until t={r.until:.3f} {r.detail}".rstrip()
    if isinstance(r, ProcSample):
        return f"t={r.t:.3f} {r.name} pid {r.pid}: {r.rss_mb:.1f} MB, {r.threads} threads, {r.fds} fds, log {r.log_bytes} B"
    if isinstance(r, ProcExit):
        return (
            f"t={r.t:.3f} {r.name} pid {r.pid} exited {r.code}{' (expected)' if r.expected else ''} {r.tail[-200:]!r}"
        )
    if isinstance(r, Mark):
        return f"t={r.t:.3f} mark {r.what} {r.detail}".rstrip()
    return f"t={r.t:.3f} {r!r}"


def _q(q: Sequence[float]) -> str:
    return "[" + ", ".join(f"{x:.3f}" for x in q) + "]"


def _dist(a: Sequence[float], b: Sequence[float]) -> float:
    if len(a) != len(b):
        return float("inf")
    return max((abs(x - y) for x, y in zip(a, b)), default=0.0)


# ---------------------------------------------------------------------- the fenced view


def fenced(history: Iterable[Record]) -> tuple[dict[str, list[OwnRec]], dict[str, list[Joints]]]:
    """The records and joints a fenced consumer acts on, per object and per robot, in time order."""
    recs: dict[str, list[OwnRec]] = defaultdict(list)
    joints: dict[str, list[Joints]] = defaultdict(list)
    top: dict[tuple[str, str], int] = {}
    for r in history:
        if isinstance(r, OwnRec):
            key, into = ("own", r.obj), recs[r.obj]
        elif isinstance(r, Joints):
            key, into = ("joints", r.robot), joints[r.robot]
        else:
            continue
        if r.term < top.get(key, 0):
            continue
        top[key] = r.term
        into.append(r)  # type: ignore[arg-type]
    return dict(recs), dict(joints)


class _Timeline:
    """The record of each object in force at any time."""

    def __init__(self, recs: dict[str, list[OwnRec]]) -> None:
        self.recs = recs
        self.times = {o: [r.t for r in rs] for o, rs in recs.items()}

    def at(self, obj: str, t: float) -> OwnRec | None:
        times = self.times.get(obj)
        if not times:
            return None
        i = bisect.bisect_right(times, t) - 1
        return self.recs[obj][i] if i >= 0 else None

    def next_after(self, obj: str, t: float) -> OwnRec | None:
        """The first record of ``obj`` heard after ``t``."""
        times = self.times.get(obj)
        if not times:
            return None
        i = bisect.bisect_right(times, t)
        return self.recs[obj][i] if i < len(times) else None

    def unowned_since(self, obj: str, t: float) -> float | None:
        """Since when ``obj`` has had no owner at ``t`` (None: it has one, or no record yet)."""
        times = self.times.get(obj)
        if not times:
            return None
        i = bisect.bisect_right(times, t) - 1
        if i < 0 or self.recs[obj][i].owner:
            return None
        while i > 0 and not self.recs[obj][i - 1].owner:
            i -= 1
        return self.recs[obj][i].t


# ---------------------------------------------------------------------- invariants


def owners(h: Sequence[Record], lim: Limits) -> list[Violation]:
    recs, _ = fenced(h)
    out = []
    for obj, rs in recs.items():
        at_epoch: dict[int, OwnRec] = {}
        top: OwnRec | None = None
        for r in rs:
            if top is not None and r.epoch < top.epoch:
                out.append(Violation("owners", f"{obj}'s epoch went back from {top.epoch} to {r.epoch}", (top, r)))
            if top is None or r.epoch >= top.epoch:
                top = r
            first = at_epoch.get(r.epoch)
            if first is None or not first.owner:
                at_epoch[r.epoch] = r
            elif r.owner and r.owner != first.owner:
                out.append(
                    Violation(
                        "owners", f"{obj} has two owners at epoch {r.epoch}: {first.owner} and {r.owner}", (first, r)
                    )
                )
    return out


def applied(h: Sequence[Record], lim: Limits) -> list[Violation]:
    recs, joints = fenced(h)
    tl = _Timeline(recs)
    cmds = [r for r in h if isinstance(r, Cmd) and r.q]
    ok_targets: dict[str, list[tuple[float, ...]]] = defaultdict(list)
    bad: list[tuple[Cmd, OwnRec | None]] = []
    for c in cmds:
        rec = tl.at(c.robot, c.t)
        if rec is not None and rec.owner == c.user and rec.epoch == c.epoch:
            ok_targets[c.robot].append(c.q)
        else:
            bad.append((c, rec))
    out = []
    for c, rec in bad:
        if any(_dist(c.q, q) < lim.poison_gap for q in ok_targets[c.robot]):
            continue  # an owner asked for (nearly) the same: reaching it proves nothing
        js = joints.get(c.robot, [])
        i = bisect.bisect_right([j.t for j in js], c.t)
        before = js[i - 1] if i > 0 else None
        if before is not None and _dist(before.q, c.q) < lim.poison_gap:
            continue  # it was there already
        for j in js[i:]:
            if j.t > c.t + lim.poison_window_s:
                break
            if _dist(j.q, c.q) < lim.poison_reach:
                who = f"owner {rec.owner or 'nobody'} epoch {rec.epoch}" if rec else "no record yet"
                ex = tuple(x for x in (rec, c, before, j) if x is not None)
                out.append(
                    Violation(
                        "applied",
                        f"{c.robot} reached the target of {c.user}'s command at epoch {c.epoch} "
                        f"while the record said {who}: the sim applied it",
                        ex,
                    )
                )
                break
    return out


def reset(h: Sequence[Record], lim: Limits) -> list[Violation]:
    _, joints = fenced(h)
    windows = blind(h, lim)
    out = []
    for robot, js in joints.items():
        for a, b in zip(js, js[1:]):
            same = a.source == b.source and a.term == b.term
            # the sim's own time between them, or the observer's when longer: a loaded observer takes samples in bursts;
            # across a fail-over, only what the robot did while the observer was blind (the old sim's last samples and
            # the new one's first may be lost then)
            unseen = sum(max(0.0, min(b.t, y) - max(a.t, x)) for x, y in windows)
            allowed = lim.joint_slack + lim.joint_speed * (max(0.0, b.t - a.t, b.s - a.s) if same else unseen)
            d = _dist(a.q, b.q)
            if d > allowed:
                how = "between two samples of one sim" if same else f"across the change from {a.source} to {b.source}"
                out.append(
                    Violation("reset", f"{robot}'s joints jumped {d:.3f} rad {how} (at most {allowed:.3f})", (a, b))
                )
    return out


def blind(h: Sequence[Record], lim: Limits = Limits()) -> list[tuple[float, float]]:
    """When the observer heard nothing of the wire: from each router restart until the first thing it heard after
    the restart ended, and ``blind_margin_s`` more."""
    heard = sorted(r.t for r in h if isinstance(r, (OwnRec, OwnEvent, Cmd, Joints)))
    out = []
    for f in h:
        if isinstance(f, Fault) and f.kind == "router":
            i = bisect.bisect_right(heard, f.until)
            out.append((f.t, (heard[i] if i < len(heard) else float("inf")) + lim.blind_margin_s))
    return out


def _across(prev: OwnRec, cur: OwnRec, windows: list[tuple[float, float]]) -> bool:
    """Whether the change from ``prev`` to ``cur`` is out of sight: it spans a blind stretch and records were missed
    there (every change bumps the epoch, so a gap of more than one shows it). The observer catches up on the
    records and events it missed (:mod:`robofabric.soak.observer`): a change whose records all came is judged."""
    return cur.epoch - prev.epoch > 1 and any(a < cur.t and b > prev.t for a, b in windows)


def not_judged(h: Sequence[Record], lim: Limits = Limits()) -> int:
    """How many owner changes fell in the observer's blind stretches with records missed there (``handover`` and
    ``queue`` do not judge them)."""
    recs, _ = fenced(h)
    windows = blind(h, lim)
    return sum(
        1
        for rs in recs.values()
        for prev, cur in zip(rs, rs[1:])
        if cur.owner != prev.owner and _across(prev, cur, windows)
    )


def _explained(prev: OwnRec, cur: OwnRec, events: list[OwnEvent], lim: Limits) -> bool:
    if prev.state == "still" and cur.owner:
        return True  # a still robot taken over
    a = prev.owner
    for e in events:
        if e.obj != prev.obj or not (prev.t - lim.justify_s <= e.t <= cur.t + lim.justify_s):
            continue
        if e.kind in (EventKind.OWN_RELEASED, EventKind.OWN_EXPIRED) and e.user == a:
            return True
        if e.kind == EventKind.OWN_HANDOVER and e.reason.endswith(f" by {a}"):
            return True
        if e.kind == EventKind.OWN_REVOKED and e.user == a and "while still" in e.reason:
            return True
    return False


def handover(h: Sequence[Record], lim: Limits) -> list[Violation]:
    recs, _ = fenced(h)
    events = [r for r in h if isinstance(r, OwnEvent)]
    windows = blind(h, lim)
    out = []
    for obj, rs in recs.items():
        for prev, cur in zip(rs, rs[1:]):
            if (
                prev.owner
                and cur.owner != prev.owner
                and not _explained(prev, cur, events, lim)
                and not _across(prev, cur, windows)
            ):
                out.append(
                    Violation(
                        "handover",
                        f"{obj} left {prev.owner} for {cur.owner or 'nobody'} while "
                        f"{prev.state}, and the authority said no release, expiry or take-over",
                        (prev, cur),
                    )
                )
    return out


def _passed_on(prev: OwnRec, cur: OwnRec, events: list[OwnEvent], lim: Limits) -> bool:
    """The authority passed ``prev``'s robot on (her release, expiry or a handover), as opposed to a take-over of
    a still robot, which goes to whoever asked, queued or not."""
    for e in events:
        if e.obj != prev.obj or not (prev.t - lim.justify_s <= e.t <= cur.t + lim.justify_s):
            continue
        if e.kind in (EventKind.OWN_RELEASED, EventKind.OWN_EXPIRED) and e.user == prev.owner:
            return True
        if e.kind == EventKind.OWN_HANDOVER and e.reason.endswith(f" by {prev.owner}"):
            return True
    return False


def queue(h: Sequence[Record], lim: Limits) -> list[Violation]:
    recs, _ = fenced(h)
    events = [r for r in h if isinstance(r, OwnEvent)]
    windows = blind(h, lim)
    out = []
    for obj, rs in recs.items():
        for prev, cur in zip(rs, rs[1:]):
            both = [u for u in prev.queue if u in cur.queue]
            if both != [u for u in cur.queue if u in prev.queue]:
                out.append(
                    Violation(
                        "queue", f"{obj}'s queue changed order: {list(prev.queue)} then {list(cur.queue)}", (prev, cur)
                    )
                )
            elif (
                cur.owner != prev.owner
                and cur.owner in prev.queue
                and not _across(prev, cur, windows)
                and (prev.state != "still" or not prev.owner or _passed_on(prev, cur, events, lim))
            ):
                ahead = [u for u in prev.queue[: prev.queue.index(cur.owner)] if u in cur.queue]
                if ahead:
                    out.append(
                        Violation(
                            "queue",
                            f"{obj} went to {cur.owner} ahead of {', '.join(ahead)}, who still wait",
                            (prev, cur),
                        )
                    )
    return out


def unowned_motion(h: Sequence[Record], lim: Limits) -> list[Violation]:
    recs, joints = fenced(h)
    tl = _Timeline(recs)
    cmds: dict[str, list[Cmd]] = defaultdict(list)
    for r in h:
        if isinstance(r, Cmd):
            cmds[r.robot].append(r)
    out = []
    for robot, js in joints.items():
        for a, b in zip(js, js[1:]):
            if _dist(a.q, b.q) < lim.moving:
                continue
            since = tl.unowned_since(robot, b.t)  # nobody owned it from ``since`` through the whole step
            if (
                since is not None
                and a.t - since > lim.settle_s
                and not _grant_heard_late(tl, cmds[robot], robot, b.t, lim)
            ):
                rec = tl.at(robot, b.t)
                out.append(
                    Violation(
                        "unowned_motion",
                        f"{robot} moved {_dist(a.q, b.q):.3f} rad with no owner "
                        f"({a.t - since:.1f} s after its owner went)",
                        tuple(x for x in (rec, a, b) if x is not None),
                    )
                )
                break  # one per robot tells it
    return out


def _grant_heard_late(tl: _Timeline, cmds: Sequence[Cmd], robot: str, t: float, lim: Limits) -> bool:
    """Whether the robot had an owner at ``t`` whose grant the observer heard only after its joints: the robot's next
    record, within ``order_s``, names an owner at a newer epoch, and a command of hers at that epoch was heard within
    ``order_s`` of ``t`` (a user stamps only an epoch she was granted, so the grant came first). Her command may be
    heard after the joints it moved too: it reaches the observer by her own link, the joints by the sim's (the
    two-minute soak heard the moving joints, then 6 ms later her command and the record of her grant, at load 13)."""
    nxt = tl.next_after(robot, t)
    if nxt is None or not nxt.owner or nxt.t - t > lim.order_s:
        return False
    return any(c.user == nxt.owner and c.epoch == nxt.epoch and abs(c.t - t) <= lim.order_s for c in cmds)


def _slope_per_h(pts: list[tuple[float, float]]) -> float:
    n = len(pts)
    mt = sum(t for t, _ in pts) / n
    mv = sum(v for _, v in pts) / n
    den = sum((t - mt) ** 2 for t, _ in pts)
    return 0.0 if den == 0 else sum((t - mt) * (v - mv) for t, v in pts) / den * 3600.0


def _judged_windows(h: Sequence[Record], lim: Limits) -> dict[tuple[str, int], list[ProcSample]]:
    """Each peer incarnation's samples after its warm-up, where they span enough to be judged (``min_window_s``)."""
    warm = next((r.t for r in h if isinstance(r, Mark) and r.what == "warm"), None)
    if warm is None:
        return {}
    began = next((r.t for r in h if isinstance(r, Mark) and r.what in ("class", "start")), warm)
    warm_s = max(lim.restart_warm_s, warm - began)  # every incarnation of a peer warms up as long as the run did
    groups: dict[tuple[str, int], list[ProcSample]] = defaultdict(list)
    for r in h:
        if isinstance(r, ProcSample):
            groups[(r.name, r.pid)].append(r)
    out = {}
    for key, ss in groups.items():
        start = max(warm, ss[0].t + warm_s)
        win = [s for s in ss if s.t >= start]
        if len(win) >= 4 and win[-1].t - win[0].t >= lim.min_window_s:
            out[key] = win
    return out


def memory_judged(h: Sequence[Record], lim: Limits = Limits()) -> list[str]:
    """Whose memory ``resources`` judged, and on how long a window: one entry a peer (its longest-lived incarnation),
    the others named as not judged (each incarnation too short: a peer the nemesis kills often)."""
    wins = _judged_windows(h, lim)
    best: dict[str, list[ProcSample]] = {}
    for (name, _), win in wins.items():
        if name not in best or win[-1].t - win[0].t > best[name][-1].t - best[name][0].t:
            best[name] = win
    names = sorted({r.name for r in h if isinstance(r, ProcSample)})
    return [
        f"{n} {_slope_per_h([(s.t, s.rss_mb) for s in best[n]]):+.1f} MB/h over {(best[n][-1].t - best[n][0].t) / 60:.0f} min"
        if n in best
        else f"{n} not judged (no incarnation lived past its warm-up long enough)"
        for n in names
    ]


def resources(h: Sequence[Record], lim: Limits) -> list[Violation]:
    out = []
    for (name, _pid), win in _judged_windows(h, lim).items():
        hours = (win[-1].t - win[0].t) / 3600.0
        slope = _slope_per_h([(s.t, s.rss_mb) for s in win])
        if slope > lim.mem_mb_per_h:
            out.append(
                Violation(
                    "resources",
                    f"{name}'s memory grew {slope:.1f} MB/h after warm-up (at most {lim.mem_mb_per_h:g})",
                    (win[0], max(win, key=lambda s: s.rss_mb), win[-1]),
                )
            )
        half = len(win) // 2
        for what, slack in (("threads", lim.thread_slack), ("fds", lim.fd_slack)):
            first = max(win[:half], key=lambda s: getattr(s, what))
            last = max(win[half:], key=lambda s: getattr(s, what))
            if getattr(last, what) > getattr(first, what) + slack:
                out.append(
                    Violation(
                        "resources",
                        f"{name}'s {what} rose from {getattr(first, what)} to {getattr(last, what)} "
                        f"(at most {slack} more)",
                        (first, last),
                    )
                )
        grew = (win[-1].log_bytes - win[0].log_bytes) / 1e6 / hours
        if grew > lim.log_mb_per_h:
            out.append(
                Violation(
                    "resources", f"{name}'s log grew {grew:.1f} MB/h (at most {lim.log_mb_per_h:g})", (win[0], win[-1])
                )
            )
    return out


def exits(h: Sequence[Record], lim: Limits) -> list[Violation]:
    return [
        Violation("exits", f"{r.name} (pid {r.pid}) ended with {r.code} and nobody ended it", (r,))
        for r in h
        if isinstance(r, ProcExit) and not r.expected
    ]


INVARIANTS: dict[str, Callable[[Sequence[Record], Limits], list[Violation]]] = {
    "owners": owners,
    "applied": applied,
    "reset": reset,
    "handover": handover,
    "queue": queue,
    "unowned_motion": unowned_motion,
    "resources": resources,
    "exits": exits,
}


def check(history: Sequence[Record], limits: Limits = Limits()) -> list[Violation]:
    """Every violation of every invariant, in the order of :data:`INVARIANTS`; ``history`` sorted by ``t``."""
    out: list[Violation] = []
    for inv in INVARIANTS.values():
        out += inv(history, limits)
    return out


def summary(history: Sequence[Record], violations: Sequence[Violation], limits: Limits = Limits()) -> list[str]:
    """The run's last lines: what the observer could not see, whose memory was judged (``memory: ...``), then ``faults: N``, ``fault kinds: K`` (with the count
    of each) and ``violations: V``."""
    kinds = Counter(r.kind for r in history if isinstance(r, Fault))
    by_inv = Counter(v.invariant for v in violations)
    windows = blind(history, limits)
    shut = sum(min(b, history[-1].t if history else b) - a for a, b in windows)
    missed = not_judged(history, limits)
    lines = [
        f"observer blind: {len(windows)} router restarts, {shut:.1f} s in all; not judged: {missed}"
        + (" (owner changes whose records the observer missed there and did not catch up on)" if missed else ""),
        "memory: " + ("; ".join(memory_judged(history, limits)) or "no samples"),
        f"faults: {sum(kinds.values())}",
        f"fault kinds: {len(kinds)} ({', '.join(f'{k} {n}' for k, n in sorted(kinds.items()))})"
        if kinds
        else "fault kinds: 0",
        f"violations: {len(violations)}"
        + (f" ({', '.join(f'{k} {n}' for k, n in sorted(by_inv.items()))})" if by_inv else ""),
    ]
    return lines
