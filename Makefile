# The two commands of the README: `make demo` (main job, embedded defaults) and `make test`.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo test docs build lint bench clean apt-test-deps

$(BIN)/python:
	@echo "make: creating the virtual environment $(VENV)/"
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip==25.3

# The step path's modules are compiled with mypyc (setup.py, the list in fresco_bridge/_compiled.py;
# FRESCO_BRIDGE_PURE=1 builds nothing). mypyc type-checks them against the installed
# dependencies, so the dependencies are installed first (pure) and the extensions built after
# (.build). An extension next to its .py is imported instead of it, so they are rebuilt whenever
# one of their sources changes, before `demo` and `test`: an edited .py is never silently
# shadowed by an old build.
COMPILED := $(shell sed -n 's/^    "\(.*\.py\)",$$/\1/p' fresco_bridge/_compiled.py)
BUILD_INPUTS := setup.py fresco_bridge/_compiled.py $(COMPILED)

# The runtime and the `opensees` extra: the README's OpenSeesPy examples run after `make demo`.
$(VENV)/.runtime: pyproject.toml | $(BIN)/python
	@echo "make: installing dependencies into $(VENV)/ (first run: ~3 min)..."
	FRESCO_BRIDGE_PURE=1 $(BIN)/pip install -q -e '.[opensees]'
	touch $@

$(VENV)/.test: pyproject.toml | $(BIN)/python
	@echo "make: installing the test dependencies into $(VENV)/ (torch, OpenSeesPy; first run: several minutes)..."
	FRESCO_BRIDGE_PURE=1 $(BIN)/pip install -q -e '.[test]'
	touch $@ $(VENV)/.runtime $(VENV)/.docs

# The `docs` extra: mkdocs-material alone (no torch), for `make docs`.
$(VENV)/.docs: pyproject.toml | $(BIN)/python
	@echo "make: installing the documentation tools into $(VENV)/ (mkdocs-material)..."
	FRESCO_BRIDGE_PURE=1 $(BIN)/pip install -q -e '.[docs]'
	touch $@

$(VENV)/.build: $(BUILD_INPUTS) $(VENV)/.runtime
	@echo "make: compiling the step path with mypyc (first run, or after a change to it: ~1 min)..."
	$(BIN)/pip install -q --no-deps -e .
	touch $@

build: $(VENV)/.build

demo: $(VENV)/.runtime $(VENV)/.build
	$(BIN)/fresco-bridge demo

# Debian packages the tests drive as independent peers, as program:package (mbpoll: a
# libmodbus Modbus master; mosquitto: the broker the telemetry tests and `lab up` start;
# mosquitto_sub/_pub: the independent subscriber and publisher).
# Idempotent and quiet; `apt-get update` only when the package lists do not know the package.
APT_TEST_PACKAGES := mbpoll:mbpoll mosquitto:mosquitto mosquitto_sub:mosquitto-clients
apt-test-deps:
	@for pair in $(APT_TEST_PACKAGES); do prog=$${pair%%:*}; p=$${pair##*:}; \
	  command -v $$prog >/dev/null 2>&1 && continue; \
	  export DEBIAN_FRONTEND=noninteractive; \
	  apt-get install -y -qq $$p >/dev/null 2>&1 \
	  || { apt-get update -qq >/dev/null && apt-get install -y -qq $$p >/dev/null; } \
	  || { echo "make: cannot install Debian package $$p (needed by the tests)" >&2; exit 1; }; \
	done

# The documentation site is built strictly (a broken link, anchor or included file fails).
# The whole suite runs on the compiled step path (what is installed); the protocol, record and
# server tests run once more on the pure sources (tests/conftest.py: FRESCO_BRIDGE_PURE=1), so
# both stay equal.
PURE_TESTS := tests/protocol tests/bridge/record tests/bridge/server tests/bridge/test_compiled.py

test: $(VENV)/.test $(VENV)/.build apt-test-deps
	$(BIN)/ruff check protocol fresco_bridge sim_actuator tests benchmarks setup.py
	$(BIN)/mypy
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet  # docs/ -> build/site (mkdocs.yml)
	$(BIN)/python -m pytest -q
	FRESCO_BRIDGE_PURE=1 $(BIN)/python -m pytest -q -p no:cacheprovider $(PURE_TESTS)

# The documentation site, strictly (a broken link, anchor or included file fails), into
# build/site: it browses from file:// (mkdocs.yml: use_directory_urls false), no server needed.
docs: $(VENV)/.docs
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet
	@echo "make: the documentation site: file://$(CURDIR)/build/site/index.html"

# Every benchmark as BENCHMARKS.md measured it (hours); `make bench BENCH=--quick` for the short
# versions (a smoke run), `BENCH="--only NAME"` for one (benchmarks/run_all.py).
BENCH ?=
bench: $(VENV)/.test
	$(BIN)/python -m benchmarks.run_all $(BENCH)

clean:
	rm -rf $(VENV) runs build
	find protocol fresco_bridge sim_actuator -name '*.so' -delete
