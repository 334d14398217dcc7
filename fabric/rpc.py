"""Services: queryables whose requests and replies are fabric messages, and the queries that ask them.

A handler refuses a request by raising :class:`~fabric.interfaces.ServiceError`, which the caller gets back
as :class:`~fabric.interfaces.Refused` (a ``ServiceError``) with the same reason; a query nobody answers
raises :class:`~fabric.interfaces.NoReply`. The error types live in :mod:`fabric.interfaces.errors`.

Kept apart from :mod:`fabric.session` because request/reply is its own protocol over the session (error
replies, zenoh's own timeout reply, consolidation), while the session's job is publishing and subscribing.
A :class:`~fabric.session.Fabric` holds one :class:`Rpc` as ``fabric.rpc``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any, Callable

import zenoh

from fabric.authority_stamp import AuthorityStamp
from fabric.budget import RATE_LIMITED
from fabric.codec import DecodeError, decode, encode
from fabric.declared import Declared
from fabric.interfaces import Event, EventKind, Header, NoReply, Refused, ServiceError
from fabric.limits import clip
from fabric.publishers import priority_for

log = logging.getLogger("robofabric")

ZENOH_QUERY_TIMEOUT = "Timeout"
"""The error reply zenoh itself gives a query whose time limit ran out while a server was known: a
silence, which must read as NoReply (retried by those who wait), not as a server's refusal."""
STALE = "stale term"
"""How a reply this session's fence refused is told (:class:`~fabric.interfaces.Refused`'s reason begins so): an
authority's answer stamped below a term already heard, or from a sim whose token went (:mod:`fabric.fencing`)."""
RELINK_S = 2.0
"""After this session's own link was seen down, how long a query that nobody answered at once is asked again (every
:data:`RELINK_POLL_S`, within its time limit): a client that was paused or starved past its lease finds its link
closed and reconnects within about a second, and its routes come back a moment after the link. Its first
query then met "nobody serves it" at once, though the server had been there all along (a 3 s pause of a student's
process failed her next map query: issue 49)."""
RELINK_POLL_S = 0.05
RELINK_EARLY_S = 0.25
"""A query that nobody answered and that ended later than this after it was asked, before its limit, may have ended
early: zenoh ends one at once when no route leads to a server, at its limit when a server is silent, and in between
when the link closed under it (or on a loaded box, at once taking that long)."""
RELINK_CONFIRM_S = 0.5
"""How long such a query's end waits to hear whether the link closed under it."""
TOKENS_WENT_S = 1.0
"""A query that found nobody at once less than this after a liveliness token went waits to hear whether its own link
closed (:meth:`Rpc._lost_under`)."""
SERVER_BACK_S = 5.0
"""After a server's liveliness token went (a compute peer or a sim this session watches), how long a query that found
nobody at once is asked again (every :data:`RELINK_POLL_S`, within its limit): a server starved past its lease loses
its link, and with it its services, until it runs again and reconnects, a second or two later at load; a standby sim
takes over within about a second. Before, a student's plan asked in that gap met "nobody serves it" at once, though
the compute peer that had just built her map was back a moment later (the scenario test's bob, run 4 of the
twenty-third session; docs/testing.md). A server gone for good costs its askers this long, within their limits."""
FROZEN_S = 1.0
"""An ask that ended this long past its limit was not answered because its own process did not run: paused (SIGSTOP,
a laptop's lid) or starved. Its link's loss, if it lost it meanwhile, is waited for this long more
(:meth:`Rpc._renewed`)."""

__all__ = ["Rpc", "Reply", "STALE", "ZENOH_QUERY_TIMEOUT", "relinked_lately"]


def relinked_lately(now: float, lost_at: float, back_at: float) -> bool:
    """Whether a query that nobody serves is asked again a moment later: the link was lost, or came back, within
    :data:`RELINK_S` of ``now``. From its return too: a link that took longer than that to come back (5 s for a
    student woken at load 10, CI of 2026-11-30) has its routes a moment after it, and a query asked then met "nobody
    serves it" though the sim had been there all along."""
    return now - max(lost_at, back_at) <= RELINK_S


