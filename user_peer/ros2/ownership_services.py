"""Asking for a robot and giving it up from ROS 2: ``std_srvs/Trigger`` services per driven robot.

``/NS/ROBOT/request_ownership`` asks the world's ownership authority for the robot in the bridge's login's name
(``Robot.request``, no queueing: a refusal comes back at once); ``/NS/ROBOT/release_ownership`` gives it up
(``Robot.release``). The response's ``success`` says whether it was done and ``message`` says what now holds
(``alice owns base1 (epoch 3)``, ``base1 released by alice``) or the authority's reason (``owned by bob``). The
latched ``/NS/ROBOT/owner`` topic (:mod:`user_peer.ros2.owners`) then shows the change within a second.

The services exist only for the robots the bridge drives (``--drive``): like their command topics, anything on
the DDS domain could call them, and what they do is done as this login. ``std_srvs`` is not among ROS 2 Kilted's
wheels: :mod:`user_peer.ros2.msgbuild` builds it (``make test`` does); without it there are no services and
:attr:`OwnershipServices.available` is False (the bridge says so at start). A call blocks the bridge's executor
for the authority's answer (its timeout, a few seconds at most): asking for a robot is rare and quick.
"""

from __future__ import annotations

from typing import Any, Callable

from user_peer.errors import FabricUserError
from user_peer.openfmt.ros2 import ros_topic

__all__ = ["OwnershipServices", "trigger_class", "SERVICES"]

SERVICES = ("request_ownership", "release_ownership")


def trigger_class() -> type | None:
    """``std_srvs.srv.Trigger`` where it is importable (built by :mod:`user_peer.ros2.msgbuild`), else None."""
    try:
        from std_srvs.srv import Trigger
    except ImportError:
        return None
    return Trigger


class OwnershipServices:
    """The two Trigger services of each driven robot; ``robot(rid)`` gives the login's handle of a robot
    (``World.robot``), whose ``request``/``release`` do the asking."""

    def __init__(
        self, node: Any, namespace: str, robot: Callable[[str], Any], user: str, service: type | None = None
    ) -> None:
        self.node, self.ns, self.robot, self.user = node, namespace.strip("/"), robot, user
        self.service = service if service is not None else trigger_class()
        self.available = self.service is not None
        self._services: dict[str, list[Any]] = {}  # robot -> its two services
        self.calls = 0

    def add(self, rid: str) -> None:
        """``rid``'s services (again only after :meth:`forget`)."""
        if not self.available or rid in self._services:
            return
        self._services[rid] = [
            self.node.create_service(
                self.service,
                ros_topic("/".join((self.ns, rid, "request_ownership"))),
                lambda req, resp, r=rid: self._answer(resp, r, self.request),
            ),
            self.node.create_service(
                self.service,
                ros_topic("/".join((self.ns, rid, "release_ownership"))),
                lambda req, resp, r=rid: self._answer(resp, r, self.release),
            ),
        ]

    def forget(self, rid: str) -> None:
        """The robot left the world: its services go."""
        for srv in self._services.pop(rid, []):
            self.node.destroy_service(srv)

    def request(self, rid: str) -> str:
        """Own ``rid`` now (no queue); the message for the response. :class:`FabricUserError` when refused."""
        epoch = self.robot(rid).request()
        return f"{self.user} owns {rid} (epoch {epoch})"

    def release(self, rid: str) -> str:
        """Give ``rid`` up; the message for the response. :class:`FabricUserError` when this login does not own it
        (the authority ignores such a release without a word: the replica's record says it instead)."""
        handle = self.robot(rid)
        if handle.record is not None and handle.owner != self.user:
            raise FabricUserError(f"not the owner ({handle.owner or 'free'}): {self.user} has nothing to release")
        handle.release()
        return f"{rid} released by {self.user}"

    def _answer(self, resp: Any, rid: str, do: Callable[[str], str]) -> Any:
        self.calls += 1
        try:
            resp.success, resp.message = True, do(rid)
        except FabricUserError as exc:
            resp.success, resp.message = False, f"{rid}: {exc.reason}"
        self.node.get_logger().info(f"{'done' if resp.success else 'refused'}: {resp.message}")
        return resp
