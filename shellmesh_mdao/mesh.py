"""The one mesh type that travels between all pipeline stages.

A :class:`ShellMesh` is a mixed triangle/quad surface mesh:

``points``            (n, 3) float64 node coordinates.
``faces``             (m, 4) int64 node indices; a triangle has ``-1`` in its 4th slot.
``component``         (m,) int32 component (family) id of each face.
``component_names``   list of names; ``component_names[i]`` names component id ``i``.
``fixed_vertices``    sorted unique int64 indices of nodes later stages must not move freely.
``feature_edges``     (k, 2) int64 node pairs (each row sorted, rows unique and sorted)
                      that later stages must keep as mesh edges: imprint chains,
                      member junctions, sharp feature lines.
``feature_edge_ids``  (k,) int32 owner of each feature edge: the component id of the
                      member whose chain it belongs to, or ``-1`` for a geometric
                      feature line (trailing edge, crease).

The functions here are vectorised over faces and edges; they never loop in Python
over elements. Edges are non-manifold aware: a skin/rib junction edge has three
incident faces, a rib/spar crossing edge four.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import MeshValidationError
from .families import padded_names


class _KernelsOnFirstUse:
    """Stands for :mod:`shellmesh_mdao.core.kernels` until a function here first calls a kernel:
    then it imports the module (numba, about half a second) and puts it in its own place, so
    ``import shellmesh_mdao.mesh`` stays cheap and the calls below (``_k.cross_rows(...)``, ...)
    are the module's own functions from then on, with no cost per call."""

    def __getattr__(self, name):
        global _k
        from .core import kernels

        _k = kernels
        return getattr(kernels, name)


_k = _KernelsOnFirstUse()

__all__ = ["ShellMesh", "EdgeTopology", "MeshCheck", "concatenate", "merge_close_points", "vertex_faces",
           "cross_rows", "reduce_short", "norm_rows", "dot_rows", "dot_norm_rows", "dot_unit_rows"]


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (length 3) of broadcastable arrays: the same arithmetic
    as ``np.cross`` (so the same bits) without its axis handling, which costs more than the
    product itself on the small batches of the remesher, the imprint and the smoother. Two
    (k, 3) float64 arrays go to a compiled loop (:func:`~shellmesh_mdao.core.kernels.cross_rows`,
    the same arithmetic)."""
    out = _k.cross_rows(a, b)
    if out is not None:
        return out
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    np.subtract(a[..., 1] * b[..., 2], a[..., 2] * b[..., 1], out=out[..., 0])
    np.subtract(a[..., 2] * b[..., 0], a[..., 0] * b[..., 2], out=out[..., 1])
    np.subtract(a[..., 0] * b[..., 1], a[..., 1] * b[..., 0], out=out[..., 2])
    return out


def bbox_diagonal(P) -> float:
    """Length of the bounding-box diagonal of the points ``P`` (k, 3), k >= 1: the extents
    taken column by column (numpy's ``P.max(0)`` on a (k, 3) array is about 20 times slower;
    the same values)."""
    ext = np.array([P[:, d].max() - P[:, d].min() for d in range(3)])
    return float(np.linalg.norm(ext))


def _short_axis(a, axis, op, cast=None):
    a = np.asarray(a)
    axis = axis % a.ndim
    m = a.shape[axis]
    if m == 0:
        return None
    lead = (slice(None),) * axis
    out = a[lead + (0,)]
    out = out.astype(cast) if cast is not None else out.copy()
    for j in range(1, m):
        b = a[lead + (j,)]
        op(out, b if cast is None else b.astype(cast), out=out)
    return out


def reduce_short(a, how: str, axis: int = 1) -> np.ndarray:
    """``a.sum(axis)`` (``how="sum"``; also ``"mean"``, ``"min"``, ``"max"``, ``"any"``,
    ``"all"``) over a SHORT axis (a triangle's 3 corners, a quad's 4, a vector's 3
    coordinates), the same values bit for bit, as one elementwise operation per entry of that
    axis: NumPy's reduction over a short axis costs 5 to 20 times more (it loops per row).
    NumPy sums a short axis left to right, as this does; a mean is that sum over the count;
    min and max propagate NaN as NumPy's do; a sum of booleans counts them."""
    a = np.asarray(a)
    if how in ("sum", "mean"):
        cast = np.int64 if a.dtype == np.bool_ else None
        out = _short_axis(a, axis, np.add, cast)
        if out is None:
            return a.mean(axis) if how == "mean" else a.sum(axis)
        return out / a.shape[axis] if how == "mean" else out
    op = {"min": np.minimum, "max": np.maximum, "any": np.logical_or, "all": np.logical_and}[how]
    if how in ("any", "all") and a.dtype != np.bool_:
        a = a != 0
    out = _short_axis(a, axis, op)
    if out is None:
        return getattr(a, how)(axis)
    return out


