# simbridge: `make run` installs and starts the server; `make test` installs everything the
# tests need (Python packages, Node packages, Debian's chromium and nginx) and runs them all.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
HOST   ?= 0.0.0.0
# `make run ARGS="--world config/worlds/classroom.yaml --demo-nodes"`: options for simbridge
# (paths are relative to the checkout; SIMBRIDGE_* variables pass through as well).
ARGS   ?=
# `make run EXTRAS=zenoh ARGS=--zenoh`: extras of the install (pyproject.toml).
EXTRAS ?=
# What `make deps` runs after the Python install (the tests of this Makefile replace it).
SETUP_TEST_DEPS ?= scripts/setup-test-deps.sh
comma  := ,
RUN_STAMP := $(VENV)/.run-installed$(if $(EXTRAS),-$(subst $(comma),-,$(EXTRAS)))

.PHONY: run test check lint format typecheck pytest bench deps clean test-arm64

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

# A plain (non-editable) install, exactly what `pip install simbridge` gives a user.
$(RUN_STAMP): $(BIN)/python pyproject.toml $(shell find simbridge static config -type f -not -path '*/__pycache__/*' 2>/dev/null)
	$(BIN)/pip install --quiet '.$(if $(EXTRAS),[$(EXTRAS)])'
	touch $@

run: $(RUN_STAMP)
	$(BIN)/simbridge --host $(HOST) $(ARGS)

# Everything the tests need, installed idempotently. The editable install replaces `make run`'s
# plain one, so the next `make run` installs plainly again.
deps: $(BIN)/python
	$(BIN)/pip install --quiet -e '.[test]'
	rm -f $(VENV)/.run-installed*
	$(SETUP_TEST_DEPS)

lint:
	$(BIN)/ruff format --check simbridge tests bench examples scripts
	$(BIN)/ruff check simbridge tests bench examples scripts

typecheck:
	$(BIN)/mypy

pytest:
	$(BIN)/pytest -q

test: deps lint typecheck pytest

# The arm64 (Raspberry Pi 4B/5) image, with the dds extra, built and its compose stack and
# `simbridge --dds` run under qemu-user emulation (root: registers qemu-aarch64 with binfmt_misc;
# the first run makes the arm64 base and images, the Cyclone DDS binding compiled among them,
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
