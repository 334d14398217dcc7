"""Launch files: which peers to start on this machine, and the supervisor that runs them.

A launch file is TOML (see ``robofabric/demo.toml``, the demo, also at ``examples/demo.toml``)::

    [launch]
    world = "demo"
    router = "tcp/127.0.0.1:7447"   # this process hosts the router here (omit on machines that only connect)
    connect = ["tcp/10.0.0.5:7447"] # where children connect (default: the router above)
    zenoh_config = "class/router.json5"  # optional: this process's own zenoh config (examples/secure/)

    [[peer]]
    name = "sim"
    args = ["sim", "--scene", "combined"]  # a robofabric subcommand; --world and --connect are appended
    role = "service"                       # service: runs until the launch ends; task: awaited, exit code reported
    restart = "on-failure"                 # no | on-failure | always (services)
    after = ["sim"]                        # start once these peers are ready
    ready = "peer/sim/*"                   # liveliness key expression that says this peer is ready

``{out}`` and ``{world}`` in args are replaced by the output directory and the world.

Arguments instead of hard-coded addresses: a file may declare ``[args]`` with defaults and use
them as ``{name}`` in any string of ``[launch]`` and ``[[peer]]``::

    [args]
    connect = "tcp/10.0.0.5:7447"     # the router machine
    [launch]
    connect = ["{connect}"]           # a comma-separated value becomes several endpoints

Each argument's value is, first to last: ``NAME=VALUE`` on the command line
(``robofabric up FILE connect=tcp/10.0.0.9:7447``), the environment variable ``ROBOFABRIC_NAME``
(``ROBOFABRIC_CONNECT``), the file's default. ``world=``, ``router=`` and ``connect=`` on the command
line also work for files that declare no such argument: they replace ``[launch]``'s value.
Parsing (pure) is apart from supervising (processes), so mistakes in a file are
reported with its name and line before anything starts.
"""

from __future__ import annotations

import logging
import os
import re
import signal
import subprocess
import sys
import threading
import time
import tomllib
from dataclasses import dataclass, field
from logging.handlers import RotatingFileHandler
from pathlib import Path
from typing import Any, Callable, TextIO

from fabric import keys

ROLES = ("service", "task")
BUILTIN_ARGS = ("world", "router", "connect")
_ARG_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_PLACEHOLDER = re.compile(r"\{([A-Za-z_][A-Za-z0-9_]*)\}")
RESTARTS = ("no", "on-failure", "always")
_DEFAULT_READY = {
    "sim": "peer/sim/*",
    "compute": "peer/compute/*",
    "view": "peer/viewer/*",
    "record": "peer/recorder/*",
}


class LaunchError(ValueError):
    """A launch file is wrong; the message names the file and, where known, the line."""


@dataclass(frozen=True, slots=True)
class PeerSpec:
    name: str
    args: tuple[str, ...]
    role: str = "service"
    restart: str = "on-failure"
    after: tuple[str, ...] = ()
    ready: str | None = None
    max_restarts: int = 5
    env: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True, slots=True)
class LaunchSpec:
    path: str
    world: str = "demo"
    router: str | None = None
    connect: tuple[str, ...] = ()
    peers: tuple[PeerSpec, ...] = field(default=())
    args: tuple[tuple[str, str], ...] = ()  # the arguments' values as resolved (command line > env > default)
    zenoh_config: str | None = None  # the launcher's own session: the router's config when it hosts one, else a login

    def child_connect(self) -> tuple[str, ...]:
        if self.connect:
            return self.connect
        if self.router:
            return (self.router.replace("0.0.0.0", "127.0.0.1"),)
        return ()


def _peer_lines(text: str) -> list[int]:
    return [i + 1 for i, line in enumerate(text.splitlines()) if re.match(r"^\s*\[\[\s*peer\s*\]\]", line)]


def parse_cli_args(items: list[str] | tuple[str, ...]) -> dict[str, str]:
    """``["connect=tcp/h:7447", "world=lab2"]`` -> a dict; ``LaunchError`` for anything not NAME=VALUE."""
    out: dict[str, str] = {}
    for item in items:
        name, eq, value = item.partition("=")
        if not eq or not _ARG_NAME.match(name):
            raise LaunchError(
                f"launch argument {item!r} is not NAME=VALUE (e.g. connect=tcp/10.0.0.5:7447, world=lab2)"
            )
        out[name] = value
    return out


