# Each target creates or reuses .venv, installs the project, and runs.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# pytest-xdist workers for `make test`: auto (one per core) or a number; 0 runs in one process.
TEST_WORKERS ?= auto
export TRAJPREF_DATA ?= $(abspath ../shared/data)

.PHONY: install demo test lint format clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/python -m trajpref.demo --out out/demo

test: $(STAMP)
	PYTHONPATH=src $(BIN)/lint-imports
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS)
	$(BIN)/ruff check .

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache
