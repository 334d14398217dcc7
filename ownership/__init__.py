"""Replicated, leased ownership of shared robots with disconnect recovery (issue 5).

:mod:`ownership.state` is the pure state machine; :class:`Authority` hosts it in the
sim peer as its command gate; :class:`OwnershipClient` is a user's side (requests,
renewals, replica); :func:`extrapolate` is the paper's latency compensation (Eq. 8).
"""

from ownership.authority import Authority
from ownership.client import OwnershipClient, Outcome
from ownership.extrapolate import extrapolate

__all__ = ["Authority", "OwnershipClient", "Outcome", "extrapolate"]
