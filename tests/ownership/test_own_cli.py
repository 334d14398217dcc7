"""``robofabric own`` against an in-process authority over real Zenoh."""

import subprocess

import pytest

from robofabric.testing import robofabric_cmd, wait_until

from ownership import Authority, OwnershipClient

pytestmark = pytest.mark.slow  # every test here starts processes or runs for seconds


def _own(world, port, *args):
    return subprocess.run(
        robofabric_cmd("own", *args, "--world", world, "--connect", f"tcp/127.0.0.1:{port}"),
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_own_list_request_release(world, router, connect):
    port = router[1]
    auth = Authority(connect("sim", "host"), {"arm": "exclusive", "ball": "scene"}, lease_s=5.0).start()
    try:
        r = _own(world, port, "request", "ball", "--user", "ann")
        assert r.returncode == 0 and "ball: granted" in r.stdout and "anyone writes" in r.stdout, r.stdout + r.stderr
        ann = OwnershipClient(
            connect("user", "ann"), "ann"
        ).start()  # a holder that stays (a CLI request ends with its process)
        assert ann.request("arm").outcome == "granted"
        auth.update_motion("arm", True)
        r = _own(world, port, "request", "arm", "--user", "ben")
        assert r.returncode == 1 and "denied: in motion, owned by ann" in r.stdout, r.stdout + r.stderr
        r = _own(world, port, "list", "--json")
        assert r.returncode == 0, r.stderr
        doc = __import__("json").loads(r.stdout)  # one document
        recs = {rec["object"]: rec for rec in doc["records"]}
        assert doc["world"] == world and recs["arm"]["owner"] == "ann" and recs["arm"]["state"] == "moving", doc
        assert recs["ball"]["policy"] == "scene" and recs["arm"]["authority"] == "host", doc
        r = _own(world, port, "request", "arm", "--wait", "--user", "ben")
        assert r.returncode == 0 and "queued at position 1" in r.stdout, r.stdout + r.stderr
        r = _own(world, port, "release", "arm", "--user", "cy")
        assert r.returncode == 1 and "denied: not the owner (ann)" in r.stdout, r.stdout + r.stderr
        ann.close()
        r = _own(world, port, "request", "nope", "--user", "ann")
        assert r.returncode == 1 and "unknown object" in r.stderr, r.stdout + r.stderr  # the world has no such object
    finally:
        auth.close()


def test_own_request_hold_renews_until_interrupted_then_releases(world, router, connect):
    import signal

    from robofabric.testing import wait_until

    port = router[1]
    auth = Authority(connect("sim", "host"), {"arm": "exclusive"}, lease_s=1.5).start()
    ann = OwnershipClient(connect("user", "ann"), "ann").start()
    procs = []
    try:
        assert ann.request("arm").outcome == "granted"
        auth.update_motion("arm", True)
        argv = robofabric_cmd(
            "own",
            "request",
            "arm",
            "--wait",
            "--hold",
            "--user",
            "dee",
            "--world",
            world,
            "--connect",
            f"tcp/127.0.0.1:{port}",
        )
        dee = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        procs.append(dee)
        owner = lambda: auth.records()["arm"].owner  # noqa: E731
        wait_until(
            lambda: auth.records()["arm"].queue == ("dee",), what="dee queued", seen=lambda: auth.records()["arm"]
        )
        auth.update_motion("arm", False)
        ann.release("arm")  # the queued holder is next
        wait_until(lambda: owner() == "dee", what="dee granted from the queue", seen=lambda: auth.records()["arm"])
        n0 = auth.counters["requests"]
        wait_until(
            lambda: auth.counters["requests"] >= n0 + 6,
            timeout=30,
            what="renewals over two leases",
            seen=lambda: auth.counters,
        )
        assert owner() == "dee", auth.records()["arm"]  # renewed past the 1.5 s lease
        dee.send_signal(signal.SIGINT)
        out, _ = dee.communicate(timeout=30)
        assert dee.returncode == 0, out
        assert (
            "queued at position 1" in out
            and "holding arm as dee" in out
            and "owner dee" in out
            and "arm: released" in out
        ), out
        assert owner() == "", auth.records()["arm"]  # free
        r = _own(world, port, "request", "arm", "--duration", "1", "--user", "eve")
        assert r.returncode == 2 and "--duration needs --hold" in r.stderr, r.stdout + r.stderr
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
        ann.close()
        auth.close()


def test_own_watch_skips_and_counts_garbage_bad_tokens_and_foreign_records(world, router, connect, procs):
    """What any login may put on ownership keys or the liveliness space never crashes `own watch`."""
    from fabric import keys
    from fabric.interfaces import OwnershipRecord
    from robofabric.testing import wait_until

    port = router[1]
    auth = Authority(connect("sim", "host"), {"arm": "exclusive"}, lease_s=5.0).start()
    try:
        watch = procs.start(
            robofabric_cmd(
                "own",
                "watch",
                "--duration",
                "3",
                "--user",
                "wat",
                "--world",
                world,
                "--connect",
                f"tcp/127.0.0.1:{port}",
            ),
            name="watch",
        )
        wait_until(
            lambda: "arm" in procs.output(watch),
            timeout=30,
            what="watch's first snapshot",
            seen=lambda: procs.output(watch),
        )
        mallory = connect("tool", "mallory")
        token = mallory.session.liveliness().declare_token(f"rf/{world}/peer/sim/with space")
        mallory.session.put(keys.own(world, "arm"), b"\x00not msgpack")
        mallory.publish(keys.own(world, "arm"), OwnershipRecord("arm", owner="zed", epoch=9, authority="ghost-sim"))
        watch.wait(timeout=30)
        out = procs.output(watch)
        assert watch.returncode == 0, out
        assert "Traceback" not in out and "zed" not in out, out
        assert "skipped 1 undecodable payload(s), 1 record(s) from no live authority" in out, out
        token.undeclare()
    finally:
        auth.close()


def test_own_staff_takes_back_gives_and_locks_and_says_why_it_refuses(world, router, connect):
    port = router[1]
    auth = Authority(connect("sim", "host"), {"arm": "exclusive"}, lease_s=5.0).start()
    ann = OwnershipClient(connect("user", "ann"), "ann").start()
    ben = OwnershipClient(connect("user", "ben"), "ben").start()
    try:
        from robofabric.testing import wait_until

        wait_until(lambda: {"ann", "ben"} <= set(auth._state.live), timeout=30, what="ann and ben live")
        assert ann.request("arm").granted
        r = _own(world, port, "staff", "take_back", "arm", "--user", "teacher")
        assert r.returncode == 0 and "arm: done: arm taken back from ann by instructor teacher: now free" in r.stdout, (
            r.stdout + r.stderr
        )
        r = _own(world, port, "staff", "take_back", "arm", "--user", "teacher")
        assert r.returncode == 1 and "arm: denied: arm is free: nobody to take it back from" in r.stdout, (
            r.stdout + r.stderr
        )
        r = _own(world, port, "staff", "give", "arm", "--to", "ben", "--user", "teacher")
        assert (
            r.returncode == 0
            and "given to ben by instructor teacher" in r.stdout
            and auth.records()["arm"].owner == "ben"
        ), r.stdout + r.stderr
        r = _own(world, port, "staff", "lock", "arm", "--user", "teacher")
        assert r.returncode == 0 and auth.records()["arm"].locked == "teacher", r.stdout + r.stderr
        r = _own(world, port, "list")
        assert "locked by teacher" in r.stdout, r.stdout
        for bad in (("staff", "fly", "arm"), ("staff", "give", "arm"), ("staff", "stop", "arm", "--to", "ben")):
            r = _own(world, port, *bad, "--user", "teacher")
            assert r.returncode == 2 and r.stderr.strip().count("\n") == 0, r.stdout + r.stderr
    finally:
        ann.close()
        ben.close()
        auth.close()


def test_own_list_started_before_the_sims_token_waits_for_its_records(world, router, connect):
    """A ``list`` that joined before the authority's token came (a loaded machine): its first query found nothing
    to trust, and it said "no ownership authority answered" of a world that had one; it now waits up to
    ``RECORDS_WAIT_S`` for the client to ask again when the token comes."""
    port = router[1]
    watcher = connect("tool", "watcher")
    before = {pid for _, pid in watcher.live_peers("user", timeout=1.0)}
    lister = subprocess.Popen(
        robofabric_cmd("own", "list", "--world", world, "--connect", f"tcp/127.0.0.1:{port}", "--user", "ann"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    auth = None
    try:
        wait_until(
            lambda: lister.poll() is not None or {pid for _, pid in watcher.live_peers("user", timeout=0.5)} - before,
            timeout=30,
            what="the list's session in the world",
        )  # or the list has ended already: what it said is asserted below
        auth = Authority(connect("sim", "host"), {"arm": "exclusive"}, lease_s=5.0).start()
        out, err = lister.communicate(timeout=60)
        assert lister.returncode == 0 and "arm" in out and "(free)" in out, out + err
    finally:
        if lister.poll() is None:
            lister.kill()
            lister.wait(timeout=10)
        if auth is not None:
            auth.close()
