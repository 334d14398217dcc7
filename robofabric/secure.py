"""Credentials and router rules for a class: who may say what on the fabric.

``robofabric secure init DIR --users alice,bob`` (robofabric/secure_cli.py) calls :func:`init`, which
writes ``DIR/router.json5`` (authentication + access control, default deny) and one client config
per identity, ``DIR/NAME.json5``. The rules (:func:`access_control`) follow the key layout
(fabric/keys.py, docs/architecture.md): a user writes only keys that end in ``by/{user}`` (decode
reports included: ``event/decode/by/{user}``), only sim identities write robot state, ownership
records and the other events and serve ``srv/world`` and the ownership queryables, only compute
identities serve kinematics, mapping and planning. Only instructor and sim logins move robots between sims
(``srv/move/{sim}/by/{login}``, :data:`MOVERS`). A student asks the map and plan services on her
own ``by/{user}`` keys, where the compute peer refuses her what changes the class's map; the staff
(sim, compute and instructor logins) may also ask on the forms without ``by/``, which it serves in
full. Everyone may read everything of every world (``rf/**``): a class shares one view of the world.

zenoh 1.x has no limit on how many subscribers, queryables or tokens one session declares (no such
config key; checked on the 1.10 sources): the router's config bounds what zenoh does offer
(:func:`router_limits`: sessions, pending handshakes, message and payload sizes).

Identities are zenoh usernames (``transport/auth/usrpwd``) or, with TLS, certificate common names
(mutual TLS, one certificate per identity, signed by the class's own CA). Passwords come from
:mod:`secrets`; certificates are made with ``cryptography``. Files holding a secret are 0600, and
running :func:`init` again keeps every existing secret and only adds what is missing.

zenoh's ``**`` does not match a chunk that starts with ``@`` (a verbatim chunk), so the caches and liveliness
tokens of latched publishers (``KEY/@adv/...``, fabric.publishers.declare_publisher) need rules of their own.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import ipaddress
import json
import os
import re
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from fabric.config import MAX_MESSAGE_SIZE
from fabric.keys import BY, STAFF as STAFF_KEY, validate_id
from fabric.streams import access
from robofabric.login_cards import PEOPLE, console_url, typable_password, write_cards

__all__ = ["Identity", "ROLES", "SecureInit", "access_control", "router_config", "client_config", "init", "parse_names"]

ROLES = ("user", "instructor", "sim", "compute", "viewer")
STAFF = ("instructor", "sim", "compute")
"""Roles that may change a class's shared map (set, reset, stop, save, load) and plan without owning."""
MOVERS = ("instructor", "sim")
"""Roles that may move robots between sims (``robofabric own move``): they alone may ask ``srv/move/{sim}/by/{login}``,
in their own name; a sim asks another for the robot it handed out there too. Every login may ask ``srv/state``,
and a sim refuses a move asked there (docs/sim.md, "Moving a robot between sims")."""
SHARED_SERVICES = ("map", "plan")
"""The compute peer's services whose askers are checked: a student asks on ``.../by/{user}`` only."""
W = "rf/*"  # every world: one router can serve several worlds of the class
ROUTER_INFO = "@/*/router"  # the router's own entry in its admin space (read-only); sims may ask it
ADV = "@adv/**"  # where zenoh.ext keeps a latched publisher's cache and liveliness token
ALL_MESSAGES = (
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
)
OPEN_SERVICES = ("ik", "fk", "jacobian")
"""Compute services anyone may ask in any form: they answer the asker and change nothing."""
CREDENTIALS = "credentials.txt"
TLS_DIR = "tls"
WEB_DIR = "web"
"""Under ``TLS_DIR``: the console's HTTPS certificate and key (``console.pem``, ``console-key.pem``)."""
_NAME = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


@dataclass(frozen=True, slots=True)
class Identity:
    """One login of the class: ``name`` (the user id, or a sim's / compute's / viewer's name) and its role."""

    name: str
    role: str

    def __post_init__(self) -> None:
        if self.role not in ROLES:
            raise ValueError(f"unknown role {self.role!r}; expected one of {', '.join(ROLES)}")
        if not _NAME.match(self.name):
            raise ValueError(f"identity {self.name!r} must be 1-64 letters, digits, '-' or '_'")
        validate_id(self.name, what="identity")
        if self.name in ("router", "ca"):
            raise ValueError(f"identity {self.name!r} is reserved (the router's and the CA's files)")


