"""Dirty inputs: the defects of a loaded surface counted (:func:`describe_surface`) and handled
or refused (:func:`repair_defects`): orientation per body, open boundaries and half models'
symmetry planes, intersecting bodies joined by a boolean union (manifold3d), units warnings."""
from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from ..core.topology import canonical_triangles
from ..errors import MeshValidationError
from ..mesh import ShellMesh
from .gaps import gap_closures, gap_text
from .raw import DEFAULT_NAME
from .report import AXES, SurfaceReport, plane_text

__all__ = ["UNITS_DIAGONAL_RANGE", "SYMMETRY_TOL", "SYMMETRY_MAX_COS", "SYMMETRY_MAX_SHALLOW", "SYMMETRY_MAX_FLAT",
           "symmetry_boundary_vertices", "describe_surface", "repair_defects", "read_as_skin"]


# =========================================================================== dirty inputs
#: A surface whose bounding-box diagonal is outside this range gets a units warning.
UNITS_DIAGONAL_RANGE = (1e-3, 1e5)
#: Open-boundary vertices within this fraction of the diagonal of one plane lie "in" it.
SYMMETRY_TOL = 1e-5
#: A face next to a symmetry-plane boundary with |n_face . n_plane| above this lies at a
#: shallow angle to the plane (within about 25 degrees of it).
SYMMETRY_MAX_COS = 0.9
#: A half model's surface crosses its symmetry plane: faces at a shallow angle to the plane
#: (a thin fin or trailing edge meeting it) may line at most this fraction of the boundary's
#: length; more is a hole in a flat (or gently curved) face.
SYMMETRY_MAX_SHALLOW = 0.5
#: Faces lying in a symmetry plane (every vertex within :data:`SYMMETRY_TOL`) next to its
#: boundary are accepted only as thin strips along it: every vertex of such a patch within this
#: fraction of the diagonal of the boundary (where a thin fin or trailing edge meets the plane at
#: a shallow angle). A wider patch is a flat face with a hole in it, not a half model.
SYMMETRY_MAX_FLAT = 1e-3


def _orientation_conflicts(mesh: ShellMesh) -> int:
    t = mesh.topology()
    man = np.flatnonzero(t.valence == 2)
    if not len(man):
        return 0
    order = np.argsort(t.he_edge, kind="stable")
    first = np.searchsorted(t.he_edge[order], man)
    h0, h1 = order[first], order[first + 1]
    return int((t.he_from[h0] == t.he_from[h1]).sum())


def _units_note(fmt: str) -> str:
    if fmt in ("STEP", "IGES"):
        return "millimetres (OpenCASCADE default for STEP/IGES)"
    return "the file's own length units (the format records none)"


def _face_bodies(topo, n_faces: int) -> np.ndarray:
    """Body (edge-connected piece) label of every face; labels numbered by lowest face."""
    if not n_faces:
        return np.zeros(0, np.int64)
    he = np.argsort(topo.he_edge, kind="stable")
    e = topo.he_edge[he]
    f = topo.he_face[he]
    same = e[1:] == e[:-1]
    a, b = f[:-1][same], f[1:][same]
    g = sparse.coo_matrix((np.ones(len(a)), (a, b)), shape=(n_faces, n_faces))
    _, lab = connected_components(g, directed=False)
    return _renumber_by_first(lab)


def _renumber_by_first(lab: np.ndarray) -> np.ndarray:
    """Relabel so that labels appear in increasing order of their first occurrence."""
    _, first, inv = np.unique(lab, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inv.reshape(-1)]


