"""shellmesh_mdao: conforming all-quad shell meshes of aircraft skins and internal members.

Stages, in order (one module or subpackage each): load -> layout -> project -> remesh ->
imprint -> members -> split -> merge -> smooth -> quad -> export.

The public API, importable from here::

    from shellmesh_mdao import naca_wing, naca_wing_layout, run_pipeline, write_mesh

    result = run_pipeline(naca_wing(), naca_wing_layout(), 0.1)   # surface, layout, element size
    write_mesh(result.mesh, "wing.bdf")

=====================================  =====================================================
:func:`run_pipeline`                   run the stages up to ``until``; a :class:`PipelineResult`
:class:`PipelineOptions`               solver options (the ``--option`` names of the CLI)
:class:`PipelineResult`, ``STAGES``    the result (mesh, chains, report); the stage names
:func:`run_study`                      run a study config (``shellmesh mesh --config``) and
                                       write its outputs
:class:`ShellMesh`, :func:`concatenate`  the one mesh type between stages
:func:`load_surface`, :func:`load_mesh`  read a surface triangulation / a mesh file
:func:`load_layout`                    read and check a rib/spar layout (docs/layout.md)
:func:`write_mesh`                     .bdf .nas .inp .vtu .msh, by extension
:func:`element_quality`,               per-element metrics; a summary (per component)
:func:`quality_summary`
:func:`check_guarantees`               raise :class:`GuaranteeError` when a final mesh misses a
                                       guarantee (all quads, scaled Jacobian > 0.2, ...);
                                       ``run_pipeline`` refuses such a mesh itself
:func:`naca_wing`,                     the bundled default wing and its layout
:func:`naca_wing_layout`
errors                                 :class:`ShellMeshError` and its subclasses
=====================================  =====================================================

OpenMDAO components are in :mod:`shellmesh_mdao.components`. Names are imported on first use
(PEP 562), so ``import shellmesh_mdao`` loads neither numba nor scipy, OpenMDAO or VTK.
"""
from __future__ import annotations

import importlib

from .errors import (GuaranteeError, ImprintError, InputFileError, LayoutError, MeshValidationError, OutputError,
                     ProjectionError, ShellMeshError, SizeError, SolverError)

__version__ = "0.1.0"

#: Public name -> the module that defines it (imported when the name is first used).
_LAZY = {
    "run_pipeline": "pipeline", "PipelineOptions": "pipeline", "PipelineResult": "pipeline", "STAGES": "pipeline",
    "run_study": "study",
    "ShellMesh": "mesh", "concatenate": "mesh",
    "load_surface": "load", "load_mesh": "load",
    "load_layout": "layout",
    "write_mesh": "export",
    "element_quality": "quality", "quality_summary": "quality",
    "check_guarantees": "guarantees",
    "naca_wing": "geometry", "naca_wing_layout": "geometry",
}

__all__ = sorted(_LAZY) + ["ShellMeshError", "InputFileError", "MeshValidationError", "LayoutError",
                           "ProjectionError", "ImprintError", "SizeError", "OutputError", "SolverError",
                           "GuaranteeError", "__version__"]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value          # later look-ups do not come back here
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
