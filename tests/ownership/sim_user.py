"""A user that owns ROBOT in a real sim world and sends it a slow joint target, then holds on until killed.

argv: WORLD PORT USER ROBOT Q1,Q2,...
"""

from __future__ import annotations

import sys

import numpy as np

from fabric import keys
from fabric.interfaces import Command, JointTarget
from fabric.session import shutdown_event
from robofabric.testing import client

from ownership import OwnershipClient

if __name__ == "__main__":
    world, port, user, robot = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
    q = np.array([float(x) for x in sys.argv[5].split(",")])
    stop = shutdown_event()
    with client(world, port, kind="user", peer_id=user) as fab:
        own = OwnershipClient(fab, user, renew_s=0.1, timeout=10.0).start()
        out = own.request(robot)
        print("outcome", out, flush=True)
        fab.publish(
            keys.robot_cmd(world, robot, "joints", user), Command(user, out.epoch, JointTarget(q, speed_scale=0.1))
        )
        print("sent", flush=True)
        stop.wait()
        own.close()