def parse_names(text: str | None) -> list[str]:
    """``"alice, bob"`` -> ``["alice", "bob"]`` (empty items dropped)."""
    return [n.strip() for n in (text or "").split(",") if n.strip()]


def _rule(rule_id: str, messages: Iterable[str], key_exprs: Iterable[str], flows: Iterable[str] = ("ingress",)) -> dict:
    return {
        "id": rule_id,
        "permission": "allow",
        "flows": list(flows),
        "messages": list(messages),
        "key_exprs": list(key_exprs),
    }


def _own_rules(ident: Identity) -> list[dict]:
    """What this identity alone may do, beyond what every identity may (reading)."""
    n, r = ident.name, ident.role
    put: list[str] = [f"{W}/event/decode/{BY}/{n}"]  # every peer reports payloads it could not decode, on its own key
    serve: list[str] = []  # declare_queryable + reply
    tokens: list[str] = [f"{W}/peer/tool/*"]  # CLI tools (ps, echo, own list...) under this login
    # the map and plan services in this login's name; the staff also on the forms without by/ (keys.srv_asked)
    ask: list[str] = [f"{W}/srv/{s}/**/{BY}/{n}" for s in SHARED_SERVICES]
    if r in STAFF:
        ask += [f"{W}/srv/{s}/{tail}" for s in SHARED_SERVICES for tail in ("*", "*/*")]
    if r in MOVERS:  # moving a robot between sims: the tool asks each sim in its own name; sims ask each other
        ask.append(f"{W}/srv/move/*/{BY}/{n}")
    if r in ("user", "instructor"):
        mine = [f"{W}/robot/*/cmd/*/{BY}/{n}", f"{W}/object/*/pose/{BY}/{n}"]
        put += mine
        # a latched publisher's cache (zenoh.ext) is a queryable under KEY/@adv/... that replies on KEY itself
        latched = [f"{W}/object/*/pose/{BY}/{n}/{ADV}"]
        serve += latched + mine[1:]
        tokens += [f"{W}/peer/user/{n}", f"{W}/peer/viewer/*", f"{W}/peer/recorder/*", *latched]
        ask.append(f"{W}/own/*/{BY}/{n}")
        if r == "instructor":  # the staff's actions on robots (ownership.staff): take back, give, lock, stop, reset
            ask.append(f"{W}/own/*/{STAFF_KEY}/{BY}/{n}")
    elif r == "sim":
        put += [f"{W}/{k}" for k in access(r)] + [f"{W}/own/*", f"{W}/event/**"]  # fabric.streams
        # ownership records and events keep their last samples for an observer that missed them (fabric.history)
        latched = [f"{W}/own/*/{ADV}", f"{W}/event/*/*/{ADV}"]  # (a cache replies on the key itself: event/*/* below)
        serve += [
            f"{W}/srv/world",
            f"{W}/srv/state",
            f"{W}/own/*",
            f"{W}/own/*/{BY}/*",
            f"{W}/own/*/{STAFF_KEY}/{BY}/*",  # srv/state:
            f"{W}/srv/move/*/{BY}/*",
            *latched,
            f"{W}/event/*/*",
        ]  # a standby follows the primary; srv/move: the staff's moves
        tokens += [
            f"{W}/peer/sim/*",
            f"{W}/peer/sim/*/*/*/*",
            f"{W}/peer/recorder/*",
            *latched,
        ]  # its role (keys.sim_role); a recorder on its machine
        ask.append(
            ROUTER_INFO
        )  # is my link up? (a standby judging a lost token: sim_peer.replica.roles.router_answers)
    elif r == "compute":
        put += [f"{W}/{k}" for k in access(r)] + [f"{W}/map/*", f"{W}/event/compute/**"]
        kept = [f"{W}/{k}" for k in access(r, latched=True)] + [f"{W}/map/*"]  # latched: a cache replies on its key
        latched = [f"{k}/{ADV}" for k in kept]
        serve += [f"{W}/srv/{s}/**" for s in ("ik", "fk", "jacobian", "plan", "map")] + latched + kept
        tokens += [f"{W}/peer/compute/*", *latched]
    else:  # viewer
        tokens += [f"{W}/peer/viewer/*", f"{W}/peer/recorder/*"]
    # a peer tells what it subscribes to and serves on its own token's key (fabric.declared); the staff may ask
    serve += [t for t in tokens if t.startswith(f"{W}/peer/") and t.count("/") == 4]
    if r in STAFF:
        ask.append(f"{W}/peer/*/*")
    rules = [_rule(f"{n}-put", ["put"], put), _rule(f"{n}-tokens", ["liveliness_token"], tokens)]
    if serve:
        rules.append(_rule(f"{n}-serve", ["declare_queryable", "reply"], serve))
    if ask:
        rules.append(_rule(f"{n}-ask", ["query"], ask))
    return rules


