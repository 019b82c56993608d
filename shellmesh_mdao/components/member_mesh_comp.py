"""OpenMDAO component: mesh every rib and spar on the skin's chain nodes.

Core function: the ``members`` stage of :mod:`shellmesh_mdao.pipeline` (planar Delaunay or
Coons patch per member, T and X junctions): one conforming triangle mesh of skin and members.
"""
from __future__ import annotations

from .layout_comp import StageComp

__all__ = ["MemberMeshComp"]


class MemberMeshComp(StageComp):
    """Pipeline state -> state after the ``members`` stage.

    Discrete input ``state_in``, discrete output ``state``; no partials (discrete). A
    :class:`~shellmesh_mdao.errors.ShellMeshError` of the stage is raised as
    ``om.AnalysisError`` (a failed case, see :mod:`~shellmesh_mdao.components.layout_comp`).
    """

    stages = ("members",)
