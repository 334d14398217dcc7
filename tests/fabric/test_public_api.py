"""``fabric``'s public API: every name it lists is the object its home module defines, and importing the
package loads none of them (a script that needs only the keys does not pay for zenoh or numpy)."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

import fabric


@pytest.mark.parametrize("name", fabric.__all__)
def test_each_public_name_is_the_object_its_defining_module_holds(name):
    value = getattr(fabric, name)
    defining = importlib.import_module(value.__module__)
    assert defining.__name__.startswith("fabric.") and getattr(defining, name) is value, (name, defining)
    assert name in dir(fabric)


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'Nonesuch'"):
        fabric.Nonesuch  # noqa: B018


@pytest.mark.slow
def test_importing_fabric_loads_no_session_library():
    """A child interpreter: this process has long imported zenoh and numpy."""
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys, fabric, fabric.keys; print(sorted(m for m in ('zenoh', 'numpy', 'msgpack', 'fabric.session') if m in sys.modules))",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stdout + out.stderr
