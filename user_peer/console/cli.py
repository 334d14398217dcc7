"""``robofabric console``: serve the student client (a browser page) for one world."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from fabric.cli_common import Connect, UserError, World, ZenohConfig

__all__ = ["console"]


def console(
    listen: Annotated[
        str, typer.Option("--listen", help="HOST:PORT the page is served on (0.0.0.0: every interface).")
    ] = "0.0.0.0:8080",
    grace: Annotated[
        float,
        typer.Option(
            help="Seconds a closed page's robots stay hers (stopped) before her session closes and they pass on."
        ),
    ] = 10.0,
    rerun_url: Annotated[
        Optional[str],
        typer.Option("--rerun-url", help="The Rerun web view to link to (robofabric view --serve-web prints it)."),
    ] = None,
    tls_cert: Annotated[
        Optional[str],
        typer.Option(
            "--tls-cert", help="Serve HTTPS with this certificate (PEM; secure init --tls writes tls/web/console.pem)."
        ),
    ] = None,
    tls_key: Annotated[
        Optional[str], typer.Option("--tls-key", help="The certificate's private key (PEM; tls/web/console-key.pem).")
    ] = None,
    instructors: Annotated[
        str,
        typer.Option(
            "--instructors", help="Comma-separated instructor logins that may open the teacher's page (/teacher)."
        ),
    ] = "",
    no_3d: Annotated[
        bool,
        typer.Option(
            "--no-3d",
            help="Pages without the 3D view: the top-down map alone, as before the 3D view (lighter for the server and the browsers).",
        ),
    ] = False,
    view_fps: Annotated[
        int,
        typer.Option(
            "--view-fps",
            help="Frames a second each page's 3D view draws in its browser: lower it for old machines or many pages on "
            "one (a browser with no GPU draws in software GL: about a core a page at 10, docs/console.md).",
        ),
    ] = 10,
    world: World = None,
    connect: Connect = None,
    zenoh_config: ZenohConfig = None,
) -> None:
    """Serve the student client: students open the printed URL, log in with their own name and password,
    and own, drive and plan as their scripts would. Nothing to install on their side; Ctrl-C stops it.

    --zenoh-config: a base zenoh config every page's session starts from (e.g. the class's TLS CA); it must
    hold no login (each page logs in as its student). Needs the router's address (--connect tcp/HOST:7447).
    """
    import os

    from fabric import keys
    from fabric.config import ConfigError, FabricConfig
    from user_peer.console.server import Console, serve

    host, _, port_text = listen.rpartition(":")
    if not host or not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise UserError(f"--listen {listen}: expected HOST:PORT, e.g. 0.0.0.0:8080")
    if grace < 0:
        raise UserError("--grace must be >= 0 s")
    if not 1 <= view_fps <= 60:
        raise UserError(f"--view-fps {view_fps}: expected 1 to 60 frames a second")
    tls = _tls(tls_cert, tls_key)
    try:
        cfg = FabricConfig.resolve(world=world, connect=connect, config_file=zenoh_config)
        if cfg.identity() is not None:
            raise UserError(
                f"--zenoh-config {cfg.config_file} logs in as {cfg.identity()!r}: the console holds no login of its own "
                "(each page logs in as its student); give a config without credentials"
            )
    except ConfigError as exc:
        raise UserError(str(exc)) from None
    connect_eps, _ = cfg.endpoints()
    print(f"console for world {cfg.world!r} via {', '.join(connect_eps)}", flush=True)
    os.environ.setdefault(
        "NICEGUI_STORAGE_PATH", os.path.join(os.path.expanduser("~"), ".cache", "robofabric", "nicegui")
    )
    names = tuple(n.strip() for n in instructors.split(",") if n.strip())
    for n in names:
        try:
            keys.validate_id(n, what="instructor login")
        except ValueError as exc:
            raise UserError(f"--instructors: {exc}") from None
    serve(
        Console(
            cfg.world,
            connect_eps,
            cfg.config_file,
            grace,
            rerun_url,
            instructors=names,
            view3d=not no_3d,
            view_fps=view_fps,
        ),
        host.strip("[]"),
        int(port_text),
        tls,
    )


def _tls(cert: str | None, key: str | None) -> tuple[str, str] | None:
    """The (certificate, key) to serve HTTPS with, both readable and matching; None for plain HTTP."""
    if cert is None and key is None:
        return None
    if cert is None or key is None:
        raise UserError("--tls-cert and --tls-key go together (the certificate and its private key)")
    import ssl

    ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    try:
        ctx.load_cert_chain(cert, key)
    except (OSError, ssl.SSLError) as exc:
        raise UserError(f"--tls-cert {cert} --tls-key {key}: {exc}") from None
    return cert, key


def register(app: typer.Typer) -> None:
    app.command("console")(console)
