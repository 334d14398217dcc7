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

The service composes the arms it serves and their lookup (:mod:`.arm_directory`) and the streams
(:mod:`.ik_streaming`); it holds the keys, the requests' handlers and the latest joints.

Refusals (unknown robot, NaN, wrong joint counts, unreachable targets) are error
replies with the reason: never a timeout, never a crash. This is the only module
of :mod:`compute_peer.kinematics` that touches the session.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Iterable

import numpy as np

from fabric import keys
from fabric.interfaces import (
    FKReply,
    FKRequest,
    IKReply,
    IKRequest,
    JacobianReply,
    JacobianRequest,
    JointState,
    Pose,
    ServiceError,
)
from fabric.rate import Clock, MonotonicClock, RateLoop
from fabric.session import Fabric, undeclare_all

from .arm_directory import ArmDirectory, ArmPlacement
from .ik_streaming import IKStreams
from .model import NoIKSolution

__all__ = ["KinematicsService", "register_kinematics", "ArmPlacement"]


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
        self.joints: dict[str, JointState] = {}  # the latest joint state of each arm, the seed of its IK
        self._lock = threading.RLock()
        self._closed = False
        self.counters: dict[str, int] = {
            "ik": 0,
            "fk": 0,
            "jacobian": 0,
            "refusals": 0,
            "streamed": 0,
            "stream_unreachable": 0,
            "joints_narrowed": 0,  # 1 once only the described arms' joints are heard (_hear_arms)
        }
        self.directory = ArmDirectory(fabric, discover=discover, clock=self._clock, counters=self.counters)
        self.directory.on_answered = self._arms_answered
        self._joint_keys: frozenset[str] = frozenset()  # robot/{id}/joints of each arm heard on its own subscription
        self._joint_subs: list[Any] = []
        self._joints_wildcard: Any = None  # robot/*/joints, until the sims have described the world's arms
        for rid, placement in (arms or {}).items():
            self.directory.add(rid, placement)
        self.ik_streams = IKStreams(fabric, streams, self.directory, self._latest_joints, self.counters)
        self.streams = self.ik_streams.pairs
        self._stream_rate = stream_rate
        self._started = False
        self._loop: RateLoop | None = None
        self._resources: list[Any] = []
        self._declare()

    # ------------------------------------------------------------------ lifecycle

    def _declare(self) -> None:
        f, w = self.fabric, self.world
        handlers = {
            "ik": (self._on_ik, IKRequest),
            "fk": (self._on_fk, FKRequest),
            "jacobian": (self._on_jacobian, JacobianRequest),
        }
        for name, (handler, expected) in handlers.items():
            self._resources.append(f.rpc.serve(keys.srv_per_subject(w, name), handler, expected=expected))
            self._resources.append(f.rpc.serve(keys.srv_per_subject(w, name, f.peer_id), handler, expected=expected))
        if self.directory.discovering:
            self._joints_wildcard = f.subscribe(
                keys.robot_stream_all(w, "joints"), self._on_any_joints, expected=JointState
            )
        else:  # the arms given are all there will be
            self._hear_arms(self.directory.names)
        for _, obj in self.streams:
            self._resources.append(
                f.subscribe(keys.object_pose_all(w, obj), self.ik_streams.target_seen, expected=Pose, history=True)
            )
        if self.directory.discovering:
            self._resources.append(f.watch_peers(self.directory.sim_seen, kind="sim"))

    def start(self) -> "KinematicsService":
        """Start streaming (when there are streams) and look the world up in the background (once; a
        second call, or one after ``close()``, does nothing)."""
        with self._lock:
            if self._started or self._closed:
                return self
            self._started = True
            if self.streams:
                self._loop = RateLoop(
                    self._stream_rate, self.ik_streams.tick, clock=self._clock, name="ik-stream"
                ).start()
        self.directory.start()
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
            joints = [*self._joint_subs, *([self._joints_wildcard] if self._joints_wildcard is not None else [])]
            self._joint_subs, self._joints_wildcard = [], None
        self.directory.close()
        if self._loop is not None:
            self._loop.close()
        undeclare_all(self._resources)
        undeclare_all(joints)

    # ------------------------------------------------------------------ arms

    @property
    def arms(self) -> list[str]:
        """The ids of the arms served now."""
        return self.directory.names

    def discover(self, timeout: float = 2.0) -> int:
        """Learn the arms of the world from the sim peers' ``srv/world``; returns how many are known."""
        return self.directory.discover(timeout)

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

    def _latest_joints(self, robot: str) -> JointState | None:
        with self._lock:
            return self.joints.get(robot)

    def _seed(self, robot: str, seed: np.ndarray) -> np.ndarray | None:
        if seed.shape[0] > 0:
            return seed
        js = self._latest_joints(robot)
        return None if js is None else np.asarray(js.q, float)

    def ik(self, robot: str, req: IKRequest) -> IKReply:
        """Handle one IK request (also usable in-process)."""
        arm = self.directory.find(robot)
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
            pos, quat = self.directory.find(robot).fk(req.q, req.frame)
        except (ValueError, ServiceError) as exc:
            raise self._refuse(exc) from None
        self.counters["fk"] += 1
        return FKReply(robot, pos, quat, req.frame, self.fabric.header(keys.srv(self.world, "fk", robot)))

    def _on_jacobian(self, key: str, req: JacobianRequest | None) -> JacobianReply:
        robot = self._robot_of(key)
        try:
            if req is None:
                raise ValueError("a Jacobian query needs a JacobianRequest payload (q, optional dq)")
            j, twist, speeds = self.directory.find(robot).jacobian(req.q, req.dq, req.frame)
        except (ValueError, ServiceError) as exc:
            raise self._refuse(exc) from None
        self.counters["jacobian"] += 1
        return JacobianReply(
            robot, j, twist, speeds, req.frame, self.fabric.header(keys.srv(self.world, "jacobian", robot))
        )

    # ------------------------------------------------------------------ joints (the IK's seeds)

    def _on_any_joints(self, key: str, msg: JointState) -> None:
        """Joints heard on ``robot/*/joints``: passed on unless their arm is heard on its own subscription already."""
        if key not in self._joint_keys:
            self._on_joints(key, msg)

    def _arms_answered(self, names: list[str]) -> None:
        """After each lookup the sims answered: hear the arms' joints alone, declared on a thread of its own (the
        lookup may run in a query's handler, on zenoh's callback thread). Nothing to do once narrowed to these."""
        with self._lock:
            if self._closed or (self._joints_wildcard is None and self._joint_keys.issuperset(self._keys_of(names))):
                return
        threading.Thread(target=self._hear_arms, args=(names,), name="kinematics-narrow", daemon=True).start()

    def _keys_of(self, names: Iterable[str]) -> set[str]:
        return {keys.robot_joints(self.world, robot) for robot in names}

    def _hear_arms(self, names: list[str]) -> None:
        """Hear the joints of ``names`` alone, each on its own key, and drop ``robot/*/joints``: on it every base's
        wheel joints came at 100 Hz, each decoded and passed over, and were published by the sims for this service
        alone. An arm a later lookup names is added; an arm no sim described is not heard (a request for it looks
        the world up again only when the sims there changed)."""
        with self._lock:
            if self._closed:
                return
            new = sorted(self._keys_of(names) - self._joint_keys)
            # marked before declared: the wildcard passes over what the key's own subscription hears from then on
            self._joint_keys = self._joint_keys | set(new)
            for key in new:
                self._joint_subs.append(self.fabric.subscribe(key, self._on_joints, expected=JointState))
            wildcard, self._joints_wildcard = self._joints_wildcard, None
        if wildcard is not None:
            undeclare_all([wildcard])
            self.counters["joints_narrowed"] = 1

    def _on_joints(self, key: str, msg: JointState) -> None:
        """Keep the latest joints of the arms this peer serves, and of nothing else (a flood of
        made-up robot ids must not grow it: 16 fake 23 MB states once took this peer to 1 GB).

        A base's wheels are joints too (100 Hz each): a robot the sims described as another kind is passed
        over quietly. Only an id no sim described, once the sims have answered, counts as ``unknown_robot``; an
        id not described yet sets a lookup off (every base's joints did both: thousands a minute in a class,
        and a ``srv/world`` query every second)."""
        robot = self._robot_of(key)
        if self.directory.get(robot) is not None:
            with self._lock:
                self.joints[robot] = msg
            return
        if self.directory.not_an_arm(robot):
            return
        if self.directory.answered or not self.directory.discovering:  # not merely a robot the world names late
            self.counters["unknown_robot"] = self.counters.get("unknown_robot", 0) + 1
        if self.directory.discovering:
            self.directory.look_soon()


def register_kinematics(fabric: Fabric, **options: Any) -> KinematicsService:
    """Serve kinematics on ``fabric``'s world, started; see :class:`KinematicsService` for the options."""
    return KinematicsService(fabric, **options).start()
