"""OpenMDAO wrappers, one component per file (OpenAeroStruct style).

Each component is a thin wrapper around the same core function as the CLI stage or the
analysis of the same name: ``MassComp`` (mass_comp.py) and ``CalculixShellAnalysis``
(calculix_comp.py) wrap :mod:`shellmesh_mdao.analysis` (see docs/analysis.md).
"""
