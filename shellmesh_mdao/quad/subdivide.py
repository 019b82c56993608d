"""All-quad subdivision: one Catmull-Clark-type split of every face (no vertex averaging).

A quad ``(a, b, c, d)`` becomes four quads and a triangle ``(a, b, c)`` three quads, using
one new node at the midpoint of every edge and one at the centroid of every face::

    child k = (corner_k, mid(side k), centroid, mid(side k-1))

(side ``k`` joins corner ``k`` to the next corner), so every child runs the same way as
its parent and the children of neighbouring faces share the edge midpoints. The mesh is
processed as a whole: an edge with three or four faces (skin/member junction, member
crossing) gets ONE midpoint shared by all of them, so the result stays conforming.

New nodes get supports (:class:`~shellmesh_mdao.core.supports.Supports`) and are projected onto
them: the midpoint of a feature edge with a curve slides on that curve; the midpoint of
any other edge whose faces all lie on one support (the skin surface, or one member plane)
takes that support; the centroid of a face takes its face's support. Skin nodes are
projected onto the ORIGINAL input surface (closest point restricted to triangles facing
the same way as the local faces, so nodes near a thin trailing edge never land on the
opposite skin), member nodes onto their plane, curve nodes onto their curve. Midpoints
of feature edges without a curve, and of edges between faces of different supports
that are not feature edges, are FIXED (projected onto the faces' support when there is
one, else left at the straight midpoint).

Where projecting would fold a child (a parent face spanning a crease or a rounded tip
tighter than the element size) the fold guard first keeps the new nodes at their linear
position; ``settle`` then projects those skin nodes after all and repairs the elements
around them by moving vertices along their supports (:func:`~shellmesh_mdao.smooth.untangle`),
falling back to the guarded positions only where that repair fails.
"""
from __future__ import annotations

import numpy as np

from ..core.supports import CURVE, FIXED, SURFACE, Supports
from ..core.topology import face_rings
from ..errors import MeshValidationError
from ..mesh import ShellMesh, norm_rows, vertex_faces
from ..options import QuadOptions
from ..smooth import element_min_sj, face_normals, oriented_quality, untangle

__all__ = ["subdivide_to_quads", "subdivide_faces", "settle_off_surface"]


def _unit(a):
    n = norm_rows(a, axis=1, keepdims=True)
    return np.divide(a, n, out=np.zeros_like(a), where=n > 0)


def subdivide_faces(faces: np.ndarray, face_edges: np.ndarray, n_points: int, n_edges: int):
    """Connectivity of the subdivision: ``faces`` (m, 4) (-1 in slot 4 for triangles) with
    their ``face_edges`` (m, 4) edge ids; edge ``e`` gets node ``n_points + e`` and face
    ``f`` node ``n_points + n_edges + f``. Returns ``(children (4 nq + 3 nt, 4), parent)``,
    children of each face consecutive, in face order, child k at corner k."""
    faces = np.asarray(faces, np.int64)
    m = len(faces)
    tri = faces[:, 3] < 0
    k = np.where(tri, 3, 4)
    parent = np.repeat(np.arange(m), k)
    start = np.cumsum(k) - k
    corner = np.arange(len(parent)) - np.repeat(start, k)
    prev = np.where(tri[parent], (corner + 2) % 3, (corner + 3) % 4)
    mid = n_points + face_edges
    cen = n_points + n_edges + parent
    children = np.stack([faces[parent, corner], mid[parent, corner], cen, mid[parent, prev]], 1)
    return children, parent


def _guard_folds(P, X_lin, X_proj, children, parent, parent_normal, threshold: float, rounds: int = 8):
    """Positions of the new nodes: projected (``X_proj``) except where projecting would leave a
    child quad with a scaled Jacobian at or below ``threshold`` (against its own normal or its
    parent's) that the unprojected, in-plane position (``X_lin``) does not: those children's new
    nodes keep the linear position. Happens where a parent face spans a crease or a thin edge
    tighter than the element size (the closest surface point lies across it). Returns the
    positions and the mask of the nodes kept at their linear position."""
    n = len(P)
    is_tri = np.zeros(len(children), bool)
    nref = parent_normal[parent]
    lin = np.vstack([P, X_lin])
    sj_lin = element_min_sj(lin, children, is_tri, nref)
    keep_lin = np.zeros(len(X_lin), bool)
    X = X_proj.copy()
    for _ in range(rounds):
        cur = np.vstack([P, X])
        sj = element_min_sj(cur, children, is_tri, nref)
        bad = (sj <= threshold) & (sj_lin > sj)
        if not bad.any():
            break
        nodes = children[bad].ravel()
        nodes = nodes[nodes >= n] - n
        fresh = nodes[~keep_lin[nodes]]
        if not len(fresh):
            break
        keep_lin[fresh] = True
        X[fresh] = X_lin[fresh]
    return X, keep_lin


