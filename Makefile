# Fresh-machine entry points: `make demo` (the main job) and `make test` (the test suite).
# Each installs what it needs into .venv. torch is pinned first, with the exact version,
# so that pip takes the local CPU wheel instead of pulling several GB of CUDA packages.

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.nnfmu-installed

.PHONY: setup demo test docs clean system-packages cross-toolchain

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e '.[dev,tune,search]'
	touch $(STAMP)

demo: setup
	$(VENV)/bin/nnfmu demo

test: setup system-packages cross-toolchain
	$(PY) -m pytest -q

# What the cross-platform FMU tests run binaries with: Wine (Windows), QEMU user mode and Debian's aarch64
# C library (ARM64 Linux). Installed with apt-get where it runs as root; elsewhere those tests skip, naming them.
SYSTEM_PACKAGES := wine wine64 qemu-user libc6-arm64-cross

system-packages:
	@missing=$$(for p in $(SYSTEM_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	if [ -z "$$missing" ]; then exit 0; fi; \
	if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "installing" $$missing "with apt-get (for the cross-platform FMU tests)"; \
	  { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing; } \
	    >/dev/null 2>&1 || echo "could not install" $$missing "- the tests that need them skip and name them"; \
	else echo "not installing" $$missing "(needs apt-get as root) - the tests that need them skip and name them"; fi

# Zig builds each cross target's C library into its cache (~/.cache/zig) on first use, minutes for Windows:
# once here, so that the tests and later exports take seconds. A failure only makes the first export slow.
CROSS_STAMP := $(VENV)/.nnfmu-zig-prepared

cross-toolchain: $(CROSS_STAMP)

$(CROSS_STAMP): $(STAMP)
	-$(PY) -m nnfmu.export.platforms && touch $(CROSS_STAMP)

# the documentation site (docs/, mkdocs.yml) into site/; --strict: a broken link or reference fails
docs: setup
	DISABLE_MKDOCS_2_WARNING=true NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache demo-output site
