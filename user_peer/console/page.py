"""One student's page: the login, then the paper's window (robot list, arm panel, base panel, live view, events).

Every button calls the Python user API (``user_peer``) of the page's own world, off the event loop
(:mod:`.workers`), so a slow answer holds up this page only. Refusals are shown with their
reason and the robot's owner. The console's one 5 Hz clock (:mod:`.ticker`) redraws what changed on every page
at once; a 10 Hz timer refreshes the twist
while an arrow key is held (the sim's twist is a deadman). The robot panels are those of :data:`.panels.PANELS`
(:mod:`.arm_panel`, :mod:`.base_panel`), each called through :class:`.panel.Panel`; the live view is :mod:`.view`;
what the view draws is :mod:`.state` and :mod:`.topview`.
"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING, Any, Callable

from nicegui import ui

from fabric.text import one_line

from user_peer.console import follow, state
from user_peer.console.drive import REFRESH_S
from user_peer.console.layout import Layout
from user_peer.console.login import Ticket
from user_peer.console.login_card import LoginCard
from user_peer.console.panels import PANELS, Panels
from user_peer.console.view import LiveView
from user_peer.console.view3d import View3D
from user_peer.console.wording import plain
from user_peer.console.workers import CALLS, LOGINS, off_loop
from user_peer.errors import FabricUserError, Paused
from user_peer.event_log import describe
from user_peer.pause import is_pause, pause_words

if TYPE_CHECKING:
    from user_peer.console.server import Console
    from user_peer.robot import Robot
    from user_peer.world import World

__all__ = ["ConsolePage", "event_line", "KEYS_JS", "TRUSTED", "UNVERIFIED", "EVENTS_PER_REDRAW"]

log = logging.getLogger("robofabric.console")

KEYS_JS = """
for (const type of ['keydown', 'keyup']) document.addEventListener(type, (e) => {
  const f = document.activeElement;
  const typing = f && (['INPUT', 'TEXTAREA', 'SELECT'].includes(f.tagName) || f.getAttribute('role') === 'slider');
  if (type === 'keydown' && (typing || e.repeat)) return;
  if (!typing && ['ArrowUp', 'ArrowDown', 'ArrowLeft', 'ArrowRight', ' '].includes(e.key)) e.preventDefault();
  emitEvent('rf_key', {key: e.key, down: type === 'keydown', t: Date.now()});
});
window.addEventListener('blur', () => emitEvent('rf_blur'));
"""
"""The page's keys: a key pressed while typing in a field or on a focused slider is that control's, never the
base's (the terminal UI turned the base when ← was meant for a slider); a release always counts, so a key
let go anywhere stops the base; the page losing focus stops it too. NiceGUI's ``ui.keyboard`` ignores by tag
name only, and every Quasar control is a ``div``. ``t`` is the press's time in the browser's clock, for the
console's health line (key to server)."""

A11Y_JS = """<script>
document.addEventListener('DOMContentLoaded', () => {
  const names = () => {
    document.querySelectorAll('.rf-map img:not([alt])').forEach((i) => i.setAttribute('alt', 'Map of the world from above'));
    document.querySelectorAll('.q-loading-bar:not([aria-label])').forEach((b) => b.setAttribute('aria-label', 'Loading'));
    document.querySelectorAll('.q-scrollarea__container:not([tabindex])').forEach((c) => {
      c.setAttribute('tabindex', '0');
      c.setAttribute('role', 'region');
      c.setAttribute('aria-label', c.closest('.nicegui-log') ? 'Event log' : 'Scrollable list');
    });
  };
  new MutationObserver(names).observe(document.body, {childList: true, subtree: true});
  names();
});
</script>"""
"""Names NiceGUI leaves out, on every page from its load (axe-core's image-alt and aria-progressbar-name): the map's
picture (NiceGUI's interactive image gives its ``img`` no ``alt``, and Vue may make a new one when the map's row
moves) and Quasar's loading bar (a progressbar, shown while the page waits on the server); and the keyboard's way
into a scroll area (axe-core's scrollable-region-focusable, once the event log overflows): ``ui.log``'s
``q-scroll-area`` holds only text, so its container takes the focus itself, as a named region."""

