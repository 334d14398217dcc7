"""The console's doors: page loads and websockets per address, pages that never connect, login guesses, whose socket
speaks for a page, HTTPS.

The decisions (:mod:`user_peer.console.limits`) are tested as pure functions with time passed in; the doors
themselves against a real console process, a real router and, for the foreign client id, a real sim, with pages
played by raw socket.io clients (:mod:`raw_page`), as a script on the LAN would.
"""

from __future__ import annotations

import asyncio
import json
import re
import ssl

import httpx
import pytest
import zenoh

from robofabric.secure import init
from robofabric.testing import free_port, robofabric_cmd, wait_until
from user_peer.console.doors import LOADS_BURST, WAITING_PER_ADDRESS
from user_peer.console.limits import Bucket, Buckets, LoginThrottle, Waiting, address_key, delay_after, pages_to_forget
from user_peer.console.login import LoginError, Logins, login_config

from raw_page import RawPage


# ---------------------------------------------------------------- the pure decisions


def test_an_address_is_its_ipv4_or_its_ipv6_64():
    assert address_key("10.0.0.7") == "10.0.0.7"
    assert address_key("::ffff:10.0.0.7") == "10.0.0.7"
    assert address_key("2001:db8:1:2::1") == address_key("2001:db8:1:2:aaaa:bbbb:cccc:dddd") == "2001:db8:1:2::/64"
    assert address_key("2001:db8:1:3::1") != address_key("2001:db8:1:2::1")
    assert address_key("testclient") == "testclient"


def test_a_bucket_lets_a_burst_through_then_its_rate():
    b = Buckets(rate=1.0, burst=3)
    assert [b.take("a", 0.0) for _ in range(3)] == [0.0, 0.0, 0.0]
    assert b.take("a", 0.0) == pytest.approx(1.0)  # the fourth waits a second
    assert b.take("b", 0.0) == 0.0  # another address has its own
    assert b.take("a", 1.0) == 0.0 and b.take("a", 1.0) > 0
    assert Bucket(0.0, 0.0).take(100.0, 1.0, 3)[1].tokens == 2.0  # never more than the burst
    small = Buckets(rate=1.0, burst=1, table_max=2)
    for k in "abc":
        small.take(k, 0.0)
    assert small.take("a", 0.0) == 0.0  # the oldest key was forgotten: the table stays bounded


def test_an_address_keeps_its_newest_waiting_pages_and_none_older_than_the_window():
    waiting = [Waiting(f"a{i}", "A", float(i)) for i in range(10)] + [
        Waiting("b0", "B", 0.0),
        Waiting("old", "C", -500.0),
    ]
    forget = pages_to_forget(waiting, 10.0, per_address=3, max_age=180.0)
    assert forget == ["old", "a0", "a1", "a2", "a3", "a4", "a5", "a6"]
    assert pages_to_forget([], 0.0, per_address=3, max_age=1.0) == []


def test_a_class_of_32_behind_one_nat_keeps_its_pages_while_they_wait_but_a_burst_is_still_cut():
    """A class of 32 whose pages were all served when the teacher said go, none connected yet (the server is slow
    to take their websockets then): all 32 are kept. The limit stays below the loads' burst, so an address that
    loads a burst and never connects still loses all but its newest."""
    klass = [Waiting(f"s{i}", "10.1.2.3", 100.0 + i / 10) for i in range(32)]
    assert pages_to_forget(klass, 110.0, per_address=WAITING_PER_ADDRESS, max_age=180.0) == []
    burst = [Waiting(f"f{i}", "10.6.6.6", 100.0 + i / 100) for i in range(LOADS_BURST)]
    forgotten = pages_to_forget(klass + burst, 110.0, per_address=WAITING_PER_ADDRESS, max_age=180.0)
    assert forgotten == [f"f{i}" for i in range(LOADS_BURST - WAITING_PER_ADDRESS)]  # the burst's oldest, no student


def test_the_delay_grows_with_each_failure_after_the_free_ones_up_to_a_cap():
    assert [delay_after(n, free=3, base=1.0, cap=60.0) for n in range(10)] == [0, 0, 0, 1, 2, 4, 8, 16, 32, 60]
    assert delay_after(10_000, free=3, base=1.0, cap=60.0) == 60.0


