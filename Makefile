# simbridge: `make run` installs and starts the server; `make test` installs everything the
# tests need (Python packages, Node packages, Debian's chromium and nginx) and runs them all.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
HOST   ?= 0.0.0.0

.PHONY: run test check lint format typecheck pytest bench deps clean test-arm64

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

# A plain (non-editable) install, exactly what `pip install simbridge` gives a user.
$(VENV)/.run-installed: $(BIN)/python pyproject.toml $(shell find simbridge static config -type f -not -path '*/__pycache__/*' 2>/dev/null)
	$(BIN)/pip install --quiet .
	touch $@

run: $(VENV)/.run-installed
	cd /tmp && $(abspath $(BIN))/simbridge --host $(HOST)

# Everything the tests need, installed idempotently.
deps: $(BIN)/python
	$(BIN)/pip install --quiet -e '.[test]'
	scripts/setup-test-deps.sh

lint:
	$(BIN)/ruff format --check simbridge tests bench examples scripts
	$(BIN)/ruff check simbridge tests bench examples scripts

typecheck:
	$(BIN)/mypy

pytest:
	$(BIN)/pytest -q

test: deps lint typecheck pytest

# The arm64 (Raspberry Pi 4B/5) image built and its compose stack run under qemu-user emulation
# (root: registers qemu-aarch64 with binfmt_misc; the first run makes the arm64 base and images,
# about 20 minutes on a busy 2-core machine; later runs reuse them: 0.5-2 minutes). Also part of
# `make test`.
test-arm64: deps
	$(BIN)/pytest -q tests/deploy/test_arm64.py

format:
	$(BIN)/ruff format simbridge tests bench examples scripts
	$(BIN)/ruff check --fix simbridge tests bench examples scripts

bench: deps
	$(BIN)/pip install --quiet -e '.[test,bench]'
	$(BIN)/python -m bench

clean:
	rm -rf $(VENV) build dist *.egg-info tests/js/node_modules artifacts
