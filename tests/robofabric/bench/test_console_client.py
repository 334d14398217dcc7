"""The emulated page reads a NiceGUI page as the page's script does: its element tree (HTML-escaped in a JS raw
string) and its socket query (a Python literal), and finds controls by what a person reads on them."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robofabric.bench.console_client import EmulatedPage, PageGone, parse_page

ESC = (("&", "&amp;"), ("<", "&lt;"), (">", "&gt;"), ("`", "&#96;"), ("$", "&#36;"))  # nicegui's, & first


def _page(elements: dict, query: str) -> str:
    raw = json.dumps(elements)
    for a, b in ESC:
        raw = raw.replace(a, b)
    return f"<script>\n const app = createApp(parseElements(String.raw`{raw}`), {{\n  query: {query},\n  extra: 1,\n</script>"


@given(st.text(max_size=40))
def test_any_label_survives_the_pages_escaping(label):
    els, q = parse_page(_page({"0": {"tag": "q-layout"}, "7": {"tag": "q-btn", "props": {"label": label}}},
                              "{'client_id': 'c-1', 'next_message_id': 3, 'implicit_handshake': True}"))
    assert els["7"]["props"]["label"] == label
    assert q == {"client_id": "c-1", "next_message_id": 3, "implicit_handshake": True}


def test_controls_are_found_by_label_aria_label_or_text_and_by_tag():
    page = EmulatedPage("http://x/")
    page.elements = {"1": {"tag": "nicegui-input", "props": {"aria-label": "Name"}},
                     "2": {"tag": "q-btn", "props": {"label": "Log in"}},
                     "3": {"tag": "div", "text": "Log in"},
                     "4": {"tag": "div", "text": "request base3: you own it (epoch 2)"}}
    assert page.find("Name") == "1"
    assert page.find("Log in", tag="q-btn") == "2" and page.find("Log in", tag="div") == "3"
    assert page.find("you own it", exact=False) == "4" and page.find("you own it") is None
    assert "request base3" in page.text()


def test_a_page_that_is_not_niceguis_is_refused_with_why():
    with pytest.raises(PageGone, match="not a NiceGUI page"):
        parse_page("<html><body>404</body></html>")