def norm_rows(a, axis: int = -1, keepdims: bool = False) -> np.ndarray:
    """``np.linalg.norm(a, axis=axis, keepdims=keepdims)``, the same bits, several times faster
    for float64 vectors of length 3 along ``axis`` (the last one): ``sqrt((x*x + y*y) + z*z)``
    is the sum NumPy's reduction forms over three elements; any other input goes to NumPy.
    (tests/test_mesh.py checks the equality on shapes, strides, magnitudes and special values.)"""
    a = np.asarray(a)
    if a.dtype == np.float64 and a.ndim >= 1 and a.shape[-1] == 3 and axis in (-1, a.ndim - 1):
        if a.ndim == 2:                                  # (k, 3): the compiled loop, same sum
            out = _k.norm_rows(a)
            return out[:, None] if keepdims else out
        x, y, z = a[..., 0], a[..., 1], a[..., 2]
        out = np.sqrt(x * x + y * y + z * z)
        return out[..., None] if keepdims else out
    return np.linalg.norm(a, axis=axis, keepdims=keepdims)


def dot_rows(a, b) -> np.ndarray:
    """``np.einsum("ij,ij->i", a, b)``, the same bits; (k, 3) float64 rows through a compiled
    loop (:func:`~shellmesh_mdao.core.kernels.dot_rows`), anything else through numpy."""
    out = _k.dot_rows(a, b)
    return np.einsum("ij,ij->i", a, b) if out is None else out


def dot_norm_rows(a) -> np.ndarray:
    """``np.sqrt(np.einsum("ij,ij->i", a, a))``, the same bits (compiled for (k, 3) rows)."""
    out = _k.dot_norm_rows(a)
    return np.sqrt(np.einsum("ij,ij->i", a, a)) if out is None else out


def dot_unit_rows(a) -> np.ndarray:
    """Rows of ``a`` over :func:`dot_norm_rows`, zero rows where that is not positive, the same
    bits as ``np.divide(a, n, out=zeros, where=n > 0)`` (compiled for (k, 3) rows)."""
    out = _k.dot_unit_rows(a)
    if out is None:
        n = dot_norm_rows(a)[:, None]
        out = np.divide(a, n, out=np.zeros_like(a), where=n > 0)
    return out


def _as_faces(faces) -> np.ndarray:
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] not in (3, 4):
        raise MeshValidationError(
            f"faces must be an (m, 3) or (m, 4) integer array, got shape {f.shape}; "
            "pad triangles with -1 in the 4th column")
    f = f.astype(np.int64, copy=False)
    if f.shape[1] == 3:
        f = np.hstack([f, np.full((len(f), 1), -1, dtype=np.int64)])
    return np.ascontiguousarray(f)


