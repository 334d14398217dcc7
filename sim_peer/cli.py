"""``robofabric sim``: run a simulation peer (its benchmarks: robofabric/bench/sim.py and failover.py)."""

from __future__ import annotations

import functools
import logging
import math
import sys
from typing import Annotated, Optional, TYPE_CHECKING

import typer

from fabric.cli_common import Joining, NothingThere, UserError, join_flags, open_fabric
from fabric.plant import check as check_plant

if TYPE_CHECKING:  # imported where used: `robofabric --help` must not load numpy
    from fabric.gate import CommandGate

log = logging.getLogger("robofabric.sim")

DEFAULT_MIRRORS = 8
"""Mirror slots a sim has by default, for the robots of other sims in its world its sensors can see (a base takes
one, an arm one per link: 8 hold one arm and one base). Unused slots are parked outside every sensor's groups
but still cost each LIDAR scan ~1 % each (docs/sim.md)."""


def make_gate(
    fabric, world, ownership: bool, restored=None, *, objects: bool = True, budgets=None, plant: str = ""
) -> CommandGate:
    """The ownership Authority when asked for and installed, else an OpenGate (with a warning if asked for).

    ``restored``: the ownership state a standby carries over when it takes the world. ``objects``: whether this
    sim is the scene objects' authority (their records); a shard joining a served world is its robots' only.
    ``budgets``: each login's budgets at the authority (:class:`ownership.admission.OwnBudgets`; None: the defaults).
    ``plant``: a test-only defect for the soak's checker (:mod:`fabric.plant`)."""
    from fabric.gate import OpenGate

    if not ownership:
        return OpenGate()
    try:
        from ownership import Authority  # lazy: the sim peer runs without the ownership package
    except ImportError as exc:
        print(f"warning: ownership is not available ({exc}); commands are not gated (OpenGate)", file=sys.stderr)
        return OpenGate()
    owned = {rid: "exclusive" for rid in world.robots}
    if objects:
        owned.update({obj: "scene" for obj in world.objects})
    if restored is not None:
        return Authority(fabric, objects=owned, restored=restored, budgets=budgets, plant=plant).start()
    return Authority(fabric, objects=owned, budgets=budgets, plant=plant).start()


def parse_twist_timeout(text: str | None, speed: float | None) -> float | None:
    """``--twist-timeout``: seconds of sim time (None: twists hold). Not given: the deadman of
    :data:`sim_peer.controllers.DEFAULT_TWIST_TIMEOUT` s of *real* time, so ``speed`` times that in sim
    time, and none at ``--speed max`` (no client can refresh a twist at a pace nobody knows)."""
    from sim_peer.controllers import DEFAULT_TWIST_TIMEOUT

    if text is None:
        return None if speed is None else DEFAULT_TWIST_TIMEOUT * speed
    if text.strip().lower() in ("none", "off", "0", "0.0"):
        return None
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"--twist-timeout must be seconds (> 0), 0 or none, got {text!r}") from None
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"--twist-timeout must be seconds (> 0), 0 or none, got {text!r}")
    return value or None


