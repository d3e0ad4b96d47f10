# Fresh-machine entry points: `make demo` (the main job) and `make test` (the test suite).
# Each installs what it needs into .venv. torch is pinned first, with the exact version,
# so that pip takes the local CPU wheel instead of pulling several GB of CUDA packages.

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.nnfmu-installed

.PHONY: setup demo test docs clean system-packages cross-toolchain

# setup: the project in .venv, and the system packages the test suite runs FMU binaries with
setup: $(STAMP) system-packages

PROJECT := -e '.[dev,tune,search]'
# A registry can fail for a moment: each install is tried a second time after a pause, without --quiet, so that
# a lasting failure prints pip's own reason.
PIP_INSTALL = $(PY) -m pip install --quiet $(1) || \
	{ echo "make setup: pip install $(1) failed; trying once more in 20 s"; sleep 20; $(PY) -m pip install $(1); }

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(call PIP_INSTALL,--upgrade pip)
	$(call PIP_INSTALL,torch==2.13.0)
	$(call PIP_INSTALL,$(PROJECT))
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/nnfmu demo

# two workers (pytest-xdist): the suite's modules split over the two cores of the CI machine
TEST_WORKERS ?= 2

test: setup cross-toolchain
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadgroup

# What the FMU tests run binaries with: Wine (the Windows DLL), QEMU user mode (qemu-aarch64 for the ARM64
# library, with Debian's aarch64 C library; qemu-x86_64 for an x86-64 CPU without AVX) - Debian packages,
# installed with apt-get as root (or through passwordless sudo); apt-get update runs when an install fails
# without it. Where that cannot be done, this says why, and the tests that need them skip, naming them.
SYSTEM_PACKAGES := wine wine64 qemu-user libc6-arm64-cross
NO_SYSTEM_PACKAGES := the tests that need them skip and name them

system-packages:
	@missing=$$(for p in $(SYSTEM_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q 'ok installed' || echo $$p; done); \
	missing=$$(echo $$missing); [ -z "$$missing" ] && exit 0; \
	if ! command -v apt-get >/dev/null 2>&1; then \
	  echo "make setup: cannot install $$missing: no apt-get on this machine; $(NO_SYSTEM_PACKAGES)"; exit 0; fi; \
	if [ "$$(id -u)" = 0 ]; then as_root=; \
	elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then as_root="sudo -n"; \
	else echo "make setup: cannot install $$missing: apt-get needs root (run 'sudo make system-packages'); \
	$(NO_SYSTEM_PACKAGES)"; exit 0; fi; \
	echo "make setup: installing $$missing with apt-get (the FMU tests run binaries with them)"; \
	log=$$(mktemp); \
	apt_install() { $$as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
	  $$missing >>$$log 2>&1; }; \
	apt_install || { echo "make setup: running apt-get update"; $$as_root apt-get update -qq >>$$log 2>&1; \
	  apt_install; } || echo "make setup: could not install $$missing: apt-get said: $$(tail -n 1 $$log); \
	$(NO_SYSTEM_PACKAGES)"; rm -f $$log

# Zig builds each cross target's C library into its cache (~/.cache/zig) on first use, minutes for Windows:
# once here, so that the tests and later exports take seconds. A failure only makes the first export slow.
CROSS_STAMP := $(VENV)/.nnfmu-zig-prepared

cross-toolchain: $(CROSS_STAMP)

$(CROSS_STAMP): $(STAMP)
	-$(PY) -m nnfmu.export.prepare_zig && touch $(CROSS_STAMP)

# the documentation site (docs/, mkdocs.yml) into site/; --strict: a broken link or reference fails
docs: setup
	DISABLE_MKDOCS_2_WARNING=true NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache demo-output site
