"""A user that owns ROBOT through the user API and turns it with one held twist (the API repeats it against
the sim's deadman), then holds on until killed.

argv: WORLD PORT USER ROBOT OMEGA
"""

from __future__ import annotations

import sys

from fabric.session import shutdown_event
from robofabric.testing import client_config
from user_peer.world import World

if __name__ == "__main__":
    world, port, user, robot, omega = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4], float(sys.argv[5])
    stop = shutdown_event()
    with World(client_config(world, port), user, timeout=10.0) as w:
        base = w.robot(robot)
        print("epoch", base.request(timeout=10.0), flush=True)
        base.twist(0.0, omega)
        print("driving", flush=True)
        stop.wait()
