"""The notebook's live view (user_peer.notebook) draws a world from the user's own session, against a
real in-process sim peer; showing it inline needs a browser, so only the drawing is checked here."""

from __future__ import annotations

import threading

from robofabric.testing import client_config, wait_until
from sim_peer.serving.peer import SimPeer
from sim_peer.physics.world import SimWorld
from user_peer import notebook
from user_peer.api import World


def test_notebook_view_draws_the_world_and_keeps_no_thread_alive(world, router, connect):
    with SimPeer(connect("sim", "nb-sim"), SimWorld("combined"), rates={"joints": 20, "pose": 20, "scan": 10}):
        w = World(client_config(world, router[1]), "nb", timeout=5.0)
        try:
            view = notebook.NotebookView(w, max_hz=0)
            wait_until(
                lambda: (
                    view.logger.counts["JointState"] >= 3
                    and view.logger.counts["Pose"] >= 3
                    and view.logger.counts["Scan"] >= 1
                ),
                timeout=30,
                what="the view drawing joints, poses and scans",
                seen=lambda: dict(view.logger.counts),
            )
            assert view.logger.robots.keys() >= {"arm1", "base1"}
            drawing = [t for t in threading.enumerate() if t.name == "notebook-view"]
            assert drawing and all(t.daemon for t in drawing)  # a kernel or script never waits for it
            view.close()
        finally:
            w.close()
    assert not [t for t in threading.enumerate() if t.name == "notebook-view" and not t.daemon]
    assert isinstance(notebook.available(), bool)
