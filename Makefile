# Two commands on a fresh machine with python3: `make demo` and `make test`.
# Both create a local virtual environment (.venv) with everything they need on first use.
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed
# test workers (pytest-xdist): the suite on both cores of the reference machine; JOBS=0 runs it serially.
# --dist loadscope keeps each module on one worker, so its module-scoped fixtures (the demo run,
# shared models and branches) are computed once: 3:07 -> 2:11 on this machine
JOBS   ?= 2
DIST    = $(if $(filter 0,$(JOBS)),,--dist loadscope)

.PHONY: demo test test-slow test-kernels bench bench-backends fast clean venv lint docs typecheck

$(STAMP): pyproject.toml
	@sh tools/sysdeps.sh
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test,plot,store,render,sweep]"
	@sh tools/fast_backends.sh $(BIN)/python
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/femodes demo

test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(JOBS) $(DIST)

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -n $(JOBS) $(DIST) -m slow || [ $$? -eq 5 ]

# the round-off-sensitive tests (marker `numerics`) again under other OpenBLAS kernels, 1 and 2 threads
test-kernels: $(STAMP)
	sh tools/blas_kernels.sh $(BIN)/python

# the documentation site (docs/, Sphinx) into docs/_build/html, warnings as errors; installs the
# docs extra into .venv when it is missing
DOCS_STAMP = $(VENV)/.docs-installed
$(DOCS_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(BIN)/python -m sphinx -b html -W --keep-going -q docs docs/_build/html
	@echo "documentation: docs/_build/html/index.html"

# ruff with the rules of pyproject.toml ([tool.ruff]); `$(BIN)/ruff check --fix .` applies the safe fixes
lint: $(STAMP)
	$(BIN)/python -m ruff check --no-cache .

# mypy on the modules of [tool.mypy] in pyproject.toml (the public face first; tests/test_typecheck.py runs it too)
typecheck: $(STAMP)
	$(BIN)/python -m mypy

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_models.py

# the optional sparse direct back-ends again (CHOLMOD, MUMPS), e.g. after installing their system libraries
fast: $(STAMP)
	@sh tools/sysdeps.sh
	@sh tools/fast_backends.sh $(BIN)/python

bench-backends: $(STAMP)
	$(BIN)/python benchmarks/bench_backends.py

clean:
	rm -rf $(VENV) out .pytest_cache docs/_build