def resolve_args(declared: dict[str, Any], given: dict[str, str], env: dict[str, str], path: str) -> dict[str, str]:
    """Values of a file's ``[args]``: command line, then ``ROBOFABRIC_NAME`` in ``env``, then the default."""
    values: dict[str, str] = {}
    for name, default in declared.items():
        if not _ARG_NAME.match(name):
            raise LaunchError(f"{path}: [args] name {name!r} must be letters, digits and _")
        if isinstance(default, bool) or not isinstance(default, (str, int, float)):
            raise LaunchError(f"{path}: [args] {name} must have a string or number default")
        env_value = env.get(f"ROBOFABRIC_{name.upper()}")
        values[name] = given[name] if name in given else env_value if env_value is not None else str(default)
    unknown = set(given) - set(declared) - set(BUILTIN_ARGS)
    if unknown:
        takes = ", ".join(sorted({*declared, *BUILTIN_ARGS}))
        raise LaunchError(f"{path}: unknown launch argument(s) {', '.join(sorted(unknown))}; this file takes {takes}")
    return values


def _substitute(obj: Any, values: dict[str, str]) -> Any:
    """``{name}`` of declared arguments replaced in every string of a TOML value (others left for later)."""
    if isinstance(obj, str):
        return _PLACEHOLDER.sub(lambda m: values.get(m.group(1), m.group(0)), obj)
    if isinstance(obj, list):
        return [_substitute(x, values) for x in obj]
    if isinstance(obj, dict):
        return {k: _substitute(v, values) for k, v in obj.items()}
    return obj


def parse_launch(
    text: str, path: str = "<launch>", *, args: dict[str, str] | None = None, env: dict[str, str] | None = None
) -> LaunchSpec:
    """Parse and check a launch file's text; raise :class:`LaunchError` naming file and line.

    ``args``: NAME=VALUE arguments from the command line; ``env``: where ``ROBOFABRIC_NAME``
    overrides are read (default: none, so parsing stays pure; the CLI passes ``os.environ``).
    """
    data = _load_toml(text, path)
    declared = data.pop("args", {})
    if not isinstance(declared, dict):
        raise LaunchError(f"{path}: [args] must be a table of NAME = default")
    given = dict(args or {})
    values = resolve_args(declared, given, dict(env or {}), path)
    data = _substitute(data, values)
    overrides = {name: given[name] for name in BUILTIN_ARGS if name in given and name not in declared}
    head = _parse_head(data.get("launch", {}), overrides, path)
    peers = _parse_peers(data.get("peer", []), _peer_lines(text), head.world, path)
    return LaunchSpec(
        path=path,
        world=head.world,
        router=head.router,
        connect=head.connect,
        peers=peers,
        args=tuple(sorted(values.items())),
        zenoh_config=head.zenoh_config,
    )


