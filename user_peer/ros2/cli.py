"""``robofabric ros2``: the live ROS 2 bridge of one world, as one login (docs/ros2.md)."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from fabric.cli_common import Joining, UserError, join_flags

__all__ = ["ros2", "register", "MISSING_RCLPY"]

MISSING_RCLPY = (
    "robofabric ros2 needs rclpy: pip install 'robofabric[ros2]' (ROS 2 Kilted's wheels), "
    "or source a ROS 2 install (e.g. . /opt/ros/kilted/setup.bash) before running it"
)


@join_flags(client=True)
def ros2(
    ctx: typer.Context,
    namespace: Annotated[
        str,
        typer.Option(
            "--namespace", help="A ROS namespace put before every topic, /clock too (e.g. class1: /class1/clock)."
        ),
    ] = "",
    request: Annotated[
        Optional[list[str]],
        typer.Option(
            "--request",
            help="A robot to ask to own at start (repeatable); cmd_vel and joint_command act only on robots this login owns.",
        ),
    ] = None,
    drive: Annotated[
        Optional[list[str]],
        typer.Option(
            "--drive",
            help="A robot whose cmd_vel and joint commands the bridge takes from ROS 2 (repeatable); without it the bridge only publishes: any node on the DDS domain could send them.",
        ),
    ] = None,
    cmd_vel_stamped: Annotated[
        bool,
        typer.Option(
            "--cmd-vel-stamped",
            help="Take cmd_vel as geometry_msgs/TwistStamped (Nav2's enable_stamped_cmd_vel, ros2_control's diff drive) instead of Twist.",
        ),
    ] = False,
    topic_map: Annotated[
        Optional[str],
        typer.Option(
            "--topic-map",
            help="A YAML file that renames topics, sets their QoS and allows or denies them (docs/ros2.md, 'Topic map').",
        ),
    ] = None,
    goal_map: Annotated[
        str,
        typer.Option(
            "--goal-map",
            help="The map a goal_pose is planned on (default: this login's own map, the one Base.build_map builds; 'map' for the class's).",
        ),
    ] = "",
    discovery: Annotated[
        Optional[str],
        typer.Option(
            "--discovery",
            help="How far DDS discovery reaches: localhost (the default, unless ROS_AUTOMATIC_DISCOVERY_RANGE is set), subnet, off or system_default.",
        ),
    ] = None,
    user_id: Annotated[
        Optional[str],
        typer.Option("--user", "-u", help="The login the bridge acts as (default: $USER); ownership is by user id."),
    ] = None,
    join: Joining = Joining(),
    trace: Annotated[
        Optional[str],
        typer.Option(
            "--trace",
            hidden=True,
            help="Write when each message entered and left the bridge to this file at the end (robofabric bench ros2).",
        ),
    ] = None,
) -> None:
    """Bridge a world to ROS 2: every robot's joint_states, scan, odom, path, the map and /clock go out as ROS 2
    topics; cmd_vel and joint_command come in only for the robots named with --drive, while this login owns them
    (refusals on /rosout). The ROS domain is ROS_DOMAIN_ID's; discovery stays on this host unless asked
    otherwise. ROS arguments go last, after --ros-args (remaps, node name, log level, parameters), as for any
    ROS 2 node. Ctrl-C stops it (its robots are released)."""
    import gc
    import logging
    import os

    try:
        import rclpy  # noqa: F401
        from user_peer.ros2.bridge import Ros2Bridge, spin
    except ImportError:
        raise UserError(MISSING_RCLPY) from None
    from user_peer.cli import open_world
    from user_peer.errors import FabricUserError
    from user_peer.ros2.trust import boundary_lines
    from user_peer.ros2.trust import discovery as discovery_range

    from user_peer.ros2.topic_map import load_topic_map

    extra = ros_args(list(ctx.args))
    try:
        found = discovery_range(os.environ, discovery)
        mapped = load_topic_map(topic_map) if topic_map else None  # TopicMapError: a ValueError saying what is wrong
    except ValueError as exc:
        raise UserError(str(exc)) from None

    log = logging.getLogger("robofabric.ros2")
    w = open_world(join, user_id)
    try:
        for rid in request or ():
            try:
                w.robot(rid).request()
                print(f"{w.user} owns {rid}", flush=True)
            except FabricUserError as exc:  # the bridge goes on: its cmd_vel for that robot will be refused, and told
                log.warning("could not own %s: %s", rid, exc.reason)
                print(f"{w.user} does not own {rid}: {exc.reason}", flush=True)
        os.environ.update(found.set_env)  # read by the middleware when rclpy starts
        rclpy.init(args=["robofabric", *extra])
        node = rclpy.create_node("robofabric_" + "".join(c if c.isalnum() else "_" for c in w.user))
        bridge = Ros2Bridge(
            w,
            node,
            namespace=namespace,
            trace=trace is not None,
            drive=drive or (),
            stamped_cmd_vel=cmd_vel_stamped,
            goal_map=goal_map,
            topic_map=mapped,
        )
        if mapped is not None:
            print(f"topic map {topic_map}: {mapped.summary()}", flush=True)
        for line in boundary_lines(w.user, drive or (), os.environ.get("ROS_DOMAIN_ID", "0"), found):
            print(line, flush=True)
        # what the start built (rclpy's, zenoh's, numpy's ~80,000 objects) lives as long as the bridge: frozen out
        # of the collector, a full collection walks only what came after, not a pause of tens of ms for every
        # message in flight (docs/ros2.md, Benchmark)
        gc.collect()
        gc.freeze()
        print(
            f"bridging world {w.name!r} as {w.user!r} to ROS 2 domain {os.environ.get('ROS_DOMAIN_ID', '0')}"
            f"{' under /' + namespace.strip('/') if namespace.strip('/') else ''}",
            flush=True,
        )
        try:
            spin(bridge)
        finally:
            bridge.close()
            if trace is not None:
                bridge.write_trace(trace)
            print(bridge.summary(), flush=True)
            node.destroy_node()
            if rclpy.ok():
                rclpy.shutdown()
    finally:
        w.close()


def ros_args(extra: list[str]) -> list[str]:
    """The ROS arguments given after the command's own: only after ``--ros-args`` (rclpy parses them), else an
    error naming what was not understood."""
    if extra and extra[0] != "--ros-args":
        raise UserError(
            f"unexpected arguments {' '.join(extra)}: ROS 2 arguments go last, after --ros-args "
            "(e.g. --ros-args -r __node:=bridge1)"
        )
    return extra


def register(app: typer.Typer) -> None:
    # --ros-args and what follows it reach the command as ctx.args, for rclpy.init
    app.command("ros2", context_settings={"allow_extra_args": True, "ignore_unknown_options": True})(ros2)
