import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
GEOMETRY = SHARED / "geometry"


def _have_ccx() -> bool:
    from shellmesh_mdao.analysis import find_ccx
    from shellmesh_mdao.errors import SolverError

    try:
        find_ccx()
        return True
    except SolverError:
        return False


#: skip marker for tests that run CalculiX (``from conftest import needs_ccx``)
needs_ccx = pytest.mark.skipif(not _have_ccx(), reason="CalculiX 'ccx' is not installed (apt-get install "
                                                       "calculix-ccx); CI has it")


@pytest.fixture(autouse=True)
def _openmdao_reports_elsewhere(tmp_path, monkeypatch):
    """OpenMDAO writes each Problem's reports under OPENMDAO_WORKDIR: keep them out of the repo."""
    monkeypatch.setenv("OPENMDAO_WORKDIR", str(tmp_path))


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: heavy case (whole corpus, large meshes); run with -m slow")


@pytest.fixture(scope="session")
def geometry_dir() -> Path:
    if not (GEOMETRY / "manifest.json").is_file():
        pytest.fail(f"benchmark corpus not found at {GEOMETRY}: check out ../shared beside the repo")
    return GEOMETRY


@pytest.fixture(scope="session")
def manifest(geometry_dir) -> dict:
    return json.loads((geometry_dir / "manifest.json").read_text())
