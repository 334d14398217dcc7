"""A query asked while this client's own link is down waits for the link, within its time limit (real zenoh on
loopback: the router is closed and opened again on its port, and both clients reconnect by themselves)."""

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable

import pytest

from fabric import keys
from fabric.interfaces import NoReply, Twist
from fabric.rpc import SERVER_BACK_S, relinked_lately
from fabric.session import Fabric
from robofabric.testing import client, free_port, router_config, wait_until


@pytest.fixture
def cut_link(world):
    """(server, caller, cut): two clients of a router on a fresh port; ``cut(down_s)`` closes the router and
    opens another on the same port ``down_s`` later (in a thread: it returns at once)."""
    port = free_port()
    routers = [Fabric(router_config(world, port), kind="router", peer_id="router")]
    server, caller = client(world, port, kind="compute", peer_id="c1"), client(world, port, kind="user", peer_id="u1")
    # sessions long open, as the rules these tests judge meet them: a session just opened asks again anything that
    # found nobody (its own rule, its own test below), which would hide the others
    caller.rpc._opened_at = server.rpc._opened_at = float("-inf")
    threads: list[threading.Thread] = []

    def cut(down_s: float) -> None:
        routers[-1].close()
        wait_until(lambda: not caller._linked(), what="the caller's link down")

        def reopen() -> None:
            time.sleep(down_s)  # the outage itself, not a wait on a condition
            routers.append(Fabric(router_config(world, port), kind="router", peer_id="router"))

        threads.append(threading.Thread(target=reopen))
        threads[-1].start()

    yield server, caller, cut
    for t in threads:
        t.join(timeout=10)
    caller.close()
    server.close()
    for r in routers:
        r.close()


@pytest.mark.slow  # seconds: a router closed and opened again on its port
def test_a_query_asked_while_the_link_is_down_is_answered_once_it_is_back(world, cut_link):
    server, caller, cut = cut_link
    key = keys.srv(world, "fk", "arm1")
    server.rpc.serve(key, lambda k, req: Twist(req.v * 2, 0.0, header=server.header(k)), expected=Twist)
    wait_until(lambda: _answer(caller, key, 2.0), what="the first answer")
    cut(0.8)
    reply = caller.rpc.call(key, Twist(1.5, 0.0), timeout=10.0)  # before, at once: "nobody serves it"
    assert reply.v == 3.0
    assert caller.counters["queries_after_relink"] >= 1  # it waited for the link, then asked again


def test_nobody_serving_still_says_so_at_once_on_a_link_that_is_up(world, cut_link):
    _server, caller, _cut = cut_link
    with pytest.raises(NoReply, match="nobody serves it"):  # said only within half the limit: not waited out
        caller.rpc.call(keys.srv(world, "fk", "nobody"), Twist(1.0, 0.0), timeout=5.0)
    assert caller.counters["queries_after_relink"] == 0


@pytest.mark.slow  # seconds: a router closed and opened again on its port
def test_a_link_back_late_is_waited_for_its_routes_as_one_lost_just_now(world, cut_link):
    """A link that took 5 s to come back (a student woken at load 10) has its routes a moment after it: a query that
    finds nobody then is asked again for RELINK_S from the link's return, not from its loss (the times are set here,
    as a clock would; before, "nobody serves it" at once, CI of 2026-11-30)."""
    _server, caller, _cut = cut_link
    now = time.monotonic()
    caller._link_lost_at, caller._link_back_at = now - 5.0, now
    t0 = time.monotonic()
    with pytest.raises(NoReply, match="nobody serves it"):
        caller.rpc.call(keys.srv(world, "fk", "nobody"), Twist(1.0, 0.0), timeout=6.0)
    assert caller.counters["queries_after_relink"] >= 1
    assert 1.5 <= time.monotonic() - t0 < 6.0


def test_nobody_at_once_just_after_a_token_went_asks_again_until_its_server_could_be_back_then_says_nobody(
    world, cut_link
):
    """A closing link takes its tokens first and is told closed after them: a query that finds nobody at once just
    after a token went waits a moment to hear whether its own link closed (a student's plan query, asked in between
    at load 22). The server whose token went may be reconnecting (starved past its lease): the query is asked again
    until SERVER_BACK_S after the token went. Nobody came: "nobody serves it" then (the times set here)."""
    _server, caller, _cut = cut_link
    caller._token_gone_at = time.monotonic() - 0.5
    t0 = time.monotonic()
    with pytest.raises(NoReply, match="nobody serves it"):
        caller.rpc.call(keys.srv(world, "fk", "nobody"), Twist(1.0, 0.0), timeout=SERVER_BACK_S + 2.0)
    assert SERVER_BACK_S - 1.0 <= time.monotonic() - t0 < SERVER_BACK_S + 1.5  # until then, not its whole limit
    assert caller.counters["queries_after_server_left"] == 1  # one query, counted once
    # its link held, and no ask ended early: neither of those rules asked it again
    assert caller.counters["queries_after_relink"] == 0
    assert caller.counters["queries_after_server_went"] == 0


