"""The action servers' own node: one per kind of action, spun by a multi-threaded executor on a thread of its own.

An action's execute callback runs until its goal ends, and rclpy's single-threaded executor, which spins the
bridge's node, would resume a waiting coroutine on every turn (a busy loop) or block every other callback behind a
waiting function. So each kind of action (:mod:`.navigate`, :mod:`.follow_trajectory`) serves from a node of its
own, ``<bridge's node>_<suffix>``. It takes the bridge's ``--ros-args`` as the bridge's node does (rclpy's global
arguments: remaps of the action names, ``-p``/``--params-file`` parameters such as ``use_sim_time``, the log level)
but its own name: a node's local ``__node:=`` remap comes before the global one, which would give both nodes the
bridge's name.
"""

from __future__ import annotations

import threading
from typing import Any

from user_peer.openfmt.ros2 import ros_topic

__all__ = ["ActionHost"]


class ActionHost:
    """One ``action`` server per robot (``/NS/ROBOT/<name>``) on a node of its own; a subclass executes the goals
    (``_execute(rid, handle)``). ``available`` is False when ``action`` is None (its messages are not built)."""

    def __init__(self, node: Any, namespace: str, action: Any, name: str, suffix: str) -> None:
        self.action, self.name = action, name
        self.available = action is not None
        self.namespace = namespace.strip("/")
        self._servers: dict[str, Any] = {}
        self.node: Any = None
        self._executor: Any = None
        if self.available:
            import rclpy
            from rclpy.executors import MultiThreadedExecutor

            own = f"{node.get_name()}_{suffix}"  # the bridge's name after its --ros-args
            self.node = rclpy.create_node(own, context=node.context, cli_args=["--ros-args", "-r", f"__node:={own}"])
            self._executor = MultiThreadedExecutor(context=node.context)
            self._executor.add_node(self.node)
            threading.Thread(target=self._spin, name=f"ros2-{suffix}", daemon=True).start()

    def _spin(self) -> None:
        try:
            self._executor.spin()
        except Exception:  # the context shut down (Ctrl-C): the thread ends with it
            pass

    def _execute(self, rid: str, handle: Any) -> Any:
        raise NotImplementedError

    def serve(self, rid: str) -> None:
        """``rid``'s action server (a robot the bridge drives)."""
        if not self.available or rid in self._servers:
            return
        from rclpy.action import ActionServer, CancelResponse

        self._servers[rid] = ActionServer(
            self.node,
            self.action,
            ros_topic("/".join([self.namespace, rid, self.name])),
            lambda handle, r=rid: self._execute(r, handle),
            cancel_callback=lambda _request: CancelResponse.ACCEPT,
        )

    def forget(self, rid: str) -> None:
        server = self._servers.pop(rid, None)
        if server is not None:
            server.destroy()

    def close(self) -> None:
        """The servers, the executor and the node gone (idempotent; after Ctrl-C the context is down already)."""
        try:
            for rid in list(self._servers):
                self.forget(rid)
            if self._executor is not None:
                self._executor.shutdown(timeout_sec=1.0)
                self.node.destroy_node()
        except Exception:  # rclpy refuses to destroy entities of a context that has shut down: nothing left to free
            pass
        self._executor = None
