# nidar_mi — set-up, demo and tests.
#   make demo   set everything up, then render scenes/street.xml into out/street
#   make test   set everything up, then run the test suite
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.nidar_setup_done
SCENE  ?= scenes/street.xml
OUT    ?= out/street

.PHONY: setup demo test lint fixtures bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml scripts/setup.sh
	PYTHON=$(PYTHON) VENV=$(VENV) bash scripts/setup.sh
	touch $(STAMP)

demo: setup
	$(PY) -m nidar_mi.render $(SCENE) -o $(OUT)

test: setup
	$(PY) -m pytest -q

lint: setup
	$(VENV)/bin/ruff check nidar_mi plugins tests benchmarks
	$(VENV)/bin/ruff format --check nidar_mi plugins tests benchmarks

fixtures: setup
	$(PY) tests/golden/regenerate.py

bench: setup
	$(PY) -m pip install -q -e ".[bench]"
	$(PY) benchmarks/bench_scan.py

clean:
	rm -rf out build *.egg-info