def test_the_throttle_holds_a_name_from_anywhere_and_an_address_for_any_name():
    t = LoginThrottle(name_free=3, address_free=10, base=1.0, cap=60.0, forget_s=900.0)
    for _ in range(3):
        assert t.wait("alice", "10.0.0.9", 0.0) == 0.0
        t.failed("alice", "10.0.0.9", 0.0)
    assert t.wait("alice", "10.0.0.9", 0.0) == 1.0
    assert t.wait("alice", "10.0.0.50", 0.5) == 0.5  # her name waits from any machine
    assert t.wait("bob", "10.0.0.9", 0.0) == 0.0  # the address has 10 free tries
    t.failed("alice", "10.0.0.9", 1.0)
    assert t.wait("alice", "10.0.0.9", 1.0) == 2.0
    for i in range(6):
        t.failed(f"n{i}", "10.0.0.9", 1.0)
    assert t.wait("carol", "10.0.0.9", 1.0) == 1.0  # the address's 10th failure: any name from it waits
    assert t.wait("carol", "10.0.0.8", 1.0) == 0.0
    t.succeeded("alice", "10.0.0.9")
    assert t.wait("alice", "10.0.0.50", 1.0) == 0.0 and t.wait("carol", "10.0.0.9", 1.0) == 0.0
    t.failed("dave", "x", 0.0)
    assert t.wait("dave", "x", 10_000.0) == 0.0  # old failures are forgotten


# ---------------------------------------------------------------- logins against a real router


@pytest.fixture
def secure_router(procs, tmp_path):
    ep = f"tcp/127.0.0.1:{free_port()}"
    d = tmp_path / "class"
    files = init(d, users=["alice", "bob"], listen=[ep]).clients
    router = procs.start(robofabric_cmd("router", "--zenoh-config", str(d / "router.json5")), name="router")
    wait_until(
        lambda: "listening" in procs.output(router), timeout=30, what="router", seen=lambda: procs.output(router)
    )
    passwords = {
        n: json.loads(zenoh.Config.from_file(str(files[n])).get_json("transport/auth/usrpwd/password"))
        for n in ("alice", "bob")
    }
    return ep, passwords


@pytest.mark.slow
def test_a_login_flood_is_throttled_per_name_and_address_and_reaches_the_router_only_a_few_times(secure_router, world):
    from user_peer.world import World

    ep, passwords = secure_router
    tried: list[str] = []
    opened: list = []

    def open_world(config, name):
        tried.append(name)
        w = World(config, name, join_timeout=5.0)
        opened.append(w)
        return w

    now = [0.0]
    logins = Logins(open_world, grace=0.1, on_leave=lambda w: None, clock=lambda: now[0])

    def attempt(name: str, password: str, address: str) -> str:
        try:
            logins.login(login_config(world, (ep,), name, password), name, password, address)
        except LoginError as exc:
            return exc.reason
        return "in"

    try:
        answers = [attempt("alice", f"guess{i}", "10.0.0.66") for i in range(30)]
        assert all("Login failed" in a for a in answers[:3]), answers[:3]
        assert all("Too many failed logins for alice" in a for a in answers[3:]), answers[3:]
        assert len(tried) == 3 and logins.throttled == 27  # 27 guesses never reached the router
        assert "Too many failed logins" in attempt(
            "alice", passwords["alice"], "10.0.0.5"
        )  # her name waits, from anywhere
        assert attempt("bob", passwords["bob"], "10.0.0.5") == "in"  # another name from another machine: not held
        now[0] += 1.0  # the first delay (1 s) passed: one more guess is tried, and the next waits 2 s
        assert "Login failed" in attempt("alice", "guess30", "10.0.0.66") and len(tried) == 5
        assert "try again in 2 s" in attempt("alice", passwords["alice"], "10.0.0.5")
        now[0] += 2.0
        assert attempt("alice", passwords["alice"], "10.0.0.5") == "in"
        assert "Login failed" in attempt("alice", "guess31", "10.0.0.66")  # a success started her count again
    finally:
        logins.close()


