"""A reload keeps her session (:class:`user_peer.console.login.Logins` tickets): real worlds on the test's router."""

from __future__ import annotations

import pytest

from robofabric.testing import wait_until
from user_peer.console.login import LOG_LINES, LoginError, Logins, login_config


def _logins(worlds: list, grace: float, stopped: list) -> Logins:
    from user_peer.world import World

    def open_world(config, name: str):
        w = World(config, name)
        worlds.append(w)
        return w

    return Logins(open_world, grace=grace, on_leave=stopped.append)


def test_a_reloaded_tab_gets_her_world_and_its_ticket_back_within_the_grace_without_her_password(world, router, worlds):
    stopped: list = []
    logins = _logins(worlds, 0.5, stopped)
    w = logins.login(login_config(world, (f"tcp/127.0.0.1:{router[1]}",), "alice", ""), "alice", "")
    token, ticket = logins.ticket("alice")
    ticket.lines.append(("ownership base1: nobody -> alice", None))
    ticket.selected = "base1"
    logins.leave("alice", w)  # the tab reloads: its page goes, the grace begins
    assert stopped == [w]
    assert logins.resume(token) == (w, ticket)  # the same session, the tab's log and selection
    assert logins._held["alice"].closer is None and not w.closed  # back within the grace: it stays open
    assert logins.resume("not-" + token) is None and logins.resume("") is None
    logins.leave("alice", w)
    wait_until(lambda: w.closed, timeout=10, what="her world closed after the grace")
    assert logins.resume(token) is None  # the session ended: the ticket with it
    assert len(worlds) == 1


def test_log_out_ends_her_session_at_once_and_a_page_of_the_old_session_leaves_nothing_of_a_new_one(
    world, router, worlds
):
    stopped: list = []
    logins = _logins(worlds, 60.0, stopped)
    cfg = login_config(world, (f"tcp/127.0.0.1:{router[1]}",), "alice", "")
    w = logins.login(cfg, "alice", "")
    assert logins.login(cfg, "alice", "") is w  # a second tab of hers
    token, _ = logins.ticket("alice")
    logins.logout("alice", w)
    assert stopped == [w] and w.closed and logins.users() == []  # at once, not after the grace, every tab
    assert logins.resume(token) is None
    w2 = logins.login(cfg, "alice", "")
    assert w2 is not w
    logins.leave("alice", w)  # her old tab goes, after she logged in anew: not her new session's page
    logins.logout("alice", w)
    assert stopped == [w] and not w2.closed and logins.users() == ["alice"]
    with pytest.raises(LoginError, match="not logged in"):
        logins.ticket("bob")
    logins.close()


def test_a_tabs_log_keeps_its_newest_lines():
    from user_peer.console.login import Ticket

    t = Ticket("alice")
    for i in range(LOG_LINES + 50):
        t.lines.append((f"line {i}", None))
    assert len(t.lines) == LOG_LINES and t.lines[0][0] == "line 50"
