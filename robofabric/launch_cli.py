"""``robofabric up`` and ``robofabric demo``: run a launch file's peers on this machine."""

from __future__ import annotations

import dataclasses

import threading
import time
from collections import Counter
from pathlib import Path
from typing import Annotated, Optional, TYPE_CHECKING

import typer
import zenoh

from fabric import keys
from fabric.cli_common import UserError
from fabric.config import FabricConfig

if TYPE_CHECKING:  # imported where used: `robofabric --help` must not load numpy
    from robofabric.launch import LaunchSpec, Supervisor
    from fabric.session import Fabric

DEMO_RESOURCE = "demo.toml"
"""The demo's launch file ships inside the package (``robofabric/demo.toml``; ``examples/demo.toml`` links to it)."""


def load_demo_spec() -> LaunchSpec:
    """The built-in demo's launch spec, read from the installed package (works from a wheel, not only a checkout)."""
    from robofabric.launch import LaunchError, parse_launch
    from importlib.resources import files

    res = files("robofabric").joinpath(DEMO_RESOURCE)
    try:
        text = res.read_text(encoding="utf-8")
    except OSError as exc:
        raise LaunchError(f"the built-in demo launch file {res} cannot be read: {exc}") from None
    return parse_launch(text, str(res))


class _Watch:
    """What the launcher sees of the world: live peers and message counts per key."""

    def __init__(self, fab: Fabric) -> None:
        self.fab = fab
        self.peers_seen: set[tuple[str, str]] = set()
        self.counts: Counter[str] = Counter()
        self.bytes = 0
        self._lock = threading.Lock()
        fab.watch_peers(self._on_peer)
        fab.subscribe_raw(keys.world_all(fab.world), self._on_sample)

    def _on_peer(self, kind: str, pid: str, alive: bool) -> None:
        if alive:
            with self._lock:
                self.peers_seen.add((kind, pid))

    def _on_sample(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            p = keys.parse(key)
            label = {"robot": f"robot/*/{p.leaf}", "cmd": f"robot/*/cmd/{p.leaf}", "event": f"event/{p.subject}"}.get(
                p.category, p.category
            )
        except ValueError:
            label = "other"
        with self._lock:
            self.counts[label] += 1
            self.bytes += len(sample.payload)

    def is_ready(self, expr: str) -> bool:
        try:
            return bool(self.fab.live_tokens(expr, timeout=0.5))
        except Exception:
            return False


def _open_launcher(spec: LaunchSpec, router: str | None) -> Fabric:
    from fabric.session import Fabric

    ep = router or spec.router
    try:
        if ep:
            cfg = FabricConfig(world=spec.world, profile="embedded", listen=(ep,), config_file=spec.zenoh_config)
        else:
            cfg = FabricConfig(
                world=spec.world, profile="client", connect=spec.child_connect(), config_file=spec.zenoh_config
            )
    except ValueError as exc:  # a zenoh_config that is not there: say which
        raise UserError(f"{spec.path}: {exc}") from None
    try:
        return Fabric(cfg, kind="router" if ep else "tool", peer_id="launch-router" if ep else None)
    except Exception as exc:
        said = cfg.join_failure(exc)  # the one line every command gives: a refused login names the identity
        if not ep or said.startswith("authentication failed"):
            raise UserError(said) from None  # joining another router: no router of ours, no port of ours
        raise UserError(
            f"cannot start the launch's router on {ep}: {exc} (is another router using that port?)"
        ) from None


def _run(spec: LaunchSpec, *, out: Path, duration: float | None, router: str | None, demo: bool) -> int:
    from robofabric.launch import Supervisor
    from fabric.session import shutdown_event

    out.mkdir(parents=True, exist_ok=True)
    stop = shutdown_event()
    if router:
        spec = dataclasses.replace(spec, router=router)
    with _open_launcher(spec, router) as fab:
        watch = _Watch(fab)
        sup = Supervisor(spec, out_dir=out, is_ready=watch.is_ready)
        where = spec.router or ", ".join(spec.child_connect())
        sup.say(f"world {spec.world!r} via {where}; {len(spec.peers)} peer(s) from {spec.path}; output in {out}")
        if spec.args:
            sup.say("arguments: " + ", ".join(f"{k}={v}" for k, v in spec.args))
        t0 = time.monotonic()
        starter = threading.Thread(target=sup.start_all, daemon=True)
        starter.start()
        reason = "stopped by signal"
        while True:
            if stop.wait(0.2):
                break
            sup.poll()
            if not starter.is_alive() and sup.tasks_done():
                reason = "all tasks finished"
                break
            if duration is not None and time.monotonic() - t0 >= duration:
                reason = f"duration of {duration:.0f} s reached"
                break
            if not starter.is_alive() and sup.peers and all(p.done for p in sup.peers.values()):
                reason = "every peer exited"
                break
        sup.say(f"{reason}; stopping peers")
        sup.stop_all()
        elapsed = time.monotonic() - t0
        # Give the network a moment to drain tokens we no longer care about; the summary is what we saw.
        return _summary(sup, watch, elapsed, out, demo)


def _summary(sup: Supervisor, watch: _Watch, elapsed: float, out: Path, demo: bool) -> int:
    from rich.console import Console
    from rich.table import Table

    console = Console()
    table = Table(title=f"{'demo' if demo else 'launch'} summary: {elapsed:.1f} s")
    table.add_column("peer")
    table.add_column("role")
    table.add_column("exit")
    table.add_column("restarts")
    table.add_column("last word")
    failed = []
    for pp in sup.peers.values():
        code = pp.exit_code
        status = "-" if code is None else str(code)
        if pp.spec.role == "task" and code != 0:
            failed.append(pp.spec.name)
            status = f"[red]{status}[/red]"
        table.add_row(pp.spec.name, pp.spec.role, status, str(pp.restarts), pp.last_line[:100])
    console.print(table)
    kinds = Counter(k for k, _ in watch.peers_seen)
    console.print("peers seen: " + (", ".join(f"{n} {k}" for k, n in sorted(kinds.items())) or "none"))
    if watch.counts:
        t2 = Table(title="messages seen by the launcher")
        t2.add_column("keys")
        t2.add_column("messages", justify="right")
        t2.add_column("rate (Hz)", justify="right")
        for label, n in sorted(watch.counts.items()):
            t2.add_row(label, str(n), f"{n / max(elapsed, 1e-9):.1f}")
        console.print(t2)
        console.print(f"total {sum(watch.counts.values())} messages, {watch.bytes / 1e6:.2f} MB")
    files = sorted(p for p in out.iterdir() if p.is_file())
    for f in files:
        console.print(f"wrote {f} ({f.stat().st_size / 1e6:.2f} MB)")
    if failed:
        console.print(f"[red]failed: {', '.join(failed)}[/red] (logs in {out / 'logs'})")
        return 1
    console.print("[green]ok[/green]")
    return 0


def up(
    file: Annotated[
        Path, typer.Argument(help="Launch file (TOML): [args], [launch] world/router/connect and [[peer]] entries.")
    ],
    args: Annotated[
        Optional[list[str]],
        typer.Argument(
            help="NAME=VALUE launch arguments: the file's [args] (env ROBOFABRIC_NAME otherwise), or world=, router=, connect= for any file.",
            show_default=False,
        ),
    ] = None,
    out: Annotated[Path, typer.Option(help="Directory for peers' output and logs.")] = Path("out/launch"),
    duration: Annotated[
        Optional[float], typer.Option(help="Stop everything after S seconds (default: until Ctrl-C).")
    ] = None,
    router: Annotated[
        Optional[str], typer.Option(help="Host the router on this endpoint instead of the file's.")
    ] = None,
    zenoh_config: Annotated[
        Optional[Path],
        typer.Option(
            "--zenoh-config",
            help="This launcher's own zenoh config (the router's where it hosts one), instead of [launch] zenoh_config.",
        ),
    ] = None,
) -> None:
    """Start the peers a launch file lists on this machine; restart per policy; Ctrl-C stops them all.

    Example: robofabric up examples/lan/sim.toml connect=tcp/10.0.0.5:7447 world=lab2
    """
    from robofabric.launch import LaunchError, load_launch
    import os

    from robofabric.launch import parse_cli_args

    try:
        spec = load_launch(file, args=parse_cli_args(args or []), env=dict(os.environ))
    except LaunchError as exc:
        raise UserError(str(exc)) from None
    if zenoh_config is not None:
        spec = dataclasses.replace(spec, zenoh_config=str(zenoh_config))
    raise typer.Exit(_run(spec, out=out, duration=duration, router=router, demo=False))


def demo(
    duration: Annotated[float, typer.Option(help="Upper bound on the demo's length in seconds.")] = 180.0,
    out: Annotated[Path, typer.Option(help="Output directory (demo.rrd, demo.mcap, logs).")] = Path("out/demo"),
    launch: Annotated[Optional[Path], typer.Option(help="Launch file to run instead of the built-in demo.")] = None,
    router: Annotated[
        Optional[str], typer.Option(help="Router endpoint (default from the launch file, tcp/127.0.0.1:7447).")
    ] = None,
) -> None:
    """Run the embedded default: router, sim peer with both robots, compute peer and scripted users."""
    from robofabric.launch import LaunchError, load_launch

    try:
        spec = load_launch(launch) if launch is not None else load_demo_spec()
    except LaunchError as exc:
        raise UserError(str(exc)) from None
    raise typer.Exit(_run(spec, out=out, duration=duration, router=router, demo=True))


def register(app: typer.Typer) -> None:
    app.command("up")(up)
    app.command("demo")(demo)
