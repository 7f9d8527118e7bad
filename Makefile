# Each target sets itself up: a virtual environment in .venv with loosefit installed.
PYTHON ?= python3.11
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: demo test clean package-check

$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "need $(PYTHON) (Python 3.11)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --upgrade pip >/dev/null
	$(VENV)/bin/python -m pip install -e ".[dev]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/loosefit demo --out demo_out

test: $(STAMP)
	$(VENV)/bin/python -m pytest -q tests

# CI step of packaging: build the wheel, install it into a fresh venv, check the extras (about 10 s).
package-check: $(STAMP)
	$(VENV)/bin/python scripts/check_wheel.py

clean:
	rm -rf $(VENV) demo_out
