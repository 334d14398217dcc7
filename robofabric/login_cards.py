"""Login cards: what `robofabric secure init` hands each student (and instructor) of a password class.

A student who logs in from the browser console types her name and password; she should not have to copy a
24-character token out of a JSON5 file. People get a typable password (:func:`typable_password`: three groups
of four lower-case letters and digits, without the look-alikes 0 o 1 l i: about 59 bits, far past what an
online guesser gets through the router and the console's login throttle), the peers keep their long random
tokens. Each person's card (``cards/NAME.txt``) and one printable page of all of them (``cards/cards.html``) say
her name, her password and the console's address; the same password is in her ``NAME.json5`` for her scripts.
The printable page carries a QR code of the console's address on every card (:func:`qr_svg`, made with segno), so
a phone or a tablet opens the console without typing the address; ``cards/console-qr.svg`` is the code alone.
A class with mutual TLS (``--tls``) has no passwords: its people log in with certificates, and no card is written.
"""

from __future__ import annotations

import os
import secrets
from html import escape
from pathlib import Path
from typing import Iterable

__all__ = [
    "TYPABLE",
    "typable_password",
    "is_typable",
    "card_text",
    "write_cards",
    "console_url",
    "qr_svg",
    "PEOPLE",
    "QR_QUIET",
]

TYPABLE = "abcdefghjkmnpqrstuvwxyz23456789"
"""The letters a typable password is made of: lower case and digits, without 0 o 1 l i (read alike on a card)."""
PEOPLE = ("user", "instructor")
"""The roles whose logins a person types (the others are peers' configs)."""
CARDS_DIR = "cards"
QR_QUIET = 4
"""The light margin around a QR code, in modules (the standard's quiet zone)."""


def typable_password(groups: int = 3, size: int = 4) -> str:
    """``groups`` groups of ``size`` characters of :data:`TYPABLE`, joined by ``-`` (e.g. ``k7mp-x3qa-9wte``)."""
    return "-".join("".join(secrets.choice(TYPABLE) for _ in range(size)) for _ in range(groups))


def is_typable(password: str) -> bool:
    """Whether ``password`` is one :func:`typable_password` makes (a second ``secure init`` keeps older ones)."""
    parts = password.split("-")
    return len(parts) >= 3 and all(p and set(p) <= set(TYPABLE) for p in parts)


def console_url(connect: Iterable[str], *, https: bool, port: int = 8080) -> str:
    """The console's address on a card: the router's first host (where the teacher usually serves the console
    too), the console's default port."""
    first = next(iter(connect), "tcp/127.0.0.1:7447")
    host = first.partition("/")[2].rsplit(":", 1)[0]
    if host in ("0.0.0.0", "[::]", ""):
        host = "127.0.0.1"
    return f"{'https' if https else 'http'}://{host}:{port}/"


def teacher_url(url: str) -> str:
    """The teacher's page of the console at ``url`` (user_peer.console.teacher.ROUTE), on an instructor's card."""
    return url.rstrip("/") + "/teacher"


def card_text(name: str, password: str, url: str, role: str = "user") -> str:
    """One person's card, as plain text."""
    who = "instructor" if role == "instructor" else "student"
    return (
        f"robofabric login card ({who})\n\n"
        f"  Console   {url}\n"
        f"  Name      {name}\n"
        f"  Password  {password}\n"
        + (f"  Teacher   {teacher_url(url)}  (the teacher's page)\n" if role == "instructor" else "")
        + "\n"
        f"Open the console's address in a browser, type your name and password, press Log in.\n"
        f"Scripts and the terminal UI log in with {name}.json5 (the same password), from your teacher.\n"
    )


def qr_svg(url: str) -> str:
    """A QR code of ``url`` as an SVG element: one 1x1 ``rect`` per dark module of segno's matrix (error correction M),
    inside a quiet zone of :data:`QR_QUIET` modules, named for a screen reader."""
    import segno

    qr = segno.make(url, error="m", micro=False)
    n = len(qr.matrix)
    size = n + 2 * QR_QUIET
    dark = "".join(
        f'<rect x="{x + QR_QUIET}" y="{y + QR_QUIET}" width="1" height="1"/>'
        for y, row in enumerate(qr.matrix)
        for x, v in enumerate(row)
        if v
    )
    return (
        f'<svg class="qr" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {size} {size}" role="img" '
        f'aria-label="QR code of {escape(url)}" shape-rendering="crispEdges"><rect width="{size}" height="{size}" fill="#fff"/>'
        f'<g fill="#000">{dark}</g></svg>'
    )


def _card_html(name: str, password: str, url: str, role: str, qr: str) -> str:
    who = "instructor" if role == "instructor" else "student"
    return (
        f'<section class="card">{qr}<h2>robofabric login card <small>({who})</small></h2><dl>'
        f"<dt>Console</dt><dd>{escape(url)}</dd><dt>Name</dt><dd>{escape(name)}</dd>"
        f'<dt>Password</dt><dd class="pw">{escape(password)}</dd>'
        + (f"<dt>Teacher</dt><dd>{escape(teacher_url(url))}</dd>" if role == "instructor" else "")
        + "</dl>"
        "<p>Open the console's address in a browser (or scan the code), type your name and password, press "
        "<b>Log in</b>.</p></section>"
    )


CSS = """body{font-family:sans-serif;margin:1cm}.card{border:1px dashed #555;padding:0.5cm;margin:0 0 0.5cm;width:12cm;
break-inside:avoid}h2{font-size:1.1rem;margin:0 0 0.3cm}dl{display:grid;grid-template-columns:6em auto;margin:0}dd{margin:0;
font-family:monospace;font-size:1.2rem}.pw{letter-spacing:0.1em}.qr{float:right;width:3cm;height:3cm;margin:0 0 0.2cm 0.3cm}"""


def write_cards(d: Path, people: Iterable[tuple[str, str]], passwords: dict[str, str], url: str) -> dict[str, Path]:
    """Write ``d/cards/NAME.txt`` for each (name, role) of ``people`` that has a password, and ``d/cards/cards.html``
    with every card (print it and cut); all private (0600 in a 0700 folder): a card holds a password."""
    out: dict[str, Path] = {}
    folder = d / CARDS_DIR
    html = []
    qr = qr_svg(url)
    for name, role in people:
        if name not in passwords:
            continue
        folder.mkdir(exist_ok=True)
        os.chmod(folder, 0o700)
        path = folder / f"{name}.txt"
        _private(path, card_text(name, passwords[name], url, role))
        out[name] = path
        html.append(_card_html(name, passwords[name], url, role, qr))
    if out:
        _private(folder / "console-qr.svg", qr + "\n")
        _private(
            folder / "cards.html",
            f'<!doctype html><html lang="en"><head><meta charset="utf-8"><title>robofabric login cards</title>'
            f"<style>{CSS}</style></head><body>{''.join(html)}</body></html>\n",
        )
    return out


def _private(path: Path, text: str) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.chmod(path, 0o600)
