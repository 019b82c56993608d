"""OpenMDAO component: the smoothing QP.

Core function: the ``smooth`` stage of :mod:`shellmesh_mdao.pipeline` (paper eq. 6-8, steps
projected back onto the skin, member planes and feature curves; no step folds an element).
"""
from __future__ import annotations

from .layout_comp import StageComp

__all__ = ["SmoothComp"]


class SmoothComp(StageComp):
    """Pipeline state -> state after the ``smooth`` stage.

    Discrete input ``state_in``, discrete output ``state``; no partials (discrete). A
    :class:`~shellmesh_mdao.errors.ShellMeshError` of the stage is raised as
    ``om.AnalysisError`` (a failed case, see :mod:`~shellmesh_mdao.components.layout_comp`).
    """

    stages = ("smooth",)
