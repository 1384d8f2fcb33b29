# The two set-up commands of the README: `make demo` (main job) and `make test`.
# Both create .venv and install the project with its test dependencies first.
# `make test-quick` skips the tests marked slow (Docker images and containers,
# cargo and other native builds): for development, not a replacement of `make test`.

PYTHON ?= python3
VENV ?= .venv
STAMP := $(VENV)/.installed-stamp

.PHONY: demo test test-quick test-deps bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/skinet demo

test-deps:
	scripts/install-test-deps.sh

test: $(STAMP) test-deps
	$(VENV)/bin/python -m pytest -q

test-quick: $(STAMP)
	$(VENV)/bin/python -m pytest -q -m "not slow"

bench: $(STAMP)
	for b in benchmarks/bench_*.py; do $(VENV)/bin/python $$b || exit 1; done

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis docker/wheels
