"""How a peer reaches the others: profiles, endpoints and the zenoh config behind them.

Three profiles (docs/design.md): ``embedded`` opens this process as the router
(the demo, tests, a one-machine class); ``client`` connects to routers (the
default: ``tcp/127.0.0.1:7447`` unless ``--connect`` or ``ROBOFABRIC_CONNECT``
says otherwise); ``peer`` scouts the LAN by multicast. Values come from flags
first, then the environment, then an optional zenoh json5 file, whose every
other setting (TLS, auth, access control) is kept.
"""

from __future__ import annotations

import json
import os
import socket
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import zenoh

from fabric.keys import validate_id

PROFILES = ("embedded", "client", "peer")
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
DEFAULT_WORLD = "demo"
ENV_CONNECT = "ROBOFABRIC_CONNECT"
ENV_WORLD = "ROBOFABRIC_WORLD"
ENV_PROFILE = "ROBOFABRIC_PROFILE"
ENV_CONFIG = "ROBOFABRIC_ZENOH_CONFIG"
MAX_MESSAGE_SIZE = 4 * 1024 * 1024
"""``transport/link/rx/max_message_size`` of every session we open (zenoh's default is 1 GiB): a
larger message is dropped on arrival and the link stays up (checked on zenoh 1.10). The largest
message the fabric itself sends is a map of at most 2 MiB (fabric.interfaces.MAX_GRID_CELLS)."""
ZENOH_DEFAULT_MAX_MESSAGE_SIZE = 1 << 30
RECONNECT_RETRY = {"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}
"""``connect/retry`` of every client and peer session (zenoh's default backs off to 4 s): after a router's restart
every peer reconnects within a second of the router being back, and at about the same time, so a class resumes at
once and a standby that waits for its leader's token after its own link came back (sim_peer.replica.roles, three leases)
does not wait on a leader still sleeping between two attempts. A zenoh config file that sets its own keeps it."""
ZENOH_DEFAULT_BLOCK_WAIT_US = 5_000_000
BLOCK_WAIT_SHARE = 2
"""A router waits at most this share of its lease (a half: 1 s of a 2 s lease) to queue a blocking sample
(``transport/link/tx/queue/congestion_control/block/wait_before_close``) for a subscriber that does not read, then
closes that subscriber's link. Zenoh's default is 5 s, and the router routes a sample on the thread that reads its
publisher's link: a student's laptop paused with a full queue kept the compute peer's map, or the sim's ownership
record, waiting that long, and the router, reading nothing more from the publisher meanwhile, dropped the compute
peer or the sim itself when its lease ran out (issue 49, CI of 2026-11-30). Now the one who does not read loses
her link, and reconnects when she wakes, and the peers everyone needs keep theirs. Half, not less: a subscriber
starved a moment (a console's page server at load, its GIL held) keeps its link through a second's stall; not more:
the publisher's link is read again well within its lease (keep-alives come every quarter of it)."""
SOCKET_BUFFER = 64 * 1024
"""TCP ``so_sndbuf``/``so_rcvbuf`` of every link. With the kernel's autotuned loopback buffers (MBs),
a flood of small junk samples piled up in the sockets between the router and the sim, ahead of an
owner's command (1.2 s of backlog for the sim to decode); with small buffers the backlog stays in
the router's per-priority queues, where commands and ownership (fabric.publishers.priority_for) go first
and junk is dropped under zenoh's congestion control."""


class ConfigError(ValueError):
    """A configuration the user gave cannot work; the text says why."""


def default_peer_id(kind: str) -> str:
    host = socket.gethostname().split(".")[0] or "host"
    safe = "".join(c if c.isalnum() or c in "-_" else "-" for c in host)
    return f"{kind}-{safe}-{uuid.uuid4().hex[:6]}"


def _reachable(endpoint: str, timeout: float = 1.0) -> bool:
    """Whether something accepts a TCP connection at a tcp/ or tls/ endpoint."""
    parts = _split(endpoint)
    if parts is None:
        return False
    try:
        with socket.create_connection(parts[1:], timeout=timeout):
            return True
    except OSError:
        return False


def _split(endpoint: str) -> tuple[str, str, int] | None:
    """(proto, host, port) of a tcp/ or tls/ endpoint, else None."""
    proto, _, addr = endpoint.partition("/")
    host, _, port = addr.rpartition(":")
    if proto not in ("tcp", "tls") or not port.isdigit():
        return None
    return proto, host.strip("[]"), int(port)


def _tls_refusal(endpoint: str, ca: object, cert: object, key: object, timeout: float = 2.0) -> str | None:
    """Why this side refuses the router's TLS certificate at ``endpoint``, or None (it is accepted, or the
    handshake failed for another reason: then the router refused us). zenoh says "Unable to connect" either
    way; a handshake of our own with the same CA, the endpoint's host as the expected name, and the same
    client certificate tells the router's certificate apart from ours."""
    import ssl

    parts = _split(endpoint)
    if parts is None or parts[0] != "tls" or not isinstance(ca, str) or not ca:
        return None
    _, host, port = parts
    try:
        ctx = ssl.create_default_context(cafile=ca)
        if isinstance(cert, str) and isinstance(key, str) and cert and key:
            ctx.load_cert_chain(cert, key)
    except (OSError, ssl.SSLError, ValueError):
        return None
    try:
        with (
            socket.create_connection((host, port), timeout=timeout) as sock,
            ctx.wrap_socket(sock, server_hostname=host),
        ):
            return None
    except ssl.SSLCertVerificationError as exc:
        if exc.verify_code == 62 or "mismatch" in str(exc.verify_message).lower():  # X509_V_ERR_HOSTNAME_MISMATCH
            names = _certificate_names(host, port, timeout)
            return (
                f"the router's certificate does not name {host}"
                + (f" (it names {', '.join(names)})" if names else "")
                + " (connect to a name it has, or re-run secure init with --connect naming this host)"
            )
        return f"this client does not trust the router's certificate ({exc.verify_message}: is this login from the router's class?)"
    except (OSError, ssl.SSLError):
        return None


def _certificate_names(host: str, port: int, timeout: float) -> list[str]:
    """The DNS names and addresses the certificate served at host:port names (unverified: only to say so)."""
    import ssl

    from cryptography import x509

    ctx = ssl.create_default_context()
    ctx.check_hostname = False
    ctx.verify_mode = ssl.CERT_NONE
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock, ctx.wrap_socket(sock) as tls:
            der = tls.getpeercert(binary_form=True)
        if der is None:  # no certificate: nothing to name
            return []
        sans = x509.load_der_x509_certificate(der).extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except Exception:  # only for a message: nothing to add
        return []
    return [*sans.get_values_for_type(x509.DNSName), *map(str, sans.get_values_for_type(x509.IPAddress))]


@dataclass(frozen=True, slots=True)
class JoinFailure:
    """Why a session could not open: ``endpoint`` (where it tried), ``cause`` (why, in words) and ``text``,
    the one line saying both (what commands print and the user API's :class:`JoinFailed` carries)."""

    endpoint: str
    cause: str
    text: str


def _check_endpoint(ep: str) -> str:
    proto, sep, rest = ep.partition("/")
    if not sep or proto not in ("tcp", "udp", "tls", "quic", "ws", "unixsock-stream") or not rest:
        raise ConfigError(f"endpoint {ep!r} is not of the form PROTO/ADDRESS:PORT, e.g. tcp/192.168.1.10:7447")
    return ep


@dataclass(frozen=True, slots=True)
class FabricConfig:
    """Everything a peer needs to join a world. Build with :meth:`resolve` to apply env defaults."""

    world: str = DEFAULT_WORLD
    profile: str = "client"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    config_file: str | None = None
    lease_ms: int = 2000
    multicast: bool | None = None
    socket_buffer: int | None = SOCKET_BUFFER
    """TCP send/receive buffer size (bytes) of every link; None leaves the kernel's autotuning."""
    shared_memory: bool = False
    """zenoh's shared-memory transport (on by default in zenoh): off unless asked for. With it, any
    process on the host can map its own memory into a peer (a flood of 5 MB messages added 35 MB of
    shared pages to the sim's and the compute peer's resident memory) and the router's message size
    cap does not apply; fabric messages are small (a 240-ray scan is ~560 bytes, under zenoh's
    3 kB threshold for using shared memory at all), so nothing is lost by leaving it off."""
    extra: tuple[tuple[str, str], ...] = field(default=())

    def __post_init__(self) -> None:
        validate_id(self.world, what="world")
        if self.profile not in PROFILES:
            raise ConfigError(f"unknown profile {self.profile!r}; expected one of {', '.join(PROFILES)}")
        for ep in (*self.connect, *self.listen):
            _check_endpoint(ep)
        if self.lease_ms < 100:
            raise ConfigError(f"lease of {self.lease_ms} ms is too short (at least 100 ms)")
        if self.config_file is not None and not Path(self.config_file).is_file():
            raise ConfigError(f"zenoh config file {self.config_file!r} does not exist")

    @classmethod
    def resolve(
        cls,
        *,
        world: str | None = None,
        profile: str | None = None,
        connect: list[str] | tuple[str, ...] | None = None,
        listen: list[str] | tuple[str, ...] | None = None,
        config_file: str | None = None,
        lease_ms: int | None = None,
        env: Mapping[str, str] | None = None,
    ) -> "FabricConfig":
        """Flags win over the environment, which wins over defaults."""
        env = os.environ if env is None else env
        connect = tuple(connect or ())
        if not connect and env.get(ENV_CONNECT):
            connect = tuple(e.strip() for e in env[ENV_CONNECT].split(",") if e.strip())
        prof = profile or env.get(ENV_PROFILE) or "client"
        return cls(
            world=world or env.get(ENV_WORLD) or DEFAULT_WORLD,
            profile=prof,
            connect=connect,
            listen=tuple(listen or ()),
            config_file=config_file or env.get(ENV_CONFIG) or None,
            lease_ms=lease_ms or 2000,
        )

    def file_value(self, key: str) -> object:
        """A setting of the zenoh config file (None without a file or when it is unset)."""
        if not self.config_file:
            return None
        try:
            return json.loads(zenoh.Config.from_file(self.config_file).get_json(key))
        except Exception:
            return None

    def _file_endpoints(self, which: str) -> tuple[str, ...]:
        """Endpoints the file lists (a plain list; zenoh's own per-mode defaults are a map and do not count)."""
        value = self.file_value(f"{which}/endpoints")
        return tuple(str(v) for v in value) if isinstance(value, list) else ()

    def endpoints(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(connect, listen) after defaults: flags, then the zenoh config file's, then the profile's."""
        file_connect = self._file_endpoints("connect") if not self.connect else ()
        file_listen = self._file_endpoints("listen") if not self.listen else ()
        connect, listen = self.connect or file_connect, self.listen or file_listen
        if self.profile == "embedded":
            return connect, listen or (DEFAULT_ENDPOINT,)
        if self.profile == "client":
            return connect or (DEFAULT_ENDPOINT,), listen
        return connect, listen

    def identity(self) -> str | None:
        """Who the router will know this session as: the usrpwd user or the TLS certificate's common
        name of the zenoh config file (``robofabric secure init``); None without credentials."""
        user = self.file_value("transport/auth/usrpwd/user")
        if isinstance(user, str) and user:
            return user
        cert = self.file_value("transport/link/tls/connect_certificate")
        if isinstance(cert, str) and cert:
            try:
                return certificate_common_name(cert)
            except (OSError, ValueError) as exc:
                raise ConfigError(f"cannot read the certificate {cert!r} of {self.config_file!r}: {exc}") from None
        return None

    def join_failure(self, exc: BaseException) -> str:
        """One line saying why a session could not open: which world, through where, and why."""
        return self.diagnose_join(exc).text

    def diagnose_join(self, exc: BaseException) -> JoinFailure:
        """Where and why a session could not open (:class:`JoinFailure`).

        zenoh says only "Unable to connect" whether nobody listens, the router refused the login or this
        client refused the router's TLS certificate; a TCP connection that succeeds says a router is there,
        and a TLS handshake of our own says whether its certificate is the problem (:func:`_tls_refusal`)."""
        reason = str(exc).split(" at /")[0]  # zenoh appends the Rust source location
        connect, listen = self.endpoints()
        where = ", ".join(connect or listen) or "the LAN"
        if reason.startswith("authentication failed"):
            return JoinFailure(where, reason, reason)  # said already
        if self.profile == "client" and connect and "Unable to connect" in reason:
            up = [ep for ep in connect if _reachable(ep)]
            if up:
                try:
                    who = self.identity()
                except ValueError:
                    who = None
                tls = _tls_refusal(
                    up[0],
                    self.file_value("transport/link/tls/root_ca_certificate"),
                    self.file_value("transport/link/tls/connect_certificate"),
                    self.file_value("transport/link/tls/connect_private_key"),
                )
                if tls is not None:
                    return JoinFailure(up[0], tls, f"cannot join world {self.world!r} at {up[0]}: {tls}")
                if who is not None:
                    cause = "the router refused this login (wrong password, unknown user, or a certificate it does not trust)"
                    return JoinFailure(up[0], cause, f"authentication failed for {who} at {up[0]}: {cause}")
                cause = "the router refused the connection (it may require credentials: --zenoh-config FILE from your instructor)"
                return JoinFailure(up[0], cause, f"authentication failed at {up[0]}: {cause}")
            if connect:
                # in robofabric's words (zenoh's "Unable to connect to any of [Single(tcp/...)]!" says less)
                cause = "no router answers there (is it running, and is this its address?)"
                return JoinFailure(
                    where,
                    cause,
                    f"cannot join world {self.world!r}: no router answers at {where} (is it running, and is this its address?)",
                )
        return JoinFailure(where, reason, f"cannot join world {self.world!r} via {where}: {reason}")

    def user_id(self, user: str | None) -> str | None:
        """The user a session speaks for: the authenticated identity when there is one (a different
        ``user`` is a :class:`ConfigError`), else ``user``."""
        ident = self.identity()
        if ident is None:
            return user
        if user is not None and user != ident:
            raise ConfigError(f"{self.config_file} logs in as {ident!r}: the user id is the identity, not {user!r}")
        return ident

    def zenoh_config(self) -> zenoh.Config:
        if self.config_file:
            try:
                conf = zenoh.Config.from_file(self.config_file)
            except Exception as exc:
                raise ConfigError(f"cannot read zenoh config {self.config_file!r}: {exc}") from None
        else:
            conf = zenoh.Config()
        mode = {"embedded": "router", "client": "client", "peer": "peer"}[self.profile]
        connect, listen = self.endpoints()
        multicast = self.multicast if self.multicast is not None else self.profile == "peer"
        conf.insert_json5("mode", json.dumps(mode))
        conf.insert_json5("scouting/multicast/enabled", json.dumps(multicast))
        if connect:
            conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
        if listen:
            conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
        conf.insert_json5("transport/link/tx/lease", json.dumps(self.lease_ms))
        if mode != "router" and not (self.config_file and "retry" in _file_text(self.config_file)):
            conf.insert_json5("connect/retry", json.dumps(RECONNECT_RETRY))
        if self.socket_buffer is not None:
            conf.insert_json5("transport/link/tcp/so_sndbuf", json.dumps(self.socket_buffer))
            conf.insert_json5("transport/link/tcp/so_rcvbuf", json.dumps(self.socket_buffer))
        if not self.shared_memory:
            conf.insert_json5("transport/shared_memory/enabled", "false")
        # a file that chose its own cap keeps it; otherwise a few MB, not zenoh's 1 GiB
        if json.loads(conf.get_json("transport/link/rx/max_message_size")) == ZENOH_DEFAULT_MAX_MESSAGE_SIZE:
            conf.insert_json5("transport/link/rx/max_message_size", json.dumps(MAX_MESSAGE_SIZE))
        block_wait = "transport/link/tx/queue/congestion_control/block/wait_before_close"
        if mode == "router" and json.loads(conf.get_json(block_wait)) == ZENOH_DEFAULT_BLOCK_WAIT_US:
            conf.insert_json5(block_wait, json.dumps(self.lease_ms * 1000 // BLOCK_WAIT_SHARE))
        # A router answers read-only queries on its admin space: its own entry (``@/ZID/router``) tells a standby sim its
        # link is up (sim_peer.replica.roles). Its subscriber and queryable entries can stop a zenoh 1.10.2 router for
        # good, and no tool of ours asks them (fabric/declared.py). Never writable; a config file that sets the admin
        # space keeps its choice; ACLs still decide who may ask.
        if (
            mode == "router"
            and not json.loads(conf.get_json("adminspace/enabled"))
            and not (self.config_file and "adminspace" in _file_text(self.config_file))
        ):
            conf.insert_json5(
                "adminspace", json.dumps({"enabled": True, "permissions": {"read": True, "write": False}})
            )
        # Timestamps let advanced subscribers ask publishers' caches for history.
        conf.insert_json5("timestamping/enabled", json.dumps({"router": True, "peer": True, "client": True}))
        for key, value in self.extra:
            conf.insert_json5(key, value)
        return conf


def _file_text(path: str) -> str:
    try:
        with open(path, encoding="utf-8") as f:
            return f.read()
    except OSError:
        return ""


def certificate_common_name(path: str | Path) -> str | None:
    """The common name of a PEM certificate (an identity, in a TLS world), or None if it has none."""
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    cert = x509.load_pem_x509_certificate(Path(path).read_bytes())
    names = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    return str(names[0].value) if names else None
