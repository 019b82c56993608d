"""OpenMDAO component: linear static CalculiX analysis of the shell mesh.

A thin wrapper of :func:`shellmesh_mdao.analysis.analyse_shell`: every ``compute`` writes the
deck with the current per-family thicknesses, runs ``ccx`` in a temporary folder and parses
the ``.dat`` results. Partials are central finite differences (``declare_partials(method='fd')``,
relative step ``fd_step`` = 1e-2), declared only for the families that have faces, so one
evaluation of the partials costs two ccx runs per non-empty family. See ``docs/analysis.md``.

The mesh comes either as the option ``mesh`` or, when that option is not given, as the
discrete input ``shell_mesh`` (from a :class:`~shellmesh_mdao.components.group.ShellMeshGroup`:
a new mesh at every design point). Then the ``thickness`` order is the option
``family_names`` (default: the families of the option ``layout``, fixed by the layout; a mesh
family takes the thickness of its own name or of its nearest listed parent, e.g. the pieces of
a station-given wing's kinked spar that of the spar), the clamped nodes are
found again for every new mesh, FD partials are declared for every family, and a
:class:`~shellmesh_mdao.errors.ShellMeshError` of the analysis (ccx fails on this mesh) is
raised as ``om.AnalysisError`` so a DOE records the case as failed and goes on.
``last_result.ks_von_mises`` is then in ``family_names`` order too (the KS aggregate over the
faces of each listed family outside the clamp band).
"""
from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import openmdao.api as om

from ..analysis import ANALYSIS_MATERIAL, ELEMENT_TYPES, analyse_shell, clamped_nodes, find_ccx, ks_aggregate, \
    n_families, resolve_up, select_tip_nodes
from ..export import DEFAULT_THICKNESS, resolve_material
from ..families import LOWER_SKIN_PATTERN, padded_names
from ..errors import SolverError
from ..mesh import ShellMesh
from .layout_comp import case_errors
from .mass_comp import discrete_family_names, mesh_family_positions

__all__ = ["CalculixShellAnalysis"]


