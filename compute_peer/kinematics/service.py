"""Kinematics served over Zenoh: ``srv/{ik,fk,jacobian}/{robot}`` and streamed IK (the paper's Test A).

:func:`register_kinematics` attaches a :class:`KinematicsService` to a peer's
:class:`~fabric.session.Fabric`. It learns each arm's type and base placement
from the sim's world description (``srv/world``), so it needs no local copy of
the scene, and builds one Pinocchio model per robot type from robots/.

Every robot's services answer on two keys: ``rf/{world}/srv/ik/{robot}`` (the
shared name: Zenoh's best-matching target sends it to the nearest compute peer)
and ``rf/{world}/srv/ik/{robot}/{peer_id}`` (this peer only), so a user can
pick a compute peer (a local one, say) or spread queries over several.

Streaming mode follows scene objects: for each ``(robot, object)`` pair it
watches the object's pose, solves position IK near the arm's current joints at
a fixed rate whenever the target moved, and publishes :class:`IKStream` on
``rf/{world}/robot/{robot}/ik``; applying it is the owner's choice.

Refusals (unknown robot, NaN, wrong joint counts, unreachable targets) are error
replies with the reason: never a timeout, never a crash. This is the only module
of :mod:`compute_peer.kinematics` that touches the session.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from fabric import keys
from fabric.interfaces import (
    Event,
    EventKind,
    FKReply,
    FKRequest,
    IKReply,
    IKRequest,
    IKStream,
    JacobianReply,
    JacobianRequest,
    JointState,
    Pose,
    NoReply,
    ServiceError,
)
from fabric.limits import quote
from fabric.rate import Clock, MonotonicClock, RateLoop
from fabric.session import Fabric, undeclare_all

from ..world_lookup import BackgroundLookup, described_robots
from .arm import PlacedArm
from .model import ArmModel, NoIKSolution

log = logging.getLogger("robofabric.kinematics")

__all__ = ["KinematicsService", "register_kinematics", "ArmPlacement"]

DISCOVERY_INTERVAL = 1.0  # s between two srv/world lookups set off by streams
REQUEST_DISCOVERY_INTERVAL = 0.2  # s: a request for an unknown arm may look again this soon (a sim that just came)


@dataclass(frozen=True, slots=True)
class ArmPlacement:
    """What the service needs of one arm: its robot type and base pose (x, y, z, yaw) in the world."""

    type: str
    pose: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)


class KinematicsService:
    """IK/FK/Jacobian queryables and IK streaming for the arms of one world. ``close()`` is idempotent.

    ``arms``: robot id -> :class:`ArmPlacement`, for worlds without a sim peer to ask; otherwise the arms
    are learnt from ``srv/world`` (``discover``). ``streams``: (robot, object) pairs to follow at
    ``stream_rate`` Hz.

    Constructing one declares its keys and answers queries at once; it starts no thread. The stream
    loop and the background lookups of the world (on a sim's coming, on joints of an unknown arm) run
    once it is started (``start()`` or ``with KinematicsService(...) as svc:``).
    """

    def __init__(
        self,
        fabric: Fabric,
        *,
        arms: dict[str, ArmPlacement] | None = None,
        streams: Iterable[tuple[str, str]] = (),
        stream_rate: float = 20.0,
        discover: bool = True,
        clock: Clock | None = None,
    ) -> None:
        self.fabric = fabric
        self.world = fabric.world
        self._clock = clock or MonotonicClock()
        self._models: dict[str, ArmModel] = {}
        self._arms: dict[str, PlacedArm] = {}
        self.joints: dict[str, JointState] = {}  # the latest joint state of each arm, the seed of its IK
        self._targets: dict[str, Pose] = {}
        self._solved: dict[tuple[str, str], tuple[float, ...]] = {}
        self.streams = [(keys.validate_id(r, what="robot id"), keys.validate_id(o, what="object id")) for r, o in streams]
        self._lock = threading.RLock()
        self._discover = bool(discover)
        self._lookup = BackgroundLookup(self.discover, name="kinematics-discovery", clock=self._clock,
                                        on_error=lambda exc: self._discovery_failed(f"{type(exc).__name__}: {exc}"))
        self._last_discovery_error = ""
        self._sims_changed = 0  # bumped when a sim peer comes or goes: the world's arms may have changed
        self._answered_at = -1  # the value of _sims_changed when srv/world last answered
        self._closed = False
        self.counters: dict[str, int] = {"ik": 0, "fk": 0, "jacobian": 0, "refusals": 0, "streamed": 0, "stream_unreachable": 0}
        for rid, placement in (arms or {}).items():
            self.add_arm(rid, placement)
        self._stream_rate = stream_rate
        self._started = False
        self._loop: RateLoop | None = None
        self._resources: list[Any] = []
        self._declare()

    # ------------------------------------------------------------------ lifecycle

    def _declare(self) -> None:
        f, w = self.fabric, self.world
        handlers = {"ik": (self._on_ik, IKRequest), "fk": (self._on_fk, FKRequest), "jacobian": (self._on_jacobian, JacobianRequest)}
        for name, (handler, expected) in handlers.items():
            self._resources.append(f.rpc.serve(keys.srv_per_subject(w, name), handler, expected=expected))
            self._resources.append(f.rpc.serve(keys.srv_per_subject(w, name, f.peer_id), handler, expected=expected))
        self._resources.append(f.subscribe(keys.robot_stream_all(w, "joints"), self._on_joints, expected=JointState))
        for _, obj in self.streams:
            self._resources.append(f.subscribe(keys.object_pose_all(w, obj), self._on_target, expected=Pose, history=True))
        if self._discover:
            self._resources.append(f.watch_peers(self._on_sim, kind="sim"))

    def _on_sim(self, kind: str, peer: str, alive: bool) -> None:
        """A sim came or went: look the world up again now (its description may name other arms)."""
        with self._lock:
            self._sims_changed += 1
        self._lookup.again_now()
        self._discover_soon()

    def start(self) -> "KinematicsService":
        """Start streaming (when there are streams) and look the world up in the background (once; a
        second call, or one after ``close()``, does nothing)."""
        with self._lock:
            if self._started or self._closed:
                return self
            self._started = True
            if self.streams:
                self._loop = RateLoop(self._stream_rate, self._stream_tick, clock=self._clock, name="ik-stream").start()
        if self._discover:
            self._discover_soon()
        return self

    def __enter__(self) -> "KinematicsService":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop streaming and undeclare this service's keys (the session stays open); safe twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._lookup.close()
        if self._loop is not None:
            self._loop.close()
        undeclare_all(self._resources)

    # ------------------------------------------------------------------ arms

    def add_arm(self, robot: str, placement: ArmPlacement) -> PlacedArm:
        """Serve ``robot`` (an arm of type ``placement.type`` at ``placement.pose``)."""
        keys.validate_id(robot, what="robot id")
        with self._lock:
            model = self._models.get(placement.type)
            if model is None:
                model = self._models[placement.type] = ArmModel(placement.type)
            arm = self._arms[robot] = PlacedArm(model, placement.pose)
        return arm

    @property
    def arms(self) -> list[str]:
        with self._lock:
            return sorted(self._arms)

    def discover(self, timeout: float = 2.0) -> int:
        """Learn the arms of the world from the sim peers' ``srv/world``; returns how many are known."""
        with self._lock:
            generation = self._sims_changed
        try:
            described = described_robots(self.fabric, "arm", timeout=timeout)
        except NoReply as exc:
            # no sim yet: normal when the compute starts first (`robofabric up`); its token brings a lookup
            self._discovery_failed(str(exc), quiet="nobody serves it" in str(exc))
            return len(self.arms)
        except ServiceError as exc:
            self._discovery_failed(str(exc))
            return len(self.arms)
        with self._lock:
            self._answered_at = generation
        for r in described:
            if r.id in self._arms:
                continue
            try:
                self.add_arm(r.id, ArmPlacement(r.type, tuple(float(v) for v in r.pose)))
                log.info("serving kinematics for %s (%s)", r.id, r.type)
            except Exception as exc:  # a robot type this installation has no model for
                log.warning("cannot serve kinematics for %s (%s): %s", r.id, r.type, exc)
        return len(self.arms)

    def _discovery_failed(self, why: str, *, quiet: bool = False) -> None:
        self.counters["discovery_failed"] = self.counters.get("discovery_failed", 0) + 1
        # said once per distinct reason; "nobody serves it" (no sim yet) is normal at a start: not a warning
        if why != self._last_discovery_error:
            self._last_discovery_error = why
            log.log(logging.INFO if quiet else logging.WARNING, "looking the world's arms up: %s", why)

    def _discover_soon(self) -> None:
        """Look the world up in a thread (never inside a Zenoh callback), at most once a second; not before
        ``start()``, which looks it up itself (a sim's token seen while declaring only marks the world changed)."""
        if self._started:
            self._lookup.start(DISCOVERY_INTERVAL)

    def _discover_now(self, timeout: float = 2.0) -> None:
        """Look the world up before answering a request for an arm not known yet (a sim that just came,
        or joints that have not arrived): the request waits up to ``timeout`` rather than failing.

        Runs in the query's own handler thread; joins a lookup already under way. Once the world has
        answered with the sims there are now, an unknown id is refused at once: a flood of made-up ids
        never stalls the service."""
        deadline = time.monotonic() + timeout
        while True:
            with self._lock:
                if self._answered_at == self._sims_changed or self._closed:
                    return
            wait = self._lookup.until_allowed(REQUEST_DISCOVERY_INTERVAL)
            if self._lookup.claim(REQUEST_DISCOVERY_INTERVAL):
                self._lookup.run(max(0.1, deadline - time.monotonic()))
                return
            left = deadline - time.monotonic()
            if left <= 0:
                return
            if self._lookup.running:
                self._lookup.wait(left)
                return
            time.sleep(min(max(wait, 0.01), left))

    def arm(self, robot: str) -> PlacedArm:
        """The placed arm ``robot``; :class:`ServiceError` naming the known ones otherwise."""
        with self._lock:
            arm = self._arms.get(robot)
        if arm is None and self._discover:
            self._discover_now()
            with self._lock:
                arm = self._arms.get(robot)
        if arm is None:
            known = self.arms
            raise ServiceError(f"unknown arm {quote(robot, 64)}: this compute peer serves {', '.join(known) or 'no arms yet'}")
        return arm

    # ------------------------------------------------------------------ handlers

    @staticmethod
    def _robot_of(key: str) -> str:
        """The robot a service key names (``srv/ik/{robot}[/{peer}]``)."""
        parsed = keys.parse(key)
        if parsed.category == "srv":
            return parsed.rest[0] if parsed.rest else ""
        return parsed.subject

    def _refuse(self, exc: Exception) -> ServiceError:
        self.counters["refusals"] += 1
        return ServiceError(getattr(exc, "reason", None) or str(exc))

    def _seed(self, robot: str, seed: np.ndarray) -> np.ndarray | None:
        if seed.shape[0] > 0:
            return seed
        with self._lock:
            js = self.joints.get(robot)
        return None if js is None else np.asarray(js.q, float)

    def ik(self, robot: str, req: IKRequest) -> IKReply:
        """Handle one IK request (also usable in-process)."""
        arm = self.arm(robot)
        t0 = time.perf_counter()
        quat = req.quaternion if req.quaternion.shape[0] else None
        sol = arm.ik(req.position, quat, self._seed(robot, req.seed), frame=req.frame, method=req.method)
        us = (time.perf_counter() - t0) * 1e6
        self.counters["ik"] += 1
        hdr = self.fabric.header(keys.srv(self.world, "ik", robot))
        return IKReply(robot, sol.q, sol.solver, sol.position_error, sol.orientation_error, sol.candidates, us, hdr)

    def _on_ik(self, key: str, req: IKRequest | None) -> IKReply:
        robot = self._robot_of(key)
        if req is None:
            raise self._refuse(ValueError("an IK query needs an IKRequest payload (position, optional quaternion)"))
        try:
            return self.ik(robot, req)
        except (NoIKSolution, ValueError, ServiceError) as exc:
            raise self._refuse(exc) from None

    def _on_fk(self, key: str, req: FKRequest | None) -> FKReply:
        robot = self._robot_of(key)
        try:
            if req is None:
                raise ValueError("an FK query needs an FKRequest payload (q)")
            pos, quat = self.arm(robot).fk(req.q, req.frame)
        except (ValueError, ServiceError) as exc:
            raise self._refuse(exc) from None
        self.counters["fk"] += 1
        return FKReply(robot, pos, quat, req.frame, self.fabric.header(keys.srv(self.world, "fk", robot)))

    def _on_jacobian(self, key: str, req: JacobianRequest | None) -> JacobianReply:
        robot = self._robot_of(key)
        try:
            if req is None:
                raise ValueError("a Jacobian query needs a JacobianRequest payload (q, optional dq)")
            j, twist, speeds = self.arm(robot).jacobian(req.q, req.dq, req.frame)
        except (ValueError, ServiceError) as exc:
            raise self._refuse(exc) from None
        self.counters["jacobian"] += 1
        return JacobianReply(robot, j, twist, speeds, req.frame, self.fabric.header(keys.srv(self.world, "jacobian", robot)))

    # ------------------------------------------------------------------ streaming (Test A)

    def _on_joints(self, key: str, msg: JointState) -> None:
        """Keep the latest joints of the arms this peer serves, and of nothing else (a flood of
        made-up robot ids must not grow it: 16 fake 23 MB states once took this peer to 1 GB)."""
        robot = self._robot_of(key)
        with self._lock:
            if robot in self._arms:
                self.joints[robot] = msg
                return
        self.counters["unknown_robot"] = self.counters.get("unknown_robot", 0) + 1
        if self._discover:
            self._discover_soon()

    def _on_target(self, key: str, msg: Pose) -> None:
        obj = self._robot_of(key)  # one subscription per streamed object: never a made-up id
        with self._lock:
            self._targets[obj] = msg

    def _stream_tick(self, now: float) -> None:
        for robot, obj in self.streams:
            with self._lock:
                target = self._targets.get(obj)
                arm = self._arms.get(robot)
                js = self.joints.get(robot)
            if target is None:
                continue
            if arm is None:
                if self._discover:
                    self._discover_soon()
                continue
            position = tuple(float(v) for v in target.position)
            if self._solved.get((robot, obj)) == position:
                continue  # the target has not moved since the last solution
            try:
                self.publish_stream(robot, obj, arm, np.asarray(position), None if js is None else np.asarray(js.q, float))
            except Exception as exc:  # a closing session; the next tick tries again
                log.debug("IK stream for %s failed: %s", robot, exc)
                continue
            self._solved[(robot, obj)] = position

    def publish_stream(self, robot: str, obj: str, arm: PlacedArm, position: np.ndarray, q_now: np.ndarray | None) -> IKStream:
        """Solve one streamed target and publish it on ``robot/{robot}/ik``."""
        step = arm.stream_step(position, q_now)
        key = keys.robot_stream(self.world, robot, "ik")
        msg = IKStream(robot, obj, position, step.ok, step.reason, step.q, step.dq, step.speeds, step.seconds, self.fabric.header(key))
        self.fabric.publish(key, msg)
        if step.ok:
            self.counters["streamed"] += 1
        else:
            self.counters["stream_unreachable"] += 1
            self.fabric.reports.emit(
                Event(kind=EventKind.IK_UNREACHABLE, reason=step.reason, object=robot, severity="warning", header=self.fabric.header("event")),
                "compute", robot,
            )
        return msg


def register_kinematics(fabric: Fabric, **options: Any) -> KinematicsService:
    """Serve kinematics on ``fabric``'s world, started; see :class:`KinematicsService` for the options."""
    return KinematicsService(fabric, **options).start()
