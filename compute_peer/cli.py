"""``robofabric compute``: run a compute peer (its benchmarks: robofabric/bench/ik.py and nav.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from fabric.cli_common import Joining, UserError, join_flags


@join_flags()
def compute(
    stream: Annotated[
        Optional[list[str]],
        typer.Option(
            "--stream",
            help="Stream IK for ROBOT:OBJECT (the arm follows the object's pose; repeatable), e.g. arm1:target.",
        ),
    ] = None,
    arm: Annotated[
        Optional[list[str]],
        typer.Option(
            "--arm",
            help="Serve an arm without asking a sim: ID:TYPE[@X,Y,Z[,YAW_DEG]] (repeatable), e.g. arm1:meca500@3,0,0.75.",
        ),
    ] = None,
    stream_rate: Annotated[float, typer.Option("--stream-rate", help="IK streaming rate in Hz.")] = 20.0,
    kinematics: Annotated[
        bool, typer.Option("--kinematics/--no-kinematics", help="Serve srv/ik, srv/fk, srv/jacobian.")
    ] = True,
    navigation: Annotated[
        bool, typer.Option("--navigation/--no-navigation", help="Serve srv/map and srv/plan; map from scans.")
    ] = True,
    mapping: Annotated[
        bool, typer.Option("--mapping/--no-mapping", help="Accumulate scans from the start (else on srv/map start).")
    ] = True,
    maps_dir: Annotated[
        Optional[Path],
        typer.Option("--maps-dir", help="The only folder map save/load may use (default: saving disabled)."),
    ] = None,
    duration: Annotated[Optional[float], typer.Option("--duration", help="Stop after this many seconds.")] = None,
    join: Joining = Joining(),
) -> None:
    """Serve kinematics (IK, FK, Jacobian, IK streaming) and navigation (mapping, Hybrid A*/OMPL plans) to a world.

    Several compute peers may serve one world: a query on srv/ik/ROBOT goes to the nearest one, and
    srv/ik/ROBOT/PEER_ID to one chosen peer. Arms and sensors are learnt from the sim peer's srv/world.
    """
    from fabric.extras import require

    require("compute", "compute")  # a student's install has no Pinocchio, CasADi, OMPL: one line naming the extra
    from compute_peer.peer import ComputeOptions, ComputePeer, parse_arms, parse_streams
    from fabric.heap import HeapTrimmer, limit_arenas
    from fabric.session import shutdown_event

    if not (kinematics or navigation):
        raise UserError("nothing to serve: --no-kinematics and --no-navigation together leave the peer idle")
    if not stream_rate > 0:
        raise UserError(f"--stream-rate must be positive, got {stream_rate}")
    if duration is not None and not duration > 0:
        raise UserError(f"--duration must be positive, got {duration}")
    if maps_dir is not None and not maps_dir.is_dir():
        raise UserError(f"--maps-dir {maps_dir}: not a folder")
    try:
        streams = parse_streams(stream or [])
    except ValueError as exc:
        raise UserError(str(exc)) from None
    try:
        arms = parse_arms(arm or [])
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if streams and not kinematics:
        raise UserError("--stream needs kinematics (drop --no-kinematics)")
    cfg = join.config()
    stop = shutdown_event()
    limit_arenas()  # before the session's threads: what they free through hours of faults goes back (fabric.heap)
    fab = join.open("compute", cfg)
    options = ComputeOptions(kinematics, navigation, streams, stream_rate, maps_dir, mapping, arms=arms)
    with fab, ComputePeer(fab, options) as peer:
        served_arms = peer.discover(timeout=2.0)
        served = [s for s, on in (("ik/fk/jacobian", kinematics), ("map/plan", navigation)) if on]
        streaming = ", ".join(f"{r}<-{o}" for r, o in streams) or "none"
        print(
            f"compute {fab.peer_id}: world {fab.world}, serving {' + '.join(served)}; arms {', '.join(served_arms) or 'from the sims, as they come'}; "
            f"IK streams {streaming}; Ctrl-C to stop",
            flush=True,
        )
        with HeapTrimmer():
            peer.run(stop, duration)
        counts = ", ".join(f"{k} {v}" for k, v in peer.counters().items() if v)
        print(f"compute stopped: {counts or 'no requests'}", flush=True)


def register(app: typer.Typer) -> None:
    app.command("compute")(compute)
