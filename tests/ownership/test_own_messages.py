"""Ownership service messages round-trip through the codec."""

from hypothesis import given, strategies as hs

from fabric.codec import decode, encode
from fabric.interfaces import OwnershipRecord, OwnReply, OwnRequest


ids = hs.text("abcxyz0123", min_size=1, max_size=8)


@given(hs.sampled_from(["request", "release", "renew"]), ids, hs.booleans())
def test_request_round_trip(op, user, wait):
    assert decode(encode(OwnRequest(op, user, wait)), OwnRequest) == OwnRequest(op, user, wait)


@given(
    hs.sampled_from(["granted", "denied", "queued", "released", "renewed"]),
    hs.text(max_size=20),
    hs.integers(0, 100),
    ids,
    hs.integers(0, 10**6),
    hs.lists(ids, max_size=4),
)
def test_reply_round_trip(outcome, reason, pos, owner, epoch, queue):
    rep = OwnReply(outcome, reason, pos, OwnershipRecord(object="arm", owner=owner, epoch=epoch, queue=tuple(queue)))
    assert decode(encode(rep), OwnReply) == rep
