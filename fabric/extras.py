"""The optional stacks of an install: a command that needs one it lacks names the extra that brings it.

``pip install robofabric`` is what a student needs (the user API, the terminal UI, the console, the CLI
tools); the sim's MuJoCo and the compute peer's Pinocchio, CasADi and OMPL come with the extras
``robofabric[sim]``, ``robofabric[compute]`` (or ``robofabric[all]``). ``robofabric sim`` on a student's
install then says so in one line (exit 2) instead of a traceback from deep inside the sim.
"""

from __future__ import annotations

import importlib

__all__ = ["EXTRAS", "missing", "require"]

EXTRAS: dict[str, tuple[str, ...]] = {"sim": ("mujoco",), "compute": ("pinocchio", "casadi", "ompl")}
"""Extra -> the modules it brings (pyproject's ``[project.optional-dependencies]``)."""


def missing(extra: str) -> list[str]:
    """The modules of ``extra`` this install cannot import."""
    out = []
    for name in EXTRAS[extra]:
        try:
            importlib.import_module(name)
        except ImportError:
            out.append(name)
    return out


def require(extra: str, command: str) -> None:
    """:class:`~fabric.cli_common.UserError` (one line, exit 2) naming the extra when ``command`` lacks its modules."""
    gone = missing(extra)
    if gone:
        from fabric.cli_common import UserError

        raise UserError(
            f"robofabric {command} needs {', '.join(gone)}, which this install lacks: pip install 'robofabric[{extra}]'"
        )
