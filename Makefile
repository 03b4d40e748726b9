# Two commands on a fresh machine:
#   make demo   installs the project in .venv and runs the main job on small embedded defaults
#   make test   runs the tests (what CI runs)
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python

.PHONY: install demo test test-extended test-all bench platform-up platform-down

# (setuptools prints an informational notice for every editable install of a mapped package layout: silenced)
$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install -q --upgrade pip
	PYTHONWARNINGS=ignore::UserWarning $(VENV)/bin/pip install -q -e '.[dev]'
	touch $@

install: $(VENV)/.installed

# the main job on small embedded defaults, then the kernels of every kind's first commands compiled (python -m eosp.cli.warmup)
demo: install
	$(PY) jobs/train.py --demo
	$(PY) -m eosp.cli.warmup

# the tests without Ray on two xdist workers, then those with Ray one after another (within 10 minutes on 2 cores);
# the extended suite: Ray services and jobs under faults, training variants, the README's blocks (CI runs both)
test: install
	$(VENV)/bin/ruff check --quiet .
	$(PY) -m pytest -q -n 2 -m "not slow and not ray and not extended" --durations=10
	$(PY) -m pytest -q -m "ray and not slow and not extended" --durations=10

test-extended: install
	$(PY) -m pytest -q -m "extended and not slow" --durations=10

test-all: install
	$(PY) -m pytest -q -m ""

bench: install
	$(PY) benchmarks/bench_graphs.py
	$(PY) benchmarks/bench_env.py

# local Ray head + MLflow server on 127.0.0.1 (state, ports and logs in .platform/; see platform/README.md)
platform-up: install
	scripts/platform-up.sh

platform-down:
	scripts/platform-down.sh
