"""User names, quoting and the per-key rate limiter: pure, property-tested."""

from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as hs

from fabric.codec import DecodeError, decode, encode
from fabric.limits import MAX_USER_LEN, RateLimiter, clip, is_valid_user, quote, validate_user
from fabric.interfaces import Command, JointState, Scan, Stop


@pytest.mark.parametrize("name", ["alice", "a", "user-host-1a2b3c", "Bob_2.0", "x" * MAX_USER_LEN])
def test_good_user_names(name):
    assert validate_user(name) == name and is_valid_user(name)


@pytest.mark.parametrize(
    "name, why",
    [
        ("", "empty"),
        ("x" * (MAX_USER_LEN + 1), "too long"),
        ("a/b", "may hold only"),
        ("@alice", "may hold only"),
        ("-x", "may hold only"),
        ("al ice", "may hold only"),
        ("é", "may hold only"),
        (3, "must be a string"),
    ],
)
def test_bad_user_names(name, why):
    with pytest.raises(ValueError, match=why):
        validate_user(name)
    assert not is_valid_user(name)


def test_the_codec_refuses_bad_user_names_and_quotes_little():
    huge = "u" * 1_000_000
    with pytest.raises(DecodeError, match="may hold only") as err:
        decode(encode(Command("alice", 0, Stop())).replace(b"alice", b"al/ce"))
    assert "al/ce" in str(err.value)
    payload = encode(Command("alice", 0, Stop())).replace(
        b"\xa5alice", b"\xdb" + len(huge).to_bytes(4, "big") + huge.encode()
    )
    with pytest.raises(DecodeError, match="too long") as err:
        decode(payload)
    assert len(str(err.value)) < 300


def test_an_unknown_type_name_of_a_megabyte_is_quoted_short():
    import msgpack

    with pytest.raises(DecodeError, match="unknown message type") as err:
        decode(msgpack.packb(["T" * 1_000_000, 1, 2]))
    assert len(str(err.value)) < 200


def test_array_caps():
    import numpy as np

    with pytest.raises(DecodeError, match="too many"):
        decode(encode(Scan(0.0, 0.001, 10.0, np.zeros(1_000_000, np.uint16))))
    with pytest.raises(DecodeError, match="too many"):
        decode(encode(JointState([f"j{i}" for i in range(300)], np.zeros(300), np.zeros(300))))


@given(hs.text(max_size=2000) | hs.binary(max_size=2000))
def test_quote_and_clip_are_short(value):
    assert len(quote(value)) <= 240
    if isinstance(value, str):
        assert len(clip(value)) <= 240
        assert clip(value) == value or len(value) > 200


def test_rate_limiter_reports_a_burst_then_counts():
    rl = RateLimiter(5.0, burst=2)
    assert [bool(rl.check("k", t)) for t in (0.0, 0.1, 0.2, 0.3)] == [True, True, False, False]
    v = rl.check("k", 5.1)
    assert v.report and v.suppressed == 2
    assert rl.check("other", 5.1).report


@settings(max_examples=100, deadline=None)
@given(hs.lists(hs.tuples(hs.sampled_from("abcdefgh"), hs.floats(0, 2)), max_size=300), hs.integers(1, 3))
def test_rate_limiter_bounds(events, burst):
    """Per key: at most ``burst`` reports per window, every check is reported or counted, memory bounded."""
    rl = RateLimiter(1.0, burst=burst, max_keys=4)
    now, reports, suppressed_told, checks = 0.0, 0, 0, 0
    for key, dt in events:
        now += dt
        v = rl.check(key, now)
        checks += 1
        assert len(rl) <= 4
        if v:
            reports += 1
            suppressed_told += v.suppressed
    assert reports + suppressed_told + sum(rl.pending().values()) <= checks
    assert reports >= min(checks, 1)


def test_put_dropping_oldest_keeps_the_newest_and_counts_what_it_dropped():
    import queue

    from fabric.limits import put_dropping_oldest

    q: queue.Queue = queue.Queue(maxsize=3)
    dropped = sum(put_dropping_oldest(q, i) for i in range(10))
    assert dropped == 7
    assert [q.get_nowait() for _ in range(3)] == [7, 8, 9]
