"""Whether the console's world asks for logins: the login card says what applies (a login card's name and
password in a class, a name of her choice in an open world), not both.

The console holds no login, so it asks the router the one way it can: it opens a session without credentials
(:func:`probe_logins`). A router of a class (``secure init``'s config) refuses it at the door; an open router
takes it (the probe closes it at once, having declared nothing). While the router cannot be reached the answer
is unknown, and the card says both ways, as it did before the console could tell.
"""

from __future__ import annotations

import logging

import socket

from fabric.config import ConfigError, FabricConfig

__all__ = ["probe_logins", "login_caption", "CAPTIONS"]

log = logging.getLogger("robofabric.console")

CAPTIONS = {
    True: "Type the name and password of your login card.",
    False: "This world has no logins: pick a name (letters, digits, '-' or '_') and leave the password empty.",
    None: "Type the name and password of your login card. In an open world (no logins), pick a name and leave the password empty.",
}
"""The login card's caption in a world that asks for logins (True), an open one (False), and one not known yet (None)."""


def login_caption(required: bool | None) -> str:
    """The login card's caption for a world that asks for logins (True), does not (False), or is not known (None)."""
    return CAPTIONS[required]


def probe_logins(world: str, connect: tuple[str, ...], base_file: str | None = None) -> bool | None:
    """Whether the router at ``connect`` refuses a session without credentials (True: a class's router; False: an
    open one), or None when no router answers there (nothing is known yet: ask again later)."""
    import zenoh

    try:
        cfg = FabricConfig(world=world, profile="client", connect=connect, config_file=base_file)
        conf = cfg.zenoh_config()
    except ConfigError as exc:
        log.info("console: cannot probe the router: %s", exc)
        return None
    try:
        session = zenoh.open(conf)
    except Exception as exc:  # zenoh says "Unable to connect" for a refused login and for nobody there alike
        up = [ep for ep in connect if _answers(ep)]
        log.info(
            "console: a session without a login %s (%s)",
            "was refused: logins required" if up else "found no router",
            str(exc).split(" at /")[0],
        )
        return True if up else None
    session.close()
    return False


def _answers(endpoint: str, timeout: float = 1.0) -> bool:
    """Whether something takes a TCP connection at ``endpoint`` (``tcp/HOST:PORT``, ``tls/...``): a router that
    refused the session is there; nobody there means nothing is known."""
    host, _, port = endpoint.partition("/")[2].rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port.split("#")[0])), timeout=timeout):
            return True
    except (OSError, ValueError):
        return False
