"""A user peer for the benchmark's kill test: requests the arm and holds it until killed. argv: WORLD PORT USER"""

from __future__ import annotations

import sys
import threading

from fabric.testing import client

from ownership.client import OwnershipClient

if __name__ == "__main__":
    world, port, user = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    with client(world, port, kind="user", peer_id=user) as fab:
        own = OwnershipClient(fab, user, renew_s=0.1).start()
        print(own.request("arm"), flush=True)
        threading.Event().wait()
