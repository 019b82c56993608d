"""OpenMDAO component: the layout inputs -> the morphed mesh, continuous node coordinates with exact
partials.

A thin wrapper of :func:`shellmesh_mdao.morph.morph` / :func:`~shellmesh_mdao.morph.morph_jacobian`
on a :class:`~shellmesh_mdao.morph.MorphReference` (one mesh, built once, of the reference layout):
every ``compute`` moves the reference mesh's nodes to the layout inputs, connectivity unchanged.
``x_struct0`` (MPhys naming: the node coordinates, flattened ``(3 n,)``) is a continuous output with
exact partials with respect to ``<wing>:rib_eta`` and ``<wing>:spar_chord`` (complex step through
the morph, the input triangles held); ``shell_mesh`` is the discrete mesh to analyse.

A morphed mesh that misses the checks (:func:`~shellmesh_mdao.morph.morph_check`: an element at or
below the scaled Jacobian ``min_scaled_jacobian``, a node off its support) is not analysed: with
``on_failure="remesh"`` (default) ``shell_mesh`` is a new mesh of the moved layout (a new topology:
the pipeline of the reference's surface, size and options) and the output ``remeshed`` is 1; with
``on_failure="error"`` the case fails (``om.AnalysisError``, the reason in the message), which a
gradient-based driver needs (``x_struct0`` keeps the reference's node count; with ``remeshed`` = 1 it
is the failed morph's coordinates, not the analysed mesh's). Layouts the pipeline refuses (stations
out of order, members that coincide at the element size) fail the case likewise. Same input, same
mesh, whatever the order of the cases: every case starts from the reference.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import openmdao.api as om

from ..errors import ShellMeshError
from ..guarantees import POOR_JACOBIAN
from ..morph import MorphReference, morph, morph_jacobian
from .layout_comp import case_errors

__all__ = ["MorphComp"]


class MorphComp(om.ExplicitComponent):
    """Layout inputs -> ``x_struct0`` (continuous, exact partials) and ``shell_mesh`` (discrete).

    Options: ``reference`` (a :class:`~shellmesh_mdao.morph.MorphReference`,
    :func:`~shellmesh_mdao.morph.morph_reference`), ``on_failure`` ("remesh" or "error"),
    ``min_scaled_jacobian`` (the morph's element check, default the README's 0.2; a lower bound lets an
    optimiser analyse intermediate designs whose meshes the README would not guarantee: mesh the final
    layout anew, as ``run_scripts/optimize_layout.py`` does).

    Inputs ``<wing>:rib_eta`` (K,) and ``<wing>:spar_chord`` (J,) of each wing (the reference
    layout's values as defaults). Outputs ``x_struct0`` (3 n,), ``remeshed`` (0 or 1),
    ``min_scaled_jacobian`` (of the mesh in ``shell_mesh``), ``morph_seconds`` (time of the morph and
    its checks, or of the new mesh), ``n_nodes`` and ``n_elements`` (of ``shell_mesh``, as
    ``ShellMeshGroup``'s) and the discrete ``shell_mesh``. :attr:`last_check` the
    :class:`~shellmesh_mdao.morph.MorphCheck` of the latest ``compute``.
    """

    def initialize(self):
        o = self.options
        o.declare("reference", types=MorphReference, desc="the reference mesh and layout (morph_reference)")
        o.declare("on_failure", default="remesh", values=("remesh", "error"),
                  desc="a morphed mesh that misses the checks: a new mesh of the layout, or a failed case")
        o.declare("min_scaled_jacobian", default=POOR_JACOBIAN, types=float,
                  desc="every morphed element's scaled Jacobian must be above this")

    def setup(self):
        ref = self.options["reference"]
        self._layout_vars = []
        for W in ref.wings:
            for what, val in (("rib_eta", W.rib_eta), ("spar_chord", W.spar_chord)):
                if len(val):
                    name = f"{W.name}:{what}"
                    self.add_input(name, val=val.copy(), shape=val.shape, desc=f"{what} of wing {W.name}")
                    self._layout_vars.append((name, W.name, what))
        n = ref.n_points
        self.add_output("x_struct0", val=ref.mesh.points.reshape(-1).copy(), shape=(3 * n,),
                        desc="node coordinates of the morphed mesh, flattened (x0, y0, z0, x1, ...)")
        self.add_output("remeshed", val=0.0, desc="1 when the morph missed its checks and shell_mesh is a new mesh")
        self.add_output("min_scaled_jacobian", val=0.0, desc="lowest scaled Jacobian of shell_mesh")
        self.add_output("morph_seconds", val=0.0, desc="time of the morph and its checks (or of the new mesh)")
        self.add_output("n_nodes", val=float(n), desc="nodes of shell_mesh (the reference's unless remeshed)")
        self.add_output("n_elements", val=float(ref.mesh.n_faces),
                        desc="elements of shell_mesh (the reference's unless remeshed)")
        self.add_discrete_output("shell_mesh", val=None, desc="the mesh to analyse (ShellMesh)")
        for name, _, _ in self._layout_vars:
            self.declare_partials("x_struct0", name)
        self.last_check = None
        self._jac_key, self._jac = None, None

    def _params(self, inputs):
        ref = self.options["reference"]
        out = ref.parameters()
        for name, wing, what in self._layout_vars:
            eta, ch = out[wing]
            val = np.array(inputs[name], dtype=np.float64)
            out[wing] = (val, ch) if what == "rib_eta" else (eta, val)
        return out

    def compute(self, inputs, outputs, discrete_inputs=None, discrete_outputs=None):
        ref = self.options["reference"]
        params = self._params(inputs)
        t0 = time.perf_counter()
        with case_errors():
            ref.layout_for(params)                   # the pipeline's layout rules (order, coincident members)
            x, chk = morph(ref, params, min_sj=self.options["min_scaled_jacobian"])
        self.last_check = chk
        outputs["x_struct0"] = x.reshape(-1)
        if chk.ok:
            mesh = dataclasses.replace(ref.mesh, points=x)
            outputs["remeshed"] = 0.0
            outputs["min_scaled_jacobian"] = chk.min_scaled_jacobian
        elif self.options["on_failure"] == "error":
            raise om.AnalysisError(f"{self.msginfo}: the morphed mesh misses its checks ({chk.reason}); "
                                   "on_failure='remesh' builds a new mesh of this layout instead")
        else:
            try:
                res = ref.remesh(params)
            except ShellMeshError as e:
                raise om.AnalysisError(f"{self.msginfo}: the morphed mesh misses its checks ({chk.reason}) and "
                                       f"a new mesh of this layout failed: {type(e).__name__}: {e}") from e
            mesh = res.mesh
            outputs["remeshed"] = 1.0
            outputs["min_scaled_jacobian"] = float(res.report["guarantees"]["min_scaled_jacobian"])
        outputs["morph_seconds"] = time.perf_counter() - t0
        outputs["n_nodes"] = mesh.n_points
        outputs["n_elements"] = mesh.n_faces
        discrete_outputs["shell_mesh"] = mesh

    def compute_partials(self, inputs, partials, discrete_inputs=None):
        ref = self.options["reference"]
        params = self._params(inputs)
        key = b"".join(np.asarray(inputs[name], np.float64).tobytes() for name, _, _ in self._layout_vars)
        if self._jac_key != key:
            self._jac = morph_jacobian(ref, params)
            self._jac_key = key
        for name, _, _ in self._layout_vars:
            partials["x_struct0", name] = self._jac[name]
