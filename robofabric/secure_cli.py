"""``robofabric secure init``: credentials and router rules for a class (robofabric/secure.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from fabric.cli_common import UserError

secure_app = typer.Typer(
    help="Credentials and access control for a class: who may say what on the fabric.", no_args_is_help=True
)


@secure_app.command("init")
def init_cmd(
    directory: Annotated[
        Path, typer.Argument(help="Where to write router.json5 and NAME.json5 per identity (made 0700).")
    ],
    users: Annotated[str, typer.Option("--users", help="Comma-separated user ids, e.g. alice,bob,mallory.")],
    sims: Annotated[
        str, typer.Option("--sims", help="Comma-separated sim identities (may publish robot state and ownership).")
    ] = "sim",
    computes: Annotated[
        str, typer.Option("--computes", help="Comma-separated compute identities (serve IK, maps, plans).")
    ] = "compute",
    viewers: Annotated[
        str, typer.Option("--viewers", help="Comma-separated viewer identities (read only).")
    ] = "viewer",
    instructors: Annotated[
        str,
        typer.Option(
            "--instructors",
            help="Comma-separated instructor identities: users who may also set, reset, stop, save and load the class's map.",
        ),
    ] = "",
    tls: Annotated[
        bool, typer.Option("--tls", help="Mutual TLS: a CA and one certificate per identity; endpoints tls/...")
    ] = False,
    listen: Annotated[
        Optional[list[str]],
        typer.Option("--listen", "-l", help="Router endpoint (default tcp/0.0.0.0:7447, tls/... with --tls)."),
    ] = None,
    connect: Annotated[
        Optional[list[str]],
        typer.Option(
            "--connect",
            "-e",
            help="Where clients reach the router, e.g. tcp/10.0.0.5:7447 (default: the listen address).",
        ),
    ] = None,
    days: Annotated[int, typer.Option(help="Certificates' validity in days (--tls).")] = 365,
    console: Annotated[
        Optional[str],
        typer.Option(
            "--console",
            help="The console's URL on the login cards (default http://ROUTER-HOST:8080/, https with --tls or --console-tls).",
        ),
    ] = None,
    console_tls: Annotated[
        bool,
        typer.Option(
            "--console-tls",
            help="In a password class, also make the console's HTTPS certificate (tls/web/console.pem, signed by a class CA); --tls makes it anyway.",
        ),
    ] = False,
) -> None:
    """Write everything a class needs: DIR/router.json5 (authentication + access control, default deny)
    and DIR/NAME.json5 per identity, for --zenoh-config, and in a password class a login card per person
    (DIR/cards/NAME.txt, all of them in DIR/cards/cards.html). Running it again keeps existing secrets."""
    from robofabric.secure import init, parse_names

    try:
        out = init(
            directory,
            users=parse_names(users),
            sims=parse_names(sims),
            computes=parse_names(computes),
            viewers=parse_names(viewers),
            instructors=parse_names(instructors),
            tls=tls,
            listen=listen,
            connect=connect,
            days=days,
            console_tls=console_tls,
            console=console,
        )
    except (ValueError, OSError) as exc:
        raise UserError(str(exc)) from None
    print(f"router:  robofabric router --zenoh-config {out.router}")
    for name, path in out.clients.items():
        print(f"{name:8} --zenoh-config {path}")
    if out.cards:
        print(
            f"login cards: {next(iter(out.cards.values())).parent / 'cards.html'} (print it and cut; one card a person: "
            "name, typable password, the console's URL)"
        )
    new = ", ".join(out.created) or "none"
    print(
        f"new secrets: {new}; kept: {', '.join(out.kept) or 'none'} (files are 0600: hand each one to its owner only)"
    )


def register(app: typer.Typer) -> None:
    app.add_typer(secure_app, name="secure")
