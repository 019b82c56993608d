"""Mesh topology helpers the stages share: the faces around a set of vertices, rings of them, and
the mask of the edges that are given node pairs."""
from __future__ import annotations

import numpy as np

from .kernels import faces_at

__all__ = ["faces_of", "face_rings", "fixed_edge_mask", "canonical_triangles"]

def faces_of(ptr, vf, verts, m):
    """Sorted ids of the faces incident to ``verts`` (CSR ``ptr``/``vf`` of ``m`` faces; a
    compiled pass, :func:`~shellmesh_mdao.core.kernels.faces_at`)."""
    return faces_at(ptr, vf, verts, m)


def face_rings(faces, ptr, vf, verts, rings: int = 2):
    """Sorted ids of the faces within ``rings`` rings of ``verts``: the faces incident to
    them, then (``rings`` >= 2) the faces incident to those faces' vertices, and so on."""
    region = faces_of(ptr, vf, np.asarray(verts, np.int64), len(faces))
    for _ in range(rings - 1):
        v = faces[region]
        region = faces_of(ptr, vf, np.unique(v[v >= 0]), len(faces))
    return region


def fixed_edge_mask(topo, fixed_edges) -> np.ndarray:
    """(E,) bool over the edges of ``topo`` (:meth:`~shellmesh_mdao.mesh.ShellMesh.topology`): True
    on the edges given as node pairs ``fixed_edges`` (k, 2); pairs that are not edges are ignored.
    The split and merge stages never split or merge across these (default: the feature edges)."""
    mask = np.zeros(len(topo.edges), bool)
    fe = np.asarray(fixed_edges, dtype=np.int64).reshape(-1, 2)
    if len(fe) and len(topo.edges):
        ids = topo.edge_ids(fe)
        mask[ids[ids >= 0]] = True
    return mask


def canonical_triangles(V, T):
    """A deterministic vertex and triangle order of the triangulation (V, T), whatever order
    a library wrote it in: vertices sorted by coordinates, triangles rotated to start at their
    lowest vertex and sorted. Returns (V', T', order): ``T'`` is ``T[order]`` renumbered and
    rotated (carry per-triangle data along with ``order``)."""
    vo = np.lexsort(V.T[::-1])
    rank = np.empty(len(V), np.int64)
    rank[vo] = np.arange(len(V))
    T = rank[T]
    k = np.argmin(T, axis=1)
    T = T[np.arange(len(T))[:, None], (k[:, None] + np.arange(3)) % 3]
    to = np.lexsort(T.T[::-1])
    return V[vo], T[to], to