@join_flags()
def sim(
    scene: Annotated[
        str, typer.Option("--scene", "-s", help="Scene name (robots/scenes/NAME.toml) or path to a scene .toml.")
    ] = "combined",
    robot: Annotated[
        Optional[list[str]],
        typer.Option("--robot", "-r", help="Add a robot: TYPE:ID or TYPE:ID@X,Y[,YAW_DEG[,Z]] (repeatable)."),
    ] = None,
    scene_robots: Annotated[
        bool, typer.Option("--scene-robots/--no-scene-robots", help="Include the robots the scene places.")
    ] = True,
    rate: Annotated[str, typer.Option("--rate", help="Stream rates in Hz, e.g. joints=100,pose=50,scan=20.")] = "",
    speed: Annotated[
        str, typer.Option("--speed", help="1 = real time, X = X times real time, max = as fast as possible.")
    ] = "1",
    duration: Annotated[
        Optional[float], typer.Option("--duration", help="Stop after this many seconds of sim time.")
    ] = None,
    seed: Annotated[Optional[int], typer.Option("--seed", help="Seed of the sensor noise.")] = None,
    noise: Annotated[
        Optional[float], typer.Option("--noise", help="Gaussian range noise std (m) for LIDAR and ultrasonic.")
    ] = None,
    lidar_rays: Annotated[
        Optional[int], typer.Option("--lidar-rays", help="LIDAR ray count (default from the robot, 240).")
    ] = None,
    lidar_fov: Annotated[
        Optional[float], typer.Option("--lidar-fov", help="LIDAR field of view in degrees (default 135).")
    ] = None,
    twist_timeout: Annotated[
        Optional[str],
        typer.Option(
            "--twist-timeout",
            help="The twist deadman: a base brakes to a halt when no fresh twist came for this "
            "long (s of sim time); default 0.5 s of real time (0.5 x --speed; off with "
            "--speed max); 0 or none: twists hold until the next command. See docs/sim.md.",
        ),
    ] = None,
    bumper: Annotated[bool, typer.Option("--bumper/--no-bumper", help="Stop bases before obstacles ahead.")] = True,
    mirrors: Annotated[
        int,
        typer.Option(
            "--mirrors",
            help="Mirror slots for robots of other sims of the world, so this sim's sensors see them: "
            "a base takes 1, an arm 1 per link (7); each costs every LIDAR ray ~1 %; 0: none. See docs/sim.md.",
        ),
    ] = DEFAULT_MIRRORS,
    ownership: Annotated[
        bool,
        typer.Option("--ownership/--no-ownership", help="Gate commands by ownership (needs the ownership package)."),
    ] = True,
    standby: Annotated[
        bool,
        typer.Option(
            "--standby",
            help="Follow the world's primary sim and take the world over (no reset) if it goes; see docs/sim.md.",
        ),
    ] = False,
    budget: Annotated[
        str,
        typer.Option(
            "--budget",
            help="Each login's budgets at the ownership authority, RATE/BURST per second: "
            "requests=20/40,owner=200/400 (renewals, releases),queries=50/100; past them "
            "asks are refused as rate_limited. See docs/ownership.md.",
        ),
    ] = "",
    list_: Annotated[bool, typer.Option("--list", help="List the known robot types and scenes, then exit.")] = False,
    plant: Annotated[
        str, typer.Option("--plant", hidden=True, help="TEST-ONLY: a defect for the soak's checker (fabric/plant.py).")
    ] = "",
    join: Joining = Joining(),
) -> None:
    """Simulate a scene's robots and serve them on the fabric: joints, poses, scans out; commands in."""
    if list_:
        _print_catalog()
        return
    from fabric.extras import require

    require("sim", "sim")  # a student's install has no MuJoCo: one line naming the extra
    from fabric.heap import limit_arenas

    limit_arenas()  # before any session's threads: what they free is reused, not kept per thread (fabric.heap)
    from fabric.session import shutdown_event
    from sim_peer.physics.world import SimWorld
    from sim_peer.physics.world import WorldError

    rates, pace, deadman = _parse_options(rate, speed, duration, noise, twist_timeout)
    budgets = _parse_budget(budget) if ownership else None
    plant = _parse_plant(plant)
    gate_of = functools.partial(make_gate, budgets=budgets, plant=plant)

    def build(placements=None):
        """This sim's world; ``placements``: other robots than the command line's (a robot moved in or out)."""
        return SimWorld(
            scene,
            (robot or []) if placements is None else placements,
            scene_robots=scene_robots and placements is None,
            seed=seed,
            noise_std=noise,
            lidar_rays=lidar_rays,
            lidar_fov_deg=lidar_fov,
            bumper=bumper,
            twist_timeout=deadman,
            mirrors=mirrors,
        )

    try:
        sim_world = build()
    except WorldError as exc:
        raise UserError(str(exc)) from None
    if not sim_world.robots:
        raise UserError(f"scene {sim_world.scene.name!r} has no robots and none were added with --robot")
    cfg = join.config()
    first = True  # the world's first sim: the scene objects' authority too
    if not standby:
        first = _check_world_free(cfg, join.peer_id, sim_world)
    stop = shutdown_event()
    if standby or not replicated_off():
        _run_replicated(
            cfg,
            join.peer_id,
            sim_world,
            build,
            ownership,
            rates,
            pace,
            stop,
            duration,
            standby,
            first,
            gate_of,
            plant=plant,
        )
        return
    _run_single(cfg, join.peer_id, sim_world, ownership, rates, pace, stop, duration, first, gate_of)


def _parse_plant(text: str) -> str:
    """``--plant`` (test-only: the soak's launcher plants a defect this way, fabric/plant.py); an unknown one is a
    :class:`UserError` naming the known ones."""
    try:
        return check_plant(text)
    except ValueError as exc:
        raise UserError(f"--plant: {exc}") from None