@dataclass
class EdgeTopology:
    """Unique edges of a mixed mesh with their incident faces.

    ``edges``        (E, 2) sorted node pairs, rows sorted lexicographically.
    ``face_edges``   (m, 4) edge id of each face side (side i joins corner i and the
                     next corner); ``-1`` in the 4th slot of triangles.
    ``valence``      (E,) number of incident faces of each edge.
    ``edge_faces_ptr``, ``edge_faces``: CSR list of the faces incident to each edge,
                     ``edge_faces[edge_faces_ptr[e]:edge_faces_ptr[e+1]]``, sorted.
    ``he_face``, ``he_side``, ``he_edge``, ``he_from``, ``he_to``: every half-edge
                     (one per face side) with its face, side, edge id and direction.
    """

    edges: np.ndarray
    face_edges: np.ndarray
    valence: np.ndarray
    edge_faces_ptr: np.ndarray
    edge_faces: np.ndarray
    he_face: np.ndarray
    he_side: np.ndarray
    he_edge: np.ndarray
    he_from: np.ndarray
    he_to: np.ndarray

    def faces_of(self, e: int) -> np.ndarray:
        return self.edge_faces[self.edge_faces_ptr[e]:self.edge_faces_ptr[e + 1]]

    @property
    def boundary(self) -> np.ndarray:
        """Ids of edges with exactly one incident face."""
        return np.flatnonzero(self.valence == 1)

    @property
    def nonmanifold(self) -> np.ndarray:
        """Ids of edges with more than two incident faces."""
        return np.flatnonzero(self.valence > 2)

    def edge_ids(self, pairs: np.ndarray) -> np.ndarray:
        """Edge id of each node pair (any order), ``-1`` where the pair is not an edge."""
        pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
        if len(self.edges) == 0 or len(pairs) == 0:
            return np.full(len(pairs), -1, dtype=np.int64)
        n = int(max(self.edges.max(), pairs.max())) + 1
        keys = self.edges[:, 0] * n + self.edges[:, 1]
        q = pairs[:, 0] * n + pairs[:, 1]
        pos = np.searchsorted(keys, q)
        pos = np.minimum(pos, len(keys) - 1)
        return np.where(keys[pos] == q, pos, -1)


@dataclass
class MeshCheck:
    """Problems found by :meth:`ShellMesh.check`; every array empty means valid."""

    duplicate_points: np.ndarray      # (d, 2) pairs of coincident node indices
    degenerate_faces: np.ndarray      # face indices with repeated nodes or ~zero area
    unreferenced_points: np.ndarray   # node indices used by no face
    inconsistent_edges: np.ndarray    # (k, 2) edges whose two same-component faces run the same way
    hanging_nodes: np.ndarray         # (h, 3) rows (a, b, c): node c lies inside boundary edge a-b
    nonfinite_points: np.ndarray      # node indices with NaN/inf coordinates

    @property
    def ok(self) -> bool:
        return all(len(getattr(self, k)) == 0 for k in self.__dataclass_fields__)

    def problems(self) -> list[str]:
        """One human-readable line per kind of problem found."""
        out = []
        if len(self.nonfinite_points):
            out.append(f"{len(self.nonfinite_points)} nodes with NaN/inf coordinates "
                       f"(first: {self.nonfinite_points[:5].tolist()})")
        if len(self.duplicate_points):
            out.append(f"{len(self.duplicate_points)} pairs of coincident nodes "
                       f"(first: {self.duplicate_points[:3].tolist()})")
        if len(self.degenerate_faces):
            out.append(f"{len(self.degenerate_faces)} degenerate faces "
                       f"(first: {self.degenerate_faces[:5].tolist()})")
        if len(self.unreferenced_points):
            out.append(f"{len(self.unreferenced_points)} unreferenced nodes "
                       f"(first: {self.unreferenced_points[:5].tolist()})")
        if len(self.inconsistent_edges):
            out.append(f"{len(self.inconsistent_edges)} edges with inconsistent face orientation "
                       f"(first: {self.inconsistent_edges[:3].tolist()})")
        if len(self.hanging_nodes):
            out.append(f"{len(self.hanging_nodes)} hanging nodes (node lies on another face's edge; "
                       f"first a,b,c: {self.hanging_nodes[:3].tolist()})")
        return out


