"""OpenMDAO wrappers, one component per file (OpenAeroStruct style); see docs/openmdao.md.

Stage components, each calling the pipeline stage of the same name (:mod:`shellmesh_mdao.pipeline`):
``LayoutComp`` (layout_comp.py), ``ProjectionComp`` (projection_comp.py), ``ImprintComp``
(imprint_comp.py: remesh + imprint), ``MemberMeshComp`` (member_mesh_comp.py), ``SplitComp``,
``MergeComp``, ``SmoothComp``, ``QuadComp``; ``ShellMeshGroup`` (group.py) wires them in order.
Analysis: ``MassComp`` (mass_comp.py) and ``CalculixShellAnalysis`` (calculix_comp.py) wrap
:mod:`shellmesh_mdao.analysis` (docs/analysis.md).
"""
