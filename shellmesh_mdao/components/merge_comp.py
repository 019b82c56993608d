"""OpenMDAO component: the triangle-merging integer program.

Core function: the ``merge`` stage of :mod:`shellmesh_mdao.pipeline` (HiGHS MIP, paper eq. 4-5).
"""
from __future__ import annotations

from .layout_comp import StageComp

__all__ = ["MergeComp"]


class MergeComp(StageComp):
    """Pipeline state -> state after the ``merge`` stage.

    Discrete input ``state_in``, discrete output ``state``; no partials (discrete). A
    :class:`~shellmesh_mdao.errors.ShellMeshError` of the stage is raised as
    ``om.AnalysisError`` (a failed case, see :mod:`~shellmesh_mdao.components.layout_comp`).
    """

    stages = ("merge",)