@dataclass
class ShellMesh:
    """Mixed triangle/quad shell mesh with component families and fixed/feature sets."""

    points: np.ndarray
    faces: np.ndarray
    component: np.ndarray | None = None
    component_names: list = field(default_factory=list)
    fixed_vertices: np.ndarray | None = None
    feature_edges: np.ndarray | None = None
    feature_edge_ids: np.ndarray | None = None

    def __post_init__(self):
        self.points = np.ascontiguousarray(np.asarray(self.points, dtype=np.float64))
        if self.points.ndim != 2 or (self.points.size and self.points.shape[1] != 3):
            raise MeshValidationError(f"points must be an (n, 3) array, got shape {self.points.shape}")
        self.points = self.points.reshape(-1, 3)
        self.faces = _as_faces(self.faces) if np.asarray(self.faces).size else np.zeros((0, 4), np.int64)
        m = len(self.faces)
        if m and (self.faces[:, :3].min() < 0 or self.faces.max() >= len(self.points)
                  or (self.faces[:, 3] < -1).any()):
            raise MeshValidationError(
                "face node indices out of range: every index must be in [0, n_points) "
                "(-1 allowed only in the 4th column, for triangles)")
        if self.component is None:
            self.component = np.zeros(m, dtype=np.int32)
        self.component = np.ascontiguousarray(np.asarray(self.component, dtype=np.int32).reshape(-1))
        if len(self.component) != m:
            raise MeshValidationError(f"component has {len(self.component)} entries for {m} faces")
        ncomp = int(self.component.max()) + 1 if m else 0
        self.component_names = [str(s) for s in self.component_names]
        if len(self.component_names) < ncomp:
            self.component_names = padded_names(self.component_names, ncomp)
        if self.fixed_vertices is None:
            self.fixed_vertices = np.zeros(0, dtype=np.int64)
        self.fixed_vertices = np.unique(np.asarray(self.fixed_vertices, dtype=np.int64).reshape(-1))
        if self.feature_edges is None:
            self.feature_edges = np.zeros((0, 2), dtype=np.int64)
            self.feature_edge_ids = np.zeros(0, dtype=np.int32)
        fe = np.asarray(self.feature_edges, dtype=np.int64).reshape(-1, 2)
        ids = (np.full(len(fe), -1, dtype=np.int32) if self.feature_edge_ids is None
               else np.asarray(self.feature_edge_ids, dtype=np.int32).reshape(-1))
        if len(ids) != len(fe):
            raise MeshValidationError(f"feature_edge_ids has {len(ids)} entries for {len(fe)} feature edges")
        self.feature_edges, self.feature_edge_ids = _unique_edges_with_ids(fe, ids)
        self._topo = None

    # ------------------------------------------------------------------ basics
    @property
    def n_points(self) -> int:
        return len(self.points)

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    @property
    def is_quad(self) -> np.ndarray:
        return self.faces[:, 3] >= 0

    @property
    def is_tri(self) -> np.ndarray:
        return self.faces[:, 3] < 0

    @property
    def n_quads(self) -> int:
        return int(self.is_quad.sum())

    @property
    def n_tris(self) -> int:
        return int(self.is_tri.sum())

    @property
    def diagonal(self) -> float:
        """Length of the bounding-box diagonal of the points (0 for no points)."""
        if not len(self.points):
            return 0.0
        return bbox_diagonal(self.points)

    def with_points(self, points) -> "ShellMesh":
        """The same mesh (faces, components, fixed vertices, feature edges: shared, not copied)
        on other ``points`` (n_points, 3): a smoothing's or a projection's result."""
        return ShellMesh(points, self.faces, self.component, list(self.component_names), self.fixed_vertices,
                         self.feature_edges, self.feature_edge_ids)

    def copy(self) -> "ShellMesh":
        return ShellMesh(self.points.copy(), self.faces.copy(), self.component.copy(),
                         list(self.component_names), self.fixed_vertices.copy(),
                         self.feature_edges.copy(), self.feature_edge_ids.copy())

    def component_id(self, name: str) -> int:
        """Id of a component name, adding the name to the table if new."""
        if name in self.component_names:
            return self.component_names.index(name)
        self.component_names.append(name)
        return len(self.component_names) - 1

    def face_corners(self) -> np.ndarray:
        """(m, 4, 3) corner coordinates; a triangle repeats its first corner in slot 4."""
        f = np.where(self.faces >= 0, self.faces, self.faces[:, :1])
        return self.points[f]

    def triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """Split every quad into two triangles (0,1,2),(0,2,3).

        Returns ``(tris, parent)``: (t, 3) node indices and the face each came from.
        """
        q = np.flatnonzero(self.is_quad)
        t = np.flatnonzero(self.is_tri)
        tris = np.vstack([self.faces[t, :3], self.faces[q][:, [0, 1, 2]], self.faces[q][:, [0, 2, 3]]])
        parent = np.concatenate([t, q, q])
        order = np.argsort(parent, kind="stable")
        return tris[order], parent[order]

    # ------------------------------------------------------------ geometry
    def face_area_vectors(self) -> np.ndarray:
        """(m, 3) area vectors: unit normal times area (quads: half the diagonals' cross product)."""
        c = self.face_corners()
        tri = self.is_tri
        v = 0.5 * np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1])
        if tri.any():
            ct = c[tri]
            v[tri] = 0.5 * np.cross(ct[:, 1] - ct[:, 0], ct[:, 2] - ct[:, 0])
        return v

    def face_areas(self) -> np.ndarray:
        return norm_rows(self.face_area_vectors(), axis=1)

    def face_normals(self) -> np.ndarray:
        v = self.face_area_vectors()
        n = norm_rows(v, axis=1, keepdims=True)
        return np.divide(v, n, out=np.zeros_like(v), where=n > 0)

    def face_centroids(self) -> np.ndarray:
        c = self.face_corners()
        k = np.where(self.is_tri, 3.0, 4.0)[:, None]
        s = c.sum(1) - np.where(self.is_tri[:, None], c[:, 3], 0.0)
        return s / k

    def vertex_normals(self) -> np.ndarray:
        """(n, 3) area-weighted unit vertex normals (zero for unreferenced nodes)."""
        av = self.face_area_vectors()
        f = self.faces
        valid = f >= 0
        idx = f[valid]
        w = np.repeat(av[:, None, :], 4, axis=1)[valid]
        acc = np.zeros((self.n_points, 3))
        for d in range(3):
            acc[:, d] = np.bincount(idx, weights=w[:, d], minlength=self.n_points)
        n = norm_rows(acc, axis=1, keepdims=True)
        return np.divide(acc, n, out=np.zeros_like(acc), where=n > 0)

    # ------------------------------------------------------------ topology
    def topology(self) -> EdgeTopology:
        """Unique edges and their incident faces (cached until faces change)."""
        key = (id(self.faces), self.faces.shape, self.n_points)
        if self._topo is not None and self._topo[0] == key:
            return self._topo[1]
        topo = edge_topology(self.faces)
        self._topo = (key, topo)
        return topo

    def edges(self) -> np.ndarray:
        return self.topology().edges

    def boundary_edges(self) -> np.ndarray:
        """(b, 2) node pairs of the edges with exactly one incident face."""
        t = self.topology()
        return t.edges[t.boundary]

    def nonmanifold_edges(self) -> np.ndarray:
        t = self.topology()
        return t.edges[t.nonmanifold]

    def sharp_edges(self, angle: float = 30.0) -> np.ndarray:
        """(k, 2) node pairs of the manifold edges whose two faces' normals differ by more
        than ``angle`` degrees (creases: trailing edges, tip caps), plus open boundary edges."""
        topo = self.topology()
        nrm = self.face_normals()
        two = np.flatnonzero(topo.valence == 2)
        f0 = topo.edge_faces[topo.edge_faces_ptr[two]]
        f1 = topo.edge_faces[topo.edge_faces_ptr[two] + 1]
        cos = np.einsum("ij,ij->i", nrm[f0], nrm[f1])
        keep = np.concatenate([two[cos < np.cos(np.radians(angle))], np.flatnonzero(topo.valence == 1)])
        return topo.edges[np.sort(keep)]

    def edge_lengths(self) -> np.ndarray:
        e = self.edges()
        return norm_rows(self.points[e[:, 1]] - self.points[e[:, 0]], axis=1)

    def n_bodies(self) -> int:
        """Number of face-connected pieces (faces connected through shared edges)."""
        if not self.n_faces:
            return 0
        t = self.topology()
        he = np.argsort(t.he_edge, kind="stable")
        e = t.he_edge[he]
        f = t.he_face[he]
        same = e[1:] == e[:-1]
        a, b = f[:-1][same], f[1:][same]
        from scipy import sparse
        from scipy.sparse.csgraph import connected_components

        g = sparse.coo_matrix((np.ones(len(a)), (a, b)), shape=(self.n_faces, self.n_faces))
        return int(connected_components(g, directed=False)[0])

    def is_closed(self) -> bool:
        """True when every edge has exactly two incident faces."""
        t = self.topology()
        return bool(len(t.edges)) and bool((t.valence == 2).all())

    # ------------------------------------------------------------ editing
    def submesh(self, face_mask) -> "ShellMesh":
        """Faces selected by a mask or index array; nodes kept as they are (indices unchanged)."""
        sel = np.asarray(face_mask)
        if sel.dtype == bool:
            sel = np.flatnonzero(sel)
        return ShellMesh(self.points, self.faces[sel], self.component[sel], list(self.component_names),
                         self.fixed_vertices, self.feature_edges, self.feature_edge_ids)

    def compact(self) -> tuple["ShellMesh", np.ndarray]:
        """Drop unreferenced nodes. Returns the new mesh and ``old_to_new`` (-1 for dropped)."""
        used = np.zeros(self.n_points, bool)
        used[self.faces[self.faces >= 0]] = True
        fe = self.feature_edges
        keep_fe = used[fe].all(1) if len(fe) else np.zeros(0, bool)
        old_to_new = np.full(self.n_points, -1, dtype=np.int64)
        old_to_new[used] = np.arange(int(used.sum()))
        faces = np.where(self.faces >= 0, old_to_new[np.maximum(self.faces, 0)], -1)
        fv = old_to_new[self.fixed_vertices]
        m = ShellMesh(self.points[used], faces, self.component, list(self.component_names),
                      fv[fv >= 0], old_to_new[fe[keep_fe]], self.feature_edge_ids[keep_fe])
        return m, old_to_new

    # ------------------------------------------------------------ validation
    def check(self, tol: float = 1e-9) -> MeshCheck:
        """Find duplicate points (within ``tol`` times the diagonal), degenerate faces,
        unreferenced points, inconsistent orientation within a component, and hanging nodes."""
        pts = self.points
        finite = np.isfinite(pts).all(1)
        nonfinite = np.flatnonzero(~finite)
        diag = bbox_diagonal(pts[finite]) if finite.any() else 0.0
        eps = tol * diag if diag > 0 else tol
        if len(nonfinite):
            empty2 = np.zeros((0, 2), np.int64)
            return MeshCheck(empty2, np.zeros(0, np.int64), np.zeros(0, np.int64), empty2,
                             np.zeros((0, 3), np.int64), nonfinite)
        from scipy.spatial import cKDTree

        dup = np.array(sorted(cKDTree(pts).query_pairs(eps)), dtype=np.int64).reshape(-1, 2) \
            if len(pts) else np.zeros((0, 2), np.int64)
        # degenerate: repeated node in a face or area below eps^2-scale
        f = self.faces
        tri = self.is_tri
        rep = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
        rep |= ~tri & ((f[:, 3] == f[:, 0]) | (f[:, 3] == f[:, 1]) | (f[:, 3] == f[:, 2]))
        area = self.face_areas() if len(f) else np.zeros(0)
        degenerate = np.flatnonzero(rep | (area <= (tol * diag) ** 2 if diag > 0 else area <= 0))
        used = np.zeros(len(pts), bool)
        used[f[f >= 0]] = True
        unref = np.flatnonzero(~used)
        topo = self.topology()
        inconsistent = _inconsistent_edges(topo, self.component)
        hanging = _hanging_nodes(pts, topo, eps)
        return MeshCheck(dup, degenerate, unref, inconsistent, hanging, nonfinite)

    def validate(self, tol: float = 1e-9, allow_unreferenced: bool = False) -> None:
        """Raise :class:`MeshValidationError` listing every problem :meth:`check` finds."""
        c = self.check(tol)
        if allow_unreferenced:
            c.unreferenced_points = np.zeros(0, np.int64)
        if not c.ok:
            raise MeshValidationError("invalid mesh: " + "; ".join(c.problems()))


