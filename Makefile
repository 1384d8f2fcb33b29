# The two set-up commands of the README: `make demo` (main job) and `make test`.
# Both create .venv and install the project with its test dependencies first.
# `make test-quick` skips the tests marked slow (Docker images and containers,
# cargo and other native builds): for development, not a replacement of `make test`.
# `make screenshot` photographs the live dashboard for the README (docs/dashboard.png):
# `skinet demo --live` in headless Chromium (tests/screenshot.py; needs chromium).
# Both run pytest on every core (pytest-xdist, at most 4 workers); a module of slow
# tests, or of tests sharing a module-scoped fixture, runs whole on one worker, in
# file order (tests/conftest.py), while the other tests are spread one by one.
# PYTEST_ADDOPTS adds options (e.g. -k, -x); pytest's exit status 5 (nothing
# collected) fails both targets like any other non-zero status.

PYTHON ?= python3
# Python caches compiled modules in __pycache__/ (git ignores them). Some sandboxes set
# PYTHONDONTWRITEBYTECODE, and then every pytest worker and every process a test starts
# compiles the project and rewrites the tests' asserts again: about a minute of a run.
unexport PYTHONDONTWRITEBYTECODE
PYTEST := -m pytest -q -n auto --maxprocesses 4 --dist loadgroup --durations 15
VENV ?= .venv
STAMP := $(VENV)/.installed-stamp

.PHONY: demo test test-quick test-deps bench screenshot clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/skinet demo

# The one-command live demo: the paper's unassisted run in real time through the whole chain,
# the dashboard on http://127.0.0.1:$(PORT)/ (LIVE_ARGS adds options, e.g. --speed 4 --linger 0).
PORT ?= 8080
live: $(STAMP)
	$(VENV)/bin/skinet demo --live --dashboard $(PORT) $(LIVE_ARGS)

test-deps:
	scripts/install-test-deps.sh

test: $(STAMP) test-deps
	$(VENV)/bin/python $(PYTEST)

test-quick: $(STAMP)
	$(VENV)/bin/python $(PYTEST) -m "not slow"

screenshot: $(STAMP)
	$(VENV)/bin/python tests/screenshot.py -o docs/dashboard.png

bench: $(STAMP)
	for b in benchmarks/bench_*.py; do $(VENV)/bin/python $$b || exit 1; done

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis docker/wheels
