# Two commands a new user needs: `make serve` and `make test`.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
HOST ?= 127.0.0.1
PORT ?= 8000
DATA_DIR ?= ../shared/data
export MOTION_DATA_DIR ?= $(DATA_DIR)

.PHONY: setup serve test lint unit clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

# Serving needs no torch; tests and training do.
$(VENV)/.serve: pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[serve]"
	touch $@

$(VENV)/.dev: pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[serve,train,dev]"
	touch $@ $(VENV)/.serve

setup: $(VENV)/.dev

serve: $(VENV)/.serve
	$(PY) -m service --host $(HOST) --port $(PORT)

lint: $(VENV)/.dev
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

test: $(VENV)/.dev
	$(PY) -m ruff check .
	$(PY) -m pytest -q

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