def _unique_edges_with_ids(fe: np.ndarray, ids: np.ndarray):
    if not len(fe):
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int32)
    fe = np.sort(fe, axis=1)
    order = np.lexsort((ids, fe[:, 1], fe[:, 0]))
    fe, ids = fe[order], ids[order]
    keep = np.ones(len(fe), bool)
    keep[1:] = (fe[1:] != fe[:-1]).any(1)
    return np.ascontiguousarray(fe[keep]), np.ascontiguousarray(ids[keep])


def _pair_runs(lo, hi):
    """The pairs ``(lo[i], hi[i])`` (non-empty, non-negative ids) in sorted order, stably (two
    counting sorts, :func:`~shellmesh_mdao.core.kernels.stable_pair_order`): ``(order, first,
    pairs)``, ``first`` marking the first of each run of one pair in that order and ``pairs``
    (runs, 2) the distinct pairs."""
    order = _k.stable_pair_order(lo, hi, int(hi.max()) + 1)
    slo, shi = lo[order], hi[order]
    first = np.ones(len(order), bool)
    first[1:] = (slo[1:] != slo[:-1]) | (shi[1:] != shi[:-1])
    return order, first, np.stack([slo[first], shi[first]], 1)


def unique_edges(a, b) -> np.ndarray:
    """The distinct node pairs among ``(a[i], b[i])`` (non-negative ids, either order), each
    as (lower, higher), sorted: ``np.unique(np.sort(np.stack([a, b], 1), axis=1), axis=0)``'s
    array, by two counting sorts instead of a row sort."""
    a = np.asarray(a, np.int64).reshape(-1)
    b = np.asarray(b, np.int64).reshape(-1)
    if not len(a):
        return np.zeros((0, 2), np.int64)
    return _pair_runs(np.minimum(a, b), np.maximum(a, b))[2]


