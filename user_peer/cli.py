"""``robofabric view``, ``export``, ``user`` and ``scenario``: the user peer's commands."""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Optional

import typer

from fabric.cli_common import (
    Connect,
    Joining,
    Listen,
    PeerId,
    Profile,
    UserError,
    World,
    ZenohConfig,
    join_error,
    join_flags,
    make_config,
)
from user_peer.completion import complete_export_formats, matching

RERUN_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://", "http://", "https://")


def _split_connect(connect: list[str] | None) -> tuple[list[str], list[str]]:
    """``--connect`` takes Zenoh endpoints (tcp/...) and Rerun viewer URLs (rerun+http://...): split them."""
    zenoh_eps, rerun_urls = [], []
    for c in connect or []:
        (rerun_urls if c.startswith(RERUN_SCHEMES) else zenoh_eps).append(c)
    return zenoh_eps, rerun_urls


def view(
    spawn: Annotated[bool, typer.Option("--spawn", help="Start a local Rerun viewer and stream to it.")] = False,
    serve_web: Annotated[
        bool, typer.Option("--serve-web", help="Serve a web viewer; prints the URL to open from any machine.")
    ] = False,
    advertise: Annotated[
        Optional[str],
        typer.Option(
            "--advertise",
            help="With --serve-web: this machine's name or address as other machines reach it (default: its host name).",
        ),
    ] = None,
    save: Annotated[Optional[Path], typer.Option("--save", help="Write the view to FILE.rrd.")] = None,
    duration: Annotated[
        Optional[float], typer.Option("--duration", help="Stop after S seconds (default: until Ctrl-C).")
    ] = None,
    web_port: Annotated[int, typer.Option(help="Port of the web viewer (--serve-web).")] = 9090,
    bind: Annotated[
        str,
        typer.Option(
            "--bind",
            help="With --serve-web: the IPv4 address the page and data ports listen on (default: every interface).",
        ),
    ] = "0.0.0.0",
    grpc_port: Annotated[int, typer.Option(help="Port of the Rerun gRPC server (--spawn, --serve-web).")] = 9876,
    max_hz: Annotated[float, typer.Option(help="Thin 3D and plot updates to this rate per stream (0: all).")] = 30.0,
    window: Annotated[
        float,
        typer.Option(
            help="Draw what arrived every this many seconds, as one chunk per entity (longer: less work for slow browsers, a less live view)."
        ),
    ] = 0.1,
    max_lag: Annotated[
        float,
        typer.Option(
            help="Drop samples that waited longer than this (s) when drawn, oldest first per stream; never a stream's newest."
        ),
    ] = 0.5,
    world: World = None,
    connect: Connect = None,
    listen: Listen = None,
    peer_id: PeerId = None,
    profile: Profile = None,
    zenoh_config: ZenohConfig = None,
) -> None:
    """Show a world live in Rerun: robots, scans, maps, paths, target and goal, ownership, plots.

    --connect takes both Zenoh endpoints (tcp/HOST:7447: where the router is) and Rerun viewer
    URLs (rerun+http://HOST:9876/proxy: stream to a viewer running elsewhere).
    """
    from fabric.session import shutdown_event
    from user_peer.viewer import Viewer, ViewerOptions

    zenoh_eps, rerun_urls = _split_connect(connect)
    if len(rerun_urls) > 1:
        raise UserError("give at most one Rerun viewer URL")
    if save is not None and save.suffix != ".rrd":
        raise UserError(f"--save {save}: the file must end in .rrd")
    opts = ViewerOptions(
        spawn=spawn,
        connect_url=rerun_urls[0] if rerun_urls else None,
        serve_web=serve_web,
        web_port=web_port,
        bind=bind,
        grpc_port=grpc_port,
        save=save,
        max_hz=max_hz,
        advertise=advertise,
        window_s=window,
        max_lag_s=max_lag,
    )
    if not (0 < window <= 5) or max_lag <= 0:
        raise UserError("--window must be in (0, 5] s and --max-lag positive")
    if advertise is not None and not serve_web:
        raise UserError("--advertise goes with --serve-web")
    if bind != "0.0.0.0":
        import ipaddress

        if not serve_web:
            raise UserError("--bind goes with --serve-web")
        try:
            ipaddress.IPv4Address(bind)
        except ValueError:
            raise UserError(
                f"--bind {bind}: expected an IPv4 address of this machine, e.g. 10.0.0.7 or 127.0.0.1"
            ) from None
    if not (spawn or serve_web or save or rerun_urls):
        raise UserError(
            "nowhere to show the world: give --spawn, --connect rerun+http://HOST:PORT/proxy, --serve-web or --save FILE.rrd"
        )
    cfg = make_config(world, zenoh_eps, listen, profile, zenoh_config)
    stop = shutdown_event()
    try:
        viewer = Viewer(cfg, opts, peer_id=peer_id)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    except Exception as exc:  # zenoh.ZError: no router there
        raise join_error(cfg, exc) from None
    with viewer:
        print(f"viewer on world {cfg.world!r}" + (f", saving to {save}" if save else ""), flush=True)
        if serve_web:
            from user_peer.viewer import default_advertise, web_urls

            page, grpc = web_urls(
                advertise or (bind if bind != "0.0.0.0" else default_advertise()), web_port, grpc_port
            )
            print(f"web viewer: open {page}", flush=True)
            print(
                f"  (from any machine that reaches this one; TCP ports {web_port} (page) and {grpc_port} (data {grpc}) must be open)",
                flush=True,
            )
        n = viewer.run(stop, duration)
    lag = viewer.lag_summary()
    print(
        f"viewer: {n} messages logged, {viewer.dropped} dropped, {viewer.logger.skipped} thinned"
        f"{'; ' + lag if lag else ''}; robots: {', '.join(sorted(viewer.logger.robots)) or 'none'}",
        flush=True,
    )


