"""Is a generated triangulation a valid closed surface: watertight, consistently oriented, outward,
free of self-intersections.

:func:`surface_defects` counts what is wrong; :func:`self_intersections` finds the pairs of
triangles that cross. Both work on plain arrays, the counts vectorised, the crossings by a compiled sweep over the
triangles' boxes (each pair tested in floating point with a relative tolerance).
"""
from __future__ import annotations

import numpy as np

__all__ = ["surface_defects", "self_intersections"]

#: relative tolerance of the orientation tests (volumes below it count as zero: touching, not crossing)
ORIENT_TOL = 1e-12


def _arrays(mesh_or_points, tris=None):
    if tris is None:
        m = mesh_or_points
        P = np.asarray(m.points, float)
        T, _ = m.triangles() if m.n_quads else (np.asarray(m.faces[:, :3], np.int64), None)
        return P, np.asarray(T, np.int64)
    return np.asarray(mesh_or_points, float), np.asarray(tris, np.int64)


def surface_defects(mesh_or_points, tris=None, intersections: bool = True) -> dict:
    """Counts of what keeps a triangulation (a :class:`~shellmesh_mdao.mesh.ShellMesh` or
    ``points, tris``) from being a closed, consistently oriented, outward, non-self-intersecting
    surface: ``open_edges`` (a directed edge whose reverse no face uses), ``repeated_edges`` (a
    directed edge two faces use: a flipped face or a non-manifold edge), ``degenerate_faces`` (a
    repeated vertex or zero area), ``self_intersections`` (pairs of triangles sharing no vertex
    that cross; with ``intersections``), and the enclosed ``volume`` (positive when outward). All
    counts zero and a positive volume: valid."""
    P, T = _arrays(mesh_or_points, tris)
    e = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    N = len(P)
    fwd = e[:, 0] * N + e[:, 1]
    uniq, cnt = np.unique(fwd, return_counts=True)
    rev = e[:, 1] * N + e[:, 0]
    area2 = np.linalg.norm(np.cross(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]]), axis=1)
    rep = (T[:, 0] == T[:, 1]) | (T[:, 1] == T[:, 2]) | (T[:, 0] == T[:, 2])
    v = P[T]
    out = {"open_edges": int((~np.isin(rev, uniq)).sum()), "repeated_edges": int((cnt > 1).sum()),
           "degenerate_faces": int((rep | (area2 == 0)).sum()),
           "volume": float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)}
    if intersections:
        out["self_intersections"] = int(len(self_intersections(P, T)))
    return out


def self_intersections(points, tris) -> np.ndarray:
    """Pairs ``(i, j)`` (``i < j``) of triangles that share no vertex and cross (an edge of one
    passes through the other's interior): a sweep over the triangles' boxes along their longest
    extent (:func:`~shellmesh_mdao.geometry.kernels.sweep_crossings`). Touching within
    :data:`ORIENT_TOL` of the pair's size cubed does not count, nor do coplanar overlaps."""
    from .kernels import sweep_crossings

    P = np.ascontiguousarray(points, np.float64)
    T = np.ascontiguousarray(tris, np.int64)
    if not len(T):
        return np.zeros((0, 2), np.int64)
    V = P[T]
    lo, hi = np.ascontiguousarray(V.min(1)), np.ascontiguousarray(V.max(1))
    axis = int(np.argmax(P.max(0) - P.min(0)))
    order = np.argsort(lo[:, axis], kind="stable")
    pairs, _ = sweep_crossings(P, T, lo, hi, order, axis, ORIENT_TOL)
    return pairs[np.lexsort(pairs.T[::-1])] if len(pairs) else pairs
