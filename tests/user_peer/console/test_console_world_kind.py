"""Whether the console's world asks for logins (user_peer/console/world_kind.py): the login card says what applies."""

from __future__ import annotations

import pytest

from robofabric.secure import init
from robofabric.testing import free_port, robofabric_cmd, wait_until
from user_peer.console.world_kind import CAPTIONS, login_caption, probe_logins


def test_the_caption_says_what_applies():
    assert login_caption(True) == "Type the name and password of your login card."
    assert "leave the password empty" in login_caption(False) and "login card" not in login_caption(False)
    assert "login card" in login_caption(None) and "open world" in login_caption(None)  # not known: both ways
    assert set(CAPTIONS) == {True, False, None}


def test_nobody_there_is_not_known_and_an_open_router_takes_a_session_without_a_login(world, router):
    assert probe_logins(world, (f"tcp/127.0.0.1:{free_port()}",)) is None
    assert probe_logins(world, (f"tcp/127.0.0.1:{router[1]}",)) is False


@pytest.mark.slow
def test_a_class_router_refuses_a_session_without_a_login(world, tmp_path, procs):
    ep = f"tcp/127.0.0.1:{free_port()}"
    init(tmp_path / "class", users=["alice"], listen=[ep])
    r = procs.start(robofabric_cmd("router", "--zenoh-config", str(tmp_path / "class" / "router.json5")), name="router")
    wait_until(
        lambda: "listening" in procs.output(r), timeout=30, what="the class's router", seen=lambda: procs.output(r)
    )
    assert probe_logins(world, (ep,)) is True