SERVER = textwrap.dedent(
    """
    import sys
    from fabric.interfaces import Twist
    from robofabric.testing import client
    world, port, key = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    c = client(world, port, kind="compute", peer_id="starved")
    c.rpc.serve(key, lambda k, req: Twist(req.v * 2, 0.0, header=c.header(k)), expected=Twist)
    print("serving", flush=True)
    sys.stdin.read()  # until the test closes its end
    c.close()
    """
)


@pytest.mark.slow  # a process, stopped past its lease
def test_a_query_that_finds_nobody_just_after_its_servers_token_went_is_answered_when_the_server_is_back(world):
    """The server's process stopped past its lease (a compute peer starved at load): the router drops its link, its
    services and its token. A student's query asked then found nobody at once, though the server reconnected a moment
    after it ran again (the scenario test's plan, right after the same compute peer built bob's map: run 4 of the
    twenty-third session). Her world watches the compute peers' tokens; a query that finds nobody at once within
    SERVER_BACK_S of one going is asked again, and the server, woken 0.3 s into the query, answers it."""
    port = free_port()
    router = Fabric(router_config(world, port), kind="router", peer_id="router")
    caller = client(world, port, kind="user", peer_id="u1")
    caller.rpc._opened_at = float("-inf")  # a session long open: its own rule (asked again after its opening) aside
    caller.watch_peers(lambda kind, peer, alive: None, kind="compute")  # as a user's world does (SimPresence.watch)
    key = keys.srv(world, "fk", "arm1")
    child = subprocess.Popen(
        [sys.executable, "-c", SERVER, world, str(port), key],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    waker: threading.Timer | None = None
    try:
        assert child.stdout is not None and child.stdin is not None
        assert child.stdout.readline().strip() == "serving"
        wait_until(lambda: _answer(caller, key, 2.0), timeout=30, what="the first answer")
        stopped_at = time.monotonic()
        child.send_signal(signal.SIGSTOP)
        wait_until(  # its lease (2 s) ran out: its link, services and token dropped, and the caller heard it
            lambda: ("compute", "starved") not in router.live_peers("compute") and caller._token_gone_at > stopped_at,
            timeout=30,
            interval=0.25,
            what="the router dropping the stopped server, and the caller hearing its token go",
        )
        waker = threading.Timer(0.3, child.send_signal, args=(signal.SIGCONT,))
        waker.start()
        reply = caller.rpc.call(key, Twist(1.5, 0.0), timeout=10.0)  # before: "nobody serves it" after 0.0 s
        assert reply.v == 3.0
        assert caller.counters["queries_after_server_left"] == 1
    finally:
        if waker is not None:
            waker.join()
        if child.poll() is None:
            child.send_signal(signal.SIGCONT)
            child.stdin.close()
            try:
                child.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.kill(child.pid, signal.SIGKILL)
                child.wait(timeout=10)
        caller.close()
        router.close()


def test_a_session_just_opened_asks_again_a_query_that_found_nobody(world, cut_link):
    """A fresh session's routes come a moment after it opens: at load a student's first request met "nobody serves
    it" at once with the authority there all along (run 42's alice, run 24's mallory). For RELINK_S from its opening
    a query that found nobody asks again: here its server comes 0.5 s after the ask, as late routes would."""
    server, caller, _cut = cut_link
    key = keys.srv(world, "fk", "late")
    caller.opened_at = time.monotonic()  # as if just opened (the fixture's wait for the router may have been long)
    caller.rpc._opened_at = caller.opened_at
    timer = threading.Timer(
        0.5,
        lambda: server.rpc.serve(key, lambda k, req: Twist(req.v * 2, 0.0, header=server.header(k)), expected=Twist),
    )
    timer.start()
    try:
        reply = caller.rpc.call(key, Twist(1.5, 0.0), timeout=5.0)  # before: "nobody serves it" at once
    finally:
        timer.join()
    assert reply.v == 3.0
    assert caller.counters["queries_after_open"] >= 1 and caller.counters["queries_after_relink"] == 0


def test_a_session_just_opened_still_says_nobody_when_its_last_ask_was_slow(world, cut_link, monkeypatch):
    """A session just opened asks again until its limit; its last ask has a few hundredths of a second, and at load
    finding nobody took longer than half of that: "no server answered in time" for an object nobody serves, and the
    own CLI did not say "unknown object" (run 49). Each ask here ends 0.06 s late, as a starved process's would."""
    _server, caller, _cut = cut_link
    caller.opened_at = time.monotonic()
    caller.rpc._opened_at = caller.opened_at
    real_ask = caller.rpc._ask

    def slow_ask(*args, **kwargs):
        said = real_ask(*args, **kwargs)
        time.sleep(0.06)  # the time a starved process takes to see the end (a fake for time only)
        return said

    monkeypatch.setattr(caller.rpc, "_ask", slow_ask)
    with pytest.raises(NoReply, match="nobody serves it") as info:
        caller.rpc.call(keys.srv(world, "fk", "nobody"), Twist(1.0, 0.0), timeout=2.0)
    assert info.value.nobody and caller.counters["queries_after_open"] >= 1


def test_a_silent_server_is_told_from_nobody_by_zenohs_own_word(world, cut_link):
    """A server there but silent: zenoh ends the ask with its Timeout, and the query says so, not "nobody"."""
    server, caller, _cut = cut_link
    key = keys.srv(world, "fk", "silent")
    held: list = []  # queries kept unanswered (a query dropped unanswered ends at once, as nobody's would)
    queryable = server.session.declare_queryable(key, held.append)
    try:
        # its route has reached the caller once zenoh's own probe of the key times out rather than finds nobody
        wait_until(
            lambda: any(rep.err is not None for rep in caller.session.get(key, timeout=0.2)),
            timeout=10,
            what="the silent server's route",
        )
        with pytest.raises(NoReply, match="no server answered in time") as info:
            caller.rpc.call(key, Twist(1.0, 0.0), timeout=1.0)
        assert not info.value.nobody
    finally:
        queryable.undeclare()
        held.clear()


def test_an_older_session_still_says_nobody_at_once(world, cut_link):
    _server, caller, _cut = cut_link
    caller.rpc._opened_at = time.monotonic() - 10.0  # opened long ago
    with pytest.raises(NoReply, match="nobody serves it"):
        caller.rpc.call(keys.srv(world, "fk", "nobody"), Twist(1.0, 0.0), timeout=5.0)
    assert caller.counters["queries_after_open"] == 0  # said as before: not asked again


def test_relinked_lately_counts_from_the_loss_or_the_return_whichever_is_later():
    assert relinked_lately(10.0, lost_at=9.0, back_at=float("-inf"))
    assert relinked_lately(10.0, lost_at=3.0, back_at=8.5)
    assert not relinked_lately(10.0, lost_at=3.0, back_at=7.0)
    assert not relinked_lately(10.0, lost_at=float("-inf"), back_at=float("-inf"))


def _slow_from_now(server: Fabric, caller: Fabric, key: str, slow_s: float | Callable[[], float]) -> threading.Event:
    """``server`` answers ``key`` (twice the request's ``v``), at once until it answered the caller three times in a
    row (right after the first, a query once found nobody at once: its routes still settling), then ``slow_s`` late
    (or ``slow_s()``, asked at each query); the event is set when a slow answer begins."""
    asked, slow_now = threading.Event(), threading.Event()

    def slow(k, req):
        if slow_now.is_set():
            asked.set()
            time.sleep(slow_s() if callable(slow_s) else slow_s)
        return Twist(req.v * 2, 0.0, header=server.header(k))

    server.rpc.serve(key, slow, expected=Twist)
    wait_until(lambda: all(_answer(caller, key, 3.0) for _ in range(3)), what="three answers in a row")
    slow_now.set()
    return asked


def _answer(caller: Fabric, key: str, v: float) -> bool:
    try:
        return caller.rpc.call(key, Twist(v / 2, 0.0), timeout=1.0).v == v
    except NoReply:
        return False


def test_a_query_whose_server_went_under_it_is_answered_by_the_server_back_a_moment_later(world, cut_link):
    """The server's side: the query found its server, which went before it answered (here its session closes; a
    compute peer starved past its lease loses its link that way, a sim dies and its standby takes over). The asker's
    link stayed up. A server back within about a second answers the same query, within its limit."""
    server, caller, _cut = cut_link
    key = keys.srv(world, "fk", "arm1")
    port = server.config.endpoints()[0][0].rsplit(":", 1)[1]
    asked = _slow_from_now(server, caller, key, 2.0)  # still working when its session goes
    back: list[Fabric] = []

    def go_and_come_back() -> None:
        asked.wait(10.0)
        time.sleep(0.5)  # half a second into its answer (an ask ended within RELINK_EARLY_S found no server)
        server.close()  # the query it holds ends at once for the asker: nobody answered
        time.sleep(0.3)
        again = client(world, int(port), kind="compute", peer_id="c2")
        again.rpc.serve(key, lambda k, req: Twist(req.v * 3, 0.0, header=again.header(k)), expected=Twist)
        back.append(again)

    t = threading.Thread(target=go_and_come_back)
    t.start()
    try:
        reply = caller.rpc.call(key, Twist(1.5, 0.0), timeout=10.0)  # before: "nobody serves it" after ~0.1 s
        assert reply.v == 4.5  # the server that came back answered
        assert caller.counters["queries_after_server_went"] == 1
    finally:
        t.join(timeout=10)
        for f in back:
            f.close()


@pytest.mark.slow  # seconds: a router closed and opened again on its port
def test_a_query_whose_limit_ran_out_while_its_link_was_down_is_asked_once_more_when_it_is_back(world, cut_link):
    """A student paused past her lease while her map was built wakes with her query's limit spent and her link
    closed: the limit is given again, once, from when her link is back (here the router is down longer than the
    limit). Before: "no reply after 1.0 s of 1.0 s", though the server was there all along."""
    server, caller, cut = cut_link
    key = keys.srv(world, "fk", "arm1")
    asked = _slow_from_now(server, caller, key, 0.6)  # still working when the router goes
    # the router goes 0.3 s into the answer (an ask ended within RELINK_EARLY_S found no server) and is down 1.2 s:
    # past the query's limit, and back within RELINK_S of it
    t = threading.Thread(target=lambda: (asked.wait(10.0), time.sleep(0.3), cut(1.2)))
    t.start()
    try:
        t0 = time.monotonic()
        reply = caller.rpc.call(key, Twist(1.5, 0.0), timeout=1.0)
        assert reply.v == 3.0
        assert caller.counters["queries_renewed"] == 1
        assert time.monotonic() - t0 >= 1.5  # it outlived its first limit: the router was down for 1.2 s of it
    finally:
        t.join(timeout=10)


@pytest.mark.slow  # seconds: a router closed and opened again on its port
def test_a_query_whose_link_came_back_too_late_in_its_limit_is_given_its_limit_again(world, cut_link):
    """The link is lost early in the query and back before its limit, with too little of it left for the server's
    answer (CI: the paused student's link came back 5 s after its loss, 1.4 s before his map's limit). The limit is
    given again from the link's return. Before: only a loss under the last ask counted, "no reply after 3.0 s of
    3.0 s", though the server was there all along."""
    server, caller, cut = cut_link
    key = keys.srv(world, "fk", "arm1")
    limit, started = 6.0, [float("inf")]
    # the first slow answer outlives the link; each later one comes 0.3 s past the first limit, whenever the link is
    # back (the limit is long: at load a link took 5 s to come back, and one back after it would prove nothing)
    answers = iter([1.5])
    asked = _slow_from_now(
        server, caller, key, lambda: next(answers, max(0.0, started[0] + limit + 0.3 - time.monotonic()))
    )
    t = threading.Thread(target=lambda: (asked.wait(10.0), time.sleep(0.3), cut(0.8)))
    t.start()
    try:
        started[0] = t0 = time.monotonic()
        reply = caller.rpc.call(key, Twist(1.5, 0.0), timeout=limit)
        took = time.monotonic() - t0
        assert reply.v == 3.0
        assert caller.counters["queries_after_relink"] >= 1, "the link was not back within the limit: proves nothing"
        assert caller.counters["queries_renewed"] == 1
        assert took >= limit, took  # it outlived its first limit
    finally:
        t.join(timeout=10)


@pytest.mark.slow  # seconds: its query waits out its limit for a router that never comes back
def test_a_query_to_a_router_gone_for_good_is_not_renewed(world, cut_link):
    _server, caller, cut = cut_link
    key = keys.srv(world, "fk", "arm1")
    cut(5.0)  # the router is back only after the query has given up
    t0 = time.monotonic()
    with pytest.raises(NoReply):
        caller.rpc.call(key, Twist(1.0, 0.0), timeout=1.0)
    assert caller.counters["queries_renewed"] == 0
    assert time.monotonic() - t0 < 1.0 + 2.0 + 1.0  # its limit, and RELINK_S waiting for a link not back in time


def test_nobody_found_at_once_just_after_a_standstill_says_so_after_its_wait(world, connect):
    """A query that found nobody at once just after its process stood still waits to hear whether its link closed,
    and then says what it found: nobody, not a silent server (a whole run at load read "no server answered in
    time" where nobody served the key, 2026-12-01)."""
    caller = connect("user", "u1")
    assert caller._standstill is not None
    now = time.monotonic()
    caller._standstill._since, caller._standstill._until = now - 1.5, now  # as its thread notes a 1.5 s gap
    with pytest.raises(NoReply) as err:
        caller.rpc.call(keys.srv(world, "fk", "nobody"), Twist(1.0, 0.0), timeout=1.0)
    assert "nobody serves it (found at once" in err.value.reason, err.value.reason
    assert "after 1.0 s of 1.0 s" in err.value.reason, err.value.reason  # it did wait: its link held
