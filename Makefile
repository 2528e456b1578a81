# The README's two commands: `make run` (the main job on the default preset)
# and `make test`. Both build .venv and install what the project needs first.
VENV  := .venv
BIN   := $(VENV)/bin
STAMP := $(VENV)/.installed
# Debian packages: libLLVM 19 for drjit's CPU backend (LLVM 15 cannot compile its kernels).
DEBS  := libllvm19
CORES ?= all

# snakemake and pytest come from the venv (the rules themselves run the
# project through the interpreter that runs snakemake).
export PATH := $(abspath $(BIN)):$(PATH)

.PHONY: run test lint explore setup debs

# setup's two parts, the Python install and the Debian packages (a fresh
# machine's apt-get), may run at once.
MAKEFLAGS += --jobs=2

# The headline target: Table 5 (the 1D CNN under five splits) on the demo preset.
run: setup
	snakemake --cores $(CORES) results/table5.csv

# One pytest worker per core, a test file per worker (module fixtures such as
# the tiny DAG run are built once): the end-to-end runs overlap with each
# other and with the unit tests (tests/conftest.py collects them first;
# --no-loadscope-reorder keeps that order, where xdist would hand out the
# files with the most tests first and leave the one-test SLURM run to the end).
test: setup lint
	python -m pytest -n auto --dist loadfile --no-loadscope-reorder

# The style holds without anyone policing it: ruff (lint, format) on the
# Python, snakefmt on the workflow, import-linter's layer contracts on the
# package; settings in pyproject.toml.
lint: setup
	ruff check src tests scripts examples
	ruff format --check src tests scripts examples
	snakefmt --check Snakefile rules
	lint-imports

# The capture explorer over results/ (what `make run` built, or any run's):
# http://127.0.0.1:8050 (PORT=..., HOST=... to change).
PORT ?= 8050
HOST ?= 127.0.0.1
explore: setup
	denali explore --results results --host $(HOST) --port $(PORT)

setup: $(STAMP) debs

# pip byte-compiles what it installs (50 of a fresh install's 120 s): where
# PYTHONDONTWRITEBYTECODE is set, as on this project's machines, nothing else
# would, and every process would compile each module it imports anew
# (`--no-compile` took make test from 1,106 to 1,684 CPU-s).
$(STAMP): pyproject.toml
	test -x $(BIN)/python || python3 -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@

debs:
	@scripts/ensure-debs $(DEBS)
