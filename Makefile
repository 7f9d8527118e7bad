# Each target sets itself up: a virtual environment in .venv with loosefit installed.
PYTHON ?= python3.11
VENV := .venv
STAMP := $(VENV)/.installed

CHROMIUM := /usr/bin/chromium
SUDO := $(if $(filter 0,$(shell id -u)),,sudo)

.PHONY: demo test test-fast clean package-check viewer-vendor

# pip installs without compiling, then compileall byte-compiles on every core (pip's own step compiles one file
# after another, the larger part of the install). A few third-party files written for newer Pythons do not
# compile, as under pip, hence the ignored status.
$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "need $(PYTHON) (Python 3.11)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --upgrade pip >/dev/null
	$(VENV)/bin/python -m pip install --no-compile -e ".[dev]"
	$(VENV)/bin/python -m compileall -q -j 0 "$$($(VENV)/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')" >/dev/null || true
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/loosefit demo --out demo_out

# The viewer's browser tests drive Debian's Chromium through Playwright (no browser download).
$(CHROMIUM):
	$(SUDO) apt-get update
	DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y chromium

# Two test processes (one test module each at a time, so module fixtures are built once): 676 s for the whole suite on
# two idle cores (benchmarks/test_suite_timing.py -> benchmarks/results/test-suite-timing.json).
test: $(STAMP) $(CHROMIUM)
	$(VENV)/bin/python -m pytest -q -n 2 --dist loadscope tests

# The fast subset while developing (tests/fast_tests.txt, chosen by scripts/mark_fast_tests.py).
test-fast: $(STAMP)
	$(VENV)/bin/python -m pytest -q -n 2 --dist loadscope -m "not slow" tests

# CI step of packaging: build the wheel, install it into a fresh venv, check the extras (about 10 s).
package-check: $(STAMP)
	$(VENV)/bin/python scripts/check_wheel.py

# three.js and uPlot for `loosefit view`, pinned, from the npm registry into src/loosefit/viz/static/vendor/
# (committed: installing loosefit needs no npm; run this only to change a version).
viewer-vendor:
	scripts/fetch_viewer_vendor.sh

clean:
	rm -rf $(VENV) demo_out
