# The two commands: `make demo` and `make test` (`make test-fast`: without the slow tests). Each creates .venv when missing.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
STAMP_TEST := $(VENV)/.installed-test

.PHONY: demo test test-fast lint install clean bench

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[all]"
	touch $@

$(STAMP_TEST): pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[test]"
	touch $@ $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/robofabric demo --out out/demo

test: $(STAMP_TEST)
	$(PY) -m pytest -q

# the fast suite: no process-spawning or multi-second tests (those are marked slow)
test-fast: $(STAMP_TEST)
	$(PY) -m pytest -q -m "not slow"

# the linter and the type checker alone (tests/test_lint.py runs both in `make test`)
lint: $(STAMP_TEST)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy

# every benchmark, shortened (`robofabric bench all` without --quick for the figures in docs/benchmarks.md)
bench: $(STAMP)
	$(VENV)/bin/robofabric bench all --quick

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis .mypy_cache .ruff_cache
