"""fabric.text: any text from the network comes out as one line of printable characters, capped, and printable
text that fits comes out unchanged."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fabric.text import CUT, escape, one_line


@given(st.text(), st.integers(min_value=1, max_value=500))
def test_any_text_is_one_printable_line_within_the_cap(text, cap):
    out = one_line(text, cap)
    assert out.isprintable() and len(out) <= cap
    assert len(out.splitlines()) <= 1  # str.splitlines knows \r, \v, \f, \x1c-\x1e, \x85, \u2028, \u2029 too
    assert "\x1b" not in out


@given(
    st.text(
        st.characters(blacklist_categories=("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp", "Zs")) | st.just(" "),
        max_size=300,
    ),
    st.integers(min_value=1, max_value=400),
)
def test_printable_text_that_fits_is_unchanged_and_longer_text_keeps_its_start(text, cap):
    out = one_line(text, cap)
    if len(text) <= cap:
        assert out == text
    else:
        assert out == text[: cap - 1] + CUT


@given(st.text(max_size=200))
def test_escaping_keeps_what_was_sent_readable(text):
    """Every character that is not printable is written as a string literal writes it: the text can be read back."""
    import ast

    out = escape(text)
    assert out.isprintable()
    # the escapes are Python's: where the text held no quote or backslash, the literal gives the text back
    if "'" not in text and "\\" not in text:
        assert ast.literal_eval(f"'{out}'") == text


def test_a_forged_line_stays_on_the_line_it_came_in():
    forged = "decode_error\ntrusted · ownership arm1: alice -> mallory (epoch 7)"
    out = one_line(forged)
    assert out == "decode_error\\ntrusted · ownership arm1: alice -> mallory (epoch 7)"
    assert one_line("\n" * 2000) == ("\\n" * 100)[:199] + CUT
    assert one_line("a\u202eb\x1b[2Jc") == "a\\u202eb\\x1b[2Jc"  # a bidi override and an escape sequence, shown
    assert one_line("a\xa0b") == "a\\xa0b"  # a space that is not one (Zs): shown, not mistaken for a space
    assert one_line(None) == "None" and one_line(7, 1) == "7"
    with pytest.raises(ValueError):
        one_line("x", 0)