def _flip_faces(faces: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Reverse the orientation of ``faces[rows]`` keeping the first corner."""
    f = faces.copy()
    if not len(rows):
        return f
    quad = f[rows, 3] >= 0
    t, q = rows[~quad], rows[quad]
    f[t, 1], f[t, 2] = faces[t, 2], faces[t, 1]
    f[q, 1], f[q, 3] = faces[q, 3], faces[q, 1]
    return f


def _edge_where(points: np.ndarray, edges: np.ndarray, k: int = 3) -> str:
    """'at (x, y, z), (x, y, z) ...' for the midpoints of the first ``k`` edges."""
    mid = 0.5 * (points[edges[:k, 0]] + points[edges[:k, 1]])
    more = f" and {len(edges) - k} more" if len(edges) > k else ""
    return "at " + ", ".join("(" + ", ".join(f"{v:.6g}" for v in p) + ")" for p in mid) + more


def _orient_consistently(mesh: ShellMesh, body: np.ndarray, name: str) -> tuple[np.ndarray, int]:
    """Faces re-oriented so that every manifold edge is traversed once each way, per body
    (the orientation most of the body's faces have is kept; a tie keeps the lowest face's).
    Vectorised: the face graph is doubled (face f in state 0 and state 1) and an edge joins
    equal or opposite states by whether the two faces agree; a component holding both states
    of a face is a non-orientable body.
    Returns (faces, number of faces flipped)."""
    topo = mesh.topology()
    m = mesh.n_faces
    man = np.flatnonzero(topo.valence == 2)
    if not len(man):
        return mesh.faces.copy(), 0
    order = np.argsort(topo.he_edge, kind="stable")
    first = np.searchsorted(topo.he_edge[order], man)
    h0, h1 = order[first], order[first + 1]
    f0, f1 = topo.he_face[h0], topo.he_face[h1]
    flip = (topo.he_from[h0] == topo.he_from[h1]).astype(np.int64)   # same direction: must differ
    a = np.concatenate([f0, f0 + m])
    b = np.concatenate([f1 + flip * m, f1 + (1 - flip) * m])
    g = sparse.coo_matrix((np.ones(len(a)), (a, b)), shape=(2 * m, 2 * m))
    _, lab = connected_components(g, directed=False)
    bad = np.flatnonzero(lab[:m] == lab[m:])
    if len(bad):
        c = mesh.face_centroids()[bad[0]]
        raise MeshValidationError(
            f"{name}: a body of the surface is non-orientable (a Moebius-like band: its faces cannot all face "
            f"the same side; e.g. face {int(bad[0])} at ({', '.join(f'{v:.6g}' for v in c)})); re-export the "
            "surface as closed shells with consistent normals")
    # per body, the state holding most faces keeps its orientation (ties: the lowest face's)
    nb = int(body.max()) + 1
    root = np.full(nb, m, np.int64)
    np.minimum.at(root, body, np.arange(m))
    other = lab[:m] != lab[root[body]]
    n_other = np.bincount(body, weights=other, minlength=nb)
    n_all = np.bincount(body, minlength=nb)
    swap = n_other > n_all - n_other
    rows = np.flatnonzero(other != swap[body])
    return _flip_faces(mesh.faces, rows), len(rows)


def _signed_volumes(points, faces, body, n_body, apex) -> np.ndarray:
    """Signed volume of every body: cones from ``apex[body]`` over its faces (quads split)."""
    tri_a = faces[:, [0, 1, 2]]
    quad = np.flatnonzero(faces[:, 3] >= 0)
    t = np.vstack([tri_a, faces[quad][:, [0, 2, 3]]])
    tb = np.concatenate([body, body[quad]])
    ap = apex[tb]
    v = points[t] - ap[:, None, :]
    vol = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])) / 6.0
    return np.bincount(tb, weights=vol, minlength=n_body)


def _boundary_info(mesh: ShellMesh, tol_frac: float = SYMMETRY_TOL):
    """Classify the open boundary of a mesh.

    Returns ``(n_loops, plane, reason)``: ``plane`` is a dict (normal pointing away from the
    surface, a point, the axis name for a coordinate plane) when every open-boundary vertex
    lies in one plane, the whole surface lies on one side of it and no face next to the
    boundary lies in it (a half model cut at its symmetry plane); otherwise ``None`` and
    ``reason`` says why (``""`` for a closed surface)."""
    topo = mesh.topology()
    be = topo.edges[topo.valence == 1]
    if not len(be):
        return 0, None, ""
    bv, inv = np.unique(be, return_inverse=True)
    inv = inv.reshape(-1, 2)
    g = sparse.coo_matrix((np.ones(len(be)), (inv[:, 0], inv[:, 1])), shape=(len(bv), len(bv)))
    n_loops = int(connected_components(g, directed=False)[0])
    P = mesh.points[bv]
    diag = mesh.diagonal
    tol = tol_frac * diag
    lo, hi = P.min(0), P.max(0)
    spread = hi - lo
    ax = int(np.argmin(spread))
    if spread[ax] <= tol:
        normal = np.zeros(3)
        normal[ax] = 1.0
        point = 0.5 * (lo + hi)
        point[ax] = float(np.median(P[:, ax]))
        axis = AXES[ax]
    else:
        c = P.mean(0)
        _, s, vt = np.linalg.svd(P - c, full_matrices=False)
        normal, point, axis = vt[2], c, None
        if len(s) < 3 or s[1] <= tol * np.sqrt(len(P)):
            return n_loops, None, "the open boundary edges lie along one line (a crack or an unzipped seam)"
        d = (P - c) @ normal
        if np.abs(d).max() > tol:
            k = int(np.argmax(np.abs(d)))
            return n_loops, None, (
                f"the {len(be)} open boundary edges ({n_loops} loop{'s' if n_loops > 1 else ''}) do not lie in "
                f"one plane (vertex at ({', '.join(f'{v:.6g}' for v in P[k])}) is {abs(d[k]):.3g} off their "
                "best-fit plane)")
    d_all = (mesh.points - point) @ normal
    if d_all.max() > tol and d_all.min() < -tol:
        return n_loops, None, (
            f"the open boundary lies in the plane {plane_text(normal, point, axis)} but the surface lies on "
            "both sides of it, so it is not a half model cut at that plane")
    if d_all.max() > tol:
        normal = -normal
    # the surface must cross the plane: faces at a shallow angle along at most part of the
    # boundary (thin features), and faces lying in it only as thin strips
    bid = np.flatnonzero(topo.valence == 1)
    fb = topo.edge_faces[topo.edge_faces_ptr[bid]]
    cos = np.abs(mesh.face_normals()[fb] @ normal)
    elen = np.linalg.norm(mesh.points[topo.edges[bid, 1]] - mesh.points[topo.edges[bid, 0]], axis=1)
    shallow = float(elen[cos > SYMMETRY_MAX_COS].sum() / max(elen.sum(), 1e-300))
    k = int(fb[np.argmax(cos)]) if shallow > SYMMETRY_MAX_SHALLOW else _flat_face_next_to(mesh, topo, d_all, tol)
    if k >= 0:
        c = mesh.points[mesh.faces[k, :3]].mean(0)
        return n_loops, None, (
            f"the open boundary lies in the plane {plane_text(normal, point, axis)} but faces next to it lie in "
            f"that plane too (face {k} at ({', '.join(f'{v:.6g}' for v in c)}); faces within 25 degrees of the "
            f"plane along {100 * shallow:.0f}% of the boundary): a hole in a flat face, not a half model cut at "
            "its symmetry plane")
    plane = {"normal": [float(v) + 0.0 for v in normal], "point": [float(v) for v in point],
             "offset": float(point @ normal), "axis": axis}
    return n_loops, plane, ""


def _flat_face_next_to(mesh: ShellMesh, topo, d_all, tol) -> int:
    """A face lying in the plane (every vertex within ``tol``; ``d_all`` the signed distances
    of all vertices) next to the open boundary, in a patch of such faces with a vertex farther
    than :data:`SYMMETRY_MAX_FLAT` of the diagonal from the open boundary: a flat face with a
    hole, not a thin strip where a thin feature meets the plane at a shallow angle. ``-1``
    when there is none."""
    f = mesh.faces
    flat = np.all((np.abs(d_all[f]) <= tol) | (f < 0), axis=1)
    fb = topo.edge_faces[topo.edge_faces_ptr[np.flatnonzero(topo.valence == 1)]]
    if not flat[fb].any():
        return -1
    # patches of flat faces (connected across edges), those touching the boundary
    man = np.flatnonzero(topo.valence == 2)
    f0 = topo.edge_faces[topo.edge_faces_ptr[man]]
    f1 = topo.edge_faces[topo.edge_faces_ptr[man] + 1]
    both = flat[f0] & flat[f1]
    g = sparse.coo_matrix((np.ones(int(both.sum())), (f0[both], f1[both])), shape=(mesh.n_faces, mesh.n_faces))
    _, lab = connected_components(g, directed=False)
    touching = np.unique(lab[fb[flat[fb]]])
    rows = np.flatnonzero(flat & np.isin(lab, touching))
    from scipy.spatial import cKDTree

    # distance to the boundary: to points along its edges at most a quarter of the limit apart
    limit = SYMMETRY_MAX_FLAT * mesh.diagonal
    be = topo.edges[topo.valence == 1]
    a, b = mesh.points[be[:, 0]], mesh.points[be[:, 1]]
    k = np.maximum(np.ceil(np.linalg.norm(b - a, axis=1) / (0.25 * limit)).astype(np.int64), 1) + 1
    t = (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)) / np.repeat(k - 1, k)
    samples = np.repeat(a, k, axis=0) + t[:, None] * np.repeat(b - a, k, axis=0)
    v = np.unique(f[rows][f[rows] >= 0])
    far = cKDTree(samples).query(mesh.points[v])[0] > limit
    if not far.any():
        return -1
    wide = np.unique(lab[rows[np.isin(f[rows], v[far]).any(1)]])
    return int(fb[flat[fb] & np.isin(lab[fb], wide)].min())


def _n_zero_area(mesh: ShellMesh) -> int:
    """Number of faces of exactly zero area (a quad: both halves)."""
    f = mesh.faces
    p = mesh.points
    z = ~(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]) != 0).any(1)
    quad = np.flatnonzero(z & (f[:, 3] >= 0))
    if len(quad):
        g = f[quad]
        z[quad] = ~(np.cross(p[g[:, 2]] - p[g[:, 0]], p[g[:, 3]] - p[g[:, 0]]) != 0).any(1)
    return int(z.sum())


def _any_positive_area(mesh: ShellMesh) -> bool:
    """Whether some face has a non-zero area (relative to the diagonal: no underflow); the
    first faces are tried first, so a valid surface costs next to nothing."""
    lo = mesh.points.min(0)
    scale = max(mesh.diagonal, 1e-300)
    for rows in (np.arange(min(mesh.n_faces, 4096)), np.arange(mesh.n_faces)):
        f = mesh.faces[rows]
        p = (mesh.points[f[:, :3]] - lo) / scale
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        if (np.abs(n).max(1) > 1e-24).any():
            return True
        quad = f[:, 3] >= 0
        if quad.any():
            q = (mesh.points[f[quad][:, [0, 2, 3]]] - lo) / scale
            if (np.abs(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])).max(1) > 1e-24).any():
                return True
    return False


def symmetry_boundary_vertices(mesh: ShellMesh, plane: dict, tol: float = SYMMETRY_TOL) -> np.ndarray:
    """Sorted indices of the open-boundary vertices of ``mesh`` that lie in the symmetry
    ``plane`` (a :attr:`SurfaceReport.symmetry_plane` dict) within ``tol`` times the
    diagonal: the nodes to clamp (or give symmetry conditions) in an analysis of a half
    model, valid for any later mesh of the same surface (remeshed, imprinted, quads)."""
    if not plane:
        return np.zeros(0, np.int64)
    bv = np.unique(mesh.boundary_edges())
    if not len(bv):
        return bv.astype(np.int64)
    d = (mesh.points[bv] - np.asarray(plane["point"])) @ np.asarray(plane["normal"])
    return bv[np.abs(d) <= tol * max(mesh.diagonal, 1e-300)].astype(np.int64)


def _units_warnings(diag: float) -> list[str]:
    lo, hi = UNITS_DIAGONAL_RANGE
    if diag < lo:
        return [f"the surface is only {diag:.3g} units across (bounding-box diagonal): an aircraft in metres or "
                "millimetres is much larger; the file was probably written in kilometres or scaled by mistake. "
                "Rescale it so that one unit is a metre or a millimetre (the --size value is in the same units)"]
    if diag > hi:
        return [f"the surface is {diag:.3g} units across (bounding-box diagonal): that is {diag / 1000:.3g} m if "
                f"the units are millimetres and {diag / 1e6:.3g} m if they are micrometres; the file was "
                "probably written in micrometres (or millimetres of a very large aircraft) or scaled by mistake. "
                "Check the units and rescale if needed (the --size value is in the same units)"]
    return []


def _manifold(points, tris, name, what):
    import manifold3d as m3

    m = m3.Manifold(m3.Mesh64(np.ascontiguousarray(points, np.float64), np.ascontiguousarray(tris, np.uint64)))
    st = m.status()
    if st != m3.Error.NoError:
        raise MeshValidationError(
            f"{name}: cannot join {what} with manifold3d ({str(st).split('.')[-1]}): the body is not a closed, "
            "consistently oriented 2-manifold; export each body as a closed shell (or join the bodies in CAD)")
    return m.as_original()


def _body_triangles(faces, rows):
    f = faces[rows]
    quad = f[:, 3] >= 0
    tri = np.vstack([f[:, :3], f[quad][:, [0, 2, 3]]])
    src = np.concatenate([rows, rows[quad]])
    return tri, src


def _unite_bodies(mesh: ShellMesh, body: np.ndarray, plane, open_body: np.ndarray, name: str):
    """Boolean union (manifold3d) of every group of bodies whose volumes overlap. Open
    bodies of a half model are closed by their mirror image first and the union is cut back
    at the symmetry plane (its cap removed). Bodies that touch nothing keep their faces.
    Returns ``(mesh, groups)``: groups is a list of the united body lists."""
    import manifold3d as m3

    nb = int(body.max()) + 1
    if nb < 2:
        return mesh, []
    P, F = mesh.points, mesh.faces
    diag = mesh.diagonal
    corner_body = np.broadcast_to(body[:, None], F.shape)[F >= 0]
    order = np.argsort(corner_body, kind="stable")
    corner_pts = P[F[F >= 0]][order]
    starts = np.searchsorted(corner_body[order], np.arange(nb))
    lo = np.minimum.reduceat(corner_pts, starts, axis=0)
    hi = np.maximum.reduceat(corner_pts, starts, axis=0)
    if plane is not None:       # mirrored bodies: extend the boxes to their mirror images
        n, c = np.asarray(plane["normal"]), plane["offset"]
        box = np.stack([lo, hi], 1)                                        # (nb, 2, 3)
        corners = np.stack(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij"), -1).reshape(-1, 3)
        pts8 = box[:, corners, [0, 1, 2]]                                   # (nb, 8, 3)
        mir = pts8 - 2.0 * ((pts8 @ n) - c)[..., None] * n
        allp = np.concatenate([pts8, mir], 1)
        lo = np.where(open_body[:, None], allp.min(1), lo)
        hi = np.where(open_body[:, None], allp.max(1), hi)
    eps = 1e-9 * diag
    ov = ((lo[:, None, :] <= hi[None, :, :] + eps) & (lo[None, :, :] <= hi[:, None, :] + eps)).all(2)
    ia, ib = np.nonzero(np.triu(ov, 1))
    if not len(ia):
        return mesh, []
    mans: dict[int, object] = {}
    tri_src: dict[int, np.ndarray] = {}

    def manifold_of(b):
        if b in mans:
            return mans[b]
        rows = np.flatnonzero(body == b)
        tri, src = _body_triangles(F, rows)
        used, loc = np.unique(tri, return_inverse=True)
        loc = loc.reshape(-1, 3)
        V = P[used]
        if open_body[b]:
            if plane is None:
                raise MeshValidationError(
                    f"{name}: body {b} is open (not a closed shell) and overlaps another body, so they cannot be "
                    "joined; close it (or cut it exactly at the symmetry plane) in CAD")
            n, c = np.asarray(plane["normal"]), plane["offset"]
            d = V @ n - c
            on = np.zeros(len(used), bool)
            bnd = np.unique(mesh.boundary_edges())
            on[np.isin(used, bnd)] = True
            V = V.copy()
            V[on] -= d[on, None] * n                    # snap the cut onto the plane
            Vm = V - 2.0 * (V @ n - c)[:, None] * n
            idx = np.where(on, np.arange(len(V)), len(V) + np.cumsum(~on) - 1)
            V = np.vstack([V, Vm[~on]])
            loc = np.vstack([loc, idx[loc][:, ::-1]])
            src = np.concatenate([src, src])
        mans[b] = _manifold(V, loc, name, f"body {b}")
        tri_src[mans[b].original_id()] = src
        return mans[b]

    inter = []
    for a, b in zip(ia.tolist(), ib.tolist()):
        A, B = manifold_of(a), manifold_of(b)
        v = (A ^ B).volume()
        if v > 1e-12 * max(min(A.volume(), B.volume()), 0.0):
            inter.append((a, b))
    if not inter:
        return mesh, []
    ea = np.array(inter, np.int64)
    g = sparse.coo_matrix((np.ones(len(ea)), (ea[:, 0], ea[:, 1])), shape=(nb, nb))
    _, grp = connected_components(g, directed=False)
    sizes = np.bincount(grp)
    groups = [np.flatnonzero(grp == k).tolist() for k in np.unique(grp[sizes[grp] > 1])]
    groups.sort(key=lambda gl: gl[0])
    keep = ~np.isin(body, [b for gl in groups for b in gl])
    pieces = [mesh.submesh(keep).compact()[0]] if keep.any() else []
    for gl in groups:
        U = m3.Manifold.batch_boolean([manifold_of(b) for b in gl], m3.OpType.Add)
        if plane is not None:
            U = U.trim_by_plane([-v for v in plane["normal"]], -plane["offset"])
        out = U.to_mesh64()
        V = np.asarray(out.vert_properties, np.float64)[:, :3]
        T = np.asarray(out.tri_verts, np.int64).reshape(-1, 3)
        run = np.asarray(out.run_index, np.int64) // 3
        rid = np.asarray(out.run_original_id, np.int64)
        fid = np.asarray(out.face_id, np.int64)
        comp = np.full(len(T), -1, np.int64)
        for r in range(len(rid)):
            s = tri_src.get(int(rid[r]))
            if s is not None:                   # else the cap made by the cut: dropped
                comp[run[r]:run[r + 1]] = mesh.component[s[fid[run[r]:run[r + 1]]]]
        T, comp = T[comp >= 0], comp[comp >= 0]
        V, T, order = canonical_triangles(V, T)
        comp = comp[order]
        pieces.append(ShellMesh(V, T, comp.astype(np.int32), list(mesh.component_names)).compact()[0])
    from ..mesh import concatenate
    return concatenate(pieces, merge_tol=None), groups


def describe_surface(mesh: ShellMesh, fmt: str, path: str, counts: dict, notes: list, known: dict | None = None
              ) -> SurfaceReport:
    """The report of ``mesh``; ``known`` holds counts the caller already has (``n_bodies``,
    ``n_inconsistent``) so they are not computed again."""
    known = known or {}
    topo = mesh.topology()
    lo = mesh.points.min(0)
    hi = mesh.points.max(0)
    present = np.unique(mesh.component)
    n_loops, plane, _ = _boundary_info(mesh)
    report = SurfaceReport(
        path=path, format=fmt, n_triangles=mesh.n_tris, n_quads=mesh.n_quads,
        n_vertices=mesh.n_points, bbox_min=tuple(float(v) for v in lo), bbox_max=tuple(float(v) for v in hi),
        diagonal=mesh.diagonal, closed=mesh.is_closed(),
        n_open_boundary_edges=int((topo.valence == 1).sum()),
        n_nonmanifold_edges=int((topo.valence > 2).sum()), n_bodies=known["n_bodies"] if "n_bodies" in known else mesh.n_bodies(),
        n_inconsistent_orientation_edges=known["n_inconsistent"] if "n_inconsistent" in known
        else _orientation_conflicts(mesh),
        n_merged_vertices=int(counts.get("merged", 0)), n_removed_duplicate_faces=int(counts.get("dup", 0)),
        n_removed_degenerate_faces=int(counts.get("deg", 0)), n_zero_area_faces=_n_zero_area(mesh),
        n_components=len(present), component_names=[mesh.component_names[i] for i in present],
        units=_units_note(fmt), notes=list(notes), n_boundary_loops=n_loops, symmetry_plane=plane,
        symmetry_vertices=symmetry_boundary_vertices(mesh, plane).tolist() if plane else [],
        closed_gaps=list(known.get("gaps", [])), warnings=_units_warnings(mesh.diagonal))
    return report


def repair_defects(mesh: ShellMesh, name: str, allow_open: bool, union: bool, close_gaps: bool = True):
    """Handle or refuse the defects :func:`describe_surface` found (see :func:`repair_surface`).
    Returns ``(mesh, repairs, warnings, known)``; ``known`` holds counts the report need not
    compute again and ``gaps``, the gaps closed by strips (:func:`~.gaps.gap_closures`)."""
    repairs, warns = [], []
    topo = mesh.topology()
    nm = np.flatnonzero(topo.valence > 2)
    if len(nm):
        raise MeshValidationError(
            f"{name}: {len(nm)} non-manifold edges (shared by 3 or more faces) "
            f"{_edge_where(mesh.points, topo.edges[nm])}: internal walls, T-joints or overlapping copies. "
            "Export only the outer skin, as one closed shell per body (remove internal faces); intersecting "
            "closed bodies are then joined automatically")
    if not _any_positive_area(mesh):
        raise MeshValidationError(f"{name}: every face has zero area (all points of each face on a line); "
                                  "re-export the surface")
    body = _face_bodies(topo, mesh.n_faces)
    nb = int(body.max()) + 1
    faces, n_flip = _orient_consistently(mesh, body, name)
    if n_flip:
        repairs.append(f"re-oriented {n_flip} faces so that neighbouring faces agree "
                       f"({_orientation_conflicts(mesh)} edges were inconsistent)")
        mesh = ShellMesh(mesh.points, faces, mesh.component, list(mesh.component_names))
    n_loops, plane, reason = _boundary_info(mesh)
    gaps = []
    if plane is None and n_loops and (close_gaps or not allow_open):
        mesh, gaps, n_loops, plane = _close_gaps(mesh, name, close_gaps, n_loops, plane)
        if gaps:
            body = _face_bodies(mesh.topology(), mesh.n_faces)
            nb = int(body.max()) + 1
            for g in gaps:
                repairs.append(f"closed an open gap (an open blunt trailing edge) {gap_text(g)} by a strip of "
                               f"{g['n_triangles']} triangles")
    topo = mesh.topology()
    be = topo.edges[topo.valence == 1]
    open_face = np.zeros(mesh.n_faces, bool)
    open_face[topo.edge_faces[topo.edge_faces_ptr[np.flatnonzero(topo.valence == 1)]]] = True
    open_body = np.zeros(nb, bool)
    open_body[body[open_face]] = True
    if len(be) and plane is None:
        if not allow_open:
            raise MeshValidationError(
                f"{name}: {len(be)} open boundary edges ({n_loops} loop{'s' if n_loops > 1 else ''}) "
                f"{_edge_where(mesh.points, be)}: {reason}. Close the surface in CAD (cap the open trailing edge, "
                "fill holes, stitch seams; unmerged vertices of a crack: re-export, or load with a larger "
                "merge_tol), or for a half model cut it exactly at the symmetry plane")
        warns.append(f"{len(be)} open boundary edges ({n_loops} loops) that are not a symmetry plane: "
                               f"{reason}; meshed as free edges")
    # outward: positive volume per body, cones from a point of its open boundary (on the
    # symmetry plane for a half model: the missing half adds nothing) or from its centroid
    P = mesh.points
    fv = mesh.faces
    corner_body = np.broadcast_to(body[:, None], fv.shape)[fv >= 0]
    cp = P[fv[fv >= 0]]
    cnt = np.bincount(corner_body, minlength=nb).astype(np.float64)
    apex = np.stack([np.bincount(corner_body, cp[:, k], nb) for k in range(3)], 1) / cnt[:, None]
    if len(be):
        bf = topo.edge_faces[topo.edge_faces_ptr[np.flatnonzero(topo.valence == 1)]]
        bb = body[bf]
        k = np.bincount(bb, minlength=nb).astype(np.float64)
        s = np.stack([np.bincount(bb, P[be[:, 0], j], nb) for j in range(3)], 1)
        has = k > 0
        apex[has] = s[has] / k[has, None]
    vol = _signed_volumes(P, mesh.faces, body, nb, apex)
    inward = np.flatnonzero(vol < 0)
    if len(inward):
        rows = np.flatnonzero(np.isin(body, inward))
        mesh = ShellMesh(P, _flip_faces(mesh.faces, rows), mesh.component, list(mesh.component_names))
        repairs.append(f"turned {len(inward)} inside-out bod{'y' if len(inward) == 1 else 'ies'} "
                       f"({len(rows)} faces) to face outward")
    if nb > 1 and union:
        mesh, groups = _unite_bodies(mesh, body, plane, open_body, name)
        for gl in groups:
            repairs.append(f"joined {len(gl)} intersecting bodies ({', '.join(map(str, gl))}) into one by a "
                           "boolean union (manifold3d)")
    if plane is not None:
        n_loops, _, _ = _boundary_info(mesh)
        nbe = len(mesh.boundary_edges())
        repairs.append(f"half model: {nbe} open boundary edges ({n_loops} loop{'s' if n_loops > 1 else ''}) "
                       f"lie in the symmetry plane {plane_text(plane['normal'], plane['point'], plane['axis'])}; "
                       "they are a clamped (symmetry) boundary")
    # consistent by construction; the body count is unchanged unless bodies were joined
    known = {"n_inconsistent": 0, "gaps": gaps}
    if not any(r.startswith("joined") for r in repairs):
        known["n_bodies"] = nb
    return mesh, repairs, warns, known


def _close_gaps(mesh: ShellMesh, name: str, close: bool, n_loops: int, plane):
    """The mesh with its open gaps closed by strips when that leaves it closed or a valid half
    model (:func:`~.gaps.gap_closures`); refused when ``close`` is false and such gaps exist.
    Returns ``(mesh, gaps, n_loops, plane)``, unchanged when there is nothing to close."""
    for closed, gaps in gap_closures(mesh, SYMMETRY_TOL * mesh.diagonal):
        n2, plane2, _ = _boundary_info(closed)
        if n2 and plane2 is None:
            continue
        if not close:
            more = f" (and {len(gaps) - 1} more)" if len(gaps) > 1 else ""
            raise MeshValidationError(
                f"{name}: an open gap {gap_text(gaps[0])}{more}: an open blunt trailing edge (the trailing-edge "
                "face is missing). Close it in CAD, or let the load close it by a strip of triangles "
                "(close_gaps=True, the default)")
        return closed, gaps, n2, plane2
    return mesh, [], n_loops, plane


def read_as_skin(mesh: ShellMesh) -> tuple[ShellMesh, str | None]:
    """Every group (component) of an input surface read as the one component ``skin``: the
    surface to mesh is the skin, and the members (ribs, spars) come from the layout, so a name
    the input carries (a Gmsh physical group, an element set, a property) is not a member.
    Returns the mesh and the repair line (``None`` when the surface already is ``skin``)."""
    present = np.unique(mesh.component)
    names = [mesh.component_names[i] if i < len(mesh.component_names) else f"component_{i}" for i in present]
    if names == [DEFAULT_NAME] and list(mesh.component_names) == [DEFAULT_NAME]:
        return mesh, None
    out = ShellMesh(mesh.points, mesh.faces, np.zeros(mesh.n_faces, np.int32), [DEFAULT_NAME])
    counts = np.bincount(mesh.component)[present]
    shown = ", ".join(f"'{n}' ({c} faces)" for n, c in zip(names[:6], counts[:6]))
    more = f" and {len(names) - 6} more" if len(names) > 6 else ""
    return out, (f"read the input's group{'s' if len(names) > 1 else ''} {shown}{more} as the skin (component "
                 f"'{DEFAULT_NAME}'): members come from the layout (keep_groups=True keeps the groups)")
