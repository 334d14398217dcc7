"""Fixtures of the console's tests."""

from __future__ import annotations

import pytest


@pytest.fixture
def worlds():
    """The user worlds a test's logins opened: each closed at the end."""
    made: list = []
    yield made
    for w in made:
        w.close()
