"""The teacher's page (``/teacher``): the class at a glance, and the instructor's actions on its robots.

Who is in (her pages on this console, her live session, what she owns and waits for), every robot's owner,
queue, motion and lock, and the actions: Release a robot, Give it to a student, Lock / Unlock it, Stop it, Reset
it, and Stop all / Reset world. The page logs in as the instructor (her own name and password, her own session:
the console holds no credential), and a login that is not one of the console's ``--instructors`` is refused
before any session opens; each action checks again (:func:`.teacher.require_staff`). The actions are the
authority's staff actions (:mod:`ownership.staff`), each logged as an ``own_staff`` event in every page's log.
What the tables show is worked out by :mod:`.teacher` (pure). A reload keeps her session as a student's page does
(:mod:`.login_card`): the tab keeps a ticket in its ``sessionStorage`` (a key of its own, so a student's tab and the
teacher's never take each other's), and Log out ends the session.
"""

from __future__ import annotations

import json
import logging
import threading
from typing import TYPE_CHECKING, Any

from nicegui import ui

from fabric.interfaces import NoReply, ServiceError
from fabric.text import one_line
from user_peer.console import teacher
from user_peer.console.login import LoginError, login_config
from user_peer.console.workers import CALLS, LOGINS, off_loop
from user_peer.errors import FabricUserError

if TYPE_CHECKING:
    from user_peer.console.server import Console

__all__ = ["TeacherPage", "REFRESH_S"]

log = logging.getLogger("robofabric.console")

STORAGE_KEY = "rf-teacher-session"
"""The tab's ``sessionStorage`` key of its ticket (a student's page keeps hers under another)."""
REFRESH_S = 1.0
"""How often the tables are read again (the records, the console's logins, the world's live users)."""

STUDENT_COLUMNS = [
    {"name": n, "label": label, "field": n, "align": "left"}
    for n, label in (
        ("name", "Name"),
        ("role", "Role"),
        ("pages", "Pages here"),
        ("live", "In the world"),
        ("owns", "Owns"),
        ("waits", "Waits for"),
    )
]