def _parse_budget(text: str):
    """``--budget``'s :class:`ownership.admission.OwnBudgets` (the defaults when empty); bad text is a :class:`UserError`."""
    from ownership.admission import OwnBudgets

    try:
        return OwnBudgets.parse(text)
    except ValueError as exc:
        raise UserError(f"--budget: {exc}") from None


def _parse_options(
    rate: str, speed: str, duration: float | None, noise: float | None, twist_timeout: str | None
) -> tuple[dict[str, float], float | None, float | None]:
    """The stream rates, the pace and the twist deadman the options give; a bad option is a :class:`UserError`."""
    from fabric.rate import parse_rates
    from sim_peer.physics.pacing import parse_speed
    from sim_peer.serving.streams import DEFAULT_RATES

    try:
        rates = parse_rates(rate, DEFAULT_RATES)
        pace = parse_speed(speed)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if duration is not None and not duration > 0:
        raise UserError(f"--duration must be positive, got {duration}")
    if noise is not None and not noise >= 0:
        raise UserError(f"--noise must be >= 0, got {noise}")
    try:
        deadman = parse_twist_timeout(twist_timeout, pace)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    return rates, pace, deadman


def _run_single(cfg, peer_id, sim_world, ownership, rates, pace, stop, duration, first, make_gate=make_gate) -> None:
    """One sim, one session, no replication layer (``ROBOFABRIC_SIM_SINGLE=1``)."""
    from sim_peer.serving.peer import SimPeer

    fab = open_fabric(cfg, "sim", peer_id)
    with fab:
        gate = make_gate(fab, sim_world, ownership, objects=first)
        peer = SimPeer(fab, sim_world, gate=gate, rates=rates, speed=pace, objects=first)
        listing = ", ".join(f"{rid} ({r.desc.name})" for rid, r in sim_world.robots.items())
        pace_text = "max speed" if pace is None else ("real time" if pace == 1 else f"{pace:g}x real time")
        print(
            f"sim {fab.peer_id}: scene {sim_world.scene.name}, robots {listing}; world {fab.world}, {pace_text}; Ctrl-C to stop",
            flush=True,
        )
        try:
            peer.run(stop, duration)
        finally:
            peer.close()
            gate.close()
        _print_stopped(peer)


def _print_stopped(peer) -> None:
    c = peer.counters
    print(
        f"sim stopped at t={peer.world.time:.3f} s: {c['steps']} steps, {c['commands']} commands "
        f"({c['accepted']} accepted, {c['rejected']} rejected, {c['clamped']} clamped)",
        flush=True,
    )


def _check_world_free(cfg, peer_id, sim_world) -> bool:
    """Refuse, in one line, to serve a robot another live sim of the world serves, or another scene than the
    world's; a sim whose robots are disjoint from every live sim's joins the world as a shard (docs/sim.md,
    "Several sims, one world"). Returns whether this is the world's first sim (the scene objects' authority)."""
    if cfg.profile == "embedded":
        return True  # this process is the router: nobody is there yet
    from fabric.interfaces import ServiceError, WorldInfo
    from fabric import keys
    from fabric.session import Fabric

    try:
        probe = Fabric(cfg, kind="tool", token=False)
    except Exception as exc:
        from fabric.cli_common import join_error

        raise join_error(cfg, exc) from None
    with probe:
        others = [pid for _, pid in probe.live_peers("sim", timeout=1.0) if pid != peer_id]
        if not others:
            return True
        try:
            replies = probe.rpc.query(keys.srv(cfg.world, "world"), timeout=2.0, expected=WorldInfo, all_replies=True)
        except ServiceError:
            replies = []
    mine = set(sim_world.robots)
    for rep in replies:
        info, who = rep.message, rep.source or "another sim"
        same = sorted(mine & {r.id for r in info.robots})
        if same:
            raise UserError(
                f"robot {', '.join(same)} is already served by sim {who} in world {cfg.world!r}; give it another "
                f"id, or run this sim with --standby to follow {who}"
            )
        if info.scene != sim_world.scene.name:
            raise UserError(
                f"world {cfg.world!r} runs scene {info.scene!r} (sim {who}), not {sim_world.scene.name!r}: every "
                f"sim of a world loads the same scene"
            )
    if replies:
        served = ", ".join(f"{r.source} ({', '.join(x.id for x in r.message.robots)})" for r in replies)
        print(
            f"sim {peer_id or 'this sim'}: joining world {cfg.world!r} as a shard beside {served}; the scene objects stay "
            f"with the first sim",
            file=sys.stderr,
            flush=True,
        )
        return False
    print(
        f"warning: sim {', '.join(others)} is live in world {cfg.world!r} but did not describe it (a standby alone, "
        f"or access control): starting anyway",
        file=sys.stderr,
    )
    return True


