"""The package's layout holds: no module over ~1,000 lines, no import cycle, data flowing one way
through the stages, core helpers below every stage, no private name imported across modules.

Scanned with ``ast`` (nothing is imported), so a new module or subpackage is checked as soon as it
exists.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "shellmesh_mdao"
#: the stages in the order data flows through them (docs/architecture.md)
STAGE_ORDER = ("load", "layout", "project", "remesh", "imprint", "members", "split", "merge", "smooth", "quad",
               "export")
#: modules every stage may use: the mesh type, errors, shared helpers, measures
BELOW_STAGES = ("errors", "mesh", "core", "quality", "families", "options")
#: modules that drive the stages; no stage and no core helper imports them
ABOVE_STAGES = ("pipeline", "components", "cli", "study", "benchmarks", "guarantees", "report", "render",
                "analysis", "config", "morph")
MAX_LINES = 1000


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        rel = path.relative_to(PACKAGE_DIR.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _resolve(modname: str, path: Path, node: ast.ImportFrom) -> list[str]:
    """Absolute names of the package modules an ``from ... import ...`` brings in."""
    if node.level:
        base = modname.split(".")
        if path.name != "__init__.py":
            base = base[:-1]
        base = base[:len(base) - (node.level - 1)]
        target = ".".join(base + ([node.module] if node.module else []))
    else:
        target = node.module or ""
    if not target.startswith("shellmesh_mdao"):
        return []
    found = []
    for a in node.names:                      # "from . import kernels" imports a module
        sub = f"{target}.{a.name}"
        found.append(sub if sub in MODULES else target)
    return found


def _imports(modname: str, path: Path, top_level_only: bool) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    if top_level_only:                        # module-level, including under if/try at the top
        nodes = [n for stmt in tree.body for n in ast.walk(stmt)
                 if not isinstance(stmt, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))]
    out = set()
    for n in nodes:
        if isinstance(n, ast.ImportFrom):
            out.update(_resolve(modname, path, n))
        elif isinstance(n, ast.Import):
            out.update(a.name for a in n.names if a.name.startswith("shellmesh_mdao"))
    return {m for m in out if m in MODULES and m != modname}


def _top(modname: str) -> str:
    parts = modname.split(".")
    return parts[1] if len(parts) > 1 else ""


@pytest.mark.parametrize("modname", sorted(MODULES))
def test_module_size(modname):
    n = len(MODULES[modname].read_text(encoding="utf-8").splitlines())
    assert n <= MAX_LINES, f"{modname} has {n} lines (at most {MAX_LINES}): split it by concern"


def test_no_import_cycle():
    """Module-level imports between the package's modules form no cycle (a package's ``__init__``
    importing its own submodules is the one direction allowed)."""
    graph = {m: _imports(m, p, top_level_only=True) for m, p in MODULES.items()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                cycle = stack[stack.index(n):] + [n]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if n not in state:
                visit(n)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_data_flows_one_way():
    """No stage imports a later stage (at any level, lazy imports included); core helpers and the
    modules below the stages import no stage; no stage imports the drivers above it."""
    bad = []
    for m, p in MODULES.items():
        me = _top(m)
        for n in _imports(m, p, top_level_only=False):
            other = _top(n)
            if other == me:
                continue
            if me in STAGE_ORDER and other in STAGE_ORDER and STAGE_ORDER.index(other) > STAGE_ORDER.index(me):
                bad.append(f"{m} (stage {me}) imports {n} (later stage {other})")
            if me in BELOW_STAGES and other in STAGE_ORDER:
                bad.append(f"{m} (shared helper) imports {n} (stage {other})")
            if (me in STAGE_ORDER or me in BELOW_STAGES) and other in ABOVE_STAGES:
                bad.append(f"{m} imports {n}, which drives the stages")
    assert not bad, "\n".join(sorted(bad))


@pytest.mark.parametrize("modname", sorted(MODULES))
def test_no_private_name_across_modules(modname):
    """``from .other import _name`` or ``other._name`` couples a module to another's internals."""
    path = MODULES[modname]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith("shellmesh_mdao")):
            bad += [f"line {node.lineno}: import {a.name}" for a in node.names
                    if a.name.startswith("_") and not a.name.startswith("__")]
            bad += [f"line {node.lineno}: module {node.module}" for part in (node.module or "").split(".")
                    if part.startswith("_") and not part.startswith("__")]
    assert not bad, f"{modname} imports private names of other modules: {bad}"


def test_every_stage_has_its_module():
    """A newcomer finds each step of the paper by its name: one module or subpackage per stage."""
    missing = [s for s in STAGE_ORDER if f"shellmesh_mdao.{s}" not in MODULES]
    assert not missing, f"no module or subpackage for stage(s) {missing}"