@dataclass(frozen=True, slots=True)
class Reply:
    """One answer to a query: the replying key, the decoded message, and who answered."""

    key: str
    message: Any
    source: str


class Rpc:
    """Serve and query on one session. What it declares goes into ``resources``, which the session
    undeclares when it closes; ``believe(key, message)`` drops replies stamped below a term already heard."""

    def __init__(
        self,
        session: zenoh.Session,
        *,
        counters: Any,
        stamp: AuthorityStamp,
        header: Callable[[str], Header],
        believe: Callable[[str, Any], bool],
        resources: list[Any],
        linked: Callable[[], bool] | None = None,
        lost_at: Callable[[], float] = lambda: float("-inf"),
        back_at: Callable[[], float] = lambda: float("-inf"),
        token_gone_at: Callable[[], float] = lambda: float("-inf"),
        stood_still: Callable[[], tuple[float, float]] = lambda: (float("-inf"), float("-inf")),
        opened_at: float = float("-inf"),
        declared: Declared | None = None,
    ) -> None:
        """``linked()``: whether this client has a link to a router now (None: a router itself, always linked);
        ``lost_at()``: when it last lost one, ``back_at()``: when one last came back after a loss, ``token_gone_at()``:
        when it last heard a liveliness token go, ``stood_still()``: (since, until) this process last stood still
        (monotonic s, :mod:`fabric.standstill`); ``opened_at``: when the session opened (its routes come a moment
        after it, as after a link's return); ``declared``: where each service served is told (:mod:`fabric.declared`)."""
        self._session = session
        self._declared = declared
        self._linked = linked
        self._lost_at = lost_at
        self._back_at = back_at
        self._token_gone_at = token_gone_at
        self._stood_still = stood_still
        self._opened_at = opened_at
        self._counters = counters
        self._stamp = stamp
        self._header = header
        self._believe = believe
        self._resources = resources

    def serve(
        self,
        key_expr: str,
        handler: Callable[[str, Any], Any],
        *,
        expected: type | tuple[type, ...] | None = None,
        complete: bool = False,
        defer: Callable[[str, Any], Callable[[Callable[[], None]], bool] | None] | None = None,
        gate: Callable[[str], bytes | None] | None = None,
    ) -> zenoh.Queryable[None]:
        """Answer queries on ``key_expr`` with ``handler(key, request_or_None) -> message``.

        A handler raising :class:`ServiceError` (or ``ValueError``) sends the reason back as an error
        reply; a bad request payload is answered with the decode error. Nothing escapes to zenoh.
        While the session's stamp is muzzled, no query is answered at all.

        ``defer(key, request)``, asked first in zenoh's callback thread: None answers there and then; else
        a ``submit(job)`` (a :class:`fabric.lanes.Lane`'s, for one asker) that queues the answer elsewhere,
        so it holds up nothing behind it, and says False when it cannot (the query is refused as
        ``rate_limited``). ``defer`` may refuse at once by raising :class:`ServiceError` (a spent budget).
        ``gate(key)``, asked before anything is decoded: None to go on, else the encoded error reply that
        refuses the query (a flood's refusals then cost no decoding and no encoding each).
        """

        # zenoh 1.10 ignores a reply's priority (and warns): replies travel at the query's priority.
        # A reply goes on the queryable's own key when it names one: a wildcard query (``own/*``, a replica or a
        # viewer joining) then learns which key answered, and the reply is fenced by that key's scopes like a
        # publication on it (on the query's own ``own/*`` it named no object: unfenced, and unparseable)
        own_key = key_expr if not any(c in key_expr for c in "*$") else None

        def on_query(query: zenoh.Query) -> None:
            key = str(query.key_expr)
            self._counters["queries"] += 1
            if self._stamp.muzzled:
                return  # no answer at all: the asker times out or hears the real authority
            refusal = gate(key) if gate is not None else None
            if refusal is not None:
                self._counters["query_errors"] += 1
                query.reply_err(refusal)
                return
            try:
                request = None
                if query.payload is not None and len(query.payload.to_bytes()) > 0:
                    request = decode(query.payload.to_bytes(), expected)
                submit = defer(key, request) if defer is not None else None
                if submit is None:
                    self._answer(query, key, request, handler, own_key)
                elif not submit(lambda: self._answer_later(query, key, request, handler, own_key)):
                    raise ServiceError(f"{RATE_LIMITED}: too many of your asks on {key} are waiting; ask again later")
            except (DecodeError, ServiceError, ValueError) as exc:
                self._refuse(query, exc)
            except Exception as exc:
                self._failed(query, key, exc)

        q = self._session.declare_queryable(key_expr, on_query, complete=complete)
        self._resources.append(q)
        if self._declared is not None:
            self._declared.add("queryable", key_expr, q)
        return q

    def _answer_later(
        self, query: zenoh.Query, key: str, request: Any, handler: Callable[[str, Any], Any], own_key: str | None
    ) -> None:
        """A deferred answer ends its query itself: zenoh sends a query's final message when its Query goes, and
        one kept alive by a worker's last job went late, past the asker's time limit, where a router with access
        control dropped it (counted as a refusal of whoever it last judged)."""
        try:
            self._answer(query, key, request, handler, own_key)
        finally:
            query.drop()

    def _answer(
        self, query: zenoh.Query, key: str, request: Any, handler: Callable[[str, Any], Any], own_key: str | None
    ) -> None:
        try:
            reply = handler(key, request)
            if reply is not None:
                query.reply(own_key or key, encode(reply))
        except (DecodeError, ServiceError, ValueError) as exc:
            self._refuse(query, exc)
        except Exception as exc:
            self._failed(query, key, exc)

    def _failed(self, query: zenoh.Query, key: str, exc: Exception) -> None:
        self._counters["query_errors"] += 1
        log.error("service %s failed", key, exc_info=exc)
        query.reply_err(
            encode(Event(kind=EventKind.SERVICE_ERROR, reason=f"internal error: {clip(str(exc))}", severity="error"))
        )

    def _refuse(self, query: zenoh.Query, exc: Exception) -> None:
        try:
            self._counters["query_errors"] += 1
            reason = clip(exc.reason if isinstance(exc, ServiceError) else str(exc), 400)
            query.reply_err(
                encode(
                    Event(kind=EventKind.SERVICE_ERROR, reason=reason, severity="warning", header=self._header("srv"))
                )
            )
        except Exception:
            log.debug("refusal not sent", exc_info=True)  # the session is closing

    def query(
        self,
        selector: str,
        request: Any = None,
        *,
        timeout: float = 2.0,
        expected: type | tuple[type, ...] | None = None,
        all_replies: bool = False,
    ) -> list[Reply]:
        """Send a query and return the decoded replies.

        Raises :class:`~fabric.interfaces.Refused` when a replier refuses (its reason), or
        :class:`~fabric.interfaces.NoReply` when nobody answers (both are ``ServiceError``).
        With ``all_replies`` every replier's answer is returned (no consolidation).
        """
        replies: list[Reply] = []
        errors: list[str] = []
        t0 = time.monotonic()
        deadline, renewed = t0 + timeout, False
        went_at: float | None = None  # when an ask ended early with its server gone under it (_server_went)
        at_once = False  # the last ask found nobody: it ended without zenoh's Timeout
        left_seen = False  # asked again already because a server's token went lately (_server_left_lately)
        while True:
            asked_at = time.monotonic()
            timed_out = self._ask(selector, request, deadline, all_replies, expected, replies, errors)
            ended_at = time.monotonic()
            # zenoh's own word, not the clock: a server there but silent ends the ask with its "Timeout", and one
            # that found nobody ends without it. A re-ask near the limit has a window of a few hundredths of a
            # second, which "at once" at load outran: "no server answered in time" for an object nobody serves
            # (run 49's own CLI, a session just opened asking again until its limit)
            at_once = not timed_out
            if replies or errors:
                break
            if self._relinked(asked_at, deadline):
                continue
            if not renewed and (again := self._renewed(selector, t0, deadline, timeout)) is not None:
                deadline, renewed = again, True
                continue
            if at_once and self._server_left_lately(deadline, counted=left_seen):
                left_seen = True
                continue
            went_at = self._server_went(asked_at, ended_at, deadline, went_at)
            if went_at is None:
                break
        if not replies:
            if errors:
                raise Refused(errors[0], key=selector)
            raise _no_reply(selector, time.monotonic() - t0, timeout, at_once=at_once)
        return replies

    def _renewed(self, selector: str, since: float, deadline: float, timeout: float) -> float | None:
        """After a query asked at ``since`` that nobody answered and whose limit ran out: its new deadline where its
        own link was lost under it (None: the silence stands). An ask that ended :data:`FROZEN_S` past its limit did
        not run (paused or starved: zenoh's timer fires only when it wakes), and the link's close is told a moment
        after it wakes: that is waited for, :data:`FROZEN_S` at most. The limit is then given again, whole, from when
        the link is back (waited for as long as the limit, :data:`RELINK_S` at least), once per query: a student
        paused past her lease while her map was built found, on waking, her limit spent and her link closed, and
        failed her test though the map was ready (issue 49, CI of 2026-11-30). A link lost at any time since the first
        ask counts, not only under the last one: in CI's next run her link came back 5 s after its loss, 1.4 s before
        her limit, and the map was not built in what was left. A silent server on a link that held is not asked
        again."""
        linked = self._linked
        now = time.monotonic()
        if linked is None or now + RELINK_POLL_S < deadline:
            return None

        def lost() -> bool:
            return self._lost_at() >= since or not linked()

        if now - deadline >= FROZEN_S:
            until = now + FROZEN_S
            while not lost() and time.monotonic() < until:
                time.sleep(RELINK_POLL_S)
        if not lost():
            return None
        if not self._wait_linked(time.monotonic() + max(RELINK_S, timeout)):
            return None  # its router is gone, not just its link: the silence stands
        self._counters["queries_renewed"] += 1
        log.info(
            "query %s: its limit ran out while its own link was lost or its process stood still; asked again", selector
        )
        return time.monotonic() + timeout

    def _relinked(self, asked_at: float, deadline: float) -> bool:
        """After nobody answered a query asked at ``asked_at``: whether to ask again within ``deadline``. Yes where
        this client's link is down now (once it is back), was lost or came back lately (its routes come a moment after it),
        or was lost while the query was out (a process woken from a pause learns only then that its router closed
        its link, and its query ends early, neither at once nor at its limit). A session opened lately is one whose
        link just came: the router's routes come a moment after it, and at load a student's first request met "nobody
        serves it" at once with the authority there all along (twice in whole runs: run 24's mallory, run 42's alice),
        so for :data:`RELINK_S` from its opening it asks again too. A query that a link up all along (and not just
        opened) answered with nobody, slowly or not, is not asked again: "nobody serves it" stays the answer."""
        if self._linked is None:
            return False
        now = time.monotonic()
        if now + RELINK_POLL_S >= deadline:
            return False
        lost_lately = relinked_lately(now, self._lost_at(), self._back_at())
        fresh = now - self._opened_at <= RELINK_S
        if not (lost_lately or fresh or not self._linked() or self._lost_under(asked_at, deadline)):
            return False
        if not self._wait_linked(deadline - RELINK_POLL_S):
            return False
        time.sleep(RELINK_POLL_S)
        self._counters["queries_after_open" if fresh and not lost_lately else "queries_after_relink"] += 1
        return True

    def _wait_linked(self, until: float) -> bool:
        """Whether this client's link is up by ``until`` (monotonic s), polled every :data:`RELINK_POLL_S`."""
        assert self._linked is not None
        while not self._linked():
            if time.monotonic() >= until:
                return False
            time.sleep(RELINK_POLL_S)
        return True

    def _server_went(self, asked_at: float, ended_at: float, deadline: float, went_at: float | None) -> float | None:
        """After an ask that nobody answered, on a link that stayed up: when its server went under it, if it is to be
        asked again (None: not). An ask that ended early (later than :data:`RELINK_EARLY_S`, before half its limit)
        found a server, which then went before it answered: it died, its own link to the router dropped (a process
        starved past its lease), or it would not answer yet (an authority unsure of itself after a freeze). For
        :data:`RELINK_S` from then, within the limit, the key is asked again every :data:`RELINK_POLL_S` (a compute
        peer reconnects within about a second, a standby takes a dead sim's world over within one). Before, the asker
        was told "nobody serves it" though the server was back a moment later (issue 49's fail-over runs at load).
        The ask is judged on when it ended (``ended_at``), not on now: a moment spent since looking at the link
        (:meth:`_lost_under`) made an ask that found nobody at once look like one that ended early."""
        now = time.monotonic()
        if now + RELINK_POLL_S >= deadline:
            return None
        if went_at is None:
            if ended_at - asked_at < RELINK_EARLY_S or ended_at >= asked_at + 0.5 * (deadline - asked_at):
                return None  # at once (no server) or at its limit (a silent one): the answer stands
            went_at = now
            self._counters["queries_after_server_went"] += 1
        elif now - went_at > RELINK_S:
            return None
        time.sleep(RELINK_POLL_S)
        return went_at

    def _server_left_lately(self, deadline: float, *, counted: bool) -> bool:
        """After an ask that found nobody at once: whether to ask again, because a server's token went less than
        :data:`SERVER_BACK_S` ago (it may be reconnecting: its services come back with its link). Polled every
        :data:`RELINK_POLL_S`, within ``deadline``; ``counted``: this query was counted already
        (``queries_after_server_left``). Only the tokens this session watches count (a user's world: its sims and
        compute peers); a token that went long ago leaves "nobody serves it" at once."""
        now = time.monotonic()
        if now + RELINK_POLL_S >= deadline or now - self._token_gone_at() > SERVER_BACK_S:
            return False
        if not counted:
            self._counters["queries_after_server_left"] += 1
        time.sleep(RELINK_POLL_S)
        return True

    def _lost_under(self, asked_at: float, deadline: float) -> bool:
        """Whether the link was lost while a query asked at ``asked_at`` was out: only a query that ended early
        (later than :data:`RELINK_EARLY_S`), or one that found nobody at once just after tokens went (a closing link
        takes every token it brought with it, and its close is told after them: a student's plan query, asked in
        between at load 22, met "nobody serves it" at once) or during or just after this process stood still (woken
        from a pause past its lease, it learns of its link's close a moment after it runs again: CI's paused student
        asked for his plan in that moment), is looked at, for up to :data:`RELINK_CONFIRM_S` (the transport's close
        is told on another thread, a moment after the query it ended; :data:`RELINK_S` after a standstill)."""
        linked = self._linked
        if linked is None:
            return False
        now = time.monotonic()
        stood_still = now - self._stood_still()[1] <= RELINK_S
        if now - asked_at < RELINK_EARLY_S and now - self._token_gone_at() > TOKENS_WENT_S and not stood_still:
            return False  # at once, with no token gone just before and no standstill: nobody serves it
        # a process that stood still runs again on a loaded box, whose threads tell the close later: RELINK_S for it
        until = min(deadline, time.monotonic() + (RELINK_S if stood_still else RELINK_CONFIRM_S))
        while True:
            if self._lost_at() >= asked_at or not linked():  # a loss before the ask: relinked_lately's
                return True
            if time.monotonic() + RELINK_POLL_S >= until:
                return False
            time.sleep(RELINK_POLL_S)

    def _ask(
        self,
        selector: str,
        request: Any,
        deadline: float,
        all_replies: bool,
        expected: type | tuple[type, ...] | None,
        replies: list[Reply],
        errors: list[str],
    ) -> bool:
        """One query with what is left of the time limit; replies and refusals are added to the lists. Returns
        whether zenoh said the limit ran out (:data:`ZENOH_QUERY_TIMEOUT`: a server was found, and was silent)."""
        timed_out = False
        left = max(0.01, deadline - time.monotonic())
        for rep in self._session.get(selector, **self._get_options(selector, request, left, all_replies)):
            if rep.ok is not None:
                try:
                    msg = decode(rep.ok.payload.to_bytes(), expected)
                except DecodeError as exc:
                    errors.append(f"bad reply: {exc}")
                    continue
                if not self._believe(str(rep.ok.key_expr), msg):
                    errors.append(f"{STALE} on {rep.ok.key_expr}")
                    continue
                src = getattr(getattr(msg, "header", None), "source", "")
                replies.append(Reply(str(rep.ok.key_expr), msg, src))
            else:
                refusal = _refusal(rep.err)
                if refusal is not None:
                    errors.append(refusal)
                else:
                    timed_out = True
        return timed_out

    def call(self, selector: str, request: Any = None, *, timeout: float = 2.0, expected: Any = None) -> Any:
        """One query, one answer: the first reply's message."""
        return self.query(selector, request, timeout=timeout, expected=expected)[0].message

    def first(
        self,
        selector: str,
        request: Any = None,
        *,
        timeout: float = 2.0,
        expected: type | tuple[type, ...] | None = None,
    ) -> Any:
        """Ask every server of ``selector`` and return the first answer as soon as it comes, without waiting
        for the others (a step of a robot's move between sims). Refusals and silence as in :meth:`query`;
        a reply that does not decode counts as a refusal, and replies are not fenced."""
        errors: list[str] = []
        t0 = time.monotonic()
        deadline, renewed = t0 + timeout, False
        while True:
            asked_at = time.monotonic()
            left = max(0.01, deadline - asked_at)
            for rep in self._session.get(selector, **self._get_options(selector, request, left, True)):
                if rep.ok is not None:
                    try:
                        return decode(rep.ok.payload.to_bytes(), expected)
                    except DecodeError as exc:
                        errors.append(f"bad reply: {exc}")
                        continue
                refusal = _refusal(rep.err)
                if refusal is not None:
                    errors.append(refusal)
            if errors:
                break
            if self._relinked(asked_at, deadline):
                continue
            if renewed or (again := self._renewed(selector, t0, deadline, timeout)) is None:
                break
            deadline, renewed = again, True
        if errors:
            raise Refused(errors[0], key=selector)
        raise _no_reply(selector, time.monotonic() - t0, timeout)

    @staticmethod
    def _get_options(selector: str, request: Any, timeout: float, all_replies: bool) -> dict[str, Any]:
        kwargs: dict[str, Any] = {"timeout": timeout}
        prio = priority_for(selector)
        if prio is not None:
            kwargs["priority"] = prio
        if request is not None:
            kwargs["payload"] = encode(request)
        if all_replies:
            kwargs["target"] = zenoh.QueryTarget.ALL
            kwargs["consolidation"] = zenoh.ConsolidationMode.NONE
        return kwargs


