"""The ownership authority: hosted by the sim peer, the only writer of ``rf/{world}/own/{object}``.

It runs :mod:`ownership.state` behind one lock, serves requests/releases/renewals
and record queries on ``rf/{world}/own/{object}``, follows users' liveliness
tokens, ticks leases on its own thread, and gates commands by (user, epoch).
It never touches the simulation: when a robot loses its owner (a release, a handover, a take-over, the
end of her lease, her departure) it tells whoever watches (:meth:`Authority.watch_stops`: the sim), which
stops the robot, before anyone hears of the new owner.
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace
import functools
import logging
import threading
from types import MappingProxyType
from typing import Any, Callable

from fabric import keys
from fabric.interfaces import Command, Event, EventKind, OwnershipRecord, OwnReply, OwnRequest, ServiceError
from fabric.limits import MAX_USER_LEN, is_valid_user, quote
from fabric.plant import check as check_plant
from fabric.rate import Clock, MonotonicClock
from fabric.session import Fabric, undeclare_all

from ownership import snapshot
from ownership.admission import Admission, OwnBudgets
from ownership import staff
from ownership import state as st
from ownership.hearing import CONFIRM_SLACK_S, Hearing

log = logging.getLogger("robofabric.ownership")

__all__ = ["Authority"]


class Authority:
    """A :class:`fabric.gate.CommandGate` backed by the ownership state machine.

    Constructing one publishes the records and serves them; leases tick only once it is started
    (``start()`` or ``with Authority(...) as auth:``), so a test or a standby can build one, look at
    it, and decide when time begins to count. ``close()`` (or leaving the ``with``) stops the ticks."""

    def __init__(
        self,
        fabric: Fabric,
        objects: dict[str, str],
        *,
        lease_s: float = 2.0,
        grace_s: float = 10.0,
        clock: Clock | None = None,
        tick_s: float | None = None,
        restored: tuple[Any, Any] | None = None,
        budgets: OwnBudgets | None = None,
        plant: str = "",
    ) -> None:
        """``restored``: ``(records, users)`` as :meth:`export_state` gave them on the authority this one
        replaces (a standby taking over): owners, epochs, queues and leases carry on. ``budgets``: each
        login's budgets of requests, renewals and queries (:mod:`ownership.admission`; defaults there).
        ``plant``: a test-only defect for the soak's checker (:mod:`fabric.plant`; "" in every real world)."""
        self.fabric = fabric
        self.clock = clock or MonotonicClock()
        self._lock = threading.RLock()
        if restored is None:
            self._state = st.initial(objects, lease_s=lease_s, grace_s=grace_s, authority=fabric.peer_id)
        else:
            self._state = snapshot.restore(
                restored[0], restored[1], self.clock.now(), lease_s=lease_s, grace_s=grace_s, authority=fabric.peer_id
            )
            missing = {o: p for o, p in objects.items() if o not in self._state.records}
            if missing:
                fresh = st.initial(missing, lease_s=lease_s, grace_s=grace_s, authority=fabric.peer_id)
                self._state = dataclasses.replace(
                    self._state, records=MappingProxyType({**self._state.records, **fresh.records})
                )
        self._plant = check_plant(plant)
        self._state = dataclasses.replace(self._state, plant=self._plant)
        self._tick_s = tick_s if tick_s is not None else min(0.02, lease_s / 10)
        self._stop = threading.Event()
        self._link_seen = fabric.link_changed_at()  # a change since the last tick: owners get a whole lease
        self.counters = {"requests": 0, "rejected": 0, "handovers": 0, "rate_limited": 0}

        def report(limit: str, make: Callable[[], Event]) -> None:
            if fabric.reports.should_report(limit) is not None:
                self._emit(replace(make(), header=fabric.header("event")))

        self.admission = Admission(
            budgets or OwnBudgets(), self.clock, self.counters, fabric_counters=fabric.counters, report=report
        )
        self._stop_watchers: list[Callable[[str, str, str], None]] = []
        self._reset_watchers: list[Callable[[str, str, str], None]] = []
        # users who may have left while no authority listened (a take-over) or while our link was down:
        # confirmed by their token within a lease of hearing again, else they leave (ownership.hearing)
        self.hearing = Hearing(lease_s, self.clock.now(), unconfirmed=self._state.live if restored is not None else ())
        self._watch = fabric.watch_peers(self._on_peer, kind="user")
        self._thread: threading.Thread | None = None
        # one queryable per object, so a wildcard query (a replica joining) gets one record from each;
        # requests come on the asker's own key (own/{obj}/by/{user}): the user is taken from the key,
        # where a router's access control vouches for it, never from the payload alone. Served before the
        # first records go out: a replica that hears one asks for the rest (ownership.client). Requests are worked
        # out on their own lane, renewals at once, each login within her budgets (ownership.admission)
        self._queryables = (
            [
                fabric.rpc.serve(
                    keys.own(fabric.world, obj), functools.partial(_answer_record, self, obj), expected=OwnRequest
                )
                for obj in objects
            ]
            + [
                fabric.rpc.serve(
                    keys.own_request_all(fabric.world, obj),
                    functools.partial(self._serve, obj),
                    expected=OwnRequest,
                    defer=self.admission.route,
                    gate=self.admission.gate,
                )
                for obj in objects
            ]
            + [
                fabric.rpc.serve(
                    keys.own_staff_all(fabric.world, obj),
                    functools.partial(_serve_staff, self, obj),
                    expected=OwnRequest,
                )
                for obj in objects
            ]
        )
        for obj in objects:
            self._publish(self._state.records[obj])

    def start(self) -> "Authority":
        """Start ticking leases on a daemon thread (once; a second call does nothing)."""
        with self._lock:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="ownership-tick", daemon=True)
                self._thread.start()
        return self

    def __enter__(self) -> "Authority":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ state

    def records(self) -> dict[str, OwnershipRecord]:
        with self._lock:
            return dict(self._state.records)

    def export_state(self) -> tuple[tuple[OwnershipRecord, ...], dict[str, Any]]:
        """The whole ownership state for a standby, times relative to now (:func:`ownership.snapshot.export`)."""
        with self._lock:
            return snapshot.export(self._state, self.clock.now())

    def _forget(self, gone: list[str]) -> None:
        """Users whose token did not show up again once this authority could hear (after a take-over, or
        its link back) left while nobody listened: they leave now (grace keeps their place)."""
        now = self.clock.now()
        for user in gone:
            self._apply(st.Leave(user, now))
            self._say_if_held(user)

    def watch_stops(self, callback: Callable[[str, str, str], None]) -> None:
        """``callback(robot, former_owner, reason)`` whenever a robot loses its owner (the state machine's
        ``stop`` effect). Called under the authority's lock, before the new record is published or the
        asker answered, so a stop the sim queues there comes before any command of the new owner; it must
        be quick and must not call back into this authority."""
        with self._lock:
            self._stop_watchers.append(callback)

    def watch_resets(self, callback: Callable[[str, str, str], None]) -> None:
        """``callback(robot, owner, reason)`` when an instructor resets a robot (:mod:`ownership.staff`); as
        :meth:`watch_stops`, called under the authority's lock."""
        with self._lock:
            self._reset_watchers.append(callback)

    def _apply(self, ev: st.Event | staff.Staff) -> list[st.Effect]:
        with self._lock:
            before = self._state.records
            self._state, effects = staff.step(self._state, ev)
            for eff in effects:
                if eff.kind in ("stop", "reset"):
                    for watch in self._stop_watchers if eff.kind == "stop" else self._reset_watchers:
                        try:
                            watch(eff.object, eff.user, eff.reason)
                        except Exception:  # the sim's trouble must not break the state machine
                            log.exception("stop of %s failed", eff.object)
            # a renewal moves only the lease's end (on the authority's clock, which means nothing elsewhere):
            # the renewer has it in the reply, and nobody else needs a record 64 times a second for a class
            changed = [
                r
                for o, r in self._state.records.items()
                if r is not before.get(o) and not _lease_only(before.get(o), r)
            ]
            for rec in changed:
                self._publish(rec)
        for eff in effects:
            if eff.kind in ("handover", "revoked", "expired", "restored", "released"):
                if eff.kind == "handover":
                    self.counters["handovers"] += 1
                self._emit(
                    Event(
                        kind=EventKind.ownership(eff.kind),
                        reason=eff.reason,
                        object=eff.object,
                        user=eff.user,
                        severity="warning" if _unasked(eff) else "info",
                        header=self.fabric.header("event"),
                    )
                )
            elif eff.kind == "done":  # an instructor's action: the class's event log says who did what
                log.info("%s", eff.reason)
                self._emit(
                    Event(
                        kind=EventKind.OWN_STAFF,
                        reason=eff.reason,
                        object=eff.object,
                        user=eff.user,
                        severity="warning",
                        header=self.fabric.header("event"),
                    )
                )
        return effects

    def _publish(self, rec: OwnershipRecord) -> None:
        key = keys.own(self.fabric.world, rec.object)
        try:
            self.fabric.publish(key, rec.__class__(**{**_fields(rec), "header": self.fabric.header(key)}))
        except Exception:  # a closing session must not break the state machine
            log.debug("publish %s failed", key, exc_info=True)

    def _emit(self, event: Event, *, limit: str | None = None) -> None:
        try:
            self.fabric.reports.emit(event, "own", event.object, limit=limit)
        except Exception:
            log.debug("emit failed", exc_info=True)

    # ------------------------------------------------------------------ peers, ticks, service

    def _on_peer(self, kind: str, peer_id: str, alive: bool) -> None:
        now = self.clock.now()
        # a going heard within a lease and a second of our own link's loss or return is our link's, like one heard
        # while it was down: a starved sim whose link dropped for 0.0 s released 33 bases of a class of 36 as
        # "left", the goings of the old link told after the new one was up (`bench console --clients 32`)
        heard_well = self.fabric.connected() and not self.fabric.relinked_within(self.hearing.lease_s + CONFIRM_SLACK_S)
        if not alive and self.hearing.deaf(now, heard_well):
            # our link died (the router dropped it while this process was paused, or the router went):
            # every user's token goes with it, and none of them left. Kept until the link is back and a
            # lease (plus a second for the liveliness history) has passed without their token
            with self._lock:
                known = peer_id in self._state.live
                if known:
                    self.hearing.suspect(peer_id)
            if known and self.fabric.reports.should_report("own:link_lost") is not None:
                log.warning(
                    "user tokens went while this authority was paused or cut off (%s first); owners keep their "
                    "robots until a lease passes, with the link up, without their token",
                    peer_id,
                )
            return
        self.hearing.confirm(peer_id)
        self._apply(st.Join(peer_id, now) if alive else st.Leave(peer_id, now))
        if not alive:
            self._say_if_held(peer_id)

    def _say_if_held(self, user: str) -> None:
        """Log (rate-limited) a token loss the state machine held: the authority could not tell it from its own deafness."""
        with self._lock:
            held = user in self._state.held
        if held and self.fabric.reports.should_report("own:held") is not None:
            log.warning(
                "the token of user %s went while this authority heard no one (a stalled router?): she keeps what "
                "she owns and her queue places until it is back, or for %.0f s without it",
                quote(user, MAX_USER_LEN),
                self._state.grace_s,
            )

    def _run(self) -> None:
        while not self._stop.wait(self._tick_s):
            paused = self.hearing.tick(self.clock.now())  # paused or starved: tokens that go now may be ours
            if paused:
                log.warning("ownership authority did not run for %.1f s (paused or starved): leases extended", paused)
            if self.hearing.pending:
                self._forget(self.hearing.due(self.clock.now(), self.fabric.connected()))
            changed = self.fabric.link_changed_at()
            relinked, self._link_seen = changed != self._link_seen, changed
            try:
                self._apply(st.Tick(self.clock.now(), relinked=relinked))
            except Exception:
                log.exception("ownership tick failed")

    def _serve_record(self, obj: str) -> OwnershipRecord:
        """``own/{obj}``: the record, whatever the query carries (requests go to the asker's own key)."""
        key = keys.own(self.fabric.world, obj)
        with self._lock:
            rec = self._state.records.get(obj)
        if rec is None:
            raise ServiceError(f"unknown object {obj!r} (known: {', '.join(sorted(self._state.records))})")
        return rec.__class__(**{**_fields(rec), "header": self.fabric.header(key)})

    def _serve(self, obj: str, key: str, request: Any) -> Any:
        """``own/{obj}/by/{user}``: a request, release or renewal by the user the key names."""
        if request is None:
            return self._serve_record(obj)
        user = keys.parse(key).user
        if request.user != user:
            # the key's user is whatever the asker put in its key (a 20 KB name without a router's access
            # control): quoted short, and logged and published at most a few times per interval
            self.counters["rejected"] += 1
            named, sender = quote(request.user, MAX_USER_LEN), quote(user, MAX_USER_LEN)
            self._emit(
                Event(
                    kind=EventKind.OWN_REFUSED,
                    reason=f"request names {named} but comes from {sender}",
                    object=obj,
                    user=user if is_valid_user(user) else "",
                    severity="warning",
                    header=self.fabric.header("event"),
                ),
                limit=f"own_refused:{obj}",
            )
            raise ServiceError(f"refused: the request names {named} but was sent by {sender}")
        with self._lock:
            known = obj in self._state.records
        if not known:
            raise ServiceError(f"unknown object {obj!r} (known: {', '.join(sorted(self._state.records))})")
        self.counters["requests"] += 1
        now = self.clock.now()
        if request.op == "request":
            ev: st.Event = st.Request(user, obj, now, request.wait)
        elif request.op == "release":
            ev = st.Release(user, obj, now)
        elif request.op == "renew":
            ev = st.Renew(user, obj, now)
        else:  # a staff action asked on a user's key: the staff's key is the router's to open (ownership.staff)
            raise ServiceError(f"refused: {request.op} is a staff action, asked on own/{obj}/staff/by/LOGIN")
        effects = self._apply(ev)
        mine = [e for e in effects if e.user == user and e.object == obj and e.kind not in ("revoked", "stop")]
        eff = mine[0] if mine else st.Effect("denied", obj, user, "no effect")
        outcome = {"handover": "granted", "restored": "granted"}.get(eff.kind, eff.kind)
        if outcome not in ("granted", "denied", "queued", "released", "renewed"):
            outcome = "denied"
        if outcome == "denied":
            self.counters["denied"] = self.counters.get("denied", 0) + 1
            if self.fabric.reports.should_report(f"own_denied:{obj}") is not None:
                log.info("%s of %s by %s denied: %s", request.op, obj, user, eff.reason)
        rec = self._serve_record(obj)  # stamped now, with this authority's term
        return OwnReply(
            outcome, eff.reason, eff.position, rec, header=self.fabric.header(keys.own(self.fabric.world, obj))
        )

    # ------------------------------------------------------------------ CommandGate

    def admit(self, robot: str, command: Command) -> str | None:
        with self._lock:
            rec = self._state.records.get(robot)
        if rec is None:
            return f"{robot!r} has no ownership record"
        if rec.policy == "scene":
            return None
        reason = None
        if not rec.owner:
            reason = f"{robot} is not owned; request it first"
        elif command.user != rec.owner:
            reason = f"{robot} is owned by {rec.owner}, not {command.user}"
        elif command.epoch != rec.epoch and self._plant != "stale-command":  # test-only defect (fabric/plant.py)
            reason = f"stale epoch {command.epoch} for {robot} (current {rec.epoch})"
        if reason:
            self.counters["rejected"] += 1
        return reason

    def update_motion(self, robot: str, moving: bool) -> None:
        with self._lock:
            rec = self._state.records.get(robot)
            if rec is None or (rec.state == "moving") == bool(moving):
                return
        self._apply(st.Motion(robot, bool(moving)))

    def close(self) -> None:
        """Stop ticking and take away the record queryables and the users' watch (a sim rebuilding its world on the
        same session serves its records from a new authority); idempotent."""
        self._stop.set()
        undeclare_all([self._watch, *self._queryables])
        self.admission.close()
        thread = self._thread
        if thread is not None and thread.is_alive() and thread is not threading.current_thread():
            thread.join(timeout=2.0)