PRIMARY = "#1864ab"
"""The page's main colour: white on it, and it on white, reach 6:1 (axe-core's colour-contrast rule asks 4.5:1;
NiceGUI's #5898d4 gave 3.06:1 on every button)."""


TRUSTED = "trusted · "
"""How a line of the event log that the console vouches for starts (an event from its robot's authority, an
ownership change from the authority's record, a robot gone)."""
UNVERIFIED = "unverified (display only) · "
"""How every other event's line starts: what its writer said, shown greyed out."""
EVENTS_PER_REDRAW = 10
"""Event lines a redraw adds to a page's log at most (5 redraws a second): a flood of events costs a page a
summary line, not a thousand labels sent down its websocket."""


def event_line(ev: Any, trusted: bool) -> str:
    """An event log line, one line whatever the event holds (:func:`~user_peer.event_log.describe`); one its
    robot's authority did not send starts with :data:`UNVERIFIED` (as the terminal UI marks it), so nothing its
    writer put in it can make it start with :data:`TRUSTED`. A sim's ``held`` refusal reads as the pause it is
    (:func:`user_peer.pause.pause_words`), not as an error."""
    if is_pause(ev):
        text = one_line(pause_words(ev.object, ev) + (f" [{ev.user}]" if ev.user else ""), 400)
    else:
        text = describe(ev)
    return (TRUSTED if trusted else UNVERIFIED) + text


def _first_handles(world: Any, user: str, selected: str | None = None) -> tuple[list, dict[str, Any], tuple]:
    """The world's robots, handles for the robot of each panel's kind (:data:`.panels.PANELS`) a page shows first
    (the one she had selected before a reload, else hers if she owns one, else the first of the kind) and the
    view's layout: all of it waits on the network or reads the scene file, so off the pages' event loop."""
    from user_peer import services

    info = world.info()
    layout = state.scene_layout(info)
    entries = services.robot_entries(info)
    handles = {}
    for kind in dict.fromkeys(e.kind for e in PANELS):
        mine = [
            e
            for e in entries
            if e.kind == kind and (rec := world.ownership.record(e.id)) is not None and rec.owner == user
        ]
        first = (
            [e for e in entries if e.kind == kind and e.id == selected]
            or mine
            or [e for e in entries if e.kind == kind]
        )
        if first:
            handles[first[0].id] = world.robot(first[0].id)
    return entries, handles, layout


