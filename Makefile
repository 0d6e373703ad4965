# Quick start: `make demo` and `make test` each set themselves up on a fresh clone.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
DOCS_STAMP := $(VENV)/.installed-docs

.PHONY: demo test test-all bench paper docs clean setup

setup: $(STAMP)

# --no-compile: Python writes the bytecode of the modules it imports when it first
# imports them, instead of pip byte-compiling every installed file up front.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --no-compile -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(PY) -m pneubayes.demo --data data --out results/demo

# The fast tier (what CI runs): every test but the statistical and end-to-end ones
# marked slow. `make test-all` runs both tiers. The kernels are compiled first, once
# (`pneubayes compile`), so the two test processes (pytest-xdist) load them from numba's
# cache instead of each compiling its own copy. OMP_WAIT_POLICY=PASSIVE: numba's OpenMP
# threads sleep instead of spinning while they wait, which two processes sharing two
# cores otherwise pay for. PYTHONDONTWRITEBYTECODE emptied: the suite starts dozens of
# interpreters (workers, the command line's subprocesses); with the bytecode written
# once into the environment each imports the package in about 1 s instead of about 4 s
# where a shell sets the variable. OPENBLAS_NUM_THREADS=1: the two test processes already
# fill the two cores; each one's BLAS threads on top of them waited on each other (a
# 4213 x 118 QR took 1.6 s instead of 0.05 s on a busy machine).
TEST_ENV := OMP_WAIT_POLICY=PASSIVE OPENBLAS_NUM_THREADS=1 PYTHONDONTWRITEBYTECODE=

test: $(STAMP)
	PYTHONDONTWRITEBYTECODE= $(VENV)/bin/pneubayes compile --jobs 2
	$(TEST_ENV) $(PY) -m pytest -q -m "not slow" -n 2

test-all: $(STAMP)
	PYTHONDONTWRITEBYTECODE= $(VENV)/bin/pneubayes compile --jobs 2
	$(TEST_ENV) $(PY) -m pytest -q -n 2

# Runs the paper's studies (cached per cell; about 30 min on 2 cores from scratch) and
# assembles paper/report.md from their saved results.
paper: $(STAMP)
	$(PY) experiments/make_paper.py --out results/paper --paper paper --workers 2

# The documentation site (docs/, Sphinx) into results/docs; a warning fails the build.
$(DOCS_STAMP): $(STAMP) pyproject.toml
	$(PY) -m pip install --quiet -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(PY) -m sphinx -b html -W --keep-going -q docs results/docs
	@echo "results/docs/index.html"

bench: $(STAMP)
	$(PY) benchmarks/simulate.py --json results/bench_simulate.json

clean:
	rm -rf $(VENV) results .pytest_cache