def replicated_off() -> bool:
    """ROBOFABRIC_SIM_SINGLE=1 runs the sim without the replication layer (no srv/state, term 0)."""
    import os

    return os.environ.get("ROBOFABRIC_SIM_SINGLE", "") not in ("", "0")


def _run_replicated(
    cfg,
    peer_id,
    first_world,
    build,
    ownership,
    rates,
    pace,
    stop,
    duration,
    standby,
    objects=True,
    gate_of=make_gate,
    plant: str = "",
) -> None:
    """Primary or standby through :func:`sim_peer.replica.replica_host.run_replicated`."""
    from fabric.config import default_peer_id
    from sim_peer.replica.replica_host import run_replicated

    pid = peer_id or default_peer_id("sim")  # one id across sessions: a primary that steps down stays itself
    worlds = [first_world]

    def make_world():
        return worlds.pop() if worlds else build()

    def announce(text: str) -> None:
        print(text, flush=True)

    robots = ", ".join(f"{rid} ({r.desc.name})" for rid, r in first_world.robots.items())
    pace_text = "max speed" if pace is None else ("real time" if pace == 1 else f"{pace:g}x real time")
    print(
        f"sim {pid}{' (standby)' if standby else ''}: scene {first_world.scene.name}, robots {robots}; world {cfg.world}, "
        f"{pace_text}; Ctrl-C to stop",
        flush=True,
    )
    host = run_replicated(
        lambda: open_fabric(cfg, "sim", pid),
        make_world,
        lambda fab, w, restored, objects=True: gate_of(fab, w, ownership, restored, objects=objects),
        stop,
        standby=standby,
        rates=rates,
        speed=pace,
        duration=duration,
        announce=announce,
        objects=objects,
        rebuild=build,
        plant=plant,
    )
    peer = host.peer if host is not None else None
    if peer is None:
        print(f"sim {pid} stopped as a standby", flush=True)
        return
    _print_stopped(peer)


def _print_catalog() -> None:
    import robots

    print("robot types:")
    for name in robots.available_robots():
        try:
            d = robots.load(name)
            print(f"  {name:<12} {d.kind:<7} {d.dof} joints  {d.description}")
        except robots.DescriptionError as exc:
            print(f"  {name:<12} (broken: {exc})")
    print("scenes:")
    for name in robots.available_scenes():
        try:
            sc = robots.scene(name)
            who = ", ".join(f"{r.id} ({r.type})" for r in sc.robots) or "no robots"
            print(f"  {name:<12} {who}; objects {', '.join(o.id for o in sc.objects) or 'none'}")
        except robots.DescriptionError as exc:
            print(f"  {name:<12} (broken: {exc})")


@join_flags(client=True)
def move_cmd(
    robot: Annotated[str, typer.Argument(help="Robot id.")],
    to: Annotated[
        str, typer.Option("--to", help="The sim peer (its id, as `robofabric ps` lists it) to serve the robot.")
    ],
    join: Joining = Joining(),
) -> None:
    """Hand ROBOT, its state and its ownership from its sim to sim TO (rebalancing a world of several sims).

    Its owner keeps it and her epoch; see docs/sim.md, "Moving a robot between sims". In a class world only the
    instructor and sim logins may move robots (docs/security.md)."""
    from sim_peer.shards.handoff import MoveError, move

    with join.open("tool") as fab:
        try:
            done = move(fab, robot, to)
        except MoveError as exc:  # a sim refused, none answered, or none serves it: the world said no (exit 1)
            raise NothingThere(f"robot {robot} not moved: {exc}") from None
    print(
        f"moved {done['robot']} from sim {done['from']} to sim {done['to']} (term {done['term']}) in {done['pause_ms']:.0f} ms",
        flush=True,
    )


def register(app: typer.Typer) -> None:
    from ownership.cli import own_app

    app.command("sim")(sim)
    own_app.command("move")(
        move_cmd
    )  # moving a robot hands its ownership over: an `own` subcommand, served by the sims
