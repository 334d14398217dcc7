"""``robofabric own`` against an in-process authority over real Zenoh."""

import subprocess

from fabric.testing import robofabric_cmd

from ownership import Authority, OwnershipClient


def _own(world, port, *args):
    return subprocess.run(robofabric_cmd("own", *args, "--world", world, "--connect", f"tcp/127.0.0.1:{port}"),
                          capture_output=True, text=True, timeout=60)


def test_own_list_request_release(world, router, connect):
    port = router[1]
    auth = Authority(connect("sim", "host"), {"arm": "exclusive", "ball": "scene"}, lease_s=5.0)
    try:
        r = _own(world, port, "request", "ball", "--user", "ann")
        assert r.returncode == 0 and "ball: granted" in r.stdout and "anyone writes" in r.stdout, r.stdout + r.stderr
        ann = OwnershipClient(connect("user", "ann"), "ann")  # a holder that stays (a CLI request ends with its process)
        assert ann.request("arm").outcome == "granted"
        auth.update_motion("arm", True)
        r = _own(world, port, "request", "arm", "--user", "ben")
        assert r.returncode == 1 and "denied: in motion, owned by ann" in r.stdout, r.stdout + r.stderr
        r = _own(world, port, "list", "--json")
        assert '"owner": "ann"' in r.stdout and '"state": "moving"' in r.stdout, r.stdout + r.stderr
        r = _own(world, port, "request", "arm", "--wait", "--user", "ben")
        assert r.returncode == 0 and "queued at position 1" in r.stdout, r.stdout + r.stderr
        r = _own(world, port, "release", "arm", "--user", "cy")
        assert r.returncode == 1 and "denied: not the owner (ann)" in r.stdout, r.stdout + r.stderr
        ann.close()
        r = _own(world, port, "request", "nope", "--user", "ann")
        assert r.returncode == 2 and "unknown object" in r.stderr, r.stdout + r.stderr
    finally:
        auth.close()
