"""OpenMDAO component: structural mass of the shell mesh from per-family thicknesses.

``mass = density * sum_f area_f * thickness[family(f)]`` with analytic partials. The
thickness vector has one entry per component family, in ``mesh.component_names`` order
(:attr:`MassComp.family_names`; families without faces are included and have zero
derivative). Core function: :func:`shellmesh_mdao.analysis.shell_mass`.

The mesh comes either as the option ``mesh`` (fixed for the life of the problem) or, when
that option is not given, as the discrete input ``shell_mesh`` (e.g. from a
:class:`~shellmesh_mdao.components.group.ShellMeshGroup`, a new mesh every design point); the
thickness order is then the option ``family_names`` or, from the option ``layout``,
:func:`~shellmesh_mdao.components.layout_comp.family_names` (fixed by the layout), and each
mesh family takes the thickness of the family of the same name or of its nearest listed
parent (a piece of a kinked or crossed spar of a station-given wing, ``w/spar_0/part_1/seg_2``,
that of ``w/spar_0``): :func:`mesh_family_positions`.
"""
from __future__ import annotations

import numpy as np
import openmdao.api as om

from ..analysis import ANALYSIS_MATERIAL, family_areas, family_areas_at, n_families
from ..errors import ShellMeshError
from ..export import DEFAULT_THICKNESS
from ..families import padded_names
from ..mesh import ShellMesh
from .layout_comp import family_index, family_names

__all__ = ["MassComp", "discrete_family_names", "mesh_family_positions", "mapped_family_areas"]


class MassComp(om.ExplicitComponent):
    """Shell mass ``density * sum(area_f * t_family(f))``.

    Options
    -------
    mesh : ShellMesh, or None (default): the mesh is then the discrete input ``shell_mesh``.
    family_names : thickness order with ``shell_mesh`` (default: from ``layout``).
    layout : layout (path, dict, Layout) giving ``family_names`` with ``shell_mesh``.
    thickness : initial thickness of every family (default 0.002, mesh length units).
    density : initial density (default 2700, aluminium, mass per volume in mesh units).
    coordinates : True: the node coordinates are the input ``x_struct0`` (3 n,) (from a
        :class:`~shellmesh_mdao.components.morph_comp.MorphComp`), the elements those of the option
        ``mesh``; the partials with respect to ``x_struct0`` are exact too.

    Inputs ``thickness`` (n_families,: :attr:`family_names` order; the mesh's own
    ``component_names`` with the option ``mesh``), ``density`` (scalar); output ``mass`` (scalar).
    Partials are exact: d mass / d t_i = density * area_i, d mass / d density = areas . t.
    """

    def initialize(self):
        self.options.declare("mesh", default=None, types=(ShellMesh, type(None)),
                             desc="the shell mesh (component families = thickness groups); None: discrete "
                                  "input shell_mesh")
        self.options.declare("family_names", default=None, types=(list, tuple, type(None)),
                             desc="thickness order when the mesh is the discrete input shell_mesh")
        self.options.declare("layout", default=None, desc="layout giving family_names (with shell_mesh)")
        self.options.declare("thickness", default=DEFAULT_THICKNESS, desc="initial thickness of every family")
        self.options.declare("density", default=ANALYSIS_MATERIAL["rho"], desc="initial density")
        self.options.declare("coordinates", default=False, types=bool,
                             desc="the node coordinates are the input x_struct0 (the option mesh gives the elements)")

    def setup(self):
        mesh = self.options["mesh"]
        self._coords = bool(self.options["coordinates"])
        if self._coords and mesh is None:
            raise ShellMeshError(f"{self.msginfo}: coordinates=True needs the option mesh (the elements whose node "
                                 "coordinates x_struct0 gives, e.g. MorphReference.mesh)")
        if mesh is not None:
            self.family_names = padded_names(mesh.component_names, n_families(mesh))
            self._areas = family_areas(mesh)
        else:
            self.family_names = discrete_family_names(self, "MassComp")
            self.add_discrete_input("shell_mesh", val=None, desc="the shell mesh (ShellMesh)")
            self._areas, self._areas_of = np.zeros(len(self.family_names)), None
        n = len(self._areas)
        self.add_input("thickness", val=np.full(n, float(self.options["thickness"])), shape=(n,),
                       desc="shell thickness of each family, in family_names order")
        self.add_input("density", val=float(self.options["density"]), desc="material density")
        self.add_output("mass", val=0.0, desc="mass of all shells")
        self.declare_partials("mass", "thickness")
        self.declare_partials("mass", "density")
        if self._coords:
            self.add_input("x_struct0", val=mesh.points.reshape(-1).copy(), shape=(3 * mesh.n_points,),
                           desc="node coordinates, flattened (x0, y0, z0, x1, ...)")
            used = np.unique(mesh.faces[mesh.faces >= 0])
            cols = (3 * used[:, None] + np.arange(3)).reshape(-1)
            self.declare_partials("mass", "x_struct0", rows=np.zeros(len(cols), np.int64), cols=cols)
            self._xcols = cols

    def _mesh_areas(self, discrete_inputs):
        if self.options["mesh"] is None:
            mesh = discrete_inputs["shell_mesh"]
            if mesh is None:
                raise om.AnalysisError(f"{self.msginfo}: no shell_mesh: connect a ShellMeshGroup's shell_mesh")
            if self._areas_of is not mesh:
                self._areas = mapped_family_areas(self, mesh)
                self._areas_of = mesh
        return self._areas

    def compute(self, inputs, outputs, discrete_inputs=None, discrete_outputs=None):
        if self._coords:
            self._areas = family_areas_at(self.options["mesh"], inputs["x_struct0"])[0]
        outputs["mass"] = inputs["density"][0] * (self._mesh_areas(discrete_inputs) @ inputs["thickness"])

    def compute_partials(self, inputs, partials, discrete_inputs=None):
        if self._coords:
            mesh = self.options["mesh"]
            self._areas, grad = family_areas_at(mesh, inputs["x_struct0"], inputs["thickness"])
            partials["mass", "x_struct0"] = inputs["density"][0] * grad.reshape(-1)[self._xcols]
        self._mesh_areas(discrete_inputs)
        partials["mass", "thickness"] = inputs["density"][0] * self._areas[None, :]
        partials["mass", "density"] = self._areas @ inputs["thickness"]