def _settle(mesh: ShellMesh, supports: Supports, nodes, X_proj, parent_normal, threshold: float,
            goal: float, iterations: int):
    """Put the guarded ``nodes`` (kept at their linear position by :func:`_guard_folds`) onto
    their supports (``X_proj``) and repair the elements around them by moving vertices along
    their supports (:func:`~shellmesh_mdao.smooth.untangle` up to ``goal``): the tangential
    moves of the neighbours make room for the projected nodes. Each face keeps the orientation
    it has in the guarded mesh (its parent's where it is folded there). Where the repair
    fails, an element that ends at or below ``threshold`` and below its guarded value gets its
    vertices back at their guarded positions (repeated until no such element is left), so the
    result is never worse than the guarded mesh below ``threshold``."""
    Pg = mesh.points
    F = mesh.faces
    is_tri = mesh.is_tri
    own = face_normals(Pg, F, is_tri)
    sj_g = element_min_sj(Pg, F, is_tri)
    nref = np.where((sj_g > 0)[:, None], own, parent_normal)
    Fc = np.where(F >= 0, F, F[:, :1])
    q_g = oriented_quality(Pg[Fc], is_tri, nref)
    P1 = Pg.copy()
    P1[nodes] = X_proj
    m1 = mesh.with_points(P1)
    # the faces around the projected nodes (two rings: room for the tangential moves)
    vptr, vface = vertex_faces(F, len(Pg))
    region = face_rings(F, vptr, vface, nodes, 2)
    m2, _ = untangle(m1, supports, goal=goal, iterations=iterations, faces=region, ref_normals=nref)
    P2 = m2.points.copy()
    while True:
        q2 = oriented_quality(P2[Fc], is_tri, nref)
        worse = np.flatnonzero((q2 <= threshold) & (q2 < q_g - 1e-12))
        if not len(worse):
            break
        v = np.unique(F[worse][F[worse] >= 0])
        v = v[(P2[v] != Pg[v]).any(1)]
        if not len(v):
            break
        P2[v] = Pg[v]
    return P2


