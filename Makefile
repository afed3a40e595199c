# Two entry points on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# Iterative solvers are single-threaded by design; threaded BLAS only adds noise.
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1
export MPLBACKEND ?= Agg

.PHONY: demo test clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed-demo: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[plot]'
	touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test,plot]'
	touch $@

demo: $(VENV)/.installed-demo
	$(BIN)/lubcontact demo --out out

# Two test workers (pytest-xdist), one per core of CI's machine (docs/guide/install.md).
test: $(VENV)/.installed-test
	$(BIN)/ruff check lubcontact tests examples
	$(BIN)/python -m pytest -q -n 2

clean:
	rm -rf $(VENV) out build *.egg-info
