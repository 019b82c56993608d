"""OpenMDAO wrappers, one component per file (OpenAeroStruct style); see docs/openmdao.md.

Stage components, each calling the pipeline stage of the same name (:mod:`shellmesh_mdao.pipeline`):
``LayoutComp`` (layout_comp.py), ``ProjectionComp`` (projection_comp.py), ``ImprintComp``
(imprint_comp.py: remesh + imprint), ``MemberMeshComp`` (member_mesh_comp.py), ``SplitComp``,
``MergeComp``, ``SmoothComp``, ``QuadComp``; ``ShellMeshGroup`` (group.py) wires them in order.
Layout changes with the connectivity kept: ``MorphComp`` (morph_comp.py: ``x_struct0`` with exact
partials, :mod:`shellmesh_mdao.morph`). Analysis: ``MassComp`` (mass_comp.py) and ``CalculixShellAnalysis``
(calculix_comp.py) wrap :mod:`shellmesh_mdao.analysis` (docs/analysis.md).
"""
from .calculix_comp import CalculixShellAnalysis
from .group import ShellMeshGroup
from .imprint_comp import ImprintComp
from .layout_comp import LayoutComp
from .mass_comp import MassComp
from .member_mesh_comp import MemberMeshComp
from .merge_comp import MergeComp
from .morph_comp import MorphComp
from .projection_comp import ProjectionComp
from .quad_comp import QuadComp
from .smooth_comp import SmoothComp
from .split_comp import SplitComp

__all__ = ["ShellMeshGroup", "LayoutComp", "ProjectionComp", "ImprintComp", "MemberMeshComp", "SplitComp",
           "MergeComp", "SmoothComp", "QuadComp", "MassComp", "CalculixShellAnalysis", "MorphComp"]
