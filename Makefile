# Two commands on a fresh machine with python3: `make demo` and `make test`.
# Both create a local virtual environment (.venv) with everything they need on first use.
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed

.PHONY: demo test test-slow bench clean venv

$(STAMP): pyproject.toml
	@sh tools/sysdeps.sh
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test,plot,store,render,sweep]"
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/femodes demo

test: $(STAMP)
	$(BIN)/python -m pytest -q

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow || [ $$? -eq 5 ]

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_models.py

clean:
	rm -rf $(VENV) out .pytest_cache
