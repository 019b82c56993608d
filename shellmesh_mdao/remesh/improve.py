"""The local clean-up the imprint stage runs after cutting member curves into the skin
(:func:`improve_triangles`): angle-improving flips and tangential relaxation on the remesher's
operations."""
from __future__ import annotations

import numpy as np

from ..errors import MeshValidationError, SizeError
from ..mesh import ShellMesh
from ..core.locator import SurfaceLocator
from .common import CORNER, REGULAR, EdgeTable
from .operations import flip_round, phase
from .relax import relax_vertices
from .work import Context, WorkMesh

__all__ = ["improve_triangles"]


# ============================================================================ local clean-up
def improve_triangles(mesh: ShellMesh, locator: SurfaceLocator, *, target_edge: float, iterations: int = 3,
                      max_dihedral: float = 3.0, relax: bool = True, min_angle_floor: float = 10.0) -> ShellMesh:
    """Local clean-up of the triangles of a skin after member curves were cut into it.

    Batched, deterministic, vectorised:

    * **edge flips** of interior triangle--triangle edges that are not in
      ``mesh.feature_edges``, whose two triangles belong to the same component, are
      nearly coplanar (normals within ``max_dihedral`` degrees, before and after) and
      whose flip raises the smaller of the two triangles' smallest angles;
    * **tangential relaxation** of the free vertices (not in ``fixed_vertices``, not on a
      feature edge, not on a quad, not on an open or non-manifold edge of the triangle
      set) to the area-weighted centroid of their triangles, projected onto the input
      surface of ``locator`` (closest point among the input triangles facing the same
      way as the vertex normal, so a vertex never jumps to the other skin of a thin
      trailing edge). A move is undone when a triangle around it would turn by more
      than 60 degrees, face against the input surface, or get a smallest angle below
      ``min(its previous smallest angle, min_angle_floor)`` -- triangles never invert.

    Feature-line vertices do not slide along their lines (member chains must keep the
    nodes the member meshes are built on). Quads, the component of every face and the
    face order are left unchanged (a flip rewrites the two triangles in place).

    Parameters
    ----------
    mesh : ShellMesh
        Skin with triangles (quads allowed, left alone), ``feature_edges`` and
        ``fixed_vertices`` marking what must stay.
    locator : SurfaceLocator
        The input (original) skin surface that free vertices are projected onto.
    target_edge : float
        Local edge length scale (used for tolerances).
    iterations : int
        Flip + relaxation rounds.
    max_dihedral : float
        Largest angle (degrees) between the normals of two triangles whose shared edge
        may be flipped.
    relax : bool
        Also run the tangential relaxation.
    """
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("improve_triangles needs a ShellMesh")
    if not np.isfinite(target_edge) or target_edge <= 0:
        raise SizeError(f"target edge length {target_edge!r} must be positive and finite: give a positive size")
    out = mesh.copy()
    tri = np.flatnonzero(mesh.is_tri)
    if not len(tri):
        return out
    n = mesh.n_points
    F = mesh.faces[tri, :3].copy()
    T = EdgeTable(F, n, allow_nonmanifold=True)
    fixed = np.zeros(n, bool)
    fixed[mesh.fixed_vertices] = True
    fixed[mesh.feature_edges.reshape(-1)] = True
    fixed[mesh.faces[mesh.is_quad].reshape(-1)] = True
    fixed[T.E[(T.valence == 1) | T.nonmanifold].reshape(-1)] = True
    used = np.zeros(n, bool)
    used[F.reshape(-1)] = True
    kind = np.where(fixed | ~used, CORNER, REGULAR).astype(np.int8)
    ctx = Context(None, locator=locator, max_flip_dihedral=max_dihedral)
    vtri = np.full(n, -1, np.int64)
    free = np.flatnonzero(kind == REGULAR)
    if len(free):
        _, t, _ = locator.closest(mesh.points[free])
        vtri[free] = t
    # non-manifold edges must not be flipped: mark them as features of the working mesh
    nm = T.E[T.nonmanifold]
    fe = np.vstack([mesh.feature_edges, nm]) if len(nm) else mesh.feature_edges
    W = WorkMesh(mesh.points.copy(), F, mesh.component[tri].astype(np.int64), kind, np.full(n, np.nan),
              np.full(n, -1, np.int64), np.full(n, -1, np.int64), vtri, fe, np.zeros(len(fe), np.int64),
              np.full(n, float(target_edge)))
    W.allow_nonmanifold = True
    W.touched()
    for _ in range(max(int(iterations), 0)):
        phase(flip_round, W, ctx, 10, "angle")
        if relax:
            relax_vertices(W, ctx, move_chains=False, min_angle_floor=min_angle_floor)
    phase(flip_round, W, ctx, 10, "angle")
    faces = out.faces.copy()
    faces[tri, :3] = W.F
    return ShellMesh(W.P, faces, out.component, out.component_names, out.fixed_vertices,
                     out.feature_edges, out.feature_edge_ids)