def discrete_family_names(comp, what: str) -> list:
    """Thickness order of a component whose mesh is the discrete input ``shell_mesh``: its
    ``family_names`` option, else the families of its ``layout`` option."""
    names = comp.options["family_names"]
    if names is None and comp.options["layout"] is not None:
        names = family_names(comp.options["layout"])
    if not names:
        raise ShellMeshError(f"{what} needs the mesh: give mesh=ShellMesh, or family_names=[...] (or layout=...) "
                             "and connect a ShellMeshGroup's shell_mesh output to its shell_mesh input")
    names = [str(n) for n in names]
    if len(set(names)) != len(names):
        raise ShellMeshError(f"{what}: family_names has repeated names; give each family once")
    return names


def mesh_family_positions(comp, mesh: ShellMesh) -> np.ndarray:
    """Position in the component's ``family_names`` of each family of ``mesh`` (in
    ``mesh.component_names`` order, padded): its own name or its nearest listed parent
    (:func:`~shellmesh_mdao.components.layout_comp.family_index`: a spar piece
    ``w/spar_0/part_1/seg_2`` takes the thickness of ``w/spar_0``), -1 for a family without faces
    that is not listed. A mesh family with faces that neither it nor a parent is listed is a
    :class:`ShellMeshError`."""
    nm = n_families(mesh)
    names = padded_names(mesh.component_names, nm)
    pos = family_index(comp.family_names, names)
    counts = np.bincount(mesh.component, minlength=nm) if mesh.n_faces else np.zeros(nm, np.int64)
    bad = np.flatnonzero((pos < 0) & (counts > 0))
    if len(bad):
        n, i = names[bad[0]], bad[0]
        raise ShellMeshError(f"{comp.msginfo}: the mesh has a family '{n}' ({int(counts[i])} faces) that "
                             f"family_names does not name; add it to family_names (or build the mesh "
                             "with the layout given to this component)")
    return pos


def mapped_family_areas(comp, mesh: ShellMesh) -> np.ndarray:
    """Face area of each of the component's ``family_names`` in ``mesh`` (summed over the mesh
    families each one stands for, :func:`mesh_family_positions`; 0 for a family without
    faces)."""
    pos = mesh_family_positions(comp, mesh)
    if not mesh.n_faces:
        return np.zeros(len(comp.family_names))
    return np.bincount(pos[mesh.component], weights=mesh.face_areas(), minlength=len(comp.family_names))
