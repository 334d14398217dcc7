"""The map and plan services end to end over Zenoh: a router, a compute peer, a fake sim and a user."""

from __future__ import annotations

import math

import numpy as np
import pytest

from compute_peer.navigation import (
    HybridAStarConfig,
    MapperConfig,
    OmplConfig,
    PlannerSettings,
    VehicleModel,
    path_collision,
    register_navigation,
)
from compute_peer.navigation.grid import UNKNOWN, dilate, make_grid
from fabric.interfaces import MapReply, MapRequest, OccupancyGrid, Path, PlanReply, PlanRequest
from fabric import keys
from fabric.interfaces import ServiceError
from robofabric.testing import wait_until
from navscenes import drive_poses, pose_at, scan_at, small_room

ROBOT = "base1"
# the planners' budgets are deadlines for a loaded box, not a pace: OMPL's default 2 s ran out at load 10-18
SETTINGS = PlannerSettings(
    vehicle=VehicleModel(robot_radius=0.25, turning_radius=0.5),
    ompl=OmplConfig(time_limit=30.0),
    hybrid=HybridAStarConfig(time_limit=30.0),
)
ROOM = MapperConfig(resolution=0.05, width=200, height=200, origin_x=0.0, origin_y=0.0)


@pytest.fixture
def peers(connect, tmp_path):
    compute = connect("compute", "compute-1")
    sim = connect("sim", "sim-1")
    user = connect("user", "user-1")
    nav = register_navigation(
        compute, robots=[ROBOT], mapper_config=ROOM, settings=SETTINGS, maps_dir=tmp_path, sensor_offset=(0.0, 0.0, 0.0)
    )
    # the queryables are reachable once a status query is answered
    wait_until(
        lambda: _try(lambda: user.rpc.call(keys.srv(user.world, "map", "map"), MapRequest("status"), timeout=1.0)),
        what="map service",
    )
    yield nav, sim, user
    nav.close()


def _try(fn):
    try:
        return fn()
    except ServiceError:
        return None


def call(user, service, arg, request, timeout=10.0):
    return user.rpc.call(keys.srv(user.world, service, arg), request, timeout=timeout)


def refused(user, service, arg, request) -> str:
    with pytest.raises(ServiceError) as info:
        call(user, service, arg, request)
    return info.value.reason


def drive_and_scan(nav, sim, scene, poses):
    """The sim's part: publish each pose, then the scan taken there (same sim stamp)."""
    world = sim.world
    for k, (x, y, yaw) in enumerate(poses):
        stamp = 1.0 + 0.05 * k
        sim.publish(keys.robot_pose(world, ROBOT), pose_at(x, y, yaw, stamp=stamp, seq=k))
        wait_until(lambda: nav.poses.at(ROBOT) is not None and nav.poses.at(ROBOT).header.seq == k, what=f"pose {k}")
        sim.publish(keys.robot_scan(world, ROBOT), scan_at(scene, x, y, yaw, stamp=stamp, seq=k))
    wait_until(lambda: nav.counters["scans"] >= len(poses), what="all scans mapped", seen=lambda: nav.counters)