def subdivide_to_quads(mesh: ShellMesh, supports: Supports, *, min_dot: float = 0.0,
                       project: bool = True, guard_jacobian: float = QuadOptions.guard_jacobian,
                       settle: bool = True, settle_iterations: int = 100) -> tuple[ShellMesh, Supports]:
    """Split every quad into 4 quads and every triangle into 3 quads (whole mesh at once).

    Parameters
    ----------
    mesh : conforming mixed mesh (skin and members; non-manifold junction edges allowed).
    supports : the supports of its vertices (:func:`~shellmesh_mdao.core.supports.derive_supports`).
    min_dot : skin nodes are projected only onto input triangles whose normal has a dot
        product above this with the local face normal.
    project : project the new nodes onto their supports (default True).
    guard_jacobian : a child whose scaled Jacobian the projection would bring to or below this
        value (and below its unprojected value) keeps its new nodes at their linear position
        (edge midpoint, face centroid) instead: no subdivision step folds an element. Default
        the solver option ``guard_jacobian`` (:class:`~shellmesh_mdao.options.QuadOptions`).
    settle : then put those guarded nodes onto their supports after all and repair the
        elements around them by moving vertices along their supports (up to
        ``settle_iterations`` rounds of :func:`~shellmesh_mdao.smooth.untangle` with goal
        ``guard_jacobian + 0.1``); an element the repair cannot bring above ``guard_jacobian``
        (and that is worse than guarded) gets its guarded vertex positions back. Default True:
        skin nodes end on the input surface also where a parent face spans a crease or a
        rounded tip tighter than the element size.

    Returns ``(quad mesh, supports)``. Node ``i < n`` keeps its index, and its position unless
    ``settle`` moves it (within two rings of a guarded node); edge
    ``e`` of ``mesh.topology()`` gets node ``n + e`` and face ``f`` node ``n + E + f``.
    Children replace their parent in face order and inherit its component; each feature
    edge becomes two feature edges with the same id, and its midpoint is added to
    ``fixed_vertices`` (as :mod:`~shellmesh_mdao.split` does; the returned supports, not
    ``fixed_vertices``, decide what the smoother moves).
    """
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("subdivide_to_quads needs a ShellMesh; build one with ShellMesh(points, faces)")
    if not isinstance(supports, Supports) or supports.n != mesh.n_points:
        raise MeshValidationError("subdivide_to_quads needs Supports with one entry per mesh vertex: build "
                                  "them with derive_supports(mesh, ...) for this mesh")
    n, m = mesh.n_points, mesh.n_faces
    topo = mesh.topology()
    E = topo.edges
    ne = len(E)
    P = mesh.points
    children, parent = subdivide_faces(mesh.faces, topo.face_edges, n, ne)
    # ---------------------------------------------------------------- feature edges
    fe, fid = mesh.feature_edges, mesh.feature_edge_ids
    fe_e = topo.edge_ids(fe) if len(fe) else np.zeros(0, np.int64)
    if (fe_e < 0).any():
        bad = fe[fe_e < 0][:3].tolist()
        raise MeshValidationError(f"{int((fe_e < 0).sum())} feature edges are not mesh edges (first: {bad}): "
                                  "feature edges must be edges of the faces; rebuild them after editing faces")
    fmid = n + fe_e
    new_fe = np.vstack([np.stack([fe[:, 0], fmid], 1), np.stack([fmid, fe[:, 1]], 1)])
    new_fid = np.concatenate([fid, fid])
    fixed = np.union1d(mesh.fixed_vertices, fmid)
    # ---------------------------------------------------------------- supports of new nodes
    ck = supports.comp_kind
    cr = supports.comp_ref
    if len(ck) < (int(mesh.component.max()) + 1 if m else 0):
        raise MeshValidationError("supports know fewer components than the mesh has: rebuild them with "
                                  "derive_supports for this mesh")
    fkind = ck[mesh.component].astype(np.int64)
    fref = cr[mesh.component]
    code = fkind * (int(max(cr.max(initial=0), 0)) + 1) + fref
    hcode = code[topo.he_face]
    lo = np.full(ne, np.iinfo(np.int64).max)
    hi = np.full(ne, np.iinfo(np.int64).min)
    np.minimum.at(lo, topo.he_edge, hcode)
    np.maximum.at(hi, topo.he_edge, hcode)
    uniq = lo == hi
    # the first face of each edge (all its faces share the support when unique)
    eface = topo.edge_faces[topo.edge_faces_ptr[:-1]]
    ekind = np.where(uniq, fkind[eface], FIXED).astype(np.int8)
    eref = np.where(uniq, fref[eface], -1)
    ecurve = supports.curve_of_edges(E)
    is_fe = np.zeros(ne, bool)
    is_fe[fe_e] = True
    # open-boundary / non-manifold edges that are not feature edges keep their nodes fixed
    # (derive_supports), so their midpoints are fixed too
    is_fe |= topo.valence != 2
    on_curve = ecurve >= 0
    # a feature edge without a curve: its midpoint is fixed (on the faces' support if unique)
    proj_kind = ekind.copy()
    proj_ref = eref.copy()
    ekind = np.where(on_curve, CURVE, np.where(is_fe, FIXED, ekind)).astype(np.int8)
    eref = np.where(on_curve, ecurve, np.where(is_fe, -1, eref))
    proj_kind = np.where(on_curve, CURVE, proj_kind).astype(np.int8)
    proj_ref = np.where(on_curve, ecurve, proj_ref)
    # normals: sum of the incident faces' area vectors
    av = mesh.face_area_vectors()
    en = np.zeros((ne, 3))
    for d in range(3):
        en[:, d] = np.bincount(topo.he_edge, weights=av[topo.he_face, d], minlength=ne)
    en = _unit(en)
    X_mid = 0.5 * (P[E[:, 0]] + P[E[:, 1]])
    X_cen = mesh.face_centroids()
    fn = _unit(av)
    new_kind = np.concatenate([ekind, fkind.astype(np.int8)])
    new_ref = np.concatenate([eref, fref])
    X_new = np.vstack([X_mid, X_cen])
    if project and len(X_new):
        pk = np.concatenate([proj_kind, fkind.astype(np.int8)])
        pr = np.concatenate([proj_ref, fref])
        nrm = np.vstack([en, fn])
        x, ok = supports.project_kind(X_new, pk, pr, nrm, min_dot)
        # a skin node without a compatible triangle nearby: plain closest point
        if (~ok).any():
            bad = np.flatnonzero(~ok)
            x[bad], _ = supports.project_kind(X_new[bad], pk[bad], pr[bad], None)
        x = np.where((pk == FIXED)[:, None], X_new, x)
        X_new, kept = _guard_folds(P, X_new, x, children, parent, fn, guard_jacobian)
        # guarded skin nodes that are off the surface (not merely rounding apart)
        kept &= (new_kind == SURFACE) & (norm_rows(x - X_new, axis=1) > 1e-9 * mesh.diagonal)
    sup = supports.extended(new_kind, new_ref)
    # feature edges of the new mesh with their curves
    ec_old = supports.curve_of_edges(fe)
    sup.edge_pairs = np.sort(new_fe, axis=1)
    sup.edge_curve = np.concatenate([ec_old, ec_old])
    out = ShellMesh(np.vstack([P, X_new]), children, mesh.component[parent], list(mesh.component_names),
                    fixed, new_fe, new_fid)
    # keep supports' feature-edge table aligned with the mesh's (sorted, unique) table
    sup.edge_curve = sup.curve_of_edges(out.feature_edges)
    sup.edge_pairs = out.feature_edges.copy()
    if project and settle and len(X_new) and kept.any():
        k = np.flatnonzero(kept)
        pts = _settle(out, sup, n + k, x[k], fn[parent], guard_jacobian, guard_jacobian + 0.1,
                      settle_iterations)
        out = out.with_points(pts)
    return out, sup


