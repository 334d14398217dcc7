"""`robofabric secure init`: the files a class needs, their secrets, and what a config says about who logs in."""

from __future__ import annotations

import json
import re
import stat
import subprocess

import pytest
import zenoh

from fabric.config import ConfigError, FabricConfig
from fabric.config import certificate_common_name
from robofabric.login_cards import QR_QUIET, TYPABLE, is_typable, typable_password
from robofabric.secure import Identity, access_control, init, read_credentials
from robofabric.testing import robofabric_cmd


def run_cli(*args, timeout=60):
    return subprocess.run(robofabric_cmd(*args), capture_output=True, text=True, timeout=timeout)


def _mode(path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_init_writes_router_and_one_config_per_identity_private_and_loadable(tmp_path):
    d = tmp_path / "class"
    out = init(d, users=["alice", "bob"], listen=["tcp/127.0.0.1:7999"])
    assert set(out.clients) == {"alice", "bob", "sim", "compute", "viewer"}
    for path in [out.router, *out.clients.values(), d / "credentials.txt"]:
        assert _mode(path) == 0o600, path
        if path.suffix == ".json5":
            zenoh.Config.from_file(str(path))  # zenoh itself accepts it
    assert _mode(d) == 0o700
    creds = read_credentials(d / "credentials.txt")
    assert set(creds) == set(out.clients) and len(set(creds.values())) == 5
    assert all(len(creds[p]) >= 20 for p in ("sim", "compute", "viewer"))  # peers: long random tokens
    assert all(is_typable(creds[p]) and len(creds[p]) == 14 for p in ("alice", "bob"))  # people type theirs
    cfg = FabricConfig(config_file=str(out.clients["alice"]))
    assert cfg.identity() == "alice" and cfg.endpoints()[0] == ("tcp/127.0.0.1:7999",)
    assert FabricConfig(config_file=str(out.router), profile="embedded").endpoints()[1] == ("tcp/127.0.0.1:7999",)
    router = zenoh.Config.from_file(str(out.router))
    assert json.loads(router.get_json("access_control/default_permission")) == "deny"
    assert 1 << 20 <= json.loads(router.get_json("transport/link/rx/max_message_size")) <= 16 << 20


def test_a_second_run_keeps_every_secret_and_adds_the_new_names(tmp_path):
    d = tmp_path / "class"
    init(d, users=["alice", "bob"])
    before = read_credentials(d / "credentials.txt")
    out = init(d, users=["carol"])  # alice and bob are not named again: they stay
    after = read_credentials(d / "credentials.txt")
    assert {k: after[k] for k in before} == before and "carol" in after
    assert out.created == ("carol",) and set(out.kept) == {"sim", "compute", "viewer"}
    rules = json.loads(zenoh.Config.from_file(str(out.router)).get_json("access_control/subjects"))
    assert {s["id"] for s in rules} >= {"alice", "bob", "carol"}


def test_a_secure_config_fixes_the_user_id(tmp_path):
    out = init(tmp_path / "c", users=["alice"])
    cfg = FabricConfig(config_file=str(out.clients["alice"]))
    assert cfg.user_id(None) == "alice" and cfg.user_id("alice") == "alice"
    with pytest.raises(ConfigError, match="logs in as 'alice'.*not 'bob'"):
        cfg.user_id("bob")
    assert FabricConfig().user_id("bob") == "bob"  # no credentials: the name given


def test_tls_makes_a_ca_and_a_certificate_per_identity_named_by_common_name(tmp_path):
    d = tmp_path / "c"
    out = init(d, users=["alice"], tls=True, listen=["tls/0.0.0.0:7447"], connect=["tls/10.0.0.5:7447"])
    t = d / "tls"
    assert certificate_common_name(t / "alice.pem") == "alice" and certificate_common_name(t / "sim.pem") == "sim"
    assert _mode(t / "ca-key.pem") == 0o600 and _mode(t / "alice-key.pem") == 0o600
    assert FabricConfig(config_file=str(out.clients["alice"])).identity() == "alice"
    ca = (t / "ca.pem").read_bytes()
    again = init(d, users=["alice", "bob"], tls=True, listen=["tls/0.0.0.0:7447"], connect=["tls/10.0.0.5:7447"])
    assert (t / "ca.pem").read_bytes() == ca and again.created == ("bob",)
    from cryptography import x509

    router = x509.load_pem_x509_certificate((t / "router.pem").read_bytes())
    sans = router.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "10.0.0.5" in [str(ip) for ip in sans.get_values_for_type(x509.IPAddress)]


def test_rules_allow_each_user_only_keys_that_name_them():
    acl = access_control([Identity("alice", "user"), Identity("sim", "sim")])
    rules = {r["id"]: r for r in acl["rules"]}
    assert acl["default_permission"] == "deny"
    assert rules["alice-put"]["key_exprs"][1:] == ["rf/*/robot/*/cmd/*/by/alice", "rf/*/object/*/pose/by/alice"]
    assert "rf/*/own/*" in rules["sim-put"]["key_exprs"] and "rf/*/own/*" not in rules["alice-put"]["key_exprs"]
    assert rules["alice-ask"]["key_exprs"] == [
        "rf/*/srv/map/**/by/alice",
        "rf/*/srv/plan/**/by/alice",
        "rf/*/own/*/by/alice",
    ]
    policy = {p["id"]: p["rules"] for p in acl["policies"]}
    assert "sim-serve" not in policy["alice"] and "alice-put" not in policy["sim"]


def test_rules_give_each_login_its_own_decode_key_and_the_staff_the_map():
    """Decode reports go on the writer's own key (a forged reject there is known as its writer's, whoever it names); a student
    asks map and plan in her own name only, the staff (instructor, sim, compute) also in the staff's forms."""
    acl = access_control(
        [
            Identity("alice", "user"),
            Identity("carol", "instructor"),
            Identity("sim", "sim"),
            Identity("compute", "compute"),
            Identity("viewer", "viewer"),
        ]
    )
    rules = {r["id"]: r for r in acl["rules"]}
    for name in ("alice", "carol", "sim", "compute", "viewer"):
        assert rules[f"{name}-put"]["key_exprs"][0] == f"rf/*/event/decode/by/{name}"
    assert not [ke for r in acl["rules"] for ke in r["key_exprs"] if ke.startswith("rf/*/event/decode/*")]
    common = rules["ask"]["key_exprs"]
    assert not [ke for ke in common if "/srv/map" in ke or "/srv/plan" in ke or ke == "rf/*/srv/**"]
    staff_forms = ["rf/*/srv/map/*", "rf/*/srv/map/*/*", "rf/*/srv/plan/*", "rf/*/srv/plan/*/*"]
    for name in ("carol", "sim", "compute"):
        assert set(staff_forms) <= set(rules[f"{name}-ask"]["key_exprs"]), name
    assert not set(staff_forms) & set(rules["alice-ask"]["key_exprs"])
    assert "rf/*/robot/*/cmd/*/by/carol" in rules["carol-put"]["key_exprs"]  # an instructor is a user too


def test_the_router_config_sets_the_limits_zenoh_offers(tmp_path):
    out = init(tmp_path / "c", users=["alice", "bob"], instructors=["carol"], listen=["tcp/127.0.0.1:7447"])
    import json

    cfg = json.loads("\n".join(out.router.read_text().splitlines()[2:]))
    assert cfg["transport"]["unicast"]["max_sessions"] == 32 + 8 * 6  # alice, bob, carol, sim, compute, viewer
    assert cfg["transport"]["link"]["rx"]["max_message_size"] == 4 * 1024 * 1024
    limits = {f["key_exprs"][0]: f["size_limit"] for f in cfg["low_pass_filter"]}
    assert limits["rf/*/event/decode/by/*"] == 16 * 1024 and limits["rf/*/robot/*/cmd/*/by/*"] >= 3 * 8 * (1 << 16)
    import zenoh

    zenoh.Config.from_file(str(out.router))  # zenoh knows every key (it refuses unknown ones)
    assert "(role: instructor)" in out.clients["carol"].read_text().splitlines()[0]


@pytest.mark.slow
@pytest.mark.parametrize(
    "args, message",
    [
        (["--users", ""], "no users"),
        (["--users", "alice,alice"], "named twice"),
        (["--users", "a/b"], "letters, digits"),
        (["--users", "alice", "--listen", "tls/0.0.0.0:7447"], "tcp/HOST:PORT"),
    ],
)
def test_init_mistakes_are_one_line_errors(tmp_path, args, message):
    out = run_cli("secure", "init", str(tmp_path / "c"), *args)
    assert out.returncode == 2 and message in out.stderr and "Traceback" not in out.stderr, out.stderr


def test_the_secure_example_launch_files_give_every_peer_its_own_login():
    from pathlib import Path

    from robofabric.launch import load_launch

    root = Path(__file__).resolve().parents[2] / "examples" / "secure"
    files = sorted(root.glob("*.toml"))
    assert {f.stem for f in files} >= {"router", "sim", "compute", "viewer", "users", "class"}
    for f in files:
        spec = load_launch(f, args={"secrets": "/srv/class"}, env={})
        assert spec.zenoh_config and spec.zenoh_config.startswith("/srv/class/"), f
        for peer in spec.peers:
            i = peer.args.index("--zenoh-config")
            login = Path(peer.args[i + 1]).stem
            assert login in ("sim", "compute", "viewer", "alice", "bob"), (f, peer)
            assert "--user" not in peer.args  # the login is the user


def test_the_audit_counts_dropped_messages_by_the_decision_that_dropped_them():
    from collections import Counter

    from robofabric.router_audit import UNKNOWN, Refusal, RefusalCounter, parse_refusal, summary

    def line(thread, text, module="zenoh::net::routing::interceptor::access_control"):
        return (
            f"\x1b[2m2026-11-23T16:58:13.924332Z\x1b[0m \x1b[35mTRACE\x1b[0m rx-1 ThreadId({thread}) "
            f"\x1b[2m{module}\x1b[0m\x1b[2m:\x1b[0m {text}"
        )

    denied = line(
        9,
        "7acdde4b4ac85c54 on Interface(lo)+Username(mallory)+Transport(Tcp)+7acdde4b4ac85c54 is unauthorized to Put (ingress) on rf/w/own/arm1",
    )
    assert parse_refusal(denied) == Refusal("mallory", "put", "ingress", "rf/w/own/arm1")
    assert parse_refusal(denied.replace("is unauthorized", "is authorized")) is None
    dropped = line(9, "Msg intercepted!", module="zenoh::net::routing::interceptor")
    cached = line(8, "Using cached result: 7acdde4b4ac85c54 is unauthorized to Put (ingress) on rf/w/own/arm1")
    c = RefusalCounter()
    for text in (
        denied,
        dropped,
        cached,
        line(8, "Msg intercepted!", module="zenoh::net::routing::interceptor"),
        line(4, "Msg intercepted!", module="zenoh::net::routing::interceptor"),
        denied.replace("is unauthorized", "is authorized"),
        "some other line",
    ):
        c.feed(text)
    ref = Refusal("mallory", "put", "ingress", "rf/w/own/arm1")
    assert c.counts == Counter({ref: 2, UNKNOWN: 1})  # a decision is logged once per key; each drop counts
    # a declaration: zenoh caches every kind of message for the key (the last one logged is Declare/Undeclare
    # Liveliness Token), then drops the declaration after a cached decision; it was counted as the last
    # one-word decision before it ("Delete"), the multi-word ones not being read
    who = "57948cd3 on Interface(lo)+Username(mallory)+Transport(Tcp)+57948cd3"
    c = RefusalCounter()
    for text in [
        line(8, f"{who} is unauthorized to {m} (ingress) on rf/w/srv/world")
        for m in ("Reply", "Put", "Delete", "Declare/Undeclare Queryable", "Declare/Undeclare Liveliness Token")
    ] + [
        line(8, "Using cached result: 57948cd3 is unauthorized to Declare Queryable (ingress) on rf/w/srv/world"),
        line(8, "Msg intercepted!", module="zenoh::net::routing::interceptor"),
    ]:
        c.feed(text)
    assert c.counts == Counter({Refusal("mallory", "declare_queryable", "ingress", "rf/w/srv/world"): 1})
    assert parse_refusal(
        line(8, f"{who} is unauthorized to Declare/Undeclare Liveliness Token (ingress) on rf/w/peer/sim/x")
    ) == Refusal("mallory", "liveliness_token", "ingress", "rf/w/peer/sim/x")  # as the rules name it
    text = summary(Counter({ref: 3, Refusal("eve", "query", "ingress", "rf/w/own/arm1/by/bob"): 1}), prefix="refused")
    assert text.startswith("refused: 4 (put 3, query 1); mallory put rf/w/own/arm1 x3")
    # a key that held a newline: the lines after it continue its record, are never read as a decision or a drop,
    # and end the refusal's key, shown escaped; the lines the audit passes on are marked as continued
    from robofabric.router_audit import CONTINUED, shown

    c = RefusalCounter()
    for text in (
        line(8, f"{who} is unauthorized to Put (ingress) on rf/w/x"),
        "refused in the last 1 s: 1; alice put k x1",
        "Msg intercepted!",
        line(8, "Msg intercepted!", module="zenoh::net::routing::interceptor"),
    ):
        c.feed(text)
    assert c.counts == Counter(
        {
            Refusal(
                "mallory", "put", "ingress", "rf/w/x\nrefused in the last 1 s: 1; alice put k x1\nMsg intercepted!"
            ): 1
        }
    )
    assert "rf/w/x\\nrefused in the last" in summary(c.counts, prefix="refused")
    assert summary(c.counts, prefix="refused").count("\n") == 0
    assert shown("refused in the last 1 s\x1b[2J") == CONTINUED + "refused in the last 1 s\\x1b[2J"
    assert shown(line(3, "an error")).startswith("2026-11-23T16:58:13.924332Z TRACE")  # a record: its colours off


@pytest.mark.slow
def test_up_takes_the_launchers_login_from_the_command_line(tmp_path):
    from pathlib import Path

    router_toml = Path(__file__).resolve().parents[2] / "examples" / "secure" / "router.toml"
    out = run_cli("up", str(router_toml), "--zenoh-config", str(tmp_path / "missing.json5"), "--duration", "1")
    assert out.returncode == 2 and "missing.json5' does not exist" in out.stderr and "Traceback" not in out.stderr, (
        out.stderr
    )


def test_only_the_instructor_and_sim_logins_may_ask_for_a_move_each_in_its_own_name():
    """No student asks for a move: moves are asked on srv/move/{sim}/by/{login}; the router lets
    the instructor and the sims ask there in their own names, nobody else, and only sims serve it."""
    acl = access_control(
        [
            Identity("alice", "user"),
            Identity("carol", "instructor"),
            Identity("sim-a", "sim"),
            Identity("compute", "compute"),
            Identity("viewer", "viewer"),
        ]
    )
    rules = {r["id"]: r for r in acl["rules"]}
    asks = {
        name: [ke for ke in rules.get(f"{name}-ask", {"key_exprs": []})["key_exprs"] if "/srv/move" in ke]
        for name in ("alice", "carol", "sim-a", "compute", "viewer")
    }
    assert asks == {
        "alice": [],
        "carol": ["rf/*/srv/move/*/by/carol"],
        "sim-a": ["rf/*/srv/move/*/by/sim-a"],
        "compute": [],
        "viewer": [],
    }
    assert not [ke for ke in rules["ask"]["key_exprs"] if "/srv/move" in ke]  # not among what everyone may ask
    assert "rf/*/srv/state" in rules["ask"]["key_exprs"]  # which is why a sim refuses a move asked there
    servers = [
        r["id"] for r in acl["rules"] if any("/srv/move" in ke for ke in r["key_exprs"]) and "reply" in r["messages"]
    ]
    assert servers == ["sim-a-serve"] and "rf/*/srv/move/*/by/*" in rules["sim-a-serve"]["key_exprs"]


def test_a_password_class_writes_each_person_a_private_login_card_with_the_password_of_her_config(tmp_path):
    d = tmp_path / "class"
    out = init(
        d, users=["alice", "bob"], instructors=["carol"], listen=["tcp/0.0.0.0:7447"], connect=["tcp/10.0.0.5:7447"]
    )
    assert set(out.cards) == {"alice", "bob", "carol"}  # people only: no card for the sim, compute or viewer
    creds = read_credentials(d / "credentials.txt")
    for name, card in out.cards.items():
        text = card.read_text()
        assert (
            _mode(card) == 0o600 and f"  Name      {name}\n" in text and "  Console   http://10.0.0.5:8080/\n" in text
        )
        password = text.split("  Password  ")[1].split("\n")[0]
        assert password == creds[name]  # what the router takes: the password of her NAME.json5
        assert (
            json.loads(zenoh.Config.from_file(str(out.clients[name])).get_json("transport/auth/usrpwd/password"))
            == password
        )
    html = (d / "cards" / "cards.html").read_text()
    assert _mode(d / "cards") == 0o700 and _mode(d / "cards" / "cards.html") == 0o600
    assert html.count('<section class="card">') == 3 and "(instructor)" in html and creds["bob"] in html
    assert (
        "  Teacher   http://10.0.0.5:8080/teacher" in out.cards["carol"].read_text()
        and "Teacher" not in out.cards["bob"].read_text()
    )
    again = init(d, users=["alice"], console="https://console.example:8443/")  # a second run: the same passwords
    assert (
        again.cards["alice"].read_text().count(creds["alice"]) == 1
        and "https://console.example:8443/" in again.cards["bob"].read_text()
    )


def _qr_modules(svg: str) -> tuple[int, set[tuple[int, int]]]:
    """The dark modules an SVG of the cards draws (its 1x1 rects, the quiet zone taken off) and the code's size."""
    size = int(re.search(r'viewBox="0 0 (\d+) \1"', svg).group(1))
    dark = {
        (int(x) - QR_QUIET, int(y) - QR_QUIET)
        for x, y in re.findall(r'<rect x="(\d+)" y="(\d+)" width="1" height="1"/>', svg)
    }
    return size - 2 * QR_QUIET, dark


@pytest.mark.parametrize("console", [None, "https://console.example:8443/"])
def test_every_printed_card_carries_a_qr_code_of_the_consoles_address(tmp_path, console):
    """cards.html draws, on each card, the modules of segno's QR code of the address the card says (and
    cards/console-qr.svg is that code alone): what a phone's camera reads is the console's address."""
    import segno

    d = tmp_path / "class"
    init(
        d,
        users=["alice", "bob"],
        instructors=["carol"],
        listen=["tcp/0.0.0.0:7447"],
        connect=["tcp/10.0.0.5:7447"],
        console=console,
    )
    url = console or "http://10.0.0.5:8080/"
    want = segno.make(url, error="m", micro=False).matrix
    want_dark = {(x, y) for y, row in enumerate(want) for x, v in enumerate(row) if v}
    html = (d / "cards" / "cards.html").read_text()
    svgs = re.findall(r"<svg class=\"qr\".*?</svg>", html)
    assert len(svgs) == 3 and html.count('<section class="card">') == 3
    alone = (d / "cards" / "console-qr.svg").read_text()
    for svg in svgs + [alone]:
        n, dark = _qr_modules(svg)
        assert n == len(want) and dark == want_dark
        assert f'aria-label="QR code of {url}"' in svg
    assert _mode(d / "cards" / "console-qr.svg") == 0o600
    other = segno.make("http://10.0.0.6:8080/", error="m", micro=False).matrix  # a code of another address differs
    assert {(x, y) for y, row in enumerate(other) for x, v in enumerate(row) if v} != want_dark


def test_a_tls_class_has_no_passwords_and_no_cards(tmp_path):
    out = init(tmp_path / "t", users=["alice"], tls=True, listen=["tls/127.0.0.1:7448"])
    assert out.cards == {} and not (tmp_path / "t" / "cards").exists()


def test_a_typable_password_is_three_groups_of_four_without_look_alikes():
    pw = {typable_password() for _ in range(200)}
    assert len(pw) == 200 and all(is_typable(p) and len(p) == 14 and p.count("-") == 2 for p in pw)
    assert not set("0o1li") & set(TYPABLE) and len(TYPABLE) ** 12 > 2**59
    assert not is_typable("Zw7qQY8izxNoIqTkJC4XKnvO") and not is_typable("ab-cd")