def test_mapping_mode_build_publish_and_navigate(peers):
    nav, sim, user = peers
    world = user.world
    scene = small_room()
    maps: list[OccupancyGrid] = []
    paths: list[Path] = []
    user.subscribe(keys.map_key(world, "map"), lambda k, m: maps.append(m), expected=OccupancyGrid)
    user.subscribe(keys.robot_path(world, ROBOT), lambda k, m: paths.append(m), expected=Path)

    poses = drive_poses(scene, step=1.5)
    drive_and_scan(nav, sim, scene, poses)
    reply = call(user, "map", "map", MapRequest("build", threshold=0.65))
    assert isinstance(reply, MapReply) and reply.scans == len(poses) and reply.mapping == 1
    truth = scene.rasterize(0.05).cells == 100
    built = reply.grid.cells
    assert ((built == 100) & truth).sum() > 0.5 * (truth & (built != UNKNOWN)).sum()
    assert ((built == 0) & ~truth).sum() > 0.5 * (~truth).sum()
    wait_until(lambda: maps, what="map published")
    assert np.array_equal(maps[-1].cells, built) and maps[-1].header.source == "compute-1"

    # navigation: from the robot's latest pose to the goal pointer, around the inner wall
    sim.publish(keys.robot_pose(world, ROBOT), pose_at(2.0, 2.0, 0.0, stamp=99.0, seq=999))
    wait_until(lambda: nav.poses.at(ROBOT).header.seq == 999, what="start pose")
    user.publish(keys.object_pose(world, "goal", "alice"), pose_at(8.0, 2.0, -math.pi / 2))
    wait_until(lambda: nav.plan_service.goal is not None, what="goal pose")
    plan = call(user, "plan", ROBOT, PlanRequest(ROBOT))
    assert isinstance(plan, PlanReply) and plan.planner == "hybrid_astar" and plan.robot == ROBOT
    p = plan.path
    assert (p.x[0], p.y[0]) == pytest.approx((2.0, 2.0)) and (p.x[-1], p.y[-1]) == pytest.approx((8.0, 2.0))
    assert p.y.max() > 7.0  # it went round the wall's end, not through it
    assert plan.length == pytest.approx(float(np.hypot(np.diff(p.x), np.diff(p.y)).sum()))
    costmap = nav.plan_service.costmap("map", 0.25)
    assert path_collision(costmap, p.x, p.y) is None
    wait_until(lambda: paths, what="path published on the robot's path key")
    assert np.array_equal(paths[-1].x, p.x) and np.array_equal(paths[-1].theta, p.theta)


