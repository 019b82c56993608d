# The two set-up commands of the README. Each installs what it needs, then runs.
#   make demo   - install the package and run the main job on the bundled default wing (mesh, pictures,
#                 report; then the CalculiX wing-box analysis through OpenMDAO)
#   make test   - install the package with its test extras and run the test suite (2 processes;
#                 PYTEST_WORKERS=0 for one)
PYTHON ?= python3
DEMO_DIR ?= demo_out
PYTEST_ARGS ?=
# test processes (pytest-xdist): 2, one per core of the reference machine; 0 runs the tests in this process
PYTEST_WORKERS ?= 2

.PHONY: install install-test install-system demo test test-fast

# System packages (Debian): the CalculiX solver (ccx) for the structural analysis, EGL with
# Mesa's software renderer for off-screen pictures (pyvista/VTK), and Open MPI for parallel DOE
# studies (mpi4py builds against it). Installed only when missing.
SYSTEM_PACKAGES = calculix-ccx libegl1 libgl1-mesa-dri openmpi-bin libopenmpi-dev
install-system:
	@if ! command -v ccx >/dev/null 2>&1 || ! ldconfig -p | grep -q 'libEGL.so.1' \
	    || ! ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1 || ! command -v mpirun >/dev/null 2>&1; then \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(SYSTEM_PACKAGES) >/dev/null; fi

# -c constraints.txt: the exact versions the tests passed with (pyproject.toml has ranges). The last line
# compiles the numba kernels once (about 45 s; cached next to the package), so that the first run does not
# pay for it
install: install-system
	$(PYTHON) -m pip install --quiet -e . -c constraints.txt
	$(PYTHON) -c "import shellmesh_mdao.kernels as k; k.warm_up()"

install-test: install-system
	$(PYTHON) -m pip install --quiet -e ".[test]" -c constraints.txt
	$(PYTHON) -c "import shellmesh_mdao.kernels as k; k.warm_up()"

demo: install
	$(PYTHON) -m shellmesh_mdao.cli demo --out-dir $(DEMO_DIR)
	$(PYTHON) run_scripts/wingbox_analysis.py --out-dir $(DEMO_DIR)/wingbox_analysis

test: install-test
	$(PYTHON) -m pytest -n $(PYTEST_WORKERS) $(PYTEST_ARGS)

test-fast: install-test
	$(PYTHON) -m pytest -n $(PYTEST_WORKERS) -m "not slow" $(PYTEST_ARGS)