def _load_toml(text: str, path: str) -> dict[str, Any]:
    """The file's tables, with a known section name each."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise LaunchError(f"{path}: {exc}") from None
    unknown = set(data) - {"launch", "peer", "args"}
    if unknown:
        raise LaunchError(
            f"{path}: unknown section(s) {', '.join(sorted(unknown))} (expected [args], [launch] and [[peer]])"
        )
    return data


@dataclass(frozen=True, slots=True)
class _Head:
    """What ``[launch]`` says, checked."""

    world: str
    router: str | None
    connect: tuple[str, ...]
    zenoh_config: str | None


def _parse_head(head: Any, overrides: dict[str, str], path: str) -> _Head:
    """``[launch]``, with ``world=``/``router=``/``connect=`` from the command line in place of its values."""
    if not isinstance(head, dict):
        raise LaunchError(f"{path}: [launch] must be a table")
    bad = set(head) - {"world", "router", "connect", "zenoh_config"}
    if bad:
        raise LaunchError(f"{path}: [launch] has unknown key(s) {', '.join(sorted(bad))}")
    head = {**head, **overrides}
    world = head.get("world", "demo")
    try:
        keys.validate_id(world, what="world")
    except ValueError as exc:
        raise LaunchError(f"{path}: [launch] {exc}") from None
    router = _parse_router(head.get("router"), path)
    connect = _parse_connect(head.get("connect", []), path)
    zenoh_config = head.get("zenoh_config") or None
    if zenoh_config is not None and not isinstance(zenoh_config, str):
        raise LaunchError(f"{path}: [launch] zenoh_config must be a file name, e.g. 'class/router.json5'")
    return _Head(world, router, connect, zenoh_config)


def _parse_router(router: Any, path: str) -> str | None:
    """The endpoint this process hosts the router on; None (an empty ``{router}`` included): none here."""
    if router is not None and not isinstance(router, str):
        raise LaunchError(f"{path}: [launch] router must be an endpoint string like 'tcp/0.0.0.0:7447'")
    return router if router is not None and router.strip() else None


def _parse_connect(connect: Any, path: str) -> tuple[str, ...]:
    """The children's endpoints: a string or a list of them, each possibly comma-separated (``"{connect}"``)."""
    if isinstance(connect, str):
        connect = [connect]
    if not isinstance(connect, list) or not all(isinstance(c, str) for c in connect):
        raise LaunchError(f"{path}: [launch] connect must be a list of endpoint strings")
    return tuple(e.strip() for c in connect for e in c.split(",") if e.strip())


_PEER_KEYS = {"name", "args", "role", "restart", "after", "ready", "max_restarts", "env"}


def _parse_peers(raw_peers: Any, lines: list[int], world: str, path: str) -> tuple[PeerSpec, ...]:
    """Every ``[[peer]]`` in file order; ``after`` may name only earlier ones, so the order starts them."""
    if not isinstance(raw_peers, list):
        raise LaunchError(f"{path}: 'peer' must be an array of tables ([[peer]])")
    peers: list[PeerSpec] = []
    names: set[str] = set()
    for i, p in enumerate(raw_peers):
        where = f"{path}:{lines[i]}" if i < len(lines) else path
        spec = _parse_peer(p, names, world, where)
        names.add(spec.name)
        peers.append(spec)
    return tuple(peers)


def _parse_peer(p: dict[str, Any], earlier: set[str], world: str, where: str) -> PeerSpec:
    """One ``[[peer]]`` table; ``earlier``: the names of the peers before it."""
    unknown = set(p) - _PEER_KEYS
    if unknown:
        raise LaunchError(f"{where}: peer has unknown key(s) {', '.join(sorted(unknown))}")
    name = p.get("name")
    if not isinstance(name, str) or not name:
        raise LaunchError(f"{where}: every [[peer]] needs a name")
    if name in earlier:
        raise LaunchError(f"{where}: peer name {name!r} is used twice")
    args = p.get("args")
    if not isinstance(args, list) or not args or not all(isinstance(a, str) for a in args):
        raise LaunchError(f'{where}: peer {name!r} needs args = ["SUBCOMMAND", ...] (a non-empty list of strings)')
    role, restart, max_restarts = _parse_policy(p, name, where)
    after = p.get("after", [])
    if isinstance(after, str):
        after = [after]
    missing = [a for a in after if a not in earlier]
    if missing:
        raise LaunchError(
            f"{where}: peer {name!r} starts after {', '.join(missing)}, which no earlier [[peer]] defines"
        )
    env = p.get("env", {})
    if not isinstance(env, dict):
        raise LaunchError(f"{where}: peer {name!r} env must be a table of strings")
    return PeerSpec(
        name=name,
        args=tuple(args),
        role=role,
        restart=restart,
        after=tuple(after),
        ready=_parse_ready(p.get("ready", _DEFAULT_READY.get(args[0])), name, world, where),
        max_restarts=max_restarts,
        env=tuple((str(k), str(v)) for k, v in env.items()),
    )


