# Two entry points, each creating the virtual environment and installing the project first:
#   make demo   runs the main job (`dynax demo`) on the embedded default
#   make test   checks style and types (ruff, basedpyright), runs the test suite and builds the docs site strictly
#   make quick  the suite without the minute-long end-to-end runs (marker `heavy`), for iteration
#   make slow   the longer end-to-end variants left out of both (marker `slow`)
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: demo test lint quick slow docs bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed-base: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-dev: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[test,docs,bench]"
	touch $@ $(VENV)/.installed-base

demo: $(VENV)/.installed-base
	$(BIN)/dynax demo

lint: $(VENV)/.installed-dev
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/basedpyright --project pyproject.toml

# --dist loadfile keeps each test file on one worker: its tests share compiled programs in one process instead of
# two workers compiling the same programs at once (two heavy diagnosis files, empty compilation cache: 888 s of CPU
# against 1,180 s with the default scheduling; docs/devdocs/ci_timings.md).
test: lint
	$(BIN)/python -m pytest -n 2 --dist loadfile --durations=30
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

quick: $(VENV)/.installed-dev
	$(BIN)/python -m pytest -n 2 --dist loadfile -m "not slow and not heavy"

slow: $(VENV)/.installed-dev
	$(BIN)/python -m pytest -n 2 --dist loadfile -m slow

docs: $(VENV)/.installed-dev
	$(BIN)/mkdocs serve

bench: $(VENV)/.installed-dev
	$(BIN)/python benchmarks/rollout.py

clean:
	rm -rf $(VENV) site dynax-demo .pytest_cache
