# sb3-swirl: `make demo` and `make test` set everything up first (idempotent .venv).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install lock demo demo-acrobot demo-linecutting demo-tensioning demo-fetchpush table1 test test-slow bench lint format clean

install: $(STAMP)

$(STAMP): pyproject.toml wrappers/pyproject.toml constraints.txt Makefile
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	# torch first, pinned: an unpinned torch pulls a multi-GB CUDA build
	$(BIN)/python -m pip install --quiet -c constraints.txt torch==2.13.0
	$(BIN)/python -m pip install --quiet -c constraints.txt -e ./wrappers -e ".[zoo,render,robosuite,fetch,ray,dev]"
	# imitation pins old SB3/gymnasium; its data types work with ours (see NOTES-stack.md)
	$(BIN)/python -m pip install --quiet --no-deps imitation==1.0.1 seals==0.2.1
	touch $(STAMP)

# pin what the current .venv holds (torch's local +cpu tag left to the index)
lock:
	head -3 constraints.txt > constraints.new
	$(BIN)/python -m pip freeze --exclude-editable | sed 's/+cpu$$//' >> constraints.new
	mv constraints.new constraints.txt

demo: install
	$(BIN)/sb3-swirl demo parking

demo-acrobot: install
	$(BIN)/sb3-swirl demo acrobot

demo-linecutting: install
	$(BIN)/sb3-swirl demo linecutting

demo-tensioning: install
	$(BIN)/sb3-swirl demo tensioning

demo-fetchpush: install
	$(BIN)/sb3-swirl demo fetchpush

table1: install
	$(BIN)/sb3-swirl reproduce table1

test: install
	$(BIN)/ruff check . && $(BIN)/ruff format --check .
	$(BIN)/python -m pytest -n 2 -q tests --doctest-modules wrappers/swirl_wrappers sb3_swirl

test-slow: install
	$(BIN)/python -m pytest -m slow -q

bench: install
	$(BIN)/python benchmarks/run_all.py $(ARGS)

lint: install
	$(BIN)/ruff check . && $(BIN)/ruff format --check .

format: install
	$(BIN)/ruff format . && $(BIN)/ruff check --fix .

clean:
	rm -rf $(VENV) results .pytest_cache .ruff_cache