def _parse_policy(p: dict[str, Any], name: str, where: str) -> tuple[str, str, int]:
    """(role, restart, max_restarts): a service restarts on failure unless told otherwise, a task never."""
    role = p.get("role", "service")
    if role not in ROLES:
        raise LaunchError(f"{where}: peer {name!r} has role {role!r}; expected one of {', '.join(ROLES)}")
    restart = p.get("restart", "on-failure" if role == "service" else "no")
    if restart not in RESTARTS:
        raise LaunchError(f"{where}: peer {name!r} has restart {restart!r}; expected one of {', '.join(RESTARTS)}")
    max_restarts = p.get("max_restarts", 5)
    if not isinstance(max_restarts, int) or max_restarts < 0:
        raise LaunchError(f"{where}: peer {name!r} max_restarts must be a non-negative integer")
    return role, restart, max_restarts


def _parse_ready(ready: Any, name: str, world: str, where: str) -> str | None:
    """The liveliness key expression that says the peer is ready (world-relative or full), checked now so
    that a bad one is named with its line before anything starts."""
    if ready is None:
        return None
    if not isinstance(ready, str):
        raise LaunchError(f"{where}: peer {name!r} ready must be a key expression string like 'peer/sim/*'")
    try:
        keys.in_world(ready, world)
    except ValueError as exc:
        raise LaunchError(f"{where}: peer {name!r} ready: {exc}") from None
    return ready


def load_launch(
    path: str | Path, *, args: dict[str, str] | None = None, env: dict[str, str] | None = None
) -> LaunchSpec:
    p = Path(path)
    if not p.is_file():
        raise LaunchError(f"{path}: no such launch file")
    return parse_launch(p.read_text(), str(path), args=args, env=env)


# --------------------------------------------------------------------------- supervisor


@dataclass
class PeerProcess:
    spec: PeerSpec
    proc: subprocess.Popen | None = None
    restarts: int = 0
    exit_code: int | None = None
    started_at: float = 0.0
    done: bool = False
    last_line: str = ""  # the last thing it printed: a task's verdict for the summary


