# gainsched — developer entry points (GNU make).
# `make tables` and `make test` are all a fresh checkout needs.

PY   ?= $(shell command -v python3.11 || command -v python3)
VENV  = .venv
BIN   = $(VENV)/bin
STAMP = $(VENV)/.stamp

PYTEST_ARGS ?=

.PHONY: venv lint test tables bench paper clean distclean

# (Re)create the virtualenv whenever the dependency pins change.
$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	$(BIN)/python -m pip install -e '.[dev,dask]'
	touch $@

venv: $(STAMP)

lint: $(STAMP)
	$(BIN)/ruff check gainsched tests bench

test: $(STAMP) lint
	$(BIN)/python -m pytest $(PYTEST_ARGS)

tables: $(STAMP)
	$(BIN)/gainsched build configs/paper.toml -o tables/

bench: $(STAMP)
	$(BIN)/python -m bench

paper: $(STAMP)
	$(BIN)/gainsched paper -o reports/paper

clean:
	rm -rf build dist *.egg-info .pytest_cache .ruff_cache
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV)
