"""The console's limits as pure decisions, time passed in: per-address buckets, the pages to forget, the login throttle.

A class's console faces its LAN: any machine on it can load pages, open websockets and guess passwords. The
decisions here say who is let in and what is forgotten; :mod:`.doors` applies them to the server. Every table is
bounded (the oldest entry goes first), so a flood of new addresses or names cannot grow the console either.
"""

from __future__ import annotations

import ipaddress
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Iterable

__all__ = ["address_key", "Bucket", "Buckets", "Waiting", "pages_to_forget", "delay_after", "LoginThrottle"]

TABLE_MAX = 10_000
"""Entries a per-address or per-name table keeps: past it the longest unused is forgotten."""


def address_key(host: str) -> str:
    """Who a request is for the limits: its IPv4 address, or its IPv6 /64 (one machine holds a whole /64 of
    addresses it may pick from, so an IPv6 address alone would be no limit); an IPv4 address mapped into IPv6 is
    the IPv4 one. Anything else (a unix socket, a test client) is its own key."""
    try:
        ip = ipaddress.ip_address(host.strip("[]"))
    except ValueError:
        return host
    if isinstance(ip, ipaddress.IPv6Address):
        if ip.ipv4_mapped is not None:
            return str(ip.ipv4_mapped)
        return str(ipaddress.IPv6Network((ip, 64), strict=False))
    return str(ip)


@dataclass(frozen=True, slots=True)
class Bucket:
    """A token bucket: ``tokens`` left at time ``stamp`` (seconds, any monotonic clock)."""

    tokens: float
    stamp: float

    def take(self, now: float, rate: float, burst: float) -> tuple[bool, "Bucket"]:
        """Whether one more is allowed at ``now`` (``rate`` a second, up to ``burst`` at once), and the bucket after."""
        tokens = min(burst, self.tokens + max(0.0, now - self.stamp) * rate)
        if tokens >= 1.0:
            return True, Bucket(tokens - 1.0, now)
        return False, Bucket(tokens, now)

    def wait(self, rate: float) -> float:
        """Seconds until the next one is allowed."""
        return max(0.0, (1.0 - self.tokens) / rate) if rate > 0 else float("inf")


class Buckets:
    """One token bucket per key (address), ``rate`` a second and ``burst`` at once; at most ``TABLE_MAX`` keys."""

    def __init__(self, rate: float, burst: float, *, table_max: int = TABLE_MAX) -> None:
        self.rate, self.burst, self.table_max = rate, burst, table_max
        self._buckets: OrderedDict[str, Bucket] = OrderedDict()

    def take(self, key: str, now: float) -> float:
        """0.0 when ``key`` may go on now (one token taken), else the seconds until it may."""
        ok, b = self._buckets.pop(key, Bucket(self.burst, now)).take(now, self.rate, self.burst)
        self._buckets[key] = b
        while len(self._buckets) > self.table_max:
            self._buckets.popitem(last=False)
        return 0.0 if ok else max(b.wait(self.rate), 1e-3)


@dataclass(frozen=True, slots=True)
class Waiting:
    """A page the server served that has not connected its websocket yet."""

    id: str
    key: str  # its address (:func:`address_key`)
    created: float


def pages_to_forget(waiting: Iterable[Waiting], now: float, *, per_address: int, max_age: float) -> list[str]:
    """The ids of the served pages to forget now: those older than ``max_age``, and for each address all but its
    ``per_address`` newest (a browser loads a page and connects it; an address holding more pages that never
    connected is loading pages it does not open). The order is the pages' own (oldest first)."""
    out: list[str] = []
    kept: dict[str, int] = {}
    for w in sorted(waiting, key=lambda w: w.created, reverse=True):
        kept[w.key] = kept.get(w.key, 0) + 1
        if kept[w.key] > per_address or now - w.created > max_age:
            out.append(w.id)
    return out[::-1]


def delay_after(failures: int, *, free: int, base: float, cap: float) -> float:
    """The wait before the next try after ``failures`` failed ones in a row: none for the first ``free``, then
    ``base`` doubling with each failure, at most ``cap``."""
    if failures < free:
        return 0.0
    return min(cap, base * 2.0 ** min(failures - free, 62))


@dataclass(frozen=True, slots=True)
class _Failures:
    count: int
    last: float


class LoginThrottle:
    """Failed logins in a row, per name and per address, each with a growing delay (:func:`delay_after`).

    A name is guessed from anywhere, so its delay holds whoever tries it (her own right password waits too: a
    throttle that let the right password through would tell a guesser when he found it); an address is one
    machine, which may try several names (a lab's NAT: more free tries). A success clears both. The tables keep
    at most ``TABLE_MAX`` names and addresses, and forget one whose last failure is older than ``forget_s``."""

    def __init__(
        self,
        *,
        name_free: int = 3,
        address_free: int = 10,
        base: float = 1.0,
        cap: float = 60.0,
        forget_s: float = 900.0,
        table_max: int = TABLE_MAX,
    ) -> None:
        self.name_free, self.address_free, self.base, self.cap = name_free, address_free, base, cap
        self.forget_s, self.table_max = forget_s, table_max
        self._names: OrderedDict[str, _Failures] = OrderedDict()
        self._addresses: OrderedDict[str, _Failures] = OrderedDict()

    def wait(self, name: str, address: str, now: float) -> float:
        """Seconds before a login of ``name`` from ``address`` may be tried (0.0: now)."""
        return max(
            self._wait(self._names.get(name), self.name_free, now),
            self._wait(self._addresses.get(address_key(address)), self.address_free, now),
        )

    def failed(self, name: str, address: str, now: float) -> None:
        """A login of ``name`` from ``address`` was refused at ``now``."""
        for table, key in ((self._names, name), (self._addresses, address_key(address))):
            f = table.pop(key, None)
            if f is not None and now - f.last > self.forget_s:
                f = None
            table[key] = _Failures(1, now) if f is None else replace(f, count=f.count + 1, last=now)
            while len(table) > self.table_max:
                table.popitem(last=False)

    def succeeded(self, name: str, address: str) -> None:
        """A login of ``name`` from ``address`` went in: both start again."""
        self._names.pop(name, None)
        self._addresses.pop(address_key(address), None)

    def _wait(self, f: _Failures | None, free: int, now: float) -> float:
        if f is None or now - f.last > self.forget_s:
            return 0.0
        return max(0.0, f.last + delay_after(f.count, free=free, base=self.base, cap=self.cap) - now)
