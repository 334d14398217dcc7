"""Who gets an ownership answer, and where it is worked out: each login's budgets and the requests' own lane.

Every ask on ``own/{obj}/by/{user}`` reaches the authority through zenoh's one callback thread per link,
in order. Were each answered there, one login's flood of requests (each a step of the state machine, a
record published, a reply) would hold up every renewal behind it until leases ran out: a lease must end
only through its owner's own silence. So, asked in that thread before any work (:meth:`Admission.route`,
the ``defer`` of :meth:`fabric.rpc.Rpc.serve`):

- a **request** (a take-over, a queue place) spends one token of its login's *requests* budget and is
  worked out on the requests' lane (:class:`fabric.lanes.Lane`, the logins in turn), never in the
  callback thread;
- a **renewal** or **release**, the owner's own lane, spends its login's *owner* budget and is answered
  at once, in the callback thread: no request waits ahead of it;
- a **record query** on the asker's own key spends her *queries* budget, answered at once (a read).

Before even the payload is decoded (:meth:`Admission.gate`), a login past all three budgets together gets
her refusal, encoded once: the flood's bulk costs the sim's Python next to nothing, so its physics, streams
and the owners' commands keep their share of the machine. A spent budget is refused there and then as
``rate_limited`` (:data:`fabric.budget.RATE_LIMITED`),
counted under ``rate_limited`` in the authority's and the session's counters, and reported at most a few
times per interval; other logins' budgets are untouched.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable

from fabric import keys
from fabric.budget import RATE_LIMITED, Budgets, Rate
from fabric.codec import encode
from fabric.interfaces import Event, EventKind, ServiceError
from fabric.lanes import Lane
from fabric.rate import Clock

log = logging.getLogger("robofabric.ownership")

__all__ = ["OwnBudgets", "Admission"]


@dataclass(frozen=True, slots=True)
class OwnBudgets:
    """Each login's budgets at one authority (docs/ownership.md, "Budgets").

    ``requests``: requests (take-overs, queue places): 40 at once (a script asking for a class's robots in one
    go), then 20 a second, far more than a person or a script retrying every 0.1 s asks. ``owner``: renewals and releases, her own lane; an owner renews each robot twice a
    lease (every 0.5 s by default), so 200/s covers a login holding 64 robots. ``queries``: record queries
    on her own key."""

    requests: Rate = field(default_factory=lambda: Rate(20.0, 40.0))
    owner: Rate = field(default_factory=lambda: Rate(200.0, 400.0))
    queries: Rate = field(default_factory=lambda: Rate(50.0, 100.0))

    @classmethod
    def parse(cls, text: str) -> "OwnBudgets":
        """``"requests=5/10,owner=100/200,queries=20"`` (any of them; the others keep their defaults)."""
        given: dict[str, Rate] = {}
        for part in filter(None, (p.strip() for p in text.split(","))):
            name, eq, value = part.partition("=")
            name = {"renewals": "owner"}.get(name.strip(), name.strip())
            if not eq or name not in ("requests", "owner", "queries"):
                raise ValueError(
                    f"a budget is requests=, owner= (renewals and releases) or queries=, then RATE[/BURST]; got {part!r}"
                )
            given[name] = Rate.parse(value)
        return cls(**given)


class Admission:
    """The budgets and the requests' lane of one authority; ``route`` is its queryables' ``defer``."""

    def __init__(
        self,
        budgets: OwnBudgets,
        clock: Clock,
        counters: dict[str, int],
        *,
        report: Callable[[str, Callable[[], Event]], None],
        fabric_counters: Any = None,
    ) -> None:
        """``report(limit, make)``: publish the event ``make()`` builds unless too many went out under ``limit``
        lately (a refusal in a flood must cost no event of its own)."""
        self.budgets = budgets
        self._clock = clock
        self._counters = counters
        self._fabric_counters = fabric_counters
        self._report = report
        self._requests = Budgets(budgets.requests)
        self._owner = Budgets(budgets.owner)
        self._queries = Budgets(budgets.queries)
        # all three together, checked before a payload is decoded: past it a flood costs a cached refusal each
        parts = (budgets.requests, budgets.owner, budgets.queries)
        self._asks = Budgets(Rate(sum(r.per_s for r in parts), sum(r.burst for r in parts)))
        self._refusals: dict[str, bytes] = {}  # login -> her encoded refusal (bounded)
        self.lane = Lane("own-requests", per_asker=4, total=256)

    def gate(self, key: str) -> bytes | None:
        """Before decoding (:meth:`fabric.rpc.Rpc.serve`'s ``gate``): None while the key's login is within all her
        budgets together, else her refusal, encoded once."""
        user = key.rsplit("/", 1)[-1]
        if self._asks.allow(user, self._clock.now()):
            return None
        refusal = self._refusals.get(user)
        if refusal is None:
            reason = self._asks.refusal(user, "ownership asks (requests, renewals, queries together)")
            refusal = encode(Event(kind=EventKind.SERVICE_ERROR, reason=reason, severity="warning"))
            if len(self._refusals) < 256:
                self._refusals[user] = refusal
        self._refused(key, user, "")
        return refusal

    def route(self, key: str, request: Any) -> Callable[[Callable[[], None]], bool] | None:
        """Where the ask on ``key`` is answered: None (now, here) or the lane's submit for its login; raises
        :class:`~fabric.interfaces.ServiceError` (``rate_limited: ...``) when her budget for it is spent."""
        user = keys.parse(key).user
        op = getattr(request, "op", None) if request is not None else None
        budgets, what = {
            "request": (self._requests, "ownership requests"),
            None: (self._queries, "record queries"),
        }.get(op, (self._owner, "renewals and releases"))
        if not budgets.allow(user, self._clock.now()):
            self._refused(key, user, budgets.refusal(user, what))
        if op == "request":
            return lambda job: self.lane.submit(user, job)
        return None

    def _refused(self, key: str, user: str, reason: str) -> None:
        """Count a refusal and report it (at most a few per interval); raise it when ``reason`` is given."""
        self._counters["rate_limited"] = self._counters.get("rate_limited", 0) + 1
        if self._fabric_counters is not None:
            self._fabric_counters["rate_limited"] += 1
        obj = key.split("/")[-3]  # own/{obj}/by/{user}: one of the authority's objects, its queryables serve no other
        said = reason or f"{RATE_LIMITED}: {user} asked more than all her ownership budgets together"
        self._report(
            f"rate_limited:{obj}",
            lambda: Event(kind=EventKind.OWN_REFUSED, reason=said, object=obj, user=user, severity="warning"),
        )
        if reason:
            raise ServiceError(reason)

    def refused(self) -> dict[str, int]:
        """Refusals per login so far, every budget together."""
        out: dict[str, int] = {}
        for b in (self._requests, self._owner, self._queries):
            for login, n in b.refused.items():
                out[login] = out.get(login, 0) + n
        return out

    def close(self) -> None:
        self.lane.close()