# ---------------------------------------------------------------- a console process


def _console(procs, world: str, router_ep: str, *extra: str) -> tuple[object, str]:
    web = free_port()
    scheme = "https" if "--tls-cert" in extra else "http"
    con = procs.start(
        robofabric_cmd("console", "--world", world, "--connect", router_ep, "--listen", f"127.0.0.1:{web}", *extra),
        name="console",
    )
    url = f"{scheme}://127.0.0.1:{web}/"
    wait_until(
        lambda: f"console: open {url}" in procs.output(con),
        timeout=60,
        what="the console's URL",
        seen=lambda: procs.output(con)[-2000:],
    )
    return con, url


def _rss_kib(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))


@pytest.mark.slow
def test_a_page_load_flood_is_refused_past_its_burst_and_pages_that_never_connect_are_forgotten(router, world, procs):
    """Pages loaded and never connected, as fast as a script asks: the address's burst is served, the rest refused at
    once (429), and of those served only the address's newest few are kept: an old one's websocket is refused
    within seconds, not after 180 s. The console's memory grows by a few MB, not 79 KiB a load."""
    con, url = _console(procs, world, f"tcp/127.0.0.1:{router[1]}")
    rss0 = _rss_kib(con.pid)

    async def flood() -> tuple[list[int], list[RawPage]]:
        async with httpx.AsyncClient(timeout=30) as http:
            pages = [RawPage(url) for _ in range(600)]
            codes = [await p.load(http) for p in pages]
        return codes, pages

    codes, pages = asyncio.run(flood())
    served = [p for p, c in zip(pages, codes) if c == 200]
    assert codes.count(429) >= 600 - LOADS_BURST - 30, codes  # a few more tokens come back while it runs
    assert set(codes) <= {200, 429} and LOADS_BURST <= len(served) <= LOADS_BURST + 30
    grown = _rss_kib(con.pid) - rss0
    print(f"console RSS {rss0} KiB -> +{grown} KiB after 600 loads ({len(served)} served)")
    assert grown < 20_000, grown  # 600 pages kept would be ~46 MB

    async def connects(page: RawPage) -> bool:
        try:
            await page.connect()
        except Exception:
            return False
        await page.close()
        return True

    # the served pages beyond the address's newest few are forgotten within seconds: an old page's handshake is refused
    wait_until(
        lambda: (w := _waiting(procs.output(con))) is not None and w <= WAITING_PER_ADDRESS,
        timeout=5,
        what="the pages beyond the address's newest forgotten",
        seen=lambda: procs.output(con)[-2000:],
    )
    assert not asyncio.run(connects(served[0]))
    assert asyncio.run(connects(served[-1]))  # the newest is kept: a browser that loaded it connects
    kept = sum(asyncio.run(connects(p)) for p in served[:-1])
    assert kept < WAITING_PER_ADDRESS


def _waiting(output: str) -> int | None:
    """The pages waiting to connect in the console's last doors line."""
    found = re.findall(r"console: doors: (\d+) pages waiting to connect", output)
    return int(found[-1]) if found else None