def edge_topology(faces: np.ndarray) -> EdgeTopology:
    """Build the :class:`EdgeTopology` of an (m, 4) face array (vectorised)."""
    faces = _as_faces(faces)
    m = len(faces)
    a = faces
    b = np.roll(faces, -1, axis=1)
    tri = faces[:, 3] < 0
    b[tri, 2] = faces[tri, 0]
    valid = np.ones((m, 4), bool)
    valid[tri, 3] = False
    he_face, he_side = np.nonzero(valid)
    he_from = a[he_face, he_side]
    he_to = b[he_face, he_side]
    lo = np.minimum(he_from, he_to)
    hi = np.maximum(he_from, he_to)
    if len(lo):
        # the half-edges in the order of their node pairs (stable: within a pair, in half-edge
        # order, which is face order); each run of one pair is an edge
        order, first, edges = _pair_runs(lo, hi)
        he_edge = np.empty(len(order), np.int64)
        he_edge[order] = np.cumsum(first) - 1
    else:
        edges, he_edge, order = np.zeros((0, 2), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    face_edges = np.full((m, 4), -1, dtype=np.int64)
    face_edges[he_face, he_side] = he_edge
    valence = np.bincount(he_edge, minlength=len(edges))
    ptr = np.zeros(len(edges) + 1, dtype=np.int64)
    np.cumsum(valence, out=ptr[1:])
    return EdgeTopology(edges.astype(np.int64), face_edges, valence, ptr, he_face[order],
                        he_face, he_side, he_edge, he_from, he_to)


def vertex_faces(faces: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR list of the faces around each vertex of a face array ((m, 3) triangles or
    (m, 4) mixed, -1 padded): ``faces_of_v = idx[ptr[v]:ptr[v + 1]]`` (ascending face order)."""
    from .core.kernels import vertex_faces as _compiled
    return _compiled(faces, n_points)


def _inconsistent_edges(topo: EdgeTopology, component: np.ndarray) -> np.ndarray:
    """Manifold edges whose two faces (same component) traverse the edge in the same direction."""
    man = np.flatnonzero(topo.valence == 2)
    if not len(man):
        return np.zeros((0, 2), np.int64)
    order = np.argsort(topo.he_edge, kind="stable")
    e_sorted = topo.he_edge[order]
    first = np.searchsorted(e_sorted, man)
    h0, h1 = order[first], order[first + 1]
    same_dir = topo.he_from[h0] == topo.he_from[h1]
    same_comp = component[topo.he_face[h0]] == component[topo.he_face[h1]]
    return topo.edges[man[same_dir & same_comp]]


def _hanging_nodes(pts: np.ndarray, topo: EdgeTopology, eps: float) -> np.ndarray:
    """Rows (a, b, c): boundary edge a-b has node c (another boundary node) in its interior."""
    bnd = topo.edges[topo.boundary]
    if len(bnd) < 3:
        return np.zeros((0, 3), np.int64)
    from scipy.spatial import cKDTree

    bnodes = np.unique(bnd)
    tree = cKDTree(pts[bnodes])
    p0, p1 = pts[bnd[:, 0]], pts[bnd[:, 1]]
    mid = 0.5 * (p0 + p1)
    half = 0.5 * norm_rows(p1 - p0, axis=1)
    cand = tree.query_ball_point(mid, half * (1 + 1e-9) + eps)
    counts = np.fromiter((len(c) for c in cand), dtype=np.int64, count=len(cand))
    if not counts.sum():
        return np.zeros((0, 3), np.int64)
    ei = np.repeat(np.arange(len(bnd)), counts)
    ci = bnodes[np.concatenate([np.asarray(c, dtype=np.int64) for c in cand if len(c)])]
    a, b = bnd[ei, 0], bnd[ei, 1]
    keep = (ci != a) & (ci != b)
    a, b, ci, ei = a[keep], b[keep], ci[keep], ei[keep]
    d = pts[b] - pts[a]
    L2 = (d * d).sum(1)
    t = ((pts[ci] - pts[a]) * d).sum(1) / np.where(L2 > 0, L2, 1.0)
    foot = pts[a] + t[:, None] * d
    dist = norm_rows(pts[ci] - foot, axis=1)
    hit = (t > 1e-6) & (t < 1 - 1e-6) & (dist <= np.maximum(eps, 1e-6 * np.sqrt(L2)))
    return np.stack([a[hit], b[hit], ci[hit]], 1)


def merge_close_points(points: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Merge points closer than ``tol`` (absolute). Deterministic: each cluster keeps the
    coordinates of its lowest-index member and clusters are numbered in order of first
    appearance. Returns ``(new_points, old_to_new)``."""
    n = len(points)
    if n == 0:
        return points.copy(), np.zeros(0, np.int64)
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")
    if len(pairs) == 0:
        return points.copy(), np.arange(n, dtype=np.int64)
    g = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(g, directed=False)
    # representative = lowest index in the cluster; renumber in order of first appearance
    rep = np.full(label.max() + 1, n, dtype=np.int64)
    np.minimum.at(rep, label, np.arange(n))
    first_order = np.argsort(rep, kind="stable")
    new_id = np.empty_like(first_order)
    new_id[first_order] = np.arange(len(first_order))
    old_to_new = new_id[label]
    return points[np.sort(rep)], old_to_new


def concatenate(meshes, merge_tol: float | None = 1e-9) -> ShellMesh:
    """Join meshes into one, merging component tables by name and (unless ``merge_tol``
    is None) merging coincident nodes within ``merge_tol`` times the bounding-box
    diagonal, so meshes that share boundary nodes become one conforming mesh."""
    meshes = list(meshes)
    if not meshes:
        raise MeshValidationError("concatenate needs at least one mesh")
    names: list[str] = []
    pts, faces, comp, fixed, fe, fid = [], [], [], [], [], []
    off = 0
    for m in meshes:
        remap = np.array([names.index(n) if n in names else (names.append(n) or len(names) - 1)
                          for n in m.component_names], dtype=np.int32)
        pts.append(m.points)
        faces.append(np.where(m.faces >= 0, m.faces + off, -1))
        comp.append(remap[m.component] if len(m.component) else m.component)
        fixed.append(m.fixed_vertices + off)
        fe.append(m.feature_edges + off)
        fid.append(np.where(m.feature_edge_ids >= 0, remap[np.maximum(m.feature_edge_ids, 0)]
                            if len(remap) else -1, -1))
        off += m.n_points
    out = ShellMesh(np.vstack(pts), np.vstack(faces), np.concatenate(comp), names,
                    np.concatenate(fixed), np.vstack(fe), np.concatenate(fid))
    if merge_tol is None:
        return out
    newp, o2n = merge_close_points(out.points, merge_tol * max(out.diagonal, 1e-300))
    f = np.where(out.faces >= 0, o2n[np.maximum(out.faces, 0)], -1)
    return ShellMesh(newp, f, out.component, out.component_names, o2n[out.fixed_vertices],
                     o2n[out.feature_edges], out.feature_edge_ids)
