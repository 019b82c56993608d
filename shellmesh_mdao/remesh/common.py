"""Pieces the remesh stage's modules share: the split / collapse thresholds, the vertex kinds,
the facing limits, small array helpers (triangle normals and angles, CSR rows, candidate
ranks) and :class:`EdgeTable`, the edge table of a triangle mesh."""
from __future__ import annotations

import numpy as np

from ..errors import MeshValidationError
from ..core.kernels import edge_lookup, edge_rows, edge_table, vertex_faces
from .kernels import corner_sin_cos, edge_neighbours, rank_desc, triangle_normals

__all__ = ["SPLIT_RATIO", "COLLAPSE_RATIO", "REGULAR", "CHAIN", "CORNER", "COS_FACING", "COS_TURNED", "tri_normals",
           "tri_min_angle", "min_angle_of", "tri_angles", "csr_entries", "rank_candidates", "EdgeTable"]

SPLIT_RATIO = 4.0 / 3.0          # split edges longer than SPLIT_RATIO * local size
COLLAPSE_RATIO = 4.0 / 5.0       # collapse edges shorter than COLLAPSE_RATIO * local size
REGULAR, CHAIN, CORNER = 0, 1, 2   # the compiled facing tests (kernels.facing_ok & co.) take kind 0 as regular
# a face standing across the surface: its normal more than 80 degrees from the input normal at
# its regular corners (operations.faces_facing_ok); a forced split's new face turned over: more
# than 100 degrees from the input normal at the new point (operations.split_round)
COS_FACING = np.cos(np.radians(80.0))
COS_TURNED = np.cos(np.radians(100.0))


# ============================================================================ small kernels
def tri_normals(P, F):
    """Unnormalised normals (twice the area vectors) of triangles ``F``."""
    return triangle_normals(P, F)


def tri_min_angle(A, B, C):
    """Smallest interior angle (degrees) of triangles with corners A, B, C (k, 3): the angles
    at A and B are ``arctan2(|u x v|, u . v)`` (numpy's arctan2 on the compiled loop's
    arguments), the third is what remains of pi."""
    return min_angle_of(corner_sin_cos(A, B, C))


def min_angle_of(sc):
    """Smallest angle (degrees) of triangles from the (4, k) :func:`~.kernels.corner_sin_cos`
    arguments of their first two corners."""
    a0, a1 = _arctan2_rows(sc)
    return np.degrees(np.minimum(np.minimum(a0, a1), np.pi - a0 - a1))


def _arctan2_rows(sc):
    """``arctan2(sc[0], sc[1])`` and ``arctan2(sc[2], sc[3])`` on fresh arrays, as the numpy
    code before the kernels computed them: on rows of one buffer numpy's AVX-512 loop was seen
    to fall back on its scalar arctan2 (other last bits) in some processes and not others."""
    return (np.arctan2(sc[0].copy(), sc[1].copy()), np.arctan2(sc[2].copy(), sc[3].copy()))


def tri_angles(P, F):
    """(m, 3) interior angles in degrees."""
    a0, a1 = _arctan2_rows(corner_sin_cos(P[F[:, 0]], P[F[:, 1]], P[F[:, 2]]))
    a0, a1 = np.degrees(a0), np.degrees(a1)
    return np.stack([a0, a1, 180.0 - a0 - a1], 1)


def csr_entries(ptr, rows):
    """For CSR pointers ``ptr`` and row ids ``rows``: (which row of ``rows``, position in the
    CSR value array) for every entry of those rows."""
    cnt = ptr[rows + 1] - ptr[rows]
    owner = np.repeat(np.arange(len(rows)), cnt)
    start = np.repeat(ptr[rows] - np.cumsum(cnt) + cnt, cnt)
    pos = start + np.arange(int(cnt.sum()))
    return owner, pos


def _hash(ids):
    """Deterministic scrambling of integer ids (Knuth multiplicative hash)."""
    return (np.asarray(ids, dtype=np.uint64) * np.uint64(2654435761)) % np.uint64(4294967291)


def rank_candidates(prio, tiebreak):
    """Unique integer rank of each candidate: larger ``prio`` first, ties broken by a hash of
    ``tiebreak`` (scrambled so that equal priorities do not form spatially ordered chains,
    which would make the independent sets small)."""
    # the hash is a bijection of ids below its prime modulus, so it breaks every tie by itself
    # (the ids as a third key never decided anything); the ranks of
    # np.lexsort((_hash(tiebreak), -prio)), by a compiled radix sort
    return rank_desc(prio, _hash(tiebreak))


# ============================================================================ topology
class EdgeTable:
    """Edge table of a triangle mesh (edges with one or two incident half-edges)."""

    def __init__(self, F, n, allow_nonmanifold=False):
        m = len(F)
        # the keys lo * n + hi sorted stably, their runs the edges (kernels.edge_table)
        self.he_edge, self.h0, self.h1, cnt, self.E, self.keys = edge_table(F, n)
        if len(cnt) and cnt.max() > 2 and not allow_nonmanifold:
            bad = self.keys[cnt > 2][:3]
            raise MeshValidationError(
                f"the skin has {(cnt > 2).sum()} non-manifold edges (more than two triangles on one "
                f"edge, first node pairs {[[int(k // n), int(k % n)] for k in bad]}): remeshing needs a "
                "manifold skin; remove internal faces or duplicate shells from the input surface")
        self.nonmanifold = cnt > 2      # (allow_nonmanifold only) treated like boundaries
        self.valence = cnt
        self.n = n
        self.m = m
        self._vn = None
        self._vf = None
        self._kptr = None

    def kptr(self):
        """Row pointers of each lower end's edges in ``E`` (E's rows are sorted by key
        lo * n + hi, so by lo: each lo's rows are one run)."""
        if self._kptr is None:
            self._kptr = edge_rows(self.E, self.n)
        return self._kptr

    def lookup(self, u, v):
        """Edge id of node pairs (u, v), -1 where absent (a compiled scan of the few edges
        whose lower end is ``min(u, v)``: :func:`~shellmesh_mdao.core.kernels.edge_lookup`)."""
        return edge_lookup(self.E, self.kptr(), np.asarray(u).reshape(-1), np.asarray(v).reshape(-1))

    def vertex_neighbors(self):
        """CSR (ptr, nbr) of vertex neighbours."""
        if self._vn is None:
            self._vn = edge_neighbours(self.E, self.n)
        return self._vn

    def vertex_faces(self, F):
        """CSR (ptr, faces) of the faces around each vertex."""
        if self._vf is None:
            self._vf = vertex_faces(F, self.n)
        return self._vf
