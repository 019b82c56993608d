"""The public API: what ``shellmesh_mdao`` and ``shellmesh_mdao.components`` export, an ``__all__``
in every public module, no private name imported across modules, and a cheap start-up (importing
the package or asking the CLI for help loads none of the heavy libraries)."""
import ast
import importlib
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import shellmesh_mdao
from shellmesh_mdao import errors

PACKAGE_DIR = Path(shellmesh_mdao.__file__).parent

#: What the package promises at its top level (README, docs/getting_started.md).
TOP_LEVEL = ["run_pipeline", "PipelineOptions", "PipelineResult", "STAGES", "ShellMesh", "load_surface",
             "load_mesh", "load_layout", "write_mesh", "element_quality", "quality_summary", "check_guarantees",
             "naca_wing", "naca_wing_layout", "run_study", "__version__"]

COMPONENTS = ["ShellMeshGroup", "MassComp", "CalculixShellAnalysis", "LayoutComp", "ProjectionComp", "ImprintComp",
              "MemberMeshComp", "SplitComp", "MergeComp", "SmoothComp", "QuadComp", "MorphComp"]

#: Libraries that take a noticeable part of a second to import; start-up must not pay for them.
HEAVY = ("numba", "openmdao", "pyvista", "vtk", "matplotlib", "gmsh")


def _error_classes():
    return sorted(n for n, v in vars(errors).items() if isinstance(v, type) and issubclass(v, Exception)
                  and v.__module__ == errors.__name__)


def _public_modules():
    """Every module of the package whose dotted name has no part starting with ``_``."""
    names = ["shellmesh_mdao"]
    for info in pkgutil.walk_packages([str(PACKAGE_DIR)], prefix="shellmesh_mdao."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names)


def _source_files():
    return sorted(p for p in PACKAGE_DIR.rglob("*.py") if "__pycache__" not in p.parts)


def test_top_level_exports_everything_promised():
    missing = [n for n in TOP_LEVEL + _error_classes() if n not in shellmesh_mdao.__all__]
    assert not missing, f"shellmesh_mdao.__all__ lacks {missing}"


@pytest.mark.parametrize("name", sorted(set(shellmesh_mdao.__all__)))
def test_top_level_name_resolves(name):
    assert getattr(shellmesh_mdao, name) is not None
    assert name in dir(shellmesh_mdao)


def test_top_level_names_are_the_modules_own():
    from shellmesh_mdao import load, mesh, pipeline, study

    assert shellmesh_mdao.run_pipeline is pipeline.run_pipeline
    assert shellmesh_mdao.ShellMesh is mesh.ShellMesh
    assert shellmesh_mdao.load_surface is load.load_surface
    assert shellmesh_mdao.run_study is study.run_study
    assert shellmesh_mdao.SizeError is errors.SizeError
    with pytest.raises(AttributeError):
        shellmesh_mdao.no_such_name


def test_components_export_every_component():
    import shellmesh_mdao.components as comps

    assert sorted(comps.__all__) == sorted(COMPONENTS)
    for name in comps.__all__:
        assert isinstance(getattr(comps, name), type), name
        assert name in dir(comps)


@pytest.mark.parametrize("modname", _public_modules())
def test_public_module_has_a_complete_all(modname):
    mod = importlib.import_module(modname)
    names = getattr(mod, "__all__", None)
    assert names is not None, f"{modname} has no __all__"
    assert len(set(names)) == len(names), f"{modname}.__all__ repeats a name"
    missing = [n for n in names if not hasattr(mod, n)]
    assert not missing, f"{modname}.__all__ names {missing}, which it does not define"


@pytest.mark.parametrize("path", _source_files(), ids=lambda p: str(p.relative_to(PACKAGE_DIR)))
def test_no_private_name_imported_from_another_module(path):
    """``from .other import _name`` couples a module to another's internals: give the helper a
    public name instead (a module's own private names, and ``__future__``/``__version__``, are fine)."""
    bad = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and (node.level > 0 or (node.module or "").startswith("shellmesh_mdao")):
            bad += [f"line {node.lineno}: from {'.' * node.level}{node.module or ''} import {a.name}"
                    for a in node.names if a.name.startswith("_") and not a.name.startswith("__")]
    assert not bad, f"{path.name} imports private names of other modules: {bad}"


def _imported_modules(args):
    """The top-level packages a fresh ``python -X importtime ARGS`` process imports."""
    r = subprocess.run([sys.executable, "-X", "importtime", *args], capture_output=True, text=True,
                       cwd=PACKAGE_DIR.parent, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    mods = set()
    for line in r.stderr.splitlines():
        if line.startswith("import time:") and line.count("|") == 2:
            mods.add(line.rsplit("|", 1)[1].strip().split(".")[0])
    assert "shellmesh_mdao" in mods        # the check looks at the right process
    return mods


@pytest.mark.parametrize("args", [
    ["-c", "import shellmesh_mdao; shellmesh_mdao.__version__; shellmesh_mdao.ShellMeshError"],
    ["-c", "from shellmesh_mdao import ShellMesh, STAGES"],
    ["-m", "shellmesh_mdao.cli", "--help"],
], ids=["import", "mesh-and-stages", "cli-help"])
def test_start_up_imports_no_heavy_library(args):
    heavy = sorted(set(HEAVY) & _imported_modules(args))
    assert not heavy, f"python {' '.join(args)} imports {heavy}"


def test_run_study_checks_the_config_before_meshing(tmp_path):
    from shellmesh_mdao.config import ConfigError, StudyConfig

    cfg = StudyConfig(surface=tmp_path / "wing.vtu", size=0.1, out=[tmp_path / "wing.bdf"])
    with pytest.raises(ConfigError, match="no layout given"):
        shellmesh_mdao.run_study(cfg, quiet=True)
    assert not list(tmp_path.iterdir())
