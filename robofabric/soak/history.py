"""The soak's history: what happened during a run, as frozen records, one JSON object a line.

The observer (:mod:`robofabric.soak.observer`) writes what it saw on the wire (ownership records and
events, commands, refusals, joints); the soak itself writes the nemesis's faults, the peers' resources
and their exits. Every record carries ``t``: seconds on the machine's monotonic clock, which every
namespace of the lab shares (libfaketime moves only the wall clock), so records of different writers sort
into one timeline. The checker (:mod:`robofabric.soak.checker`) reads nothing else.

A line that does not parse is counted and skipped with its line number (a writer killed mid-line leaves
one), never fatal: :func:`read` returns the records and the bad lines.
"""

from __future__ import annotations

import dataclasses
import json
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Iterable, Union

__all__ = [
    "OwnRec",
    "OwnEvent",
    "Cmd",
    "Reject",
    "Joints",
    "Fault",
    "ProcSample",
    "ProcExit",
    "Mark",
    "Record",
    "to_line",
    "from_line",
    "read",
    "Writer",
    "KINDS",
]


@dataclass(frozen=True, slots=True)
class OwnRec:
    """An ownership record as published on ``own/{obj}`` (``source``/``term``: the authority that wrote it)."""

    t: float
    obj: str
    owner: str
    epoch: int
    queue: tuple[str, ...]
    state: str
    source: str
    term: int


@dataclass(frozen=True, slots=True)
class OwnEvent:
    """An ownership event (``own_released``, ``own_handover``...): ``user`` and ``reason`` as the authority said."""

    t: float
    kind: str
    obj: str
    user: str
    reason: str
    source: str


@dataclass(frozen=True, slots=True)
class Cmd:
    """A command on the wire: ``name`` is joints|trajectory|twist|path|stop|reset; ``q`` the joint targets of a joints command."""

    t: float
    robot: str
    user: str
    epoch: int
    name: str
    q: tuple[float, ...] = ()


@dataclass(frozen=True, slots=True)
class Reject:
    """A sim's refusal of a command (``event/reject/{robot}``)."""

    t: float
    robot: str
    user: str
    reason: str


@dataclass(frozen=True, slots=True)
class Joints:
    """A robot's joint positions; ``s`` the sim time stamped on them, ``source``/``term`` the sim that published."""

    t: float
    robot: str
    q: tuple[float, ...]
    s: float
    source: str
    term: int


@dataclass(frozen=True, slots=True)
class Fault:
    """One fault of the nemesis: ``kind`` (pause, kill, partition, router, skew, hog, replay), ``target`` (a
    process or host), from ``t`` to ``until``; ``detail`` says what exactly (seconds, the clock offset...)."""

    t: float
    kind: str
    target: str
    until: float
    detail: str = ""


@dataclass(frozen=True, slots=True)
class ProcSample:
    """A peer's resources at ``t`` from /proc: resident memory (MB), threads, open fds, its log's size (bytes).
    ``name`` is the peer's role (``sim-a``); ``pid`` tells incarnations apart (a restart is a new pid)."""

    t: float
    name: str
    pid: int
    rss_mb: float
    threads: int
    fds: int
    log_bytes: int


@dataclass(frozen=True, slots=True)
class ProcExit:
    """A peer's process ended; ``expected`` when the nemesis killed it or the run was ending."""

    t: float
    name: str
    pid: int
    code: int
    expected: bool
    tail: str = ""


@dataclass(frozen=True, slots=True)
class Mark:
    """A phase of the run: ``start``, ``warm`` (warm-up over: resources are judged from here), ``end``."""

    t: float
    what: str
    detail: str = ""


Record = Union[OwnRec, OwnEvent, Cmd, Reject, Joints, Fault, ProcSample, ProcExit, Mark]

KINDS: dict[str, type] = {
    "own": OwnRec,
    "ev": OwnEvent,
    "cmd": Cmd,
    "rej": Reject,
    "joints": Joints,
    "fault": Fault,
    "proc": ProcSample,
    "exit": ProcExit,
    "mark": Mark,
}
_NAMES = {cls: name for name, cls in KINDS.items()}
_TUPLES = {"queue", "q"}


def to_line(rec: Record) -> str:
    """One JSON line (no newline): the record's fields and ``k``, its kind."""
    d = dataclasses.asdict(rec)
    for k in _TUPLES & d.keys():
        d[k] = list(d[k])
    return json.dumps({"k": _NAMES[type(rec)], **d}, separators=(",", ":"))


def from_line(line: str) -> Record:
    """The record of one line; ValueError naming what was wrong."""
    try:
        d = json.loads(line)
    except json.JSONDecodeError as exc:
        raise ValueError(f"not JSON ({exc.msg} at column {exc.colno})") from None
    if not isinstance(d, dict):
        raise ValueError("not a JSON object")
    cls = KINDS.get(d.pop("k", None))
    if cls is None:
        raise ValueError(f"unknown kind {line[:40]!r}")
    for k in _TUPLES & d.keys():
        d[k] = tuple(float(x) if k == "q" else str(x) for x in d[k])
    try:
        return cls(**d)
    except TypeError as exc:
        raise ValueError(f"{cls.__name__}: {exc}") from None


def read(paths: Iterable[Path | str]) -> tuple[list[Record], list[str]]:
    """Every record of the files, sorted by ``t`` (stable), and the lines that did not parse (``file:line: why``)."""
    records: list[Record] = []
    bad: list[str] = []
    for path in paths:
        p = Path(path)
        if not p.exists():
            continue
        with open(p, encoding="utf-8", errors="replace") as f:
            for n, line in enumerate(f, 1):
                if not line.strip():
                    continue
                try:
                    records.append(from_line(line))
                except ValueError as exc:
                    bad.append(f"{p.name}:{n}: {exc}")
    records.sort(key=lambda r: r.t)
    return records, bad


class Writer:
    """Appends records to one file from any thread; lines are whole (one write each) and flushed at once,
    so a reader or a crash sees only complete lines, apart from the very last."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        self._f: IO[str] = open(self.path, "a", encoding="utf-8")
        self._lock = threading.Lock()
        self.count = 0

    def write(self, rec: Record) -> None:
        line = to_line(rec) + "\n"
        with self._lock:
            if self._f.closed:
                return
            self._f.write(line)
            self._f.flush()
            self.count += 1

    def close(self) -> None:
        with self._lock:
            self._f.close()

    def __enter__(self) -> "Writer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