def _refusal(err: Any) -> str | None:
    """The reason of an error reply; None for zenoh's own word that the time limit ran out (no answer, not a refusal)."""
    try:
        return decode(err.payload.to_bytes(), Event).reason
    except DecodeError:
        text = err.payload.to_string() if err.payload is not None else "error"
        return None if text == ZENOH_QUERY_TIMEOUT else text


def _no_reply(selector: str, waited: float, timeout: float, *, at_once: bool | None = None) -> NoReply:
    """Say what happened: zenoh ends a query at once when nobody serves the key, and waits the whole time
    limit only for a server that is there but silent ("within 5 s" after 0 s would mislead). ``at_once``: whether
    the last ask found nobody, ending without zenoh's Timeout (None: judged from ``waited``). A query that found nobody at once may still have
    waited its limit out to hear whether its own link had closed (its process stood still): said so, not as a
    server that was silent (a test at load read "no server answered in time" where nobody served the key)."""
    if at_once is None:
        at_once = waited < 0.5 * timeout
    why = "nobody serves it" if at_once else "no server answered in time"
    if at_once and waited >= 0.5 * timeout:
        why += " (found at once; the rest waited for this session's link or its routes)"
    return NoReply(
        f"no reply on {selector} after {waited:.1f} s of {timeout:.1f} s: {why}", key=selector, nobody=at_once
    )
