"""OpenMDAO component: structural mass of the shell mesh from per-family thicknesses.

``mass = density * sum_f area_f * thickness[family(f)]`` with analytic partials. The
thickness vector has one entry per component family, in ``mesh.component_names`` order
(:attr:`MassComp.family_names`; families without faces are included and have zero
derivative). Core function: :func:`shellmesh_mdao.analysis.shell_mass`.
"""
from __future__ import annotations

import numpy as np
import openmdao.api as om

from ..analysis import ANALYSIS_MATERIAL, family_areas, n_families
from ..export import DEFAULT_THICKNESS
from ..mesh import ShellMesh

__all__ = ["MassComp"]


class MassComp(om.ExplicitComponent):
    """Shell mass ``density * sum(area_f * t_family(f))``.

    Options
    -------
    mesh : ShellMesh (required).
    thickness : initial thickness of every family (default 0.002, mesh length units).
    density : initial density (default 2700, aluminium, mass per volume in mesh units).

    Inputs ``thickness`` (n_families,), ``density`` (scalar); output ``mass`` (scalar).
    Partials are exact: d mass / d t_i = density * area_i, d mass / d density = areas . t.
    """

    def initialize(self):
        self.options.declare("mesh", types=ShellMesh, desc="the shell mesh (component families = thickness groups)")
        self.options.declare("thickness", default=DEFAULT_THICKNESS, desc="initial thickness of every family")
        self.options.declare("density", default=ANALYSIS_MATERIAL["rho"], desc="initial density")

    def setup(self):
        mesh = self.options["mesh"]
        self.family_names = list(mesh.component_names) + [
            f"component_{i}" for i in range(len(mesh.component_names), n_families(mesh))]
        self._areas = family_areas(mesh)
        n = len(self._areas)
        self.add_input("thickness", val=np.full(n, float(self.options["thickness"])), shape=(n,),
                       desc="shell thickness of each family, in mesh.component_names order")
        self.add_input("density", val=float(self.options["density"]), desc="material density")
        self.add_output("mass", val=0.0, desc="mass of all shells")
        self.declare_partials("mass", "thickness")
        self.declare_partials("mass", "density")

    def compute(self, inputs, outputs):
        outputs["mass"] = inputs["density"][0] * (self._areas @ inputs["thickness"])

    def compute_partials(self, inputs, partials):
        partials["mass", "thickness"] = inputs["density"][0] * self._areas[None, :]
        partials["mass", "density"] = self._areas @ inputs["thickness"]