class Supervisor:
    """Starts a launch spec's peers as child processes, restarts services per policy, stops them all.

    Output of each child is prefixed with its name on ``console`` and kept in ``out/logs/NAME.log``,
    rotated at ``log_max_bytes`` into ``NAME.log.1`` .. ``NAME.log.{log_backups}`` (stdlib
    ``RotatingFileHandler``): a chatty or flooded peer cannot fill the disk.
    ``is_ready(expr)`` says whether a liveliness key expression has a live token (given by the caller,
    which holds the session), so the supervisor itself stays free of zenoh.
    """

    def __init__(
        self,
        spec: LaunchSpec,
        *,
        out_dir: Path,
        is_ready: Callable[[str], bool],
        console: TextIO = sys.stdout,
        extra_args: tuple[str, ...] = (),
        ready_timeout: float = 60.0,
        log_max_bytes: int = 10_000_000,
        log_backups: int = 3,
    ) -> None:
        self.spec = spec
        self.log_max_bytes = log_max_bytes
        self.log_backups = log_backups
        self.out_dir = out_dir
        self.is_ready = is_ready
        self.console = console
        self.extra_args = extra_args
        self.ready_timeout = ready_timeout
        self.peers: dict[str, PeerProcess] = {p.name: PeerProcess(p) for p in spec.peers}
        self._lock = threading.Lock()
        self._stopping = False
        (out_dir / "logs").mkdir(parents=True, exist_ok=True)

    def _argv(self, spec: PeerSpec) -> list[str]:
        sub = {"{out}": str(self.out_dir), "{world}": self.spec.world}
        args = []
        for a in spec.args:
            for k, v in sub.items():
                a = a.replace(k, v)
            args.append(a)
        argv = [sys.executable, "-m", "robofabric.cli", *args, "--world", self.spec.world]
        for ep in self.spec.child_connect():
            argv += ["--connect", ep]
        return argv + list(self.extra_args)

    def pump(self, name: str, stream, log_path: Path) -> None:
        """Copy peer ``name``'s output (bytes lines) into its rotating log until the stream ends; its last line is
        kept as the peer's ``last_line``. Runs on a thread of its own per peer."""
        log = RotatingFileHandler(log_path, maxBytes=self.log_max_bytes, backupCount=self.log_backups, encoding="utf-8")
        log.setFormatter(logging.Formatter("%(message)s"))
        try:
            for line in iter(stream.readline, b""):
                text = line.decode(errors="replace").rstrip("\n")
                log.emit(logging.makeLogRecord({"msg": text, "args": None}))
                text = text.rstrip()
                with self._lock:
                    if text.strip():
                        self.peers[name].last_line = text.strip()
                    print(f"[{name}] {text}", file=self.console, flush=True)
        finally:
            log.close()

    def _spawn(self, pp: PeerProcess) -> None:
        argv = self._argv(pp.spec)
        env = {**os.environ, "PYTHONUNBUFFERED": "1", **dict(pp.spec.env)}
        pp.proc = subprocess.Popen(
            argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, start_new_session=True
        )
        pp.started_at = time.monotonic()
        pp.exit_code = None
        threading.Thread(
            target=self.pump,
            args=(pp.spec.name, pp.proc.stdout, self.out_dir / "logs" / f"{pp.spec.name}.log"),
            daemon=True,
        ).start()
        self.say(f"started {pp.spec.name} (pid {pp.proc.pid}): robofabric {' '.join(argv[3:])}")

    def say(self, text: str) -> None:
        with self._lock:
            print(f"[launch] {text}", file=self.console, flush=True)

    def _wait_ready(self, name: str, deadline: float) -> bool:
        pp = self.peers[name]
        expr = pp.spec.ready
        if expr is None:
            return True
        full = keys.in_world(expr, self.spec.world)  # checked by parse_launch
        while time.monotonic() < deadline and not self._stopping:
            if self.is_ready(full):
                return True
            if pp.proc is not None and pp.proc.poll() is not None:
                return False
            time.sleep(0.1)
        return False

    def start_all(self) -> None:
        for spec in self.spec.peers:
            for dep in spec.after:
                if not self._wait_ready(dep, time.monotonic() + self.ready_timeout):
                    self.say(f"warning: {dep} not ready after {self.ready_timeout:.0f} s; starting {spec.name} anyway")
            if self._stopping:
                return
            self._spawn(self.peers[spec.name])

    def poll(self) -> None:
        """Reap exited children and restart services per their policy."""
        for pp in self.peers.values():
            if pp.proc is None or pp.done or pp.proc.poll() is None:
                continue
            code = pp.proc.returncode
            pp.exit_code = code
            if self._stopping:
                pp.done = True
                continue
            if pp.spec.role == "task":
                pp.done = True
                self.say(f"{pp.spec.name} finished with exit code {code}")
                continue
            again = pp.spec.restart == "always" or (pp.spec.restart == "on-failure" and code != 0)
            if again and pp.restarts < pp.spec.max_restarts:
                pp.restarts += 1
                self.say(f"{pp.spec.name} exited with code {code}; restart {pp.restarts}/{pp.spec.max_restarts}")
                time.sleep(min(2.0, 0.2 * 2**pp.restarts))
                self._spawn(pp)
            else:
                pp.done = True
                self.say(f"{pp.spec.name} exited with code {code}; not restarted")

    def tasks_done(self) -> bool:
        tasks = [p for p in self.peers.values() if p.spec.role == "task"]
        return bool(tasks) and all(p.done for p in tasks)

    def stop_all(self, grace: float = 5.0) -> None:
        """SIGINT (so peers flush recordings), then SIGTERM, then SIGKILL, each by pid."""
        self._stopping = True
        live = [p for p in self.peers.values() if p.proc is not None and p.proc.poll() is None]
        for sig, wait in ((signal.SIGINT, grace), (signal.SIGTERM, 3.0), (signal.SIGKILL, 3.0)):
            for pp in live:
                if pp.proc.poll() is None:
                    try:
                        os.kill(pp.proc.pid, sig)
                    except ProcessLookupError:
                        pass
            deadline = time.monotonic() + wait
            while time.monotonic() < deadline and any(p.proc.poll() is None for p in live):
                time.sleep(0.05)
            live = [p for p in live if p.proc.poll() is None]
            if not live:
                break
        self.poll()
