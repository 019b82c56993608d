"""OpenMDAO component: subdivision to all quads, and the figures a driver can use.

Core function: the ``quad`` stage of :mod:`shellmesh_mdao.pipeline` (quad -> 4, triangle -> 3,
new nodes projected onto their supports, final smoothing pass) and
:func:`shellmesh_mdao.quality.scaled_jacobian`.
"""
from __future__ import annotations

import numpy as np

from ..quality import scaled_jacobian
from .layout_comp import StageComp

__all__ = ["QuadComp"]


class QuadComp(StageComp):
    """Pipeline state -> all-quad shell mesh.

    Discrete outputs ``state`` (after the ``quad`` stage) and ``shell_mesh`` (its
    :class:`~shellmesh_mdao.mesh.ShellMesh`); continuous outputs ``n_nodes`` (nodes used by
    faces), ``n_elements`` (faces) and ``min_scaled_jacobian`` (smallest element scaled
    Jacobian, 1 ideal) for drivers (constraints, DOE responses). These are not
    differentiable with respect to the layout parameters (no partials are declared: the
    inputs are discrete).
    """

    stages = ("quad",)

    def setup(self):
        super().setup()
        self.add_discrete_output("shell_mesh", val=None, desc="the all-quad shell mesh (ShellMesh)")
        self.add_output("n_nodes", val=0.0, desc="number of mesh nodes used by elements")
        self.add_output("n_elements", val=0.0, desc="number of shell elements")
        self.add_output("min_scaled_jacobian", val=0.0, desc="smallest element scaled Jacobian (1 ideal)")

    def set_outputs(self, state, outputs, discrete_outputs) -> None:
        m = state.mesh
        discrete_outputs["shell_mesh"] = m
        used = np.zeros(m.n_points, bool)
        used[m.faces[m.faces >= 0]] = True
        outputs["n_nodes"] = float(used.sum())
        outputs["n_elements"] = float(m.n_faces)
        outputs["min_scaled_jacobian"] = float(scaled_jacobian(m).min()) if m.n_faces else 0.0
