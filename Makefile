# Quick start: `make demo` (installs everything, runs the demo) and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test lint bench clean

install: $(STAMP)

$(STAMP): pyproject.toml client/pyproject.toml constraints.txt scripts/system-deps.sh
	sh scripts/system-deps.sh
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -c constraints.txt -e ./client -e '.[dev]'
	touch $(STAMP)

demo: install
	$(BIN)/tumblescan demo --out demo-output

lint: install
	$(BIN)/ruff check service client tests bench
	$(BIN)/ruff format --check service client tests bench
	$(BIN)/mypy

test: lint
	rm -f .pytest-running; $(BIN)/python -m pytest -q || { rc=$$?; if [ -f .pytest-running ]; then echo "pytest died (exit $$rc) during $$(cat .pytest-running)" >&2; fi; exit $$rc; }

bench: install
	$(BIN)/python -m bench.linescan.accuracy
	$(BIN)/python -m bench.linescan.solvers
	$(BIN)/python -m bench.linescan.speed
	$(BIN)/python -m bench.panel_axis.run
	$(BIN)/python -m bench.service.round_trip
	$(BIN)/python -m bench.service.startup

clean:
	rm -rf $(VENV) demo-output bench/out .pytest_cache .mypy_cache .ruff_cache
