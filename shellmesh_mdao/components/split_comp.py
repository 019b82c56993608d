"""OpenMDAO component: the splitting LP over skin and members.

Core function: the ``split`` stage of :mod:`shellmesh_mdao.pipeline` (HiGHS LP/MIP, paper eq.
1-3; chains, junctions and feature lines are never split) and the node supports.
"""
from __future__ import annotations

from .layout_comp import StageComp

__all__ = ["SplitComp"]


class SplitComp(StageComp):
    """Pipeline state -> state after the ``split`` stage.

    Discrete input ``state_in``, discrete output ``state``; no partials (discrete). A
    :class:`~shellmesh_mdao.errors.ShellMeshError` of the stage is raised as
    ``om.AnalysisError`` (a failed case, see :mod:`~shellmesh_mdao.components.layout_comp`).
    """

    stages = ("split",)
