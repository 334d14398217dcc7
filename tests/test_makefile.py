"""The Makefile's phony targets all have rules: `make bench` must not answer "No rule to make target"."""

from __future__ import annotations

import re
from pathlib import Path

MAKEFILE = Path(__file__).resolve().parents[1] / "Makefile"


def test_every_phony_target_has_a_rule():
    text = MAKEFILE.read_text()
    phony = {name for line in re.findall(r"^\.PHONY:(.*)$", text, re.M) for name in line.split()}
    rules = set(re.findall(r"^([\w.-]+):", text, re.M))
    assert phony and phony <= rules, f"phony without a rule: {sorted(phony - rules)}"
    assert re.search(r"^bench: \$\(STAMP\)\n\t\$\(VENV\)/bin/robofabric bench all --quick$", text, re.M)