class TeacherPage:
    """One tab of the teacher's page."""

    def __init__(self, console: "Console", client: Any) -> None:
        self.console = console
        self.client = client
        self.world: Any = None
        self.user = ""
        self.kinds: dict[str, str] = {}
        self.rows: dict[str, dict[str, Any]] = {}  # robot -> its row's labels and buttons
        self._busy = False
        self._ended = False

    def show(self) -> None:
        from user_peer.console.page import A11Y_JS, PRIMARY

        ui.page_title(f"robofabric teacher · {self.console.world}")
        self.client.page.language = "en-US"
        ui.colors(primary=PRIMARY)
        ui.add_head_html(A11Y_JS)
        self.root = ui.column().classes("full-width")
        with self.root, ui.card().style("margin: 4rem auto 0; width: 24rem"):
            ui.label(f"robofabric · teacher's page · world {self.console.world}").classes("text-h6").props(
                'role="heading" aria-level="1"'
            )
            self.name_in = ui.input("Name").props('autofocus aria-label="Name"').classes("full-width")
            self.pw_in = ui.input("Password", password=True).props('aria-label="Password"').classes("full-width")
            ui.label("For instructors: type the name and password of your instructor's login card.").classes(
                "text-caption"
            )
            self.button = ui.button("Log in", on_click=self.login)
            self.pw_in.on("keydown.enter", self.login)
            self.msg = ui.label("").props('role="alert"').classes("text-negative")
        self.client.on_connect(self.resume)

    async def login(self) -> None:
        name, password = (self.name_in.value or "").strip(), self.pw_in.value or ""
        try:
            teacher.require_staff(name, self.console.instructors)  # before any session opens: a student gets none
        except teacher.NotStaff as exc:
            self.msg.text = f"Refused: {exc.reason}"
            return
        self.button.disable()
        self.msg.text = f"logging in as {name}..."
        try:
            cfg = login_config(
                self.console.world, self.console.connect, name, password, base_file=self.console.base_file
            )
            world = await off_loop(LOGINS, self.console.logins.login, cfg, name, password, self.client.ip)
            self.kinds = await off_loop(LOGINS, _kinds, world)
        except LoginError as exc:
            self._refused(exc.reason)
            return
        except FabricUserError as exc:  # logged in, but the world did not answer
            self.console.logins.leave(name, None)
            self._refused(f"Could not join world {self.console.world}: {exc.reason}")
            return
        token, ticket = self.console.logins.ticket(name)
        self.client.run_javascript(f"sessionStorage.setItem({json.dumps(STORAGE_KEY)}, {json.dumps(token)})")
        await self._enter(world, name)

    async def resume(self) -> None:
        """A reloaded tab's ticket, while her session is held (her pages, then the grace), opens the page again
        with no login; the login card stays otherwise. The ticket's name is checked as a login's is."""
        if self.world is not None:
            return
        from user_peer.console.login_card import READ_TIMEOUT_S

        try:
            token = await self.client.run_javascript(
                f"sessionStorage.getItem({json.dumps(STORAGE_KEY)})", timeout=READ_TIMEOUT_S
            )
        except Exception as exc:  # a tab that never answered keeps its login card
            log.info("console: a teacher's page did not say whether it holds a ticket: %s", exc)
            return
        if not isinstance(token, str) or not token or self.world is not None:
            return
        got = self.console.logins.resume(token)
        if got is None:
            self.client.run_javascript(f"sessionStorage.removeItem({json.dumps(STORAGE_KEY)})")
            self.msg.text = "Your session ended: log in again"
            return
        world, ticket = got
        try:
            teacher.require_staff(ticket.name, self.console.instructors)
            self.kinds = await off_loop(LOGINS, _kinds, world)
        except (teacher.NotStaff, FabricUserError) as exc:
            self.console.logins.leave(ticket.name, world)
            self._refused(f"Refused: {getattr(exc, 'reason', exc)}")
            return
        await self._enter(world, ticket.name)

    async def _enter(self, world: Any, name: str) -> None:
        self.world, self.user = world, name
        self.client.on_delete(self.end)
        self.root.clear()
        with self.root:
            self._main()
        await self.refresh()

    async def logout(self) -> None:
        """Her session ends now, in every tab of hers; this one goes back to its login card."""
        self.client.run_javascript(f"sessionStorage.removeItem({json.dumps(STORAGE_KEY)})")
        world, self.world = self.world, None
        self._ended = True
        await off_loop(LOGINS, self.console.logins.logout, self.user, world)
        ui.navigate.reload()

    def _refused(self, text: str) -> None:
        self.msg.text = text
        self.button.enable()

    def end(self) -> None:
        """The tab went: her session is left as a student's page leaves it (closed after the grace)."""
        if self._ended or self.world is None:
            return
        self._ended = True
        threading.Thread(target=self.console.logins.leave, args=(self.user, self.world), daemon=True).start()

    # ------------------------------------------------------------------ layout

    def _main(self) -> None:
        ui.label(f"robofabric · teacher's page · world {self.console.world} · {self.user}").classes("text-h6").props(
            'role="heading" aria-level="1"'
        )
        self.message = (
            ui.label("").props('role="status" aria-live="polite"').classes("text-body1").style("min-height: 1.5rem")
        )
        with ui.row().classes("items-center"):
            ui.button("Stop all", on_click=lambda: self.act_all("stop")).props("color=negative")
            ui.button("Reset world", on_click=self._confirm_reset)
            ui.button("Log out", on_click=self.logout).props("flat")
        ui.label("Robots").classes("text-subtitle1").props('role="heading" aria-level="2"')
        with ui.grid(columns="repeat(6, auto) 1fr").classes("items-center full-width").style("gap: 0.25rem 1rem"):
            for head in ("Robot", "Owner", "Queue", "State", "Locked", "Give to", "Actions"):
                ui.label(head).classes("text-weight-bold")
            for rid in sorted(self.kinds):
                self._robot_row(rid)
        ui.label("Class").classes("text-subtitle1").props('role="heading" aria-level="2"')
        self.students = ui.table(columns=STUDENT_COLUMNS, rows=[], row_key="name").props(
            'flat dense aria-label="Class"'
        )
        ui.timer(REFRESH_S, self.refresh)

    def _robot_row(self, rid: str) -> None:
        row: dict[str, Any] = {"robot": ui.label(f"{rid} ({self.kinds[rid]})")}
        for f in ("owner", "queue", "state", "locked"):
            row[f] = ui.label("")
        row["to"] = (
            ui.select([], label=f"Give {rid} to")
            .props(f'dense outlined aria-label="Give {rid} to"')
            .style("min-width: 10rem")
        )
        with ui.row().classes("items-center no-wrap").style("gap: 0.25rem"):
            for op, label in teacher.LABELS.items():
                row[op] = ui.button(label, on_click=lambda _, rid=rid, op=op: self.act(rid, op)).props(
                    f'dense no-caps aria-label="{label} {rid}"'
                )
                # shown by the first refresh, as the robot's record allows: until then a reloaded page offered
                # Lock and Unlock together (the grouped run of 2026-11-30 found both on the page at once)
                row[op].set_visibility(False)
        self.rows[rid] = row

    def _confirm_reset(self) -> None:
        with ui.dialog() as dialog, ui.card():
            ui.label("Reset the world? Every robot goes back to its start; owners keep their robots.")
            with ui.row():
                ui.button("Reset every robot", on_click=lambda: (dialog.close(), self.act_all("reset")))
                ui.button("Cancel", on_click=dialog.close).props("flat")
        dialog.open()

    # ------------------------------------------------------------------ actions

    def say(self, text: str) -> None:
        self.message.text = one_line(text, 400)

    async def act(self, rid: str, op: str) -> None:
        """One staff action on ``rid``, checked here again (whatever the page sent), answered by the authority."""
        to = (self.rows[rid]["to"].value or "") if op == "give" else ""
        if op == "give" and not to:
            self.say(f"Give {rid}: choose a student first")
            return
        self.say(await off_loop(CALLS, self._staff, rid, op, to))
        await self.refresh()

    async def act_all(self, op: str) -> None:
        """Stop all / reset the world: the staff action on every robot of the class, in turn."""
        said = [await off_loop(CALLS, self._staff, rid, op, "") for rid in sorted(self.kinds)]
        refused = [s for s in said if not s.startswith("done")]
        what = "stop all" if op == "stop" else "reset world"
        self.say(
            f"{what}: {len(said) - len(refused)} of {len(said)} robots" + (f"; {'; '.join(refused)}" if refused else "")
        )
        await self.refresh()

    def _staff(self, rid: str, op: str, to: str) -> str:
        """The authority's answer to one action, in words (off the event loop)."""
        try:
            teacher.require_staff(self.user, self.console.instructors, what="this action")
            out = self.world.ownership.client.staff(rid, op, to=to, timeout=self.world.timeout)
        except teacher.NotStaff as exc:
            return f"refused: {exc.reason}"
        except NoReply:
            return (
                f"{teacher.LABELS[op]} {rid}: no answer: the router let it through to no authority (is {self.user} an "
                "instructor login of the class, secure init --instructors?)"
            )
        except ServiceError as exc:
            return f"{teacher.LABELS[op]} {rid}: {exc.reason}"
        return (
            f"{out.outcome}: {out.reason}"
            if out.outcome == "done"
            else f"{teacher.LABELS[op]} {rid} refused: {out.reason}"
        )

    # ------------------------------------------------------------------ refresh

    async def refresh(self) -> None:
        if self.world is None or self._busy or self.world.closed:
            return
        self._busy = True
        try:
            records, live = await off_loop(LOGINS, _read, self.world)
            self._show(records, live)
        except Exception:
            log.exception("console: the teacher's page's refresh failed")
        finally:
            self._busy = False

    def _show(self, records: dict, live: list[str]) -> None:
        students = teacher.student_rows(self.console.logins.pages(), live, records, self.console.instructors)
        names = [s.name for s in students if s.role == "student" and s.live]
        for r in teacher.robot_rows(self.kinds, records):
            row = self.rows.get(r.robot)
            if row is None:
                continue
            for f in ("owner", "queue", "state"):
                row[f].text = getattr(r, f)
            row["locked"].text = f"locked by {r.locked}" if r.locked else "-"
            row["to"].set_options(names, value=row["to"].value if row["to"].value in names else None)
            for op in teacher.LABELS:
                row[op].set_visibility(op in r.actions)
        self.students.rows = [
            {
                "name": s.name,
                "role": s.role,
                "pages": s.pages,
                "live": "yes" if s.live else "no",
                "owns": s.owns,
                "waits": s.waits,
            }
            for s in students
        ]


def _kinds(world: Any) -> dict[str, str]:
    from user_peer import services

    return {e.id: e.kind for e in services.robot_entries(world.info())}


def _read(world: Any) -> tuple[dict, list[str]]:
    """The records and the world's live users (their liveliness tokens: console pages and scripts alike)."""
    records = world.ownership.client.snapshot()
    live = [pid for kind, pid in world.fabric.live_peers("user", timeout=0.5)]
    return records, live