def access_control(identities: Iterable[Identity], *, tls: bool = False) -> dict:
    """zenoh's ``access_control`` section: default deny, reading for all, writing per identity.

    With ``tls`` the subjects are certificate common names, else usrpwd usernames."""
    idents = list(identities)
    common = [
        # reading: subscribe to anything, watch liveliness, ask services, records and latched caches
        _rule(
            "read",
            ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
            ["rf/**", f"rf/**/{ADV}"],
        ),
        # (srv/map and srv/plan: each login in its own name, _own_rules)
        _rule(
            "ask",
            ["query"],
            [
                f"{W}/own/*",
                f"{W}/srv/world",
                f"{W}/srv/state",
                *(f"{W}/srv/{s}/**" for s in OPEN_SERVICES),
                f"rf/**/{ADV}",
            ],
        ),
        # what the router delivers to a session: samples, queries for its queryables, replies, declarations
        _rule("deliver", ALL_MESSAGES, ["rf/**", f"rf/**/{ADV}", ROUTER_INFO], flows=("egress",)),
    ]
    field = "cert_common_names" if tls else "usernames"
    rules = list(common)
    subjects, policies = [], []
    for ident in idents:
        own = _own_rules(ident)
        rules += own
        subjects.append({"id": ident.name, field: [ident.name]})
        policies.append({"id": ident.name, "rules": [r["id"] for r in common + own], "subjects": [ident.name]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def _tls_section(d: Path, name: str, *, side: str) -> dict:
    t = d / TLS_DIR
    sec = {"root_ca_certificate": str(t / "ca.pem"), "enable_mtls": True}
    if side == "listen":
        sec.update(listen_private_key=str(t / f"{name}-key.pem"), listen_certificate=str(t / f"{name}.pem"))
    else:
        sec.update(connect_private_key=str(t / f"{name}-key.pem"), connect_certificate=str(t / f"{name}.pem"))
    return sec


SESSIONS_PER_LOGIN = 8
"""Sessions the router admits per login of the class, plus :data:`SPARE_SESSIONS` (a user, her TUI, a
viewer, a few CLI tools); zenoh's default is 1,000 for everyone together."""
SPARE_SESSIONS = 32
PAYLOAD_LIMITS = {
    f"{W}/event/decode/{BY}/*": 16 * 1024,  # a decode report: a clipped reason and the key it was about
    f"{W}/object/*/pose/{BY}/*": 4 * 1024,  # a scene object's pose
    f"{W}/robot/*/cmd/*/{BY}/*": 2 * 1024 * 1024,  # a command; a path of MAX_PATH_POINTS is 1.5 MiB
}
"""Largest payload the router takes on ingress on each key any user may write (zenoh's ``low_pass_filter``);
anything larger is dropped at the router, before it reaches every subscriber."""


def router_limits(n_identities: int) -> dict:
    """The limits zenoh 1.x offers a router, for a class of ``n_identities`` logins: sessions
    (``transport/unicast/max_sessions``), message size (``transport/link/rx/max_message_size``) and the
    payload sizes on user keys (``low_pass_filter``). zenoh has none on declarations (subscribers,
    queryables, tokens per session): docs/security.md says what a flood of them costs."""
    return {
        "transport": {
            "unicast": {"max_sessions": min(1000, SPARE_SESSIONS + SESSIONS_PER_LOGIN * n_identities)},
            "link": {"rx": {"max_message_size": MAX_MESSAGE_SIZE}},
        },
        "low_pass_filter": [
            {"id": f"user-{i}", "flows": ["ingress"], "messages": ["put"], "key_exprs": [ke], "size_limit": size}
            for i, (ke, size) in enumerate(PAYLOAD_LIMITS.items())
        ],
    }


def router_config(d: Path, identities: Iterable[Identity], *, listen: list[str], tls: bool = False) -> dict:
    """The router's zenoh config: listen, authenticate, authorize; sessions, message and payload sizes capped."""
    idents = list(identities)
    limits = router_limits(len(idents))
    transport: dict = limits["transport"]
    link: dict = transport["link"]
    if tls:
        link["tls"] = _tls_section(d, "router", side="listen")
    else:
        transport["auth"] = {"usrpwd": {"dictionary_file": str(d / CREDENTIALS)}}
    return {
        "mode": "router",
        "listen": {"endpoints": listen},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": transport,
        "low_pass_filter": limits["low_pass_filter"],
        "access_control": access_control(idents, tls=tls),
    }


def client_config(d: Path, ident: Identity, *, connect: list[str], password: str | None, tls: bool = False) -> dict:
    """One identity's client config: where the router is and how to prove who this is."""
    link: dict = {"rx": {"max_message_size": MAX_MESSAGE_SIZE}}
    transport: dict = {"link": link}
    if tls:
        link["tls"] = _tls_section(d, ident.name, side="connect")
    else:
        transport["auth"] = {"usrpwd": {"user": ident.name, "password": password}}
    return {
        "mode": "client",
        "connect": {"endpoints": connect},
        "scouting": {"multicast": {"enabled": False}},
        "transport": transport,
    }


# ---------------------------------------------------------------------------------------------- files


def _write_secret(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` readable by its owner only (created 0600, never world-readable in between)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.chmod(path, 0o600)


def read_credentials(path: Path) -> dict[str, str]:
    """``name:password`` lines of a zenoh usrpwd dictionary file (missing file: none)."""
    out: dict[str, str] = {}
    if path.is_file():
        for line in path.read_text().splitlines():
            name, sep, pw = line.partition(":")
            if sep and name.strip():
                out[name.strip()] = pw.strip()
    return out


def _name_attrs(name: str):
    from cryptography.x509.oid import NameOID
    from cryptography import x509

    return x509.Name(
        [
            x509.NameAttribute(NameOID.COMMON_NAME, name),
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "robofabric class"),
        ]
    )


def _make_ca(t: Path, days: int):
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec

    key = ec.generate_private_key(ec.SECP256R1())
    now = dt.datetime.now(dt.UTC)
    name = _name_attrs("robofabric class CA")
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                key_cert_sign=True,
                crl_sign=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .sign(key, hashes.SHA256())
    )
    _write_secret(
        t / "ca-key.pem",
        key.private_bytes(
            serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
        ).decode(),
    )
    (t / "ca.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))


def _load_ca(t: Path):
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    key = serialization.load_pem_private_key((t / "ca-key.pem").read_bytes(), password=None)
    return x509.load_pem_x509_certificate((t / "ca.pem").read_bytes()), key


def _make_cert(t: Path, name: str, hosts: list[str], days: int, *, web: bool = False) -> None:
    """A certificate for ``name`` (its common name is the identity the router's rules name), signed by the CA.
    ``web``: the console's HTTPS certificate instead, ``t/web/NAME.pem``: its common name is no identity's and it
    serves only (no client use), so it can never log in to the router."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID

    ca_cert, ca_key = _load_ca(t)
    key = ec.generate_private_key(ec.SECP256R1())
    now = dt.datetime.now(dt.UTC)
    sans: list[x509.GeneralName] = []
    for h in dict.fromkeys(hosts if web else [name, *hosts]):
        try:
            sans.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            sans.append(x509.DNSName(h))
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name_attrs(f"robofabric {name} (https)" if web else name))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.SubjectAlternativeName(sans), critical=False)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH]
                if web
                else [ExtendedKeyUsageOID.CLIENT_AUTH, ExtendedKeyUsageOID.SERVER_AUTH]
            ),
            critical=False,
        )
        .sign(ca_key, hashes.SHA256())
    )
    if web:
        t = t / WEB_DIR
        t.mkdir(exist_ok=True)
    _write_secret(
        t / f"{name}-key.pem",
        key.private_bytes(
            serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
        ).decode(),
    )
    (t / f"{name}.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))


@dataclass(frozen=True, slots=True)
class SecureInit:
    """What :func:`init` wrote: the router's config, each identity's config, and which secrets are new."""

    router: Path
    clients: dict[str, Path]
    created: tuple[str, ...]
    kept: tuple[str, ...]
    cards: dict[str, Path] = dataclasses.field(default_factory=dict)  # each person's login card (a password class)


def _host_of(endpoint: str) -> str:
    addr = endpoint.partition("/")[2]
    host = addr.rsplit(":", 1)[0].strip("[]")
    return host


def _identities(
    *,
    users: Iterable[str],
    instructors: Iterable[str],
    sims: Iterable[str],
    computes: Iterable[str],
    viewers: Iterable[str],
) -> list[Identity]:
    """The class's logins with their roles; ValueError for a name given twice, or a class without users."""
    identities = (
        [Identity(n, "user") for n in users]
        + [Identity(n, "instructor") for n in instructors]
        + [Identity(n, "sim") for n in sims]
        + [Identity(n, "compute") for n in computes]
        + [Identity(n, "viewer") for n in viewers]
    )
    seen: set[str] = set()
    for ident in identities:
        if ident.name in seen:
            raise ValueError(f"identity {ident.name!r} is named twice; every login needs its own name")
        seen.add(ident.name)
    if not any(i.role == "user" for i in identities):
        raise ValueError("no users: name them with --users alice,bob")
    return identities


def _certificates(
    t: Path, identities: list[Identity], connect: list[str], days: int, created: list[str], kept: list[str]
) -> None:
    """The CA, the router's certificate (naming every host of ``connect``), the console's HTTPS one (the same hosts)
    and one per identity under ``t``;
    those there already are kept. What was made or kept is appended to ``created`` / ``kept``."""
    t.mkdir(exist_ok=True)
    os.chmod(t, 0o700)
    if not (t / "ca.pem").is_file() or not (t / "ca-key.pem").is_file():
        _make_ca(t, days)
        created.append("ca")
    hosts = sorted({_host_of(ep) for ep in connect} | {"localhost", "127.0.0.1"})
    for name in ["router", *(i.name for i in identities)]:
        if (t / f"{name}.pem").is_file() and (t / f"{name}-key.pem").is_file():
            kept.append(name)
        else:
            _make_cert(t, name, hosts if name == "router" else [], days)
            created.append(name)
    _console_certificate(t, hosts, days, created, kept)


def _console_certificate(t: Path, hosts: list[str], days: int, created: list[str], kept: list[str]) -> None:
    """The console's page over HTTPS, named as the router is (the console usually runs beside it), signed by the
    class's CA (made when there is none): a password typed into the page never crosses the LAN in clear
    (``robofabric console --tls-cert tls/web/console.pem --tls-key tls/web/console-key.pem``)."""
    t.mkdir(exist_ok=True)
    os.chmod(t, 0o700)
    if not (t / "ca.pem").is_file() or not (t / "ca-key.pem").is_file():
        _make_ca(t, days)
        created.append("ca")
    if (t / WEB_DIR / "console.pem").is_file() and (t / WEB_DIR / "console-key.pem").is_file():
        kept.append("console (https)")
    else:
        _make_cert(t, "console", hosts, days, web=True)
        created.append("console (https)")


def _passwords(cred: Path, identities: list[Identity], created: list[str], kept: list[str]) -> dict[str, str]:
    """Every login's password: the one in ``cred`` if any, else a new random one; ``cred`` rewritten with all."""
    passwords = read_credentials(cred)
    for ident in identities:
        if ident.name in passwords:
            kept.append(ident.name)
        else:
            # a person types hers into the console's login (robofabric/login_cards.py); a peer's is a long token
            passwords[ident.name] = typable_password() if ident.role in PEOPLE else secrets.token_urlsafe(18)
            created.append(ident.name)
    _write_secret(cred, "".join(f"{n}:{p}\n" for n, p in passwords.items()))
    return passwords


def init(
    d: str | Path,
    *,
    users: Iterable[str],
    sims: Iterable[str] = ("sim",),
    computes: Iterable[str] = ("compute",),
    viewers: Iterable[str] = ("viewer",),
    instructors: Iterable[str] = (),
    tls: bool = False,
    listen: list[str] | None = None,
    connect: list[str] | None = None,
    days: int = 365,
    console_tls: bool = False,
    console: str | None = None,
) -> SecureInit:
    """Write the class's configs under ``d``; existing passwords, CA and certificates are kept.

    ``listen``: the router's endpoints (default ``PROTO/0.0.0.0:7447``); ``connect``: where clients
    find it (default the listen address, ``127.0.0.1`` for an unspecified one). With ``tls`` the
    router's certificate names every host of ``connect`` so clients can check it. ``instructors``: user
    logins that may also change the class's map (docs/security.md). ``console_tls``: a password class's console
    certificate too (a class CA and ``tls/web/console.pem``; ``tls`` makes it anyway). ``console``: the console's
    URL on the login cards (default :func:`~robofabric.login_cards.console_url`)."""
    d = Path(d).resolve()
    proto = "tls" if tls else "tcp"
    listen = list(listen or [f"{proto}/0.0.0.0:7447"])
    if connect is None:
        connect = [ep.replace("/0.0.0.0:", "/127.0.0.1:").replace("/[::]:", "/[::1]:") for ep in listen]
    for ep in [*listen, *connect]:
        if not ep.startswith(proto + "/"):
            raise ValueError(
                f"endpoint {ep!r} must be {proto}/HOST:PORT" + (" with --tls" if tls else " (tls/ needs --tls)")
            )
    identities = _identities(users=users, instructors=instructors, sims=sims, computes=computes, viewers=viewers)
    d.mkdir(parents=True, exist_ok=True)
    os.chmod(d, 0o700)
    created: list[str] = []
    kept: list[str] = []
    passwords: dict[str, str] = {}
    if tls:
        _certificates(d / TLS_DIR, identities, connect, days, created, kept)
    else:
        passwords = _passwords(d / CREDENTIALS, identities, created, kept)
        if console_tls:
            _console_certificate(
                d / TLS_DIR, sorted({_host_of(ep) for ep in connect} | {"localhost", "127.0.0.1"}), days, created, kept
            )
    # every identity ever created stays in the rules (a second run with fewer names removes nobody)
    known = {i.name: i for i in identities}
    for path in sorted(d.glob("*.json5")):
        if path.stem == "router":
            continue
        role = _role_of(path)
        if path.stem not in known and role is not None:
            known[path.stem] = Identity(path.stem, role)
    router = d / "router.json5"
    _write_secret(
        router,
        _json5(
            router_config(d, known.values(), listen=listen, tls=tls),
            f"router of a robofabric class ({len(known)} identities)",
        ),
    )
    clients = {}
    for ident in known.values():
        path = d / f"{ident.name}.json5"
        cfg = client_config(d, ident, connect=connect, password=passwords.get(ident.name), tls=tls)
        _write_secret(path, _json5(cfg, f"robofabric identity {ident.name} (role: {ident.role})"))
        clients[ident.name] = path
    url = console or console_url(connect, https=console_tls or tls)
    cards = write_cards(d, ((i.name, i.role) for i in known.values() if i.role in PEOPLE), passwords, url)
    return SecureInit(router, clients, tuple(created), tuple(kept), cards)


_ROLE_LINE = re.compile(r"^// robofabric identity (\S+) \(role: (\w+)\)")


def _role_of(path: Path) -> str | None:
    try:
        first = path.read_text().splitlines()[0]
    except (OSError, IndexError):
        return None
    m = _ROLE_LINE.match(first)
    return m.group(2) if m and m.group(2) in ROLES else None


def _json5(cfg: dict, title: str) -> str:
    return (
        f"// {title}\n// written by `robofabric secure init`; keep it private (it holds a secret or points at one)\n"
        + json.dumps(cfg, indent=2)
        + "\n"
    )
