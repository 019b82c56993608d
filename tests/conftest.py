import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
GEOMETRY = SHARED / "geometry"


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