@pytest.mark.slow
def test_a_socket_event_naming_another_pages_client_is_refused(router, world, procs):
    """mallory's script, with her own page's socket, sends a click on alice's Release naming alice's client id (the
    element's and listener's ids as alice's page holds them): alice keeps arm1. The same click from alice's own
    socket releases it (the event was well formed: only its socket was wrong)."""
    import user_peer

    ep = f"tcp/127.0.0.1:{router[1]}"
    procs.start(robofabric_cmd("sim", "--scene", "arm_cell", "--world", world, "--connect", ep), name="sim")
    con, url = _console(procs, world, ep)
    carol = user_peer.connect(world=world, connect=ep, user="carol", join_timeout=60)

    def owner() -> str:
        rec = carol.ownership.record("arm1")
        return rec.owner if rec is not None else ""

    async def play() -> None:
        alice, mallory = RawPage(url), RawPage(url)
        async with httpx.AsyncClient(timeout=30) as http:
            await alice.load(http)
            await mallory.load(http)
        await alice.connect()
        await mallory.connect()
        try:
            await alice.send(alice.find(label="Name"), "update:value", "alice")
            await alice.send(alice.find(text="Log in"), "click")
            await alice.wait_for("alice's Release button", lambda: "Release" in alice.texts())
            await alice.send(alice.find(text="Request"), "click")
            await alice.wait_for("alice owns arm1", lambda: owner() == "alice")
            release = alice.find(text="Release")
            await mallory.send(release, "click", client_id=alice.client_id, listener=alice.listener(release, "click"))
            with pytest.raises(AssertionError):
                await alice.wait_for("arm1 released", lambda: owner() != "alice", timeout=3.0)
            assert owner() == "alice"
            await alice.send(release, "click")
            await alice.wait_for("arm1 released by alice's own click", lambda: owner() == "")
        finally:
            await alice.close()
            await mallory.close()

    try:
        wait_until(lambda: carol.ownership.record("arm1") is not None, timeout=60, what="arm1's record")
        asyncio.run(play())
    finally:
        carol.close()
    wait_until(
        lambda: "1 foreign socket messages" in procs.output(con),
        timeout=20,
        what="the doors' count",
        seen=lambda: procs.output(con)[-2000:],
    )


# ---------------------------------------------------------------- HTTPS


@pytest.mark.slow
def test_the_console_serves_https_with_the_certificate_secure_init_made(router, world, procs, tmp_path):
    d = tmp_path / "class"
    out = init(d, users=["alice"], tls=True, listen=["tls/0.0.0.0:7447"])
    assert "console (https)" in out.created
    web = d / "tls" / "web"
    con, url = _console(
        procs,
        world,
        f"tcp/127.0.0.1:{router[1]}",
        "--tls-cert",
        str(web / "console.pem"),
        "--tls-key",
        str(web / "console-key.pem"),
    )
    assert url.startswith("https://")
    ctx = ssl.create_default_context(cafile=str(d / "tls" / "ca.pem"))  # the class's CA: the name and chain are checked
    r = httpx.get(url, verify=ctx, timeout=30)
    assert r.status_code == 200 and "robofabric console" in r.text
    with pytest.raises(httpx.ConnectError):
        httpx.get(url, timeout=30)  # without the class's CA a browser warns: the certificate is not a public one
    with pytest.raises(httpx.RemoteProtocolError):
        httpx.get(url.replace("https://", "http://"), timeout=30)  # nothing in clear


def test_a_password_class_gets_its_consoles_certificate_on_asking(tmp_path):
    """The console's page carries passwords: a password class (no --tls) makes its certificate with --console-tls."""
    from cryptography import x509

    d = tmp_path / "class"
    out = init(d, users=["alice"], listen=["tcp/0.0.0.0:7447"], connect=["tcp/10.0.0.5:7447"], console_tls=True)
    assert {"ca", "console (https)"} <= set(out.created)
    cert = x509.load_pem_x509_certificate((d / "tls" / "web" / "console.pem").read_bytes())
    sans = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "10.0.0.5" in [str(ip) for ip in sans.get_values_for_type(x509.IPAddress)]
    eku = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
    assert list(eku) == [x509.oid.ExtendedKeyUsageOID.SERVER_AUTH]  # it serves; it can never log in to the router
    assert "console (https)" in init(d, users=["alice"], listen=["tcp/0.0.0.0:7447"], console_tls=True).kept
    init(tmp_path / "plain", users=["alice"])
    assert not (tmp_path / "plain" / "tls").exists()  # without asking: no CA, no certificate


@pytest.mark.slow
def test_a_certificate_without_its_key_or_one_that_does_not_load_is_a_usage_error(tmp_path):
    import subprocess

    bad = tmp_path / "bad.pem"
    bad.write_text("not a certificate")
    for extra, says in (
        (("--tls-cert", str(bad)), "go together"),
        (("--tls-cert", str(bad), "--tls-key", str(bad)), "--tls-cert"),
    ):
        out = subprocess.run(
            robofabric_cmd("console", "--connect", "tcp/127.0.0.1:1", *extra),
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert out.returncode == 2 and says in out.stderr and "Traceback" not in out.stderr, out.stderr
