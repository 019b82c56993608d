# The two set-up commands of the README. Each installs what it needs, then runs.
#   make demo   - install the package and run the main job on the bundled default wing
#   make test   - install the package with its test extras and run the test suite
PYTHON ?= python3
DEMO_DIR ?= demo_out
PYTEST_ARGS ?=

.PHONY: install install-test install-system demo test test-fast

# System packages (Debian): the CalculiX solver (ccx) for the structural analysis, and EGL with
# Mesa's software renderer for off-screen pictures (pyvista/VTK). Installed only when missing.
SYSTEM_PACKAGES = calculix-ccx libegl1 libgl1-mesa-dri
install-system:
	@if ! command -v ccx >/dev/null 2>&1 || ! ldconfig -p | grep -q 'libEGL.so.1' \
	    || ! ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1; then \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(SYSTEM_PACKAGES) >/dev/null; fi

install: install-system
	$(PYTHON) -m pip install --quiet -e .

install-test: install-system
	$(PYTHON) -m pip install --quiet -e ".[test]"

demo: install
	$(PYTHON) -m shellmesh_mdao.cli demo --out-dir $(DEMO_DIR)

test: install-test
	$(PYTHON) -m pytest $(PYTEST_ARGS)

test-fast: install-test
	$(PYTHON) -m pytest -m "not slow" $(PYTEST_ARGS)
