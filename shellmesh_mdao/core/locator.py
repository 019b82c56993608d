"""The project stage's surface locator: :class:`SurfaceLocator` (exact closest points through a
compiled bounding-volume hierarchy, ray casts through Embree refined in float64; the package
docstring gives the rules and timings), with the row-wise closest point on triangles and the
Moller-Trumbore ray-triangle intersection it rests on."""
from __future__ import annotations

import numpy as np

from ..errors import ProjectionError
from ..mesh import norm_rows

__all__ = ["SurfaceLocator", "closest_point_on_triangles", "ray_triangle_intersect"]


# ----------------------------------------------------------------------------- kernels
def closest_point_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Closest point of triangle ``(a[i], b[i], c[i])`` to ``p[i]``, row-wise (Ericson's
    region test: the vertices, then the edges ab, ac, bc, then the interior). All inputs
    (k, 3) float64 (or broadcastable); returns (k, 3). Degenerate triangles (zero area) go
    to the nearest of their three edges. A compiled loop
    (:func:`~shellmesh_mdao.core.bvh.closest_on_triangles`)."""
    from .bvh import closest_on_triangles          # numba: imported on first use
    return closest_on_triangles(p, a, b, c)


def ray_triangle_intersect(o, d, a, b, c):
    """Moller-Trumbore in float64, row-wise: ray ``o + t d`` against triangle ``(a, b, c)``.

    Returns ``(t, u, v, det)``: the hit point is ``a + u (b-a) + v (c-a) = o + t d``;
    the ray hits the closed triangle when ``det != 0``, ``u >= 0``, ``v >= 0``,
    ``u + v <= 1``. ``t`` is in units of ``|d|``."""
    o, d, a, b, c = (np.asarray(x, dtype=np.float64) for x in (o, d, a, b, c))
    e1 = b - a
    e2 = c - a
    pv = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, pv)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        tv = o - a
        u = np.einsum("ij,ij->i", tv, pv) * inv
        qv = np.cross(tv, e1)
        v = np.einsum("ij,ij->i", d, qv) * inv
        t = np.einsum("ij,ij->i", e2, qv) * inv
    return t, u, v, det


def _query_threads() -> int:
    """Threads for a batch of closest-point queries: numba's thread count (the CPUs this
    process may use, or ``NUMBA_NUM_THREADS``). The answers do not depend on it."""
    from numba import config
    return max(1, int(config.NUMBA_NUM_THREADS))


# ----------------------------------------------------------------------------- locator
class SurfaceLocator:
    """Closest-point and ray queries on a fixed triangle surface (tree built once).

    Parameters
    ----------
    points : (n, 3) float
    triangles : (t, 3) int

    Attributes ``points``, ``triangles`` (as given, float64/int64), ``diagonal``
    (bounding-box diagonal), ``face_of_triangle`` (set by :meth:`from_mesh`: the
    ShellMesh face each triangle came from; identity otherwise).
    """

    def __init__(self, points, triangles):
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        tri = np.ascontiguousarray(np.asarray(triangles, dtype=np.int64).reshape(-1, 3))
        if not len(tri):
            raise ProjectionError("the surface has no triangles: load a non-empty skin surface")
        if not np.isfinite(pts).all():
            raise ProjectionError("the surface has NaN/inf coordinates: repair the input surface")
        if tri.min() < 0 or tri.max() >= len(pts):
            raise ProjectionError("triangle indices out of range: every index must be in [0, n_points)")
        self.points = pts
        self.triangles = tri
        self.face_of_triangle = np.arange(len(tri), dtype=np.int64)
        lo, hi = pts[tri.reshape(-1)].min(0), pts[tri.reshape(-1)].max(0)
        self.diagonal = float(np.linalg.norm(hi - lo))
        # shift to the box centre: float64 relative precision is then set by the size,
        # not by the position of the model; embree additionally scales to a unit box.
        self._center = 0.5 * (lo + hi)
        self._scale = 1.0 / self.diagonal if self.diagonal > 0 else 1.0
        self._local = np.ascontiguousarray(pts - self._center)
        self._bvh = None
        self._embree = None
        self._v2t = None

    def __getstate__(self):
        # the trees (embree's is a native object) are rebuilt lazily after unpickling /
        # deep-copying
        st = dict(self.__dict__)
        st["_bvh"] = st["_embree"] = None
        return st

    def __setstate__(self, st):
        self.__dict__.update(st)

    @classmethod
    def from_mesh(cls, mesh) -> "SurfaceLocator":
        """Locator on a :class:`~shellmesh_mdao.mesh.ShellMesh` (quads split (0,1,2),(0,2,3));
        ``face_of_triangle`` maps triangle indices back to mesh faces."""
        tris, parent = mesh.triangles()
        loc = cls(mesh.points, tris)
        loc.face_of_triangle = np.asarray(parent, dtype=np.int64)
        return loc

    # ------------------------------------------------------------------ trees
    def _tree(self):
        """The compiled bounding-volume hierarchy of the triangles
        (:class:`~shellmesh_mdao.core.bvh.TriangleBVH`), built on the first query."""
        if self._bvh is None:
            from .bvh import TriangleBVH          # numba: imported on first use
            self._bvh = TriangleBVH(self._local, self.triangles)
        return self._bvh

    def compiled_tree(self):
        """``(bvh, center)``: the :class:`~shellmesh_mdao.core.bvh.TriangleBVH` that answers
        :meth:`closest` and the point its triangles were shifted by (queries are shifted the
        same way), for compiled loops that query it themselves."""
        return self._tree(), self._center

    def _scene(self):
        if self._embree is None:
            from embreex import rtcore_scene
            from embreex.mesh_construction import TriangleMesh
            scene = rtcore_scene.EmbreeScene()
            TriangleMesh(scene=scene, vertices=(self._local * self._scale).astype(np.float32),
                         indices=self.triangles.astype(np.int32))
            self._embree = scene
        return self._embree

    def vertex_triangles(self):
        """CSR vertex -> incident triangles: ``(ptr, triangles)``, the triangles around vertex ``v`` being
        ``triangles[ptr[v]:ptr[v + 1]]`` (built on first use)."""
        if self._v2t is None:
            t = self.triangles
            v = t.reshape(-1)
            order = np.argsort(v, kind="stable")
            ptr = np.zeros(len(self.points) + 1, dtype=np.int64)
            np.cumsum(np.bincount(v, minlength=len(self.points)), out=ptr[1:])
            self._v2t = (ptr, (order // 3).astype(np.int64))
        return self._v2t

    def triangle_neighbourhoods(self, tri):
        """The triangles around the three vertices of each triangle ``tri[i]`` (repeats kept):
        ``(owner, candidates)``, flat, row by row and vertex by vertex (``owner`` the row ``i``)."""
        ptr, v2t = self.vertex_triangles()
        corners = self.triangles[np.asarray(tri, np.int64)].reshape(-1)          # (3 k,)
        cnt = ptr[corners + 1] - ptr[corners]
        owner = np.repeat(np.arange(len(corners)) // 3, cnt)
        offs = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        return owner, v2t[np.repeat(ptr[corners], cnt) + offs]

    # ------------------------------------------------------------------ queries
    def closest(self, q, hint=None):
        """Exact closest point on the triangle set for each query point. ``hint`` (k,) optional:
        a triangle near each point to try first (-1: none), such as the one it was closest to
        before it moved; it saves a part of the search and never changes the answer.

        Returns ``(closest_points (k,3), tri_index (k,), distance (k,))``."""
        q = np.ascontiguousarray(np.asarray(q, dtype=np.float64).reshape(-1, 3))
        if not len(q):
            return np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0)
        if not np.isfinite(q).all():
            raise ProjectionError("closest-point query with NaN/inf coordinates: give finite points")
        ql = q - self._center
        cl, idx = self._tree().closest(ql, threads=_query_threads(), hint=hint)
        dist = norm_rows(cl - ql, axis=1)
        return cl + self._center, idx, dist

    def raycast(self, origins, directions):
        """Nearest hit of each ray ``origin + t * direction``, ``t > 0``.

        Returns ``(hit_points (k,3), tri_index (k,), distance (k,))``; a miss has
        ``tri_index == -1``, ``distance == inf`` and NaN hit point. ``distance`` is the
        Euclidean distance from the origin to the hit."""
        o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        o, d = np.broadcast_arrays(o, d)
        k = len(o)
        hit_pts = np.full((k, 3), np.nan)
        tri_idx = np.full(k, -1, dtype=np.int64)
        dist = np.full(k, np.inf)
        if not k:
            return hit_pts, tri_idx, dist
        if not (np.isfinite(o).all() and np.isfinite(d).all()):
            raise ProjectionError("ray query with NaN/inf origin or direction: give finite values")
        dn = norm_rows(d, axis=1)
        if (dn <= 0).any():
            bad = np.flatnonzero(dn <= 0)[:5].tolist()
            raise ProjectionError(f"ray direction of zero length (rays {bad}): give a non-zero direction")
        d = d / dn[:, None]
        ol = o - self._center
        res = self._scene().run((ol * self._scale).astype(np.float32), d.astype(np.float32), output=1)
        prim = np.asarray(res["primID"], dtype=np.int64)
        hit = np.flatnonzero(prim >= 0)
        if not len(hit):
            return hit_pts, tri_idx, dist
        tri_f, t_f, p_f = self._refine(ol[hit], d[hit], prim[hit])
        hit_pts[hit] = p_f + self._center
        tri_idx[hit] = tri_f
        dist[hit] = norm_rows(p_f - ol[hit], axis=1)
        return hit_pts, tri_idx, dist

    def _refine(self, o, d, prim):
        """float64 re-intersection of rays (local frame) with their embree triangle,
        then with the triangles sharing a vertex with it when the hit is outside.
        Returns (triangle, t, local hit point)."""
        with np.errstate(invalid="ignore", over="ignore"):
            return self._refine_impl(o, d, prim)

    def _refine_impl(self, o, d, prim):
        L = self._local
        T = self.triangles
        tol = 1e-12
        t, u, v, det = ray_triangle_intersect(o, d, L[T[prim, 0]], L[T[prim, 1]], L[T[prim, 2]])
        ok = (det != 0) & (u >= -tol) & (v >= -tol) & (u + v <= 1 + tol) & (t > 0) & np.isfinite(t)
        # hits within float32 reach of an edge or vertex: embree's choice among the triangles
        # there is arbitrary, so re-decide among the neighbours with a fixed rule
        near = ok & (np.minimum(np.minimum(u, v), 1.0 - u - v) < 1e-6)
        tri = prim.copy()
        pts = np.empty_like(o)
        bad = np.flatnonzero(~ok | near)
        if len(bad):
            ray_of, cand = self.triangle_neighbourhoods(prim[bad])
            rb = bad[ray_of]
            t2, u2, v2, det2 = ray_triangle_intersect(o[rb], d[rb], L[T[cand, 0]], L[T[cand, 1]], L[T[cand, 2]])
            ok2 = (det2 != 0) & (u2 >= -tol) & (v2 >= -tol) & (u2 + v2 <= 1 + tol) & (t2 > 0) & np.isfinite(t2)
            # rule: the nearest valid hit; among hits equally near (to 1e-12 of the size),
            # the lowest triangle index
            tmin = np.full(len(bad), np.inf)
            np.minimum.at(tmin, ray_of, np.where(ok2, t2, np.inf))
            elig = ok2 & (t2 <= tmin[ray_of] + 1e-12 * self.diagonal)
            key_c = np.where(elig, cand, np.iinfo(np.int64).max)
            order = np.lexsort((key_c, ray_of))
            first = np.ones(len(order), dtype=bool)
            first[1:] = ray_of[order][1:] != ray_of[order][:-1]
            sel = order[first]                                       # one per ray, in ray order
            good = elig[sel]
            g = bad[good]
            tri[g] = cand[sel][good]
            t[g] = t2[sel][good]
            # still nothing (ray through a vertex within rounding, or grazing): keep the
            # embree triangle and put the point at the closest point of that triangle
            # to the embree estimate of the hit
            still = bad[~good]
            if len(still):
                a, b, c = L[T[prim[still], 0]], L[T[prim[still], 1]], L[T[prim[still], 2]]
                est = o[still] + np.where(np.isfinite(t[still]) & (t[still] > 0), t[still], 0.0)[:, None] * d[still]
                pts[still] = closest_point_on_triangles(est, a, b, c)
                t[still] = np.einsum("ij,ij->i", pts[still] - o[still], d[still])
        else:
            still = bad
        on_ray = np.ones(len(o), dtype=bool)
        on_ray[still] = False
        pts[on_ray] = o[on_ray] + t[on_ray, None] * d[on_ray]
        return tri, t, pts

