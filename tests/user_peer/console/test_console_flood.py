"""One student's event text at another's console page, in a real browser (issue 42).

dave, with only his own login, publishes decode reports (any login may, on ``event/decode/by/dave``): first one
whose kind holds a newline and, after it, a line like the console's trusted ownership lines; then the flood of
the issue, reports whose reason is 2,000 newlines, 10 a second for 20 s. alice's page shows his text as data
(one unverified line per event, escaped), keeps answering her Stop within a bound all through the flood, stays
logged in, and she keeps her base. Debian's chromium through playwright, as in test_console_browser.py.
"""

from __future__ import annotations

import re
import threading
import time
import uuid

import pytest

from fabric import keys
from fabric.config import FabricConfig
from fabric.interfaces import Event, Header
from fabric.session import Fabric
from robofabric.secure import init
from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, wait_until
from test_console_browser import Klass, _password, browser, logged_in, message, open_page, shot, wait_message  # noqa: F401

pytestmark = pytest.mark.slow

ANSWER_S = 30.0
"""How long a click may wait for the page's answer during the flood. The page of the tree before gave none within
60 s (load 10-14), as in the issue; here, at load 8-12 on the shared 2 cores, answers took 0.8-8.8 s during the
flood, one click once waited 20 s for the browser, and the same clicks with 10 one-character reports a second
took up to 12 s (the load's, not the flood's): a bound for a loaded machine, far from "never". What the flood
costs the page itself is counted apart from the load: the lines added to its log (:data:`LINES_JS`)."""
LINES_JS = """() => { const log = document.querySelector('.nicegui-log'); window.rfAdded = 0; window.rfEvents = 0;
  new MutationObserver((ms) => { for (const m of ms) for (const n of m.addedNodes) {
    window.rfAdded += 1;
    const more = /^(\\d+) more events since the last redraw/.exec(n.textContent || '');
    window.rfEvents += more ? Number(more[1]) : 1; } })
    .observe(log, {childList: true, subtree: true}); }"""
"""Count the nodes added to the page's event log from now on (the tree before added 2,001 lines per report), and
the events they account for: a redraw shows at most 10 events and sums up the rest in one line
(``EVENTS_PER_REDRAW``), so a page redrawn late at load shows fewer lines than events."""
FLOOD_HZ, FLOOD_S = 10.0, 20.0


@pytest.fixture(scope="module")
def klass(tmp_path_factory):
    import user_peer

    tmp = tmp_path_factory.mktemp("flood")
    world = f"f{uuid.uuid4().hex[:8]}"
    ep = f"tcp/127.0.0.1:{free_port()}"
    d = tmp / "class"
    files = init(d, users=["alice", "dave"], instructors=["carol"], listen=[ep]).clients
    with ProcessGroup(tmp) as procs:
        router = procs.start(robofabric_cmd("router", "--zenoh-config", str(d / "router.json5")), name="router")
        wait_until(
            lambda: "listening" in procs.output(router), timeout=30, what="router", seen=lambda: procs.output(router)
        )
        sim = procs.start(
            robofabric_cmd("sim", "--scene", "combined", "--world", world, "--zenoh-config", str(files["sim"])),
            name="sim",
        )
        web = free_port()
        console = procs.start(
            robofabric_cmd("console", "--world", world, "--connect", ep, "--listen", f"127.0.0.1:{web}"), name="console"
        )
        url = f"http://127.0.0.1:{web}/"
        wait_until(
            lambda: f"console: open {url}" in procs.output(console),
            timeout=60,
            what="the console's URL",
            seen=lambda: procs.output(console)[-2000:],
        )
        carol = user_peer.connect(world=world, zenoh_config=str(files["carol"]), join_timeout=120)
        dave = Fabric(FabricConfig(world=world, config_file=str(files["dave"])), kind="user", peer_id="dave")
        try:
            wait_until(
                lambda: carol.fabric.live_peers("sim"),
                timeout=120,
                what="the sim",
                seen=lambda: procs.output(sim)[-2000:],
            )
            k = Klass(
                world,
                url,
                f"127.0.0.1:{web}",
                {n: _password(files[n]) for n in ("alice", "dave")},
                carol,
                procs,
                console,
            )
            k.dave = dave  # type: ignore[attr-defined]
            yield k
        finally:
            dave.close()
            carol.close()


def _log_lines(page) -> list[str]:
    return page.locator(".nicegui-log").inner_text().splitlines()


def _answered(page, click: str, pattern: str) -> float:
    """Seconds from clicking the button named ``click`` to the page's message matching ``pattern``."""
    t0 = time.monotonic()
    page.get_by_role("button", name=click, exact=True).click(timeout=ANSWER_S * 1000)
    wait_message(page, pattern, timeout=max(0.5, ANSWER_S - (time.monotonic() - t0)))
    return time.monotonic() - t0