def export(
    src: Annotated[Path, typer.Argument(help="An MCAP recording (from robofabric record).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="The file to write: .rrd (Rerun) or .mcap (with --to).")],
    to: Annotated[
        Optional[str],
        typer.Option(
            "--to",
            help="rrd (Rerun), foxglove (Foxglove's schemas, JSON for the rest) or ros2 (CDR, ROS 2 types). Default: from -o's suffix.",
            autocompletion=complete_export_formats,
        ),
    ] = None,
    max_hz: Annotated[
        float, typer.Option(help="Rerun only: thin 3D and plot updates to this rate per stream (0: all).")
    ] = 0.0,
    scene: Annotated[
        Optional[str],
        typer.Option(help="Scene the recording was made in (places the arms, draws the walls), e.g. combined."),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
) -> None:
    """Turn a recording into a Rerun .rrd (the live viewer's views), or an MCAP that Foxglove or ROS 2 opens."""
    from user_peer.openfmt import FORMATS

    fmt = to or ("rrd" if out.suffix == ".rrd" else None)
    if fmt is None:
        raise UserError(
            f"-o {out}: say which format with --to rrd|{'|'.join(FORMATS)} (an .mcap needs --to foxglove or --to ros2)"
        )
    if fmt not in ("rrd", *FORMATS):
        raise UserError(f"--to {fmt}: expected rrd, {', '.join(FORMATS)}")
    if fmt == "rrd" and out.suffix != ".rrd":
        raise UserError(f"-o {out}: a Rerun export must end in .rrd")
    if fmt != "rrd" and out.suffix != ".mcap":
        raise UserError(f"-o {out}: a {fmt} export is an MCAP file and must end in .mcap")
    if out.resolve() == src.resolve():
        raise UserError(f"-o {out} would overwrite the recording it reads")
    with _progress(f"export {src.name} -> {out.name}", quiet) as progress:
        if fmt == "rrd":
            from user_peer.export import ExportError, export_mcap

            try:
                stats = export_mcap(src, out, max_hz=max_hz, scene=scene, progress=progress)
            except ExportError as exc:
                raise UserError(str(exc)) from None
            if stats.messages == 0:
                raise UserError(f"{src}: no readable messages")
            line = f"exported {stats.messages} messages ({stats.drawn} drawn, {stats.bad} undecodable) to {out}"
        else:
            from user_peer.openfmt import export_recording
            from user_peer.openfmt.convert import ExportError

            try:
                st = export_recording(src, out, fmt, scene=scene, progress=progress)
            except ExportError as exc:
                raise UserError(str(exc)) from None
            if st.messages == 0:
                raise UserError(f"{src}: no readable messages")
            line = (
                f"exported {st.messages} messages as {st.written} {fmt} messages ({st.bad} undecodable, "
                f"{st.skipped} without a place) to {out}"
            )
            stats = st
    print(f"{line}; robots: {', '.join(stats.robots) or 'none'}")


@contextmanager
def _progress(what: str, quiet: bool):
    """A rich progress bar on stderr; yields ``update(done, total)`` (a no-op when quiet)."""
    if quiet:
        yield lambda done, total: None
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=False,
    ) as bar:
        task = bar.add_task(what, total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


UserOpt = Annotated[
    Optional[str], typer.Option("--user", "-u", help="Your user id (default: $USER); ownership is by user id.")
]


def open_world(join: Joining, user, timeout: float = 5.0, join_timeout: float = 30.0):
    """Join the world the flags name as a user, waiting up to ``join_timeout`` s for a sim to serve it."""
    from user_peer.api import connect as _connect
    from user_peer.errors import FabricUserError

    zenoh_eps, _ = _split_connect(join.connect)
    cfg = make_config(join.world, zenoh_eps, None, join.profile, join.zenoh_config)
    try:
        return _connect(
            world=cfg.world,
            connect=list(cfg.connect),
            user=user,
            profile=cfg.profile,
            zenoh_config=cfg.config_file,
            timeout=timeout,
            join_timeout=join_timeout,
        )
    except FabricUserError as exc:  # the router answered, the world did not: say that, not "no router"
        raise UserError(exc.reason) from None
    except ValueError as exc:
        raise UserError(str(exc)) from None
    except Exception as exc:  # zenoh.ZError: no router there
        raise join_error(cfg, exc) from None


def tui_robots(kinds: dict[str, str], arm: str | None, base: str | None, world: str) -> tuple[str | None, str | None]:
    """The arm and the base the terminal UI shows: those named, else the world's first of each (``kinds``: each
    robot's kind, in the world's order); :class:`UserError` for a named robot that is not of that kind."""
    from robots.kinds import facts

    for rid, fits, what in ((arm, lambda k: k.chain, "an arm"), (base, lambda k: k.base, "a mobile")):
        if rid is not None and not fits(facts(kinds.get(rid, ""))):
            raise UserError(f"{rid!r} is not {what} robot in world {world!r}; robots: {', '.join(kinds)}")
    return (
        arm or next((r for r, k in kinds.items() if facts(k).chain), None),
        base or next((r for r, k in kinds.items() if facts(k).base), None),
    )


@join_flags(client=True)
def user(
    arm: Annotated[Optional[str], typer.Option(help="Arm to control (default: the world's first arm).")] = None,
    base: Annotated[Optional[str], typer.Option(help="Mobile base to drive (default: the world's first base).")] = None,
    user_id: UserOpt = None,
    join: Joining = Joining(),
) -> None:
    """Terminal UI: joint sliders, arrow-key driving, ownership, live joints, scan, latency."""
    from user_peer.errors import FabricUserError
    from user_peer.tui import UserApp

    w = open_world(join, user_id)
    try:
        try:
            ids = w.robots()
            kinds = {rid: w.robot(rid).kind for rid in ids}
        except FabricUserError as exc:
            raise UserError(exc.reason) from None
        arm_id, base_id = tui_robots(kinds, arm, base, w.name)
        UserApp(w, arm=w.robot(arm_id) if arm_id else None, base=w.robot(base_id) if base_id else None).run()
    finally:
        w.close()


def complete_scenarios(incomplete: str) -> list[str]:
    """Scenario names for shell completion (``robofabric scenario <TAB>``); [] if the scenarios do not load."""
    try:
        from user_peer.scenarios import SCENARIOS

        return matching(SCENARIOS, incomplete)
    except Exception:
        return []


@join_flags(client=True)
def scenario(
    name: Annotated[
        str,
        typer.Argument(
            help="test-a (arm follows the IK target) or test-b (map, plan, follow).", autocompletion=complete_scenarios
        ),
    ],
    user_id: UserOpt = None,
    robot: Annotated[
        Optional[str], typer.Option(help="Robot to use (default arm1 for test-a, base1 for test-b).")
    ] = None,
    wait: Annotated[float, typer.Option(help="Wait up to S seconds for the world (sim peer) to answer.")] = 30.0,
    join: Joining = Joining(),
) -> None:
    """Run one of the paper's scenarios as a scripted user; exit 0 on success."""
    from user_peer.errors import FabricUserError
    from user_peer.scenarios import SCENARIOS

    if name not in SCENARIOS:
        raise UserError(f"unknown scenario {name!r}; expected one of {', '.join(SCENARIOS)}")
    w = open_world(join, user_id, join_timeout=wait)
    try:
        kw = {}
        if robot:
            kw["arm_id" if name == "test-a" else "base_id"] = robot
        try:
            res = SCENARIOS[name](w, **kw)
        except FabricUserError as exc:
            print(f"[{name} {w.user}] FAILED: {type(exc).__name__}: {exc.reason}", flush=True)
            raise typer.Exit(1) from None
    finally:
        w.close()
    figures = ", ".join(f"{k}={v:.3g}" for k, v in res.figures.items())
    print(f"[{name} {res.user}] {'ok' if res.ok else 'FAILED'}: {figures}", flush=True)
    raise typer.Exit(0 if res.ok else 1)


def register(app: typer.Typer) -> None:
    from user_peer.console.cli import register as register_console

    register_console(app)
    app.command("scenario")(scenario)
    app.command("user")(user)
    app.command("view")(view)
    app.command("export")(export)
