# The two commands of the README: `make demo` (main job, embedded defaults) and `make test`.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo test lint bench clean apt-test-deps

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip==25.3

$(VENV)/.runtime: pyproject.toml | $(BIN)/python
	$(BIN)/pip install -q -e .
	touch $@

$(VENV)/.test: pyproject.toml | $(BIN)/python
	$(BIN)/pip install -q -e '.[test]'
	touch $@ $(VENV)/.runtime

demo: $(VENV)/.runtime
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

test: $(VENV)/.test apt-test-deps
	$(BIN)/ruff check protocol fresco_bridge sim_actuator tests benchmarks
	$(BIN)/mypy
	$(BIN)/python -m pytest -q

bench: $(VENV)/.test
	$(BIN)/python -m benchmarks.run_all

clean:
	rm -rf $(VENV) runs
