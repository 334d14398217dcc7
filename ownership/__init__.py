"""Replicated, leased ownership of shared robots with disconnect recovery.

:mod:`ownership.state` is the pure state machine; :class:`Authority` hosts it in the
sim peer as its command gate; :class:`OwnershipClient` is a user's side (requests,
renewals, replica); :func:`extrapolate` is the paper's latency compensation (Eq. 8).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ownership.authority import Authority
    from ownership.client import OwnershipClient, Outcome
    from ownership.admission import OwnBudgets
    from ownership.extrapolate import extrapolate

__all__ = ["Authority", "OwnBudgets", "OwnershipClient", "Outcome", "extrapolate"]


def __getattr__(name: str) -> Any:
    """The package's names load on first use: ``robofabric --help`` imports ``ownership.cli``, and with it this
    package, and must not pay for the session and numpy it never uses."""
    if name == "Authority":
        from ownership.authority import Authority

        return Authority
    if name == "OwnBudgets":
        from ownership.admission import OwnBudgets

        return OwnBudgets
    if name in ("OwnershipClient", "Outcome"):
        from ownership import client

        return getattr(client, name)
    if name == "extrapolate":
        from ownership.extrapolate import extrapolate

        return extrapolate
    raise AttributeError(f"module 'ownership' has no attribute {name!r}")