def test_one_logins_event_text_neither_forges_trusted_lines_nor_stalls_anothers_page(browser, klass):
    w = klass.world
    dave: Fabric = klass.dave  # type: ignore[attr-defined]
    base = klass.carol.robot("base1")
    alice = open_page(browser, klass)
    logged_in(alice, klass, "alice")
    alice.get_by_role("button", name="base1", exact=True).click()
    alice.get_by_role("button", name="Request").click()
    wait_message(alice, r"request base1: you own it")
    # read where carol sees it too: her record came after the page's answer once (epoch 0 read, 1 at the end)
    epoch = wait_until(
        lambda: base.record is not None and base.record.owner == "alice" and base.record,
        timeout=30,
        what="carol seeing alice own base1",
        seen=lambda: base.record,
    ).epoch

    # a decode report whose kind holds a newline, then a line like the console's own trusted ownership lines
    forged = "trusted · ownership base1: alice -> dave (epoch 7)"
    dave.publish(
        keys.event_decode(w, "dave"),
        Event(kind=f"decode_error\n{forged}", object="base1", user="dave", header=Header.now()),
    )
    shown = wait_until(
        lambda: [ln for ln in _log_lines(alice) if "decode_error\\ntrusted" in ln],
        timeout=30,
        what="dave's report in alice's event log",
        seen=lambda: _log_lines(alice)[-5:],
    )
    assert all(ln.startswith("unverified (display only) · ") for ln in shown), shown
    assert not [ln for ln in _log_lines(alice) if ln.startswith("trusted · ") and "dave" in ln], _log_lines(alice)

    # the flood: 2,000 newlines a report, 10 a second for 20 s, while alice's page is asked and her lease watched
    owners: list[str] = []
    done = threading.Event()

    def flood() -> None:
        n, t0 = 0, time.monotonic()
        while (t := time.monotonic() - t0) < FLOOD_S:
            dave.publish(
                keys.event_decode(w, "dave"), Event(kind="decode_error", reason="\n" * 2000, header=Header.now())
            )
            n += 1
            time.sleep(max(0.0, n / FLOOD_HZ - t))
        done.set()

    def watch() -> None:
        while not done.wait(0.2):
            rec = base.record
            owners.append(rec.owner if rec is not None else "")

    alice.evaluate(LINES_JS)
    threads = [threading.Thread(target=flood, daemon=True), threading.Thread(target=watch, daemon=True)]
    for t in threads:
        t.start()
    answers: list[float] = []
    try:
        while not done.is_set():  # the plan and follow answers need no goal: only the page's own round trip
            answers.append(_answered(alice, "Follow", r"^Follow: plan a path first"))
            answers.append(_answered(alice, "Stop base", r"^stop base1: ok"))
    finally:
        done.set()
        for t in threads:
            t.join(timeout=30)
    print(
        f"alice's page during dave's flood: {len(answers)} answers, longest {max(answers):.2f} s, "
        f"median {sorted(answers)[len(answers) // 2]:.2f} s"
    )
    shot(alice, "after-event-flood")
    sent = int(FLOOD_HZ * FLOOD_S)
    # a report is a line, or counted in a redraw's summary line; events go out as zenoh's default puts, dropped
    # rather than blocking a full queue, so a flooder's report may be lost at load: the log is read once it
    # accounts for them all or has stopped growing (198 lines for 200 reports once, in a whole `make test`)
    counts: list[int] = []

    def all_or_still() -> int:
        counts.append(alice.evaluate("window.rfEvents"))
        done = counts[-1] >= sent or (len(counts) > 10 and counts[-1] == counts[-11])
        return counts[-1] if done else 0

    accounted = wait_until(
        all_or_still,
        timeout=60,
        interval=0.5,
        what="alice's log accounting for every report, or still for 5 s",
        seen=lambda: counts[-12:],
    )
    added = alice.evaluate("window.rfAdded")
    print(f"{sent} reports of 2,000 newlines: {added} nodes added to alice's event log, accounting for {accounted}")
    assert accounted >= 0.95 * sent, (accounted, added)  # the reports reached her page
    assert added <= sent + 50, added  # a line per report (and a few counts of lines not shown), never one per newline
    assert len(answers) >= 2 and max(answers) <= ANSWER_S, answers  # at least one Stop answered during the flood
    assert owners and set(owners) == {"alice"}, set(owners)
    assert base.record.owner == "alice" and base.record.epoch == epoch, base.record
    # still her page (not its login form), and the flood's lines are one line each in a bounded log
    alice.get_by_text(f"world {w} · alice").wait_for(timeout=10_000)
    assert not alice.get_by_label("Password").count()
    lines = _log_lines(alice)
    assert len(lines) <= 200 and [
        ln for ln in lines if ln.startswith("unverified (display only) · decode_error: \\n\\n")
    ], lines[-5:]
    assert all(ln.strip() for ln in lines), "an empty line in the log: a newline was shown as layout"
    # a burst (100 reports at once): a redraw adds at most 10 of them, and says how many it left out
    for i in range(100):
        dave.publish(keys.event_decode(w, "dave"), Event(kind="decode_error", reason=f"burst {i}", header=Header.now()))
    wait_until(
        lambda: [ln for ln in _log_lines(alice) if re.match(r"^\d+ more events since the last redraw, not shown", ln)],
        timeout=30,
        what="the count of the burst's lines not shown",
        seen=lambda: _log_lines(alice)[-3:],
    )
    wait_until(
        lambda: "decode_error: burst 99" in _log_lines(alice)[-1],
        timeout=30,
        what="the burst's last report shown",
        seen=lambda: _log_lines(alice)[-3:],
    )
    assert len([ln for ln in _log_lines(alice) if ": burst " in ln]) < 100
    alice.get_by_role("button", name="Release").click()
    wait_message(alice, r"release base1: ok")
    alice.context.close()