def settle_off_surface(mesh: ShellMesh, supports: Supports, *, tol: float = 1e-6,
                       guard_jacobian: float = QuadOptions.guard_jacobian, iterations: int = 100,
                       min_dot: float = 0.0) -> tuple[ShellMesh, dict]:
    """Put the SURFACE nodes that lie farther than ``tol`` times the model's bounding-box
    diagonal from their support back onto it, repairing the elements around them as the
    subdivision's ``settle`` does (:func:`~shellmesh_mdao.smooth.untangle` on the two rings
    around them up to ``guard_jacobian + 0.1``; an element the repair leaves at or below
    ``guard_jacobian`` and worse than before gets its vertices' previous positions back).

    Meant for the mesh after the final smoothing: a node the subdivision's fold guard kept at
    its linear position (a parent face across a crease or a tip much tighter than itself) is
    often free to go onto the surface once its neighbours have been smoothed. Each node is
    projected to the closest point of the triangles facing the way of its vertex normal (the
    plain closest point where there is none within reach). No element at or below
    ``guard_jacobian`` gets worse.

    Returns ``(mesh, info)`` with ``info`` = ``{"before", "after", "max_distance_before",
    "max_distance_after"}`` (node counts and distances off the surface)."""
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("settle_off_surface needs a ShellMesh; build one with ShellMesh(points, faces)")
    if not isinstance(supports, Supports) or supports.n != mesh.n_points:
        raise MeshValidationError("settle_off_surface needs Supports with one entry per mesh vertex: build them "
                                  "with derive_supports(mesh, ...) for this mesh")
    skin = np.flatnonzero(supports.kind == SURFACE)
    d = supports.distance(mesh.points, skin) if len(skin) else np.zeros(0)
    lim = tol * mesh.diagonal
    off = skin[d > lim]
    info = {"before": int(len(off)), "after": int(len(off)), "max_distance_before": float(d.max(initial=0.0)),
            "max_distance_after": float(d.max(initial=0.0))}
    if not len(off):
        return mesh, info
    pts = mesh.points
    own = face_normals(pts, mesh.faces, mesh.is_tri)
    for facing in (True, False):
        # first onto the triangles facing the node's way, then (the nodes still off) onto the plain
        # closest point: _settle keeps every face's orientation, so a node that would land on the
        # opposite skin of a thin tip is put back
        if facing:
            x, ok = supports.project(pts, off, normals=mesh.vertex_normals(), min_dot=min_dot)
            if (~ok).any():
                x[~ok], _ = supports.project(pts, off[~ok])
        else:
            x, _ = supports.project(pts, off)
        pts = _settle(mesh.with_points(pts), supports, off, x, own, guard_jacobian, guard_jacobian + 0.1, iterations)
        d2 = supports.distance(pts, off)
        off = off[d2 > lim]
        if not len(off):
            break
    out = mesh.with_points(pts)
    d2 = supports.distance(pts, skin)
    info.update(after=int((d2 > lim).sum()), max_distance_after=float(d2.max(initial=0.0)))
    return out, info
