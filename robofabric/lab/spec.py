"""Lab files: the hosts of a lab and the ``robofabric`` commands each runs (``robofabric lab up FILE``)::

    [lab]
    subnet = "10.77.0.0/24"          # optional; a private /24 that exists only inside the lab

    [[host]]
    name = "router"
    run = [["router", "--listen", "tcp/{ip}:7447"]]
    ready = "listening"              # optional: later hosts start once this text is in its output

    [[host]]
    name = "sim"
    clock = "-5"                     # optional: this host's wall clock, 5 s behind (libfaketime's syntax)
    run = [["sim", "--scene", "combined", "--connect", "tcp/{router}:7447"]]

In ``run`` arguments, ``{ip}`` is the host's own address, ``{NAME}`` the address of host NAME and
``{logs}`` the lab's log directory (for files a command writes: recordings, .rrd views).
Parsing is pure and checks the whole file before anything is built.
"""

from __future__ import annotations

import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

from robofabric.lab.lab import DEFAULT_SUBNET, Lab, LabProcess
from robofabric.lab.netns import LabError

__all__ = ["HostSpec", "LabSpec", "load_lab", "parse_lab", "start_lab"]


@dataclass(frozen=True, slots=True)
class HostSpec:
    name: str
    run: tuple[tuple[str, ...], ...] = ()
    clock: str | None = None
    ready: str | None = None


@dataclass(frozen=True, slots=True)
class LabSpec:
    hosts: tuple[HostSpec, ...]
    subnet: str = DEFAULT_SUBNET


def parse_lab(data: dict, *, source: str = "<lab>") -> LabSpec:
    """A :class:`LabSpec` from parsed TOML; :class:`LabError` naming ``source`` for anything wrong."""
    unknown = set(data) - {"lab", "host"}
    if unknown:
        raise LabError(f"{source}: unknown table(s) {', '.join(sorted(unknown))} (expected [lab] and [[host]])")
    lab = data.get("lab", {})
    if set(lab) - {"subnet"}:
        raise LabError(f"{source}: unknown key(s) in [lab]: {', '.join(sorted(set(lab) - {'subnet'}))}")
    hosts = []
    names: set[str] = set()
    for i, h in enumerate(data.get("host", [])):
        where = f"{source}: host #{i + 1}"
        allowed = {"name", "run", "clock", "ready"}
        if set(h) - allowed:
            raise LabError(f"{where}: unknown key(s) {', '.join(sorted(set(h) - allowed))}")
        name = h.get("name")
        if not isinstance(name, str) or not name or name in names:
            raise LabError(f"{where}: needs a unique string 'name'")
        names.add(name)
        run = h.get("run", [])
        if not isinstance(run, list) or not all(
            isinstance(a, list) and a and all(isinstance(x, str) for x in a) for a in run
        ):
            raise LabError(f"{where} ({name}): 'run' must be a list of argument lists, e.g. [[\"router\"]]")
        clock = h.get("clock")
        if clock is not None and not isinstance(clock, str):
            raise LabError(f'{where} ({name}): \'clock\' must be a string such as "-5" or "+5"')
        ready = h.get("ready")
        if ready is not None and (not isinstance(ready, str) or not run):
            raise LabError(f"{where} ({name}): 'ready' must be a string and needs a command in 'run'")
        hosts.append(HostSpec(name, tuple(tuple(a) for a in run), clock, ready))
    if not hosts:
        raise LabError(f"{source}: no [[host]] entries")
    spec = LabSpec(tuple(hosts), lab.get("subnet", DEFAULT_SUBNET))
    for h in spec.hosts:  # placeholders must name hosts of the file
        for argv in h.run:
            for arg in argv:
                try:
                    arg.format_map({"ip": "", "logs": "", **{n: "" for n in names}})
                except (KeyError, ValueError, IndexError) as exc:
                    raise LabError(f"{source}: host {h.name}: argument {arg!r} names no host ({exc})") from None
    return spec


def load_lab(path: str | Path) -> LabSpec:
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except FileNotFoundError:
        raise LabError(f"lab file {p} does not exist") from None
    except tomllib.TOMLDecodeError as exc:
        raise LabError(f"{p}: {exc}") from None
    return parse_lab(data, source=str(p))


def start_lab(spec: LabSpec, lab: Lab, *, ready_timeout: float = 120.0) -> dict[str, list[LabProcess]]:
    """Add the spec's hosts to ``lab`` and start each host's commands, in file order; a host with
    ``ready`` holds the later ones back until its first command prints that text."""
    for h in spec.hosts:
        lab.add_host(h.name, clock_offset=h.clock)
    addresses = {name: host.ip for name, host in lab.hosts.items()}
    started: dict[str, list[LabProcess]] = {}
    for h in spec.hosts:
        host = lab.host(h.name)
        started[h.name] = [
            host.start(
                [a.format_map({**addresses, "ip": host.ip, "logs": str(lab.log_dir)}) for a in argv], name=argv[0]
            )
            for argv in h.run
        ]
        if h.ready:
            first = started[h.name][0]
            deadline = time.monotonic() + ready_timeout
            while h.ready not in first.output():
                if not first.alive() or time.monotonic() > deadline:
                    raise LabError(
                        f"host {h.name}: {' '.join(h.run[0])} did not print {h.ready!r} "
                        f"({'it ended' if not first.alive() else f'within {ready_timeout:.0f} s'}); "
                        f"its output:\n{first.output()[-2000:]}"
                    )
                time.sleep(0.05)
    return started
