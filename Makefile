# The two set-up commands of the README. Each installs what it needs, then runs.
#   make demo   - install the package and run the main job on the bundled default wing
#   make test   - install the package with its test extras and run the test suite
PYTHON ?= python3
DEMO_DIR ?= demo_out
PYTEST_ARGS ?=

.PHONY: install install-test install-system demo test test-fast

# System packages: the CalculiX solver (ccx) for the structural analysis.
install-system:
	@command -v ccx >/dev/null 2>&1 || (apt-get update -qq && apt-get install -y -qq calculix-ccx >/dev/null)

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