def test_injected_map_with_ompl_given_start_and_goal(peers):
    nav, sim, user = peers
    cells = np.zeros((100, 100), dtype=np.uint8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = 100
    cells[:70, 48:52] = 100  # a wall from the bottom, gap at the top
    reply = call(user, "map", "lab", MapRequest("set", name="lab", grid=make_grid(cells, 0.1)))
    assert reply.grid.cells.shape == (100, 100)
    for planner in ("ompl", "hybrid_astar"):
        plan = call(
            user,
            "plan",
            ROBOT,
            PlanRequest(
                ROBOT, goal=[8.0, 2.0, 0.0], start=[2.0, 2.0, 0.0], planner=planner, map="lab", direction="both"
            ),
            timeout=60.0,
        )
        assert plan.planner.startswith(planner) and plan.map == "lab"
        assert plan.path.y.max() > 7.0
        assert path_collision(nav.plan_service.costmap("lab", 0.25), plan.path.x, plan.path.y) is None


def test_bad_requests_get_reasons_and_the_service_keeps_answering(peers):
    nav, sim, user = peers
    world = user.world
    # no map yet, no scans
    assert "no map named 'map'" in refused(
        user, "plan", ROBOT, PlanRequest(ROBOT, goal=[1.0, 1.0, 0.0], start=[2.0, 2.0, 0.0])
    )
    assert "no scans accumulated" in refused(user, "map", "map", MapRequest("build"))
    # unknown robot, and a key that names another robot than the request
    assert "unknown robot 'ghost'" in refused(user, "plan", "ghost", PlanRequest("ghost", goal=[1.0, 1.0, 0.0]))
    assert "names robot" in refused(user, "plan", "other", PlanRequest(ROBOT, goal=[1.0, 1.0, 0.0]))
    # no pose received, no goal pointer
    assert "no pose received" in refused(user, "plan", ROBOT, PlanRequest(ROBOT, goal=[1.0, 1.0, 0.0]))
    cells = np.zeros((60, 60), dtype=np.uint8)
    cells[20:40, 20:40] = 100
    call(user, "map", "map", MapRequest("set", grid=make_grid(cells, 0.1)))
    assert "no goal given" in refused(user, "plan", ROBOT, PlanRequest(ROBOT, start=[0.5, 0.5, 0.0]))
    # NaN in the goal: refused by the decoder, with the field named
    assert "not finite" in refused(
        user, "plan", ROBOT, PlanRequest(ROBOT, goal=[math.nan, 1.0, 0.0], start=[0.5, 0.5, 0.0])
    )
    # goals outside the map and inside obstacles
    assert "outside the map" in refused(
        user, "plan", ROBOT, PlanRequest(ROBOT, goal=[9.0, 1.0, 0.0], start=[0.5, 0.5, 0.0])
    )
    assert "inside an obstacle" in refused(
        user, "plan", ROBOT, PlanRequest(ROBOT, goal=[3.0, 3.0, 0.0], start=[0.5, 0.5, 0.0])
    )
    # an all-unknown map is empty
    call(user, "map", "dark", MapRequest("set", name="dark", grid=make_grid(np.full((30, 30), UNKNOWN, np.uint8), 0.1)))
    assert "is empty" in refused(
        user, "plan", ROBOT, PlanRequest(ROBOT, goal=[1.0, 1.0, 0.0], start=[2.0, 2.0, 0.0], map="dark")
    )
    # garbage instead of a request
    with pytest.raises(ServiceError, match="not a msgpack|message"):
        for rep in user.session.get(keys.srv(world, "plan", ROBOT), payload=b"\x01\x02garbage", timeout=5.0):
            if rep.err is not None:
                from fabric.codec import decode
                from fabric.interfaces import Event

                raise ServiceError(decode(rep.err.payload.to_bytes(), Event).reason)
    # file names that would leave the maps folder
    assert "plain file name" in refused(user, "map", "map", MapRequest("save", file="../escape.yaml"))
    # still alive and counting
    status = call(user, "map", "map", MapRequest("status"))
    assert status.action == "status"
    assert nav.counters["refusals"] == 10  # the two undecodable requests were refused by the fabric layer
    assert nav.fabric.counters["query_errors"] == 12


def test_save_load_reset_stop_start(peers, tmp_path):
    nav, sim, user = peers
    cells = np.zeros((40, 50), dtype=np.uint8)
    cells[10:20, 10:30] = 100
    grid = make_grid(cells, 0.1, (1.0, 2.0))
    call(user, "map", "map", MapRequest("set", grid=grid))
    saved = call(user, "map", "map", MapRequest("save", file="office.yaml"))
    assert saved.file == "office.yaml" and (tmp_path / "office.pgm").is_file()
    call(user, "map", "map", MapRequest("save", file="office.npz"))
    for file in ("office.yaml", "office.npz"):
        loaded = call(user, "map", "copy", MapRequest("load", name="copy", file=file))
        assert np.array_equal(loaded.grid.cells, cells) and np.allclose(loaded.grid.origin, grid.origin)
    got = call(user, "map", "copy", MapRequest("get", name="copy"))
    assert np.array_equal(got.grid.cells, cells)
    assert "no map file" in refused(user, "map", "map", MapRequest("load", file="absent.npz"))
    # stop: scans are ignored; start: they count again
    assert call(user, "map", "map", MapRequest("stop")).mapping == 0
    scene = small_room()
    sim.publish(keys.robot_pose(sim.world, ROBOT), pose_at(2.0, 2.0, 0.0, stamp=1.0))
    wait_until(lambda: nav.poses.at(ROBOT) is not None, what="pose")
    sim.publish(keys.robot_scan(sim.world, ROBOT), scan_at(scene, 2.0, 2.0, 0.0, stamp=1.0))
    wait_until(lambda: nav.counters["scans_ignored"] == 1, what="scan ignored while stopped")
    assert nav.counters["scans"] == 0
    assert call(user, "map", "map", MapRequest("start")).mapping == 1
    sim.publish(keys.robot_scan(sim.world, ROBOT), scan_at(scene, 2.0, 2.0, 0.0, stamp=1.0))
    wait_until(lambda: nav.counters["scans"] == 1, what="scan mapped after start")
    live = call(user, "map", "live", MapRequest("get", name="map"))
    assert live.grid.cells.shape == cells.shape  # the map that was set is still the stored one
    reset = call(user, "map", "map", MapRequest("reset"))
    assert reset.scans == 0
    assert "no map named 'map'" in refused(user, "map", "map", MapRequest("get"))


def test_every_robot_of_the_world_when_none_are_named(connect):
    compute = connect("compute", "compute-2")
    sim = connect("sim", "sim-2")
    user = connect("user", "user-2")
    world = user.world
    with register_navigation(compute, settings=SETTINGS, mapper_config=ROOM) as nav:
        cells = np.zeros((60, 60), dtype=np.uint8)
        cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = 100
        wait_until(
            lambda: _try(lambda: call(user, "map", "map", MapRequest("set", grid=make_grid(cells, 0.1)), timeout=1.0)),
            what="map set",
        )
        # joints and commands share the robot's key space: they must not disturb the service
        from fabric.interfaces import JointState

        sim.publish(keys.robot_joints(world, "rover7"), JointState(("a",), np.zeros(1), np.zeros(1)))
        assert "unknown robot 'rover7'" in refused(user, "plan", "rover7", PlanRequest("rover7", goal=[4.0, 4.0, 0.0]))
        sim.publish(keys.robot_pose(world, "rover7"), pose_at(1.0, 1.0, 0.0))
        wait_until(lambda: nav.poses.at("rover7") is not None, what="rover7 pose")
        plan = call(user, "plan", "rover7", PlanRequest("rover7", goal=[4.0, 4.0, math.pi / 2]))
        assert (plan.path.x[0], plan.path.y[0]) == pytest.approx((1.0, 1.0))
        assert compute.counters["decode_errors"] == 0 and compute.counters["callback_errors"] == 0
    # closed: the queryables are gone, the session is not
    assert not compute.closed
    with pytest.raises(ServiceError, match="no reply"):
        user.rpc.call(keys.srv(world, "plan", "rover7"), PlanRequest("rover7", goal=[4.0, 4.0, 0.0]), timeout=0.5)


def test_sensor_mounting_and_radius_come_from_the_world_description(connect):
    """A sim peer's srv/world says where the LIDAR sits: scans are folded in from there, plans use its radius."""
    from fabric.interfaces import LidarInfo, RobotInfo, WorldInfo

    compute = connect("compute", "compute-3")
    sim = connect("sim", "sim-3")
    user = connect("user", "user-3")
    world = user.world
    info = WorldInfo(
        world=world,
        scene="test",
        timestep=0.002,
        rates={},
        robots=(
            RobotInfo(
                id="rover",
                type="reeman",
                kind="mobile",
                pose=np.zeros(4),
                joint_names=(),
                lower=np.zeros(0),
                upper=np.zeros(0),
                max_speed=np.zeros(0),
                base_radius=0.4,
                lidar=LidarInfo("lidar", 240, 2.356, -1.178, 0.00985, 0.05, 12.0, offset=np.array([0.5, 0.0, 0.25])),
            ),
        ),
    )
    sim.rpc.serve(keys.srv(world, "world"), lambda key, req: info)
    scene = small_room()
    with register_navigation(compute, settings=SETTINGS, mapper_config=ROOM) as nav:
        wait_until(lambda: nav.discover_robots(timeout=1.0) == 1, what="world description")
        # the robot stands at (2, 2) facing +x; its LIDAR is 0.5 m ahead, at (2.5, 2)
        sim.publish(keys.robot_pose(world, "rover"), pose_at(2.0, 2.0, 0.0, stamp=1.0))
        wait_until(lambda: nav.poses.at("rover") is not None, what="pose")
        sim.publish(keys.robot_scan(world, "rover"), scan_at(scene, 2.5, 2.0, 0.0, stamp=1.0))
        wait_until(lambda: nav.counters["scans"] == 1, what="scan mapped", seen=lambda: nav.counters)
        grid = nav.mapper.grid(threshold=0.65)
        truth = scene.rasterize(0.05).cells == 100
        hits = grid.cells == 100
        assert hits.sum() > 50
        assert (hits & dilate(truth, 1)).sum() == hits.sum()  # every hit on a true wall: the offset was applied
        call(user, "map", "map", MapRequest("set", grid=scene.rasterize(0.05)))
        plan = call(
            user, "plan", "rover", PlanRequest("rover", goal=[2.0, 8.5, math.pi / 2], start=[2.0, 2.0, math.pi / 2])
        )
        # radius 0.4 from the description: 0.45 m from the wall cells at y = 9.8..10 is too close, so the goal is
        # moved to where a robot of that radius fits, and the reply says so (issue 44)
        assert plan.length > 6.0
        moved = call(
            user, "plan", "rover", PlanRequest("rover", goal=[2.0, 9.4, math.pi / 2], start=[2.0, 2.0, math.pi / 2])
        )
        assert "goal moved" in moved.note and "within the robot radius (0.40 m)" in moved.note
        assert 9.8 - moved.path.y[-1] > 0.4 + 0.05


def test_a_key_of_no_layout_on_a_robots_keys_is_counted_never_a_traceback(connect, caplog):
    """Any login may put on ``robot/**``: a twist without its ``by/USER`` (what ``pub`` sent without --user), a key
    of no layout. The service hears poses and scans only; what it hears after them is still handled."""
    from fabric.interfaces import Pose, Twist

    compute = connect("compute", "compute-3")
    user = connect("user", "user-3")
    world = user.world
    with register_navigation(compute, settings=SETTINGS, mapper_config=ROOM) as nav:
        wait_until(
            lambda: _try(lambda: call(user, "map", "map", MapRequest("status"), timeout=1.0)), what="map service"
        )
        with caplog.at_level("DEBUG"):
            for key in (f"rf/{world}/robot/base1/cmd/twist", f"rf/{world}/robot/base1/no/such/layout"):
                user.publish(key, Twist(0.3, 0.0))
            wait_until(
                lambda: (
                    "ghost9" in nav.poses
                    or nav.counters.get("unknown_robot", 0) > 0
                    or user.publish(f"rf/{world}/robot/ghost9/pose", Pose([0.0, 0.0, 0.0])) < 0
                ),
                what="a pose after them handled",
                seen=lambda: nav.counters,
                interval=0.2,
            )
        assert compute.counters["callback_errors"] == 0
        assert not [r for r in caplog.records if r.levelname in ("ERROR", "CRITICAL") or r.exc_info], caplog.text
        assert call(user, "map", "map", MapRequest("status")).action == "status"  # still serving


def test_a_user_asking_in_her_name_may_not_change_the_map_nor_publish_a_plan_for_a_robot_she_does_not_own(peers):
    """srv/{map,plan}/.../by/{user} (what a class's router lets a student ask): set, reset, stop, save and load
    are refused with the reason and counted; start, status, build and get answer; a plan comes in the reply
    but is not published on the robot's path key (no authority here says she owns it). The staff's form
    (no by/) still does everything, and publishes."""
    nav, sim, user = peers
    world = user.world
    paths: list[Path] = []
    user.subscribe(keys.robot_path(world, ROBOT), lambda k, m: paths.append(m), expected=Path)
    cells = np.zeros((100, 100), np.uint8)
    assert call(user, "map", "map", MapRequest("set", grid=make_grid(cells, 0.1))).action == "set"  # the staff's form
    full = make_grid(np.full((100, 100), 100, np.uint8), 0.1)
    asked = keys.srv_asked(world, "map", "map", "mallory")
    for action, req in (
        ("set", MapRequest("set", grid=full)),
        ("reset", MapRequest("reset")),
        ("stop", MapRequest("stop")),
        ("save", MapRequest("save", file="mine.yaml")),
        ("load", MapRequest("load", file="mine.yaml")),
    ):
        with pytest.raises(
            ServiceError, match=f"map '{action}' changes the map everyone plans on: an instructor's, not mallory's"
        ):
            user.rpc.call(asked, req, timeout=5.0)
    assert nav.counters["refused_staff_only"] == 5 and nav.counters["refusals"] >= 5
    assert nav.mapping and not (nav.store.get("map").cells == 100).any()  # still on, still free
    for action in ("start", "status", "get"):
        assert user.rpc.call(asked, MapRequest(action), timeout=5.0, expected=MapReply).action == action
    plan = PlanRequest(ROBOT, goal=[8.0, 2.0, 0.0], start=[2.0, 2.0, 0.0], direction="both")
    reply = user.rpc.call(keys.srv_asked(world, "plan", ROBOT, "mallory"), plan, timeout=20.0, expected=PlanReply)
    assert len(reply.path) > 1 and nav.counters["plans_unpublished"] == 1
    staff = user.rpc.call(keys.srv(world, "plan", ROBOT), plan, timeout=20.0, expected=PlanReply)  # published
    wait_until(lambda: paths, what="the staff's plan on the path key")
    assert len(paths) == 1 and np.allclose(paths[0].x, staff.path.x)  # hers never came before it
    # the per-peer form in her name too
    with pytest.raises(ServiceError, match="an instructor's, not mallory's"):
        user.rpc.call(
            keys.srv_asked(world, "map", "map", "mallory", nav.fabric.peer_id), MapRequest("reset"), timeout=5.0
        )


def test_a_users_build_makes_her_own_map_checked_and_capped(peers):
    """A build in mallory's name (srv/map/map/by/mallory) makes ``mallory.{name}``, never the class's map (a threshold
    of 0.001 would make every seen cell occupied and every plan fail); its threshold is range-checked, and her new
    names are capped (1,400 of them would grow the compute peer for good)."""
    nav, sim, user = peers
    world = user.world
    class_maps: list[OccupancyGrid] = []
    hers: list[OccupancyGrid] = []
    user.subscribe(keys.map_key(world, "map"), lambda k, m: class_maps.append(m), expected=OccupancyGrid)
    user.subscribe(keys.map_key(world, "mallory.map"), lambda k, m: hers.append(m), expected=OccupancyGrid)
    scene = small_room()
    drive_and_scan(nav, sim, scene, drive_poses(scene, step=1.5))
    staff = call(user, "map", "map", MapRequest("build"))  # the instructor's build: the class's map
    wait_until(lambda: class_maps, what="the class's map published")
    asked = keys.srv_asked(world, "map", "map", "mallory")
    refusals = nav.counters["refusals"]
    for threshold in (0.001, 0.3, 0.999):
        with pytest.raises(ServiceError, match=rf"threshold {threshold:g} is outside \[0.5, 0.99\]"):
            user.rpc.call(asked, MapRequest("build", threshold=threshold), timeout=5.0)
    assert nav.counters["refusals"] == refusals + 3
    mine = user.rpc.call(asked, MapRequest("build", threshold=0.5), timeout=5.0, expected=MapReply)
    assert mine.name == "mallory.map" and mine.grid.cells.size
    wait_until(lambda: hers, what="her map on map/mallory.map")
    assert (
        np.array_equal(nav.store.get("map").cells, staff.grid.cells) and len(class_maps) == 1
    )  # the class's map untouched
    assert nav.store.user_maps("mallory") == ["mallory.map"]
    # plans use the class's map unless they name hers
    plan = PlanRequest(ROBOT, goal=[8.0, 2.0, 0.0], start=[2.0, 2.0, 0.0], direction="both")
    assert (
        user.rpc.call(keys.srv_asked(world, "plan", ROBOT, "mallory"), plan, timeout=20.0, expected=PlanReply).map
        == "map"
    )
    # caps: four maps of hers, then a new name is refused with the reason and counted; rebuilding one of hers is not
    for name in ("a", "b", "mallory.c"):
        assert (
            user.rpc.call(asked, MapRequest("build", name=name), timeout=5.0, expected=MapReply).name
            == f"mallory.{name.split('.')[-1]}"
        )
    with pytest.raises(
        ServiceError,
        match=r"mallory holds 4 maps, the most one user may \(mallory.a, mallory.b, mallory.c, mallory.map\)",
    ):
        user.rpc.call(asked, MapRequest("build", name="d"), timeout=5.0)
    assert nav.counters["refused_map_limit"] == 1
    assert user.rpc.call(asked, MapRequest("build", name="a"), timeout=5.0, expected=MapReply).name == "mallory.a"
    nav.store.users_total = 5  # the cap for all users together
    bob = keys.srv_asked(world, "map", "map", "bob")
    assert user.rpc.call(bob, MapRequest("build"), timeout=5.0, expected=MapReply).name == "bob.map"
    with pytest.raises(ServiceError, match="the users hold 5 maps, the most this compute peer keeps"):
        user.rpc.call(bob, MapRequest("build", name="other"), timeout=5.0)
    assert nav.counters["refused_map_limit"] == 2 and len(nav.store.user_maps()) == 5
    with pytest.raises(ServiceError, match="characters long; at most 64"):
        user.rpc.call(asked, MapRequest("build", name="x" * 60), timeout=5.0)
    assert len(class_maps) == 1 and np.array_equal(nav.store.get("map").cells, staff.grid.cells)
