# Two entry points for a fresh machine (README): `make figure7` and `make test`.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(BIN)/.thinfilm_jax-installed

.PHONY: figure7 test bench setup

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $@

setup: $(STAMP)

figure7: $(STAMP)
	$(BIN)/thinfilm-jax figure7 --out figures

# two pytest-xdist workers (the CI machine has 2 cores); work units: tests/conftest.py
test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile

bench: $(STAMP)
	$(BIN)/thinfilm-jax bench --out figures
