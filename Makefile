# Fresh-machine entry points: `make demo` (the main job) and `make test` (the test suite).
# Each installs what it needs into .venv. torch is pinned first, with the exact version,
# so that pip takes the local CPU wheel instead of pulling several GB of CUDA packages.

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.nnfmu-installed

.PHONY: setup demo test docs clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e '.[dev,tune,search]'
	touch $(STAMP)

demo: setup
	$(VENV)/bin/nnfmu demo

test: setup
	$(PY) -m pytest -q

# the documentation site (docs/, mkdocs.yml) into site/; --strict: a broken link or reference fails
docs: setup
	DISABLE_MKDOCS_2_WARNING=true NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache demo-output site
