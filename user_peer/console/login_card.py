"""The page's door: the login card, the way back in after a reload, and Log out.

A login opens her session (:class:`~.login.Logins`) and gives the tab a ticket, kept in the tab's
``sessionStorage`` (per tab, kept across a reload, gone when the tab closes; never in a cookie, which every tab
and every request would carry). When the page loads again its first connection reads the ticket back, and a
ticket whose session is still held (her pages, then the grace) opens the page as she left it: her robot
selected, her event log, nothing typed. Log out ends the session at once, in every tab of hers.
"""

from __future__ import annotations

import json
import logging
from typing import TYPE_CHECKING

from nicegui import ui

from user_peer.console.login import LoginError, login_config
from user_peer.console.world_kind import login_caption
from user_peer.console.workers import LOGINS, off_loop

if TYPE_CHECKING:
    from user_peer.console.page import ConsolePage

__all__ = ["LoginCard", "STORAGE_KEY", "READ_TIMEOUT_S"]

log = logging.getLogger("robofabric.console")

STORAGE_KEY = "rf-console-session"
"""The tab's ``sessionStorage`` key of its ticket."""
READ_TIMEOUT_S = 30.0
"""How long the server waits for a loading tab to say whether it holds a ticket: a starved browser on a loaded
class machine answers late, and the login card is there meanwhile."""


class LoginCard:
    """The login form of one page, and its ticket."""

    def __init__(self, page: "ConsolePage") -> None:
        self.page = page
        self.token: str | None = None
        self._resuming = False

    @property
    def logins(self):
        return self.page.console.logins

    def build(self) -> None:
        world = self.page.console.world
        with ui.card().style("margin: 4rem auto 0; width: 24rem"):
            ui.label(f"robofabric · world {world}").classes("text-h6").props('role="heading" aria-level="1"')
            self.name_in = ui.input("Name").props('autofocus aria-label="Name"').classes("full-width")
            self.pw_in = (
                ui.input("Password", password=True, password_toggle_button=False)
                .props('aria-label="Password"')
                .classes("full-width")
            )
            # what applies: a class's login card, or a name of her choice in an open world (both while not known)
            ui.label(login_caption(self.page.console.logins_required)).classes("text-caption")
            self.button = ui.button("Log in", on_click=self.login)
            self.pw_in.on("keydown.enter", self.login)
            self.msg = ui.label("").props('role="alert"').classes("text-negative")
        self.page.client.on_connect(self.resume)

    def refused(self, text: str) -> None:
        self.msg.text = text
        self.button.enable()

    async def login(self) -> None:
        page = self.page
        name, password = (self.name_in.value or "").strip(), self.pw_in.value or ""
        self.button.disable()
        self.msg.text = f"logging in as {name}..."
        try:
            cfg = login_config(
                page.console.world, page.console.connect, name, password, base_file=page.console.base_file
            )
            world = await off_loop(LOGINS, self.logins.login, cfg, name, password, page.client.ip)
            token, ticket = self.logins.ticket(name)
        except LoginError as exc:
            self.refused(exc.reason)
            return
        if await page.enter(world, name, ticket):
            self.token = token
            page.client.run_javascript(f"sessionStorage.setItem({json.dumps(STORAGE_KEY)}, {json.dumps(token)})")

    async def resume(self) -> None:
        """The tab's first connection (and any later one while on the login card): its ticket, if it holds one
        whose session is still held, opens the page without a login."""
        page = self.page
        if page.world is not None or self._resuming:
            return
        self._resuming = True
        try:
            token = await page.client.run_javascript(
                f"sessionStorage.getItem({json.dumps(STORAGE_KEY)})", timeout=READ_TIMEOUT_S
            )
        except Exception as exc:  # a tab that never answered keeps its login card
            log.info("console: a page did not say whether it holds a ticket: %s", exc)
            token = None
        finally:
            self._resuming = False
        if not isinstance(token, str) or not token or page.world is not None:
            return
        got = self.logins.resume(token)
        if got is None:
            page.client.run_javascript(f"sessionStorage.removeItem({json.dumps(STORAGE_KEY)})")
            self.msg.text = "Your session ended: log in again"
            return
        world, ticket = got
        self.button.disable()
        self.msg.text = f"back in as {ticket.name}..."
        if await page.enter(world, ticket.name, ticket):
            self.token = token

    async def logout(self) -> None:
        """Her session ends now (her robots stop, are released, every tab of hers goes back to its login card)."""
        page = self.page
        page.client.run_javascript(f"sessionStorage.removeItem({json.dumps(STORAGE_KEY)})")
        world, page.world = page.world, None  # the page's own leave (when it goes) leaves nothing
        page.end()
        await off_loop(LOGINS, self.logins.logout, page.user, world)
        ui.navigate.reload()