class CalculixShellAnalysis(om.ExplicitComponent):
    """CalculiX shell analysis: mass, stresses and tip deflection from per-family thicknesses.

    Input ``thickness`` (n_families,) in ``mesh.component_names`` order (with ``shell_mesh``:
    :attr:`family_names` order). Outputs ``mass``,
    ``max_von_mises`` and ``ks_von_mises`` (n_families,: KS aggregate of the element von Mises
    stresses of each family, 0 for families without faces), both over the faces outside the
    band of width ``clamp_band`` at the clamp, ``tip_deflection`` (mean displacement along
    ``up`` of the ``tip_nodes``: by default the tip rib's nodes, else the tip section's) and
    ``max_deflection`` (displacement along ``up`` of the node of largest ``|u.up|``), ``ccx_seconds`` (wall
    time of the ccx run that gave these outputs: a record for studies, no partials). The last full result
    (:class:`~shellmesh_mdao.analysis.ShellAnalysis`:
    displacement field, per-element von Mises stress, ...) of the latest ``compute`` is kept in
    ``self.last_result``. Results of the last few thickness vectors are cached, so a ``compute``
    at a point already analysed (the FD base point, a repeated run_model, a change of the
    thickness of a family without faces) does not run ccx again.

    Options: ``mesh`` (or None: the discrete input ``shell_mesh``), ``family_names`` (thickness
    order with ``shell_mesh``; default: from ``layout``), ``layout`` (gives ``up`` and the span axis), ``material``
    (overrides of aluminium E=70e9, nu=0.33, rho=2700), ``clamp`` ("root", "root_rib" or node
    ids), ``clamp_tol``, ``axis``, ``clamp_rotations``, ``up``, ``pressure`` (default 1e4,
    along +up on ``pressure_families``), ``pressure_families``, ``nodal_forces``
    ``(ids, forces)``, ``tip_nodes`` ("auto", "tip_rib", "tip_section", a family name/pattern or
    node ids: :func:`~shellmesh_mdao.analysis.select_tip_nodes`), ``clamp_band`` (distance; default 5 %
    of the reach), ``element`` ("linear": S4/S3, "quadratic": S8R/S6),
    ``ks_rho``, ``ks_ref``, ``thickness`` (initial value), ``ccx`` (executable), ``threads``,
    ``timeout`` (s), ``workdir`` (keep the files there), ``fd_step`` (relative FD step, default 1e-2)
    and ``fd_form`` (default ``"central"``: two ccx runs per family, see ``docs/analysis.md``), ``buckling``
    (number of buckling factors, default 0: outputs ``buckling_factors`` and ``ks_buckling``), ``coordinates``
    (True: the node coordinates are the continuous input ``x_struct0`` of a ``MorphComp``, the elements the
    option ``mesh``'s; no partials with respect to ``x_struct0``: the layout derivatives of the outputs are
    finite differences of the whole model, ``model.approx_totals``).
    """

    def initialize(self):
        o = self.options
        o.declare("mesh", default=None, types=(ShellMesh, type(None)),
                  desc="the shell mesh (component families = thickness groups); None: discrete input shell_mesh")
        o.declare("family_names", default=None, types=(list, tuple, type(None)),
                  desc="thickness order when the mesh is the discrete input shell_mesh")
        o.declare("layout", default=None, desc="layout (dict, path or Layout): up direction and span axis")
        o.declare("material", default=None, types=(dict, type(None)), desc="overrides of ANALYSIS_MATERIAL")
        o.declare("clamp", default="root", desc="'root', 'root_rib' or 0-based node ids to clamp")
        o.declare("clamp_tol", default=None, desc="distance tolerance of the 'root' rule (default 1e-4 diagonal)")
        o.declare("axis", default=None, values=(None, 0, 1, 2), desc="span axis of the 'root' rule")
        o.declare("clamp_rotations", default=True, types=bool, desc="fix rotations of clamped nodes too")
        o.declare("up", default=None, desc="load / deflection direction (default: the layout's up)")
        o.declare("pressure", default=1.0e4, types=(int, float), desc="pressure along +up on pressure_families")
        o.declare("pressure_families", default=LOWER_SKIN_PATTERN, desc="fnmatch pattern(s) of loaded families")
        o.declare("nodal_forces", default=None, desc="(node ids (k,), forces (k, 3)) concentrated forces")
        o.declare("tip_nodes", default="auto",
                  desc="nodes whose mean u.up is tip_deflection: 'auto', 'tip_rib', 'tip_section', family, ids")
        o.declare("clamp_band", default=None, desc="faces this close to a clamped node are left out of the stress "
                                                   "outputs (default: 5 % of the reach; 0: none)")
        o.declare("element", default="linear", values=tuple(ELEMENT_TYPES), desc="shell element order")
        o.declare("ks_rho", default=50.0, types=(int, float), desc="KS aggregation parameter")
        o.declare("ks_ref", default=None, desc="KS reference stress (default: each family's maximum)")
        o.declare("thickness", default=DEFAULT_THICKNESS, desc="initial thickness of every family")
        o.declare("ccx", default=None, desc="CalculiX executable (default: ccx on PATH)")
        o.declare("threads", default=1, types=int, desc="threads given to ccx")
        o.declare("timeout", default=None, desc="seconds before a ccx run is abandoned")
        o.declare("workdir", default=None, desc="keep deck and results in this folder (default: temporary)")
        o.declare("fd_step", default=1e-2, types=float, desc="finite-difference step relative to each thickness")
        o.declare("fd_form", default="central", values=("central", "forward", "backward"),
                  desc="finite-difference form of the thickness partials (central: 2 ccx runs per family)")
        o.declare("buckling", default=0, types=int, desc="number of lowest buckling factors (0: no *BUCKLE step)")
        o.declare("coordinates", default=False, types=bool,
                  desc="the node coordinates are the input x_struct0 (the option mesh gives the elements)")

    def setup(self):
        o = self.options
        mesh = o["mesh"]
        find_ccx(o["ccx"])                                   # SolverError with the install line if missing
        layout = o["layout"]
        if layout is not None and not hasattr(layout, "wings"):
            from ..layout import load_layout

            layout = load_layout(layout)
        self._up = resolve_up(o["up"], layout)
        self._layout = layout
        resolve_material({**ANALYSIS_MATERIAL, **(o["material"] or {})})      # validate now, not at run time
        self._ctx_mesh = None
        if mesh is None:
            self.family_names = discrete_family_names(self, "CalculixShellAnalysis")
            n = len(self.family_names)
            self.add_discrete_input("shell_mesh", val=None, desc="the shell mesh (ShellMesh)")
        else:
            self._clamped = clamped_nodes(mesh, o["clamp"], layout=layout, axis=o["axis"], tol=o["clamp_tol"])
            self._tip = select_tip_nodes(mesh, o["tip_nodes"], layout=layout, axis=o["axis"])
            n = n_families(mesh)
            self.family_names = padded_names(mesh.component_names, n)
        self.last_result = None
        if o["coordinates"]:
            if mesh is None:
                raise SolverError(f"{self.msginfo}: coordinates=True needs the option mesh (the elements whose node "
                                  "coordinates x_struct0 gives, e.g. MorphReference.mesh)")
            # no partials with respect to x_struct0: derivatives with respect to what moves the nodes (the
            # layout, through MorphComp) are finite differences of the whole model (approx_totals)
            self.add_input("x_struct0", val=mesh.points.reshape(-1).copy(), shape=(3 * mesh.n_points,),
                           desc="node coordinates, flattened (x0, y0, z0, x1, ...)")
        self.add_input("thickness", val=np.full(n, float(o["thickness"])), shape=(n,),
                       desc="shell thickness of each family, in family_names order")
        self.add_output("mass", val=0.0, desc="mass of all shells (material rho)")
        self.add_output("max_von_mises", val=0.0, desc="largest integration-point von Mises stress")
        self.add_output("ks_von_mises", val=np.zeros(n), shape=(n,), desc="KS von Mises stress per family")
        self.add_output("tip_deflection", val=0.0, desc="mean displacement along up of the tip nodes")
        self.add_output("max_deflection", val=0.0, desc="displacement along up of the node of largest |u.up|")
        self.add_output("ccx_seconds", val=0.0, desc="wall time of the ccx run of these outputs (no partials)")
        nb = int(o["buckling"])
        if nb < 0:
            raise SolverError(f"{self.msginfo}: buckling must be the number of buckling factors wanted (0: none), "
                              f"got {nb}")
        if nb:
            self.add_output("buckling_factors", val=np.zeros(nb), shape=(nb,), desc="lowest buckling load factors")
            self.add_output("ks_buckling", val=0.0, desc="KS of 1 / buckling_factors (<= 1: no buckling)")
        # with shell_mesh the non-empty families are not known yet: partials of every family
        nz = np.flatnonzero(np.bincount(mesh.component, minlength=n) > 0) if mesh is not None else np.arange(n)
        self._cache, self._cache_size, self._nonempty = {}, 2 * len(nz) + 2, nz   # results of recent thicknesses
        fd = dict(method="fd", step=o["fd_step"], step_calc="rel_element", form=o["fd_form"])
        if nb:
            self.declare_partials("buckling_factors", "thickness", rows=np.repeat(np.arange(nb), len(nz)),
                                  cols=np.tile(nz, nb), **fd)
        for name in ("mass", "max_von_mises", "tip_deflection", "max_deflection") + (("ks_buckling",) if nb else ()):
            self.declare_partials(name, "thickness", rows=np.zeros(len(nz), np.int64), cols=nz, **fd)
        self.declare_partials("ks_von_mises", "thickness", rows=np.repeat(nz, len(nz)), cols=np.tile(nz, len(nz)),
                              **fd)

    def _use_mesh(self, mesh):
        """Per-mesh context when the mesh is the discrete input: clamped nodes, thickness map."""
        o = self.options
        if mesh is None:
            raise om.AnalysisError(f"{self.msginfo}: no shell_mesh: connect a ShellMeshGroup's shell_mesh")
        if self._ctx_mesh is mesh:
            return
        self._ctx_mesh = None
        self._cache.clear()                        # results belong to the previous mesh
        with case_errors():
            self._clamped = clamped_nodes(mesh, o["clamp"], layout=self._layout, axis=o["axis"], tol=o["clamp_tol"])
            self._tip = select_tip_nodes(mesh, o["tip_nodes"], layout=self._layout, axis=o["axis"])
        self._mesh_pos = mesh_family_positions(self, mesh)   # every family with faces is listed (or a parent)
        counts = np.bincount(mesh.component, minlength=len(self._mesh_pos))
        self._nonempty = np.unique(self._mesh_pos[(counts > 0) & (self._mesh_pos >= 0)])
        self._ctx_mesh = mesh

    def compute(self, inputs, outputs, discrete_inputs=None, discrete_outputs=None):
        t = np.array(inputs["thickness"], dtype=np.float64)
        mesh = self.options["mesh"]
        key = t[self._nonempty].tobytes()          # families without faces do not change the model
        if mesh is None:
            mesh = discrete_inputs["shell_mesh"]
            self._use_mesh(mesh)
        elif self.options["coordinates"]:
            x = np.array(inputs["x_struct0"], dtype=np.float64).reshape(-1, 3)
            key += hashlib.sha1(x.tobytes()).digest()
            if not np.array_equal(x, mesh.points):
                mesh = dataclasses.replace(mesh, points=x)
        r = self._cache.pop(key, None)
        if r is None:
            if self.options["mesh"] is None:
                tm = np.where(self._mesh_pos >= 0, t[np.maximum(self._mesh_pos, 0)], float(self.options["thickness"]))
                with case_errors():
                    r = self._run(tm, mesh)
                # KS over the faces of each listed family (a spar and its pieces together) outside the band
                out = ~r.in_clamp_band
                r.ks_von_mises = ks_aggregate(r.von_mises[out], self._mesh_pos[mesh.component[out]],
                                              len(self.family_names), rho=float(self.options["ks_rho"]),
                                              ref=self.options["ks_ref"])
            else:
                r = self._run(t, mesh)
        self._cache[key] = r                      # most recent last
        while len(self._cache) > self._cache_size:
            self._cache.pop(next(iter(self._cache)))
        self.last_result = r
        outputs["mass"] = r.mass
        outputs["max_von_mises"] = r.max_von_mises
        outputs["ks_von_mises"] = r.ks_von_mises
        outputs["tip_deflection"] = r.tip_deflection
        outputs["max_deflection"] = r.max_deflection
        outputs["ccx_seconds"] = r.seconds
        if self.options["buckling"]:
            outputs["buckling_factors"] = r.buckling_factors
            outputs["ks_buckling"] = r.ks_buckling

    def _run(self, t, mesh=None):
        o = self.options
        r = analyse_shell(
            o["mesh"] if mesh is None else mesh, t, material=o["material"], clamp=self._clamped, up=self._up,
            clamp_rotations=o["clamp_rotations"], pressure=float(o["pressure"]),
            pressure_families=o["pressure_families"], nodal_forces=o["nodal_forces"], tip_nodes=self._tip,
            element=o["element"], ks_rho=float(o["ks_rho"]), ks_ref=o["ks_ref"], clamp_band=o["clamp_band"],
            buckling=int(o["buckling"]),
            executable=o["ccx"],
            threads=o["threads"], timeout=o["timeout"], workdir=o["workdir"])
        return r