def _answer_record(auth: Authority, obj: str, key: str, request: object) -> OwnershipRecord:
    """A query on ``obj``'s record key (a replica joining, a late viewer): the record as it is now."""
    return auth._serve_record(obj)


def _serve_staff(auth: Authority, obj: str, key: str, request: Any) -> OwnReply:
    """``own/{obj}/staff/by/{login}``: an instructor's action (:mod:`ownership.staff`), in the key's login's name.
    Whoever reaches this key is staff: a class's router opens it to the instructor logins alone. (A function of the
    module, not a method: the authority's class holds enough.)"""
    login = keys.parse(key).user
    if request is None or request.user != login or request.op not in staff.STAFF_OPS:
        auth.counters["rejected"] += 1
        raise ServiceError(
            f"refused: a staff action names its op (one of {', '.join(staff.STAFF_OPS)}) and the login "
            f"of its key ({quote(login, MAX_USER_LEN)})"
        )
    effects = auth._apply(staff.Staff(login, obj, request.op, auth.clock.now(), request.to))
    said = [e for e in effects if e.kind in ("done", "denied") and e.user == login]
    eff = said[-1] if said else st.Effect("denied", obj, login, "no effect")
    auth.counters[f"staff_{eff.kind}"] = auth.counters.get(f"staff_{eff.kind}", 0) + 1
    with auth._lock:
        rec = auth._state.records.get(obj)
    if rec is None:
        raise ServiceError(eff.reason)
    return OwnReply(
        eff.kind, eff.reason, 0, auth._serve_record(obj), header=auth.fabric.header(keys.own(auth.fabric.world, obj))
    )


def _unasked(eff: st.Effect) -> bool:
    """A robot taken from its owner without her asking (an expiry, her departure, a take-over): a warning, so
    the sim logs it with its reason whatever the log level. Her own release (and a handover it caused, whose
    reason is ``released by ...``) and leaving a queue are not."""
    if eff.kind in ("expired", "revoked"):
        return True
    return eff.kind in ("released", "handover") and not eff.reason.startswith(("released", "left the queue"))


def _lease_only(old: OwnershipRecord | None, new: OwnershipRecord) -> bool:
    """Whether ``new`` differs from ``old`` in its lease's end alone."""
    return old is not None and dataclasses.replace(old, lease_expiry=new.lease_expiry) == new


def _fields(rec: OwnershipRecord) -> dict[str, Any]:
    return {f.name: getattr(rec, f.name) for f in dataclasses.fields(rec)}