class ConsolePage:
    """The page of one browser tab: built by :meth:`show` when the tab opens."""

    FAILED = object()
    """What :meth:`call` returns when the call was refused or failed (its reason is on the page)."""

    def __init__(self, console: "Console", client: Any) -> None:
        self.console = console
        self.client = client
        self.world: World | None = None
        self.user = ""
        self.entries: list = []  # every robot of the world (user_peer.services.RobotEntry)
        self.handles: dict[str, Robot] = {}  # the handles made so far (a handle's robot is followed only while shown)
        self.view: LiveView | None = None
        self.view3d: View3D | None = None
        self.robots: dict[str, Robot] = {}  # kind -> the robot of that kind the page shows (its panel's)
        self.panels = Panels(self)  # the panels of .panels.PANELS the page has a robot for
        self.selected: str | None = None
        self._events_seen = 0
        self._gone_seen = 0
        self._owners: dict[str, str] = {}
        self._rows_from: dict[str, object] = {}  # robot -> the ownership record its row was written from
        self._letting_go: dict[str, int] = {}  # robot -> the epoch at which she released it herself
        self._tick: int | None = None  # its place on the console's redraw clock
        self.ticket: Ticket | None = None  # what the tab keeps across a reload
        self._ended = False

    # ------------------------------------------------------------------ login

    def show(self) -> None:
        ui.page_title(f"robofabric console · {self.console.world}")
        self.client.page.language = "en-US"  # <html lang>: a screen reader reads the page in English
        ui.colors(primary=PRIMARY)
        ui.add_head_html(A11Y_JS)
        self.root = ui.column().classes("full-width")
        self.card = LoginCard(self)  # the login, a reload's way back in, Log out (user_peer/console/login_card.py)
        with self.root:
            self.card.build()

    async def enter(self, world: World, name: str, ticket: Ticket) -> bool:
        """Her page, once she logged in (or came back with the tab's ticket): the robot she had selected, the
        tab's event log as it was. False (the reason on the login card) when the world did not answer."""
        try:
            entries, handles, (frame, boxes) = await off_loop(LOGINS, _first_handles, world, name, ticket.selected)
        except FabricUserError as exc:  # logged in, but the world did not answer
            self.console.logins.leave(name, world)
            self.card.refused(f"Could not join world {self.console.world}: {exc.reason}")
            return False
        self.world, self.user, self.entries, self.handles, self.ticket = world, name, entries, handles, ticket
        ticket.holder = self  # the tab's log is this page's now (the page before a reload lingers a while)
        self._events_seen = ticket.events_seen
        self._owners = ticket.owners = dict(ticket.owners)  # this page's from now on
        self.frame, self.view = frame, LiveView(self, frame, boxes)
        self.client.on_disconnect(self._disconnected)
        self.client.on_delete(self.end)

        def build() -> bool:  # her page in place of the login card; not when the tab went away meanwhile
            if self._ended:
                return False
            self.root.clear()
            with self.root:
                self._main()
            return True

        if not await self.console.builds.run(build):  # one build per turn of the loop (.ticker.OnePerTurn)
            return False
        for text, classes in list(ticket.lines):
            self.log.push(text, classes=classes)
        return True

    async def _disconnected(self) -> None:
        """The connection dropped (the tab closed, the network went): a held key is let go at once, since its
        release may never come."""
        await self.panels.let_go()

    def end(self) -> None:
        """The tab closed (or lost its connection for good): her robots stop, her world closes after the grace
        (a page she logged out of has no world: nothing to leave). Once."""
        if self._ended:
            return
        self._ended = True
        if self._tick is not None:
            self.console.ticker.remove(self._tick)
        self.panels.end()
        if self.view is not None:
            self.view.close()
        if self.world is not None:
            follow.forget(self.world.following, self)  # her other pages keep following what they show
            # stopping her robots waits on the network: never on the pages' event loop
            threading.Thread(
                target=self.console.logins.leave,
                args=(self.user, self.world),
                name=f"console-leave-{self.user}",
                daemon=True,
            ).start()

    # ------------------------------------------------------------------ layout

    def _main(self) -> None:
        w = self.world
        info = w.info()
        for r in self.handles.values():
            self.robots.setdefault(r.kind, r)
        had = self.ticket.selected if self.ticket is not None else None
        first = next(iter(self.robots.values()), None)  # the first panel's robot
        self.selected = had if had in self.handles else first.id if first is not None else None
        self.follow_shown()
        # every robot's pose for the view, kept in zenoh's ring and taken at a redraw: a page of a 20-robot class
        # reads at most 5 bursts a second, not 50 (only the robots it shows are followed in full: follow_shown)
        self.view.follow_poses()
        self.panels.make(info)

        with ui.row().classes("full-width items-center"):
            ui.label(f"robofabric console · world {w.name} · {w.user}").classes("text-h6").props(
                'role="heading" aria-level="1"'
            )
            if self.console.rerun_url:
                ui.link("Rerun web view (the rich view)", self.console.rerun_url, new_tab=True)
            ui.button("Log out", on_click=self.card.logout).props("flat no-caps")
        # a line high even when empty: text appearing in it must not move the view under the mouse
        self.message = (
            ui.label("").props('role="status" aria-live="polite"').classes("text-body1").style("min-height: 1.5rem")
        )
        self._robot_list()
        self.view3d = View3D(self) if self.console.view3d else None  # console --no-3d: the map alone
        self.layout = Layout(self)  # each robot's panel beside its view (user_peer/console/layout.py)
        self.layout.build()
        ui.label("Events").classes("text-subtitle1").props('role="heading" aria-level="2"')
        self.log = ui.log(max_lines=200).classes("full-width").style("height: 12rem")
        ui.on("rf_key", self.panels.key)
        ui.on("rf_blur", self._disconnected)
        ui.run_javascript(KEYS_JS)
        # the console's one clock: every page takes its poses at the start of a pass, then each redraws in turn
        self._tick = self.console.ticker.add(self.refresh, take=self.view.take)
        ui.timer(REFRESH_S, self.panels.tick)
        self.view.take()
        self.refresh()

    def _robot_list(self) -> None:
        with ui.card().classes("full-width"):
            self.rows: dict[str, ui.label] = {}
            with ui.row().classes("items-center"):  # one line for a few robots: the views stay on the screen
                ui.label("Robots").classes("text-subtitle1").props('role="heading" aria-level="2"')
                for r in self.entries:
                    with ui.row().classes("items-center no-wrap").style("gap: 0.25rem"):
                        ui.button(r.id, on_click=lambda _, rid=r.id: self._select(rid)).props("flat dense no-caps")
                        self.rows[r.id] = ui.label("")
            with ui.row().classes("items-center"):
                self.sel_label = ui.label("")
                ui.button("Request", on_click=lambda: self._ownership("request"))
                ui.button("Release", on_click=lambda: self._ownership("release"))
                ui.button("Queue", on_click=lambda: self._ownership("queue"))

    # ------------------------------------------------------------------ actions

    def say(self, text: str) -> None:
        """The page's message line: one line, whatever a reason or a name in it holds."""
        self.message.text = one_line(text, 400)

    async def call(self, what: str, fn: Callable, *args: Any, **kw: Any) -> Any:
        """``fn`` off the event loop; its refusal is shown with the reason (and the owner), never raised: it returns
        :attr:`FAILED` then."""
        try:
            out = await off_loop(CALLS, fn, *args, **kw)
        except FabricUserError as exc:
            self.say(f"{what}: {self.why(exc)}")
            return self.FAILED
        except Exception as exc:  # a network hiccup never ends the page
            log.exception("console: %s failed", what)
            self.say(f"{what}: {type(exc).__name__}: {exc}")
            return self.FAILED
        self.say(f"{what}: ok")
        return out

    def why(self, exc: FabricUserError) -> str:
        """A refusal in plain words with what to do next, then the code's reason (:func:`.wording.plain`); a pause
        is no refusal."""
        if isinstance(exc, Paused):
            return pause_words(exc.robot or self.selected or "the robot")
        rec = self.world.ownership.record(self.selected) if self.selected else None
        return plain(exc, robot=self.selected or "", owner=rec.owner if rec is not None else "", me=self.world.user)

    async def _handle(self, rid: str | None) -> Any:
        """The robot's user-API handle; made (and its streams followed) the first time she selects it."""
        if rid is None:
            return None
        if rid not in self.handles:
            r = await self.call(f"select {rid}", self.world.robot, rid)
            if r is self.FAILED:
                return None
            self.handles[rid] = r
        return self.handles[rid]

    async def _select(self, rid: str) -> None:
        self.selected = rid
        if self.ticket is not None:
            self.ticket.selected = rid
        r = await self._handle(rid)
        if r is not None:
            await self.panels.switch(r)  # her panel of its kind shows it now
        self.refresh()  # follows the robot shown now, lets go of the one shown before

    def follow_shown(self) -> None:
        """Follow in full only the robots the page shows (:func:`.follow.shown`): the selected one, and the panels'
        robots she owns; the others are drawn from the view's shared pose feed. Her other pages' robots stay
        followed (:func:`.follow.follow_for`)."""
        follow.follow_for(
            self.world.following, self, follow.shown(self.world, self.selected, self.handles, self.robots.values())
        )

    async def _ownership(self, op: str) -> None:
        r = await self._handle(self.selected)
        if r is None:
            return
        if op == "request":
            epoch = await self.call(f"request {r.id}", r.request)
            if epoch is not self.FAILED:
                self.say(f"request {r.id}: you own it (epoch {epoch})")
        elif op == "release":
            await self.panels.let_go(r)  # a key held for it lets go first
            rec = self.world.ownership.record(r.id)
            if rec is not None:
                self._letting_go[r.id] = (
                    rec.epoch
                )  # her own release: the status says "release: ok", not that she lost it
            await self.call(f"release {r.id}", r.release)
        else:  # a place in the queue (granted at once when the robot is still): the client renews a turn that comes
            out = await self.call(
                f"queue for {r.id}", self.world.ownership.client.request, r.id, wait=True, timeout=self.world.timeout
            )
            if out is not self.FAILED:
                self.say(f"queue for {r.id}: {out}")
        self.refresh()

    # ------------------------------------------------------------------ refresh

    def refresh(self) -> None:
        """Everything the page shows, from what its world holds now (the 5 Hz timer; an action's own answer)."""
        try:
            self._refresh_inner()
        except Exception:
            log.exception("console: refresh failed")

    def _refresh_inner(self) -> None:
        w = self.world
        if w is None:
            return
        if w.closed:  # she logged out in another tab of hers
            self.say("Your session has ended (you logged out): reload the page to log in again")
            return
        self.follow_shown()
        for r in self.entries:
            rec = w.ownership.record(r.id)
            if rec is not None and rec is self._rows_from.get(r.id):
                continue  # the same record as the last redraw's (a new one is a new object): nothing to say again
            self._rows_from[r.id] = rec
            self.rows[r.id].text = state.robot_line(w, r.id, r.kind).text()
            if rec is not None and self._owners.get(r.id, rec.owner) != rec.owner:
                # records come from the robot's authority only (the ownership replica checks): trusted
                self._push(
                    TRUSTED
                    + one_line(
                        f"ownership {r.id}: {self._owners[r.id] or 'nobody'} -> {rec.owner or 'nobody'} (epoch {rec.epoch})"
                    )
                )
                mine = (
                    self._owners[r.id] == w.user and self._letting_go.pop(r.id, -1) + 1 != rec.epoch
                )  # not her own release
                if mine:  # hers no more (a handover, her lease, an instructor): the status says so
                    self.say(
                        f"{r.id} is no longer yours: "
                        + (f"{rec.owner} owns it now" if rec.owner else "it is free now")
                        + " (the event log says why)"
                    )
            if rec is not None:
                self._owners[r.id] = rec.owner
        self.sel_label.text = f"selected: {self.selected}" if self.selected else "no robot"
        self.panels.refresh()
        self.layout.refresh()
        self.view.refresh()
        if self.view3d is not None:
            self.view3d.refresh(self.view.feed.raw if self.view.feed is not None else {})
        self._refresh_events()

    def _push(self, text: str, classes: str | None = None) -> None:
        """A line of the event log, kept with the tab's ticket too (a reload shows it again)."""
        self.log.push(text, classes=classes)
        if self.ticket is not None and self.ticket.holder is self:
            self.ticket.lines.append((text, classes))

    def _refresh_events(self) -> None:
        w = self.world
        mark = w.event_mark()
        if mark != self._events_seen:
            new, self._events_seen = mark - self._events_seen, mark
            if self.ticket is not None and self.ticket.holder is self:
                self.ticket.events_seen = mark
            if new > EVENTS_PER_REDRAW:
                self._push(
                    f"{new - EVENTS_PER_REDRAW} more events since the last redraw, not shown (the latest follow)"
                )
            for ev, trusted in w.recent_events(min(new, EVENTS_PER_REDRAW)):
                self._push(event_line(ev, trusted), classes=None if trusted else "text-grey-7 text-italic")
        gone = w.robots_gone
        if len(gone) != self._gone_seen:
            for rid in gone[self._gone_seen :]:
                self._push(one_line(f"robot {rid} gone: its sim peer left"))
            self._gone_seen = len(gone)
        if not w.world_alive:
            self.say(f"WORLD GONE: no sim peer of {w.name!r} (waiting for one)")
