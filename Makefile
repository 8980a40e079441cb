# Quick start: `make demo` runs a render-and-solve demo, `make test` runs the tests.
# `make test-fast`: the tests that neither render nor are slow (markers in pyproject.toml), under a minute.
# `make docs`: the documentation site (docs/_build/html/index.html): pages, API reference, gallery.
# Each bootstraps its own virtual environment in .venv (Python 3.11+, pip).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-fast venv clean bench docs

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	@# one OpenCV wheel only (opencv-contrib-python-headless): the wheels share the cv2 folder, so
	@# an older venv with another one is cleared of all of them before the install
	@if $(PY) -m pip show -q opencv-python-headless opencv-python opencv-contrib-python >/dev/null 2>&1; then \
	  $(PY) -m pip uninstall -y -q opencv-python-headless opencv-python opencv-contrib-python opencv-contrib-python-headless; fi
	@echo "installing svgs-sim and its dependencies (a few minutes on a fresh machine; pip lists what it collects) ..."
	$(PY) -m pip install --progress-bar off -e ".[render,test,dask,docs,orbit,basilisk]"
	$(PY) -m svgs_sim.cli.compile_kernels
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(PY) -m svgs_sim.cli.demo

# The full run on TEST_WORKERS pytest-xdist processes, each test file on one of them (its module
# fixtures made once), the heaviest files handed out first (tests/durations.json, in the order
# tests/conftest.py puts them; tools/test_durations.py writes it), each worker's numba threads
# its share of the cores (tests/conftest.py). Three on two cores: many tests wait on
# subprocesses, process pools and start-up, so a third worker fills the gaps (docs/performance.md,
# issue 40: 807 s serial, 581 s on two workers, 502 s on three; 433 s on four after the third
# round, against 398-409 s on three). TEST_WORKERS=0 runs them in this process, one after another.
TEST_WORKERS ?= 3

test: $(STAMP)
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder

test-fast: $(STAMP)
	$(PY) -m pytest -q -m "not slow and not render"

DOCS_STAMP := $(VENV)/.installed-docs

$(DOCS_STAMP): $(STAMP)
	$(PY) -m pip install --progress-bar off -e ".[docs]"
	touch $(DOCS_STAMP)

# -W: a warning (a broken link between the pages, a page missing from the index, a docstring
# Sphinx cannot read) fails the build
docs: $(DOCS_STAMP)
	$(PY) -m sphinx -b html -W --keep-going -q docs docs/_build/html
	@echo "docs: docs/_build/html/index.html"

bench: $(STAMP)
	for b in benchmarks/bench_*.py; do $(PY) $$b || exit 1; done

clean:
	rm -rf $(VENV) build *.egg-info docs/_build docs/api/generated docs/auto_gallery docs/sg_execution_times.rst
