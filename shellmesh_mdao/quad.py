"""All-quad subdivision: one Catmull-Clark-type split of every face (no vertex averaging).

A quad ``(a, b, c, d)`` becomes four quads and a triangle ``(a, b, c)`` three quads, using
one new node at the midpoint of every edge and one at the centroid of every face::

    child k = (corner_k, mid(side k), centroid, mid(side k-1))

(side ``k`` joins corner ``k`` to the next corner), so every child runs the same way as
its parent and the children of neighbouring faces share the edge midpoints. The mesh is
processed as a whole: an edge with three or four faces (skin/member junction, member
crossing) gets ONE midpoint shared by all of them, so the result stays conforming.

New nodes get supports (:class:`~shellmesh_mdao.smooth.Supports`) and are projected onto
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
from scipy import sparse

from .core.topology import face_rings
from .errors import MeshValidationError
from .mesh import ShellMesh, cross_rows, vertex_faces, norm_rows
from .quality import element_quality
from .smooth import (CURVE, FIXED, SURFACE, Supports, _LDL, _draped_vertices, _face_normals, _face_quality,
                     _min_corner_sj, _support_normals, untangle)

__all__ = ["subdivide_to_quads", "subdivide_faces", "settle_off_surface", "planarize"]


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
    sj_lin = _min_corner_sj(lin, children, is_tri, nref)
    keep_lin = np.zeros(len(X_lin), bool)
    X = X_proj.copy()
    for _ in range(rounds):
        cur = np.vstack([P, X])
        sj = _min_corner_sj(cur, children, is_tri, nref)
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
    own = _face_normals(Pg, F, is_tri)
    sj_g = _min_corner_sj(Pg, F, is_tri)
    nref = np.where((sj_g > 0)[:, None], own, parent_normal)
    Fc = np.where(F >= 0, F, F[:, :1])
    q_g = _face_quality(Pg[Fc], is_tri, nref)
    P1 = Pg.copy()
    P1[nodes] = X_proj
    m1 = mesh.with_points(P1)
    # the faces around the projected nodes (two rings: room for the tangential moves)
    vptr, vface = vertex_faces(F, len(Pg))
    region = face_rings(F, vptr, vface, nodes, 2)
    m2, _ = untangle(m1, supports, goal=goal, iterations=iterations, faces=region, ref_normals=nref)
    P2 = m2.points.copy()
    while True:
        q2 = _face_quality(P2[Fc], is_tri, nref)
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
                       project: bool = True, guard_jacobian: float = 0.2, settle: bool = True,
                       settle_iterations: int = 100) -> tuple[ShellMesh, Supports]:
    """Split every quad into 4 quads and every triangle into 3 quads (whole mesh at once).

    Parameters
    ----------
    mesh : conforming mixed mesh (skin and members; non-manifold junction edges allowed).
    supports : the supports of its vertices (:func:`~shellmesh_mdao.smooth.derive_supports`).
    min_dot : skin nodes are projected only onto input triangles whose normal has a dot
        product above this with the local face normal.
    project : project the new nodes onto their supports (default True).
    guard_jacobian : a child whose scaled Jacobian the projection would bring to or below this
        value (and below its unprojected value) keeps its new nodes at their linear position
        (edge midpoint, face centroid) instead: no subdivision step folds an element.
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
    ``fixed_vertices`` (as :mod:`.split` does; the returned supports, not
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


def settle_off_surface(mesh: ShellMesh, supports: Supports, *, tol: float = 1e-6, guard_jacobian: float = 0.2,
                       iterations: int = 100, min_dot: float = 0.0) -> tuple[ShellMesh, dict]:
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
    own = _face_normals(pts, mesh.faces, mesh.is_tri)
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


_TWIST = np.array([1.0, -1.0, 1.0, -1.0])


def _bounded_least_squares(A, b, reg, bound, max_rounds: int = 50, start=None, ldl: _LDL | None = None):
    """``t`` minimising ``|A t - b|^2 + sum(reg t^2)`` with ``|t| <= bound``: the primal-dual
    active-set method for box-constrained QPs (Hintermueller, Ito and Kunisch, SIAM J. Optim.
    13, 2003), until the active sets repeat (at most ``max_rounds`` rounds; the result is
    clipped to the box either way). Each round solves for the free unknowns with the bound
    ones held: the normal matrix with the held unknowns' rows and columns replaced by the
    identity's, whose pattern is the same every round, so one :class:`_LDL` (``ldl``, reused
    by the caller across problems of one pattern) orders it once and refactorises it
    numerically per round. ``start``: ``(x, lam)`` of a neighbouring problem, whose active
    sets are the first guess (default zeros: every unknown free). Returns ``(t, lam)``,
    ``lam`` the bounds' multipliers."""
    N = (A.T @ A + sparse.diags(reg)).tocsc()
    N.sort_indices()
    n = N.shape[0]
    r = A.T @ b
    c = N.diagonal()
    rows = N.indices
    cols = np.repeat(np.arange(n), np.diff(N.indptr))
    up_tri = rows <= cols
    ur, uc, ud = rows[up_tri], cols[up_tri], N.data[up_tri]
    uptr = np.concatenate([[0], np.cumsum(np.bincount(uc, minlength=n))]).astype(N.indptr.dtype)
    eye = np.where(ur == uc, 1.0, 0.0)
    ldl = _LDL() if ldl is None else ldl
    x, lam = (np.zeros(n), np.zeros(n)) if start is None else (start[0].copy(), start[1].copy())
    sets = None
    for _ in range(max_rounds):
        up = lam + c * (x - bound) > 0
        lo = lam + c * (x + bound) < 0
        if sets is not None and (up == sets[0]).all() and (lo == sets[1]).all():
            break
        sets = (up, lo)
        free = ~(up | lo)
        x = np.where(up, bound, np.where(lo, -bound, 0.0))
        solver = ldl.factor(uptr, ur, np.where(free[ur] & free[uc], ud, eye))
        x = solver.solve(np.where(free, r - N @ x, x))
        lam = r - N @ x
        lam[free] = 0.0
    return np.clip(x, -bound, bound), lam


def planarize(mesh: ShellMesh, supports: Supports, *, max_offset: float, warp_above: float = 10.0,
              local_fraction: float = 0.15, guard_jacobian: float = 0.3, iterations: int = 6,
              regularisation: float = 1e-3, rings: int = 2, aim: float | None = None, flat_angle: float = 0.5,
              draped_angle: float = 60.0, vertices=None) -> tuple[ShellMesh, dict]:
    """Flatten the skin quads warped more than ``warp_above`` degrees by moving SURFACE nodes
    along their vertex normal, off the input facets by at most ``max_offset`` (a length) and at
    most ``local_fraction`` times the mean edge of the quads around the node.

    Sliding along the input cannot flatten a quad that straddles a kink of a faceted input
    (docs/benchmarks.md); a small move off the facets can, as a pre-processor's warpage fix
    does. The movable nodes are the SURFACE nodes (never chain, junction, feature or member
    nodes, nor a node of an element at or below ``guard_jacobian``) within ``rings`` rings of
    the warped quads, except where the input is flat around the node (each of its faces has its
    corners on facets within ``flat_angle`` degrees of one another: an end cap or a flat panel,
    whose nodes a clamp or a symmetry condition may pick by coordinate) and where one of its
    faces is draped over an edge sharper than ``draped_angle`` (its corners' facets turned
    further apart: not a kink of a faceted curve); every quad at one of them has the residual
    ``(a - b + c - d) . n / D`` (its twist along its normal ``n`` over its mean diagonal ``D``:
    zero for a planar quad, about its warp in radians otherwise). Each of ``iterations`` rounds re-linearises the
    residuals at the current offsets, aims each quad warped more than ``aim`` degrees (default
    0.6 ``warp_above``) at its residual scaled by ``aim`` / warp and every other quad at its
    current residual, and solves for the offsets: the squared misses plus ``regularisation``
    times the squared offsets over the local size, within the bounds (a box-constrained sparse
    least-squares problem, solved by a primal-dual active set). Then no element whose scaled
    Jacobian is at or below ``guard_jacobian`` gets worse, none above falls to it and none
    turns over: the offsets of the nodes of such an element are halved (ten times, then
    dropped). The result is kept only if fewer quads are warped above ``warp_above`` than
    before. ``vertices``: ids of the nodes that may move (default None: every node the rules
    above allow); the others keep their positions. Same input, same offsets.

    Returns ``(mesh, info)`` with ``info`` = ``{"applied", "nodes", "moved", "max_offset",
    "quads_above_before", "quads_above_after", "halvings", "warp_p99_before",
    "warp_p99_after"}`` (``max_offset`` the largest offset applied, a length; the p99 over
    the quads)."""
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("planarize needs a ShellMesh; build one with ShellMesh(points, faces)")
    if not isinstance(supports, Supports) or supports.n != mesh.n_points:
        raise MeshValidationError("planarize needs Supports with one entry per mesh vertex: build them "
                                  "with derive_supports(mesh, ...) for this mesh")
    for name, v in (("max_offset", max_offset), ("warp_above", warp_above), ("local_fraction", local_fraction),
                    ("regularisation", regularisation), ("flat_angle", flat_angle), ("draped_angle", draped_angle)):
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"planarize needs a finite {name} >= 0, got {v!r}")
    aim = 0.6 * warp_above if aim is None else aim
    if not (np.isfinite(aim) and aim >= 0):
        raise ValueError(f"planarize needs a finite aim >= 0 (degrees), got {aim!r}")
    if int(iterations) < 1 or int(rings) < 1:
        raise ValueError(f"planarize needs iterations >= 1 and rings >= 1, got {iterations!r} and {rings!r}")
    P, F = mesh.points, mesh.faces
    quad = ~mesh.is_tri
    q0 = element_quality(P, F, ("warp", "scaled_jacobian"))
    w0 = q0["warp"]
    warped = np.flatnonzero(quad & (w0 > warp_above))
    p99 = float(np.percentile(w0[quad], 99)) if quad.any() else 0.0
    info = {"applied": False, "nodes": 0, "moved": 0, "max_offset": 0.0, "quads_above_before": int(len(warped)),
            "quads_above_after": int(len(warped)), "halvings": 0, "warp_p99_before": p99, "warp_p99_after": p99}
    if not len(warped) or max_offset == 0 or local_fraction == 0:
        return mesh, info
    n = mesh.n_points
    vptr, vface = vertex_faces(F, n)
    region = face_rings(F, vptr, vface, np.unique(F[warped][F[warped] >= 0]), rings)
    cand = np.unique(F[region])
    cand = cand[(cand >= 0)]
    cand = cand[supports.kind[cand] == SURFACE]
    if vertices is not None:
        cand = np.intersect1d(cand, np.asarray(vertices, dtype=np.int64).reshape(-1))
    # the nodes of elements at or below guard_jacobian stay on the input (the guard below would
    # undo any move of theirs that lowers such an element further)
    low = np.unique(F[q0["scaled_jacobian"] <= guard_jacobian])
    cand = np.setdiff1d(cand, low[low >= 0])
    # nodes stay on flat input: a node each of whose faces has its corners on input facets within
    # flat_angle of one another (an end cap, a flat panel: a clamp or a symmetry plane may pick
    # its nodes by coordinate), and a node of a face draped over an edge sharper than
    # draped_angle (its corners' facets turned further apart: not a kink of a faceted curve)
    if len(cand):
        near = face_rings(F, vptr, vface, cand, 1)
        verts = np.unique(F[near])
        verts = verts[verts >= 0]
        nrm = np.zeros((n, 3))
        nrm[verts] = _support_normals(supports, P, verts)
        draped = _draped_vertices(F[near], nrm, draped_angle)
        bent = _draped_vertices(F[near], nrm, flat_angle)
        cand = cand[bent[cand] & ~draped[cand]]
    rq = face_rings(F, vptr, vface, cand, 1)
    rq = rq[quad[rq]]
    Q = F[rq, :4]
    # local size: mean edge of the residual quads at each node
    L = norm_rows(P[Q] - P[np.roll(Q, -1, axis=1)], axis=2).mean(1)
    hs = np.bincount(Q.ravel(), weights=np.repeat(L, 4), minlength=n)
    hc = np.bincount(Q.ravel(), minlength=n)
    cand = cand[hc[cand] > 0]
    if not len(cand):
        return mesh, info
    h = hs[cand] / hc[cand]
    bound = np.minimum(max_offset, local_fraction * h)
    col = np.full(n, -1, np.int64)
    col[cand] = np.arange(len(cand))
    # the vertex normals from the faces at the nodes only: each node's sum runs over the same
    # faces in the same order as over the whole mesh (the same bits)
    faces_at = face_rings(F, vptr, vface, cand, 1)
    nu = ShellMesh(P, F[faces_at]).vertex_normals()[cand]
    D = 0.5 * (norm_rows(P[Q[:, 2]] - P[Q[:, 0]], axis=1) + norm_rows(P[Q[:, 3]] - P[Q[:, 1]], axis=1))
    t = np.zeros(len(cand))
    start = None
    ldl = _LDL()                     # every round's normal matrix has the same pattern
    for _ in range(int(iterations)):
        X = P.copy()
        X[cand] += t[:, None] * nu
        nq = _unit(cross_rows(X[Q[:, 2]] - X[Q[:, 0]], X[Q[:, 3]] - X[Q[:, 1]]))
        b = -np.einsum("ij,ij->i", np.einsum("k,ikj->ij", _TWIST, P[Q]), nq) / D
        c = col[Q]
        m = c >= 0
        rows = np.broadcast_to(np.arange(len(Q))[:, None], Q.shape)[m]
        vals = (_TWIST[None, :] * np.einsum("ikj,ij->ik", np.where(m[:, :, None], nu[np.where(m, c, 0)], 0.0),
                                             nq) / D[:, None])[m]
        A = sparse.csr_matrix((vals, (rows, c[m])), shape=(len(Q), len(cand)))
        if aim > 0:
            # aim each quad's residual at its own scaled by aim / warp when it is warped more:
            # the quads already flatter than aim only hold on, the moves go where warp is
            wc = element_quality(X, Q, ("warp",))["warp"]
            b = b + (A @ t - b) * np.minimum(1.0, aim / np.maximum(wc, 1e-12))
        t, lam = _bounded_least_squares(A, b, regularisation / h ** 2, bound, start=start, ldl=ldl)
        start = (t, lam)             # the next round's problem is this one re-linearised
    t[np.abs(t) <= 1e-9 * bound] = 0.0            # round-off of the solve: those nodes stay on the input
    # guard: no element at or below guard_jacobian worse, none above falls to it, none turns over
    # (after a halving only the faces at the nodes it moved are measured again: a face's figures
    # depend on its own corners alone)
    Fa = F[faces_at]
    sj0 = q0["scaled_jacobian"][faces_at]
    n0 = _face_normals(P, Fa, Fa[:, 3] < 0)
    floor = np.minimum(sj0, guard_jacobian) - 1e-12
    halvings = 0
    redo = np.arange(len(Fa))
    sj = np.empty(len(Fa))
    flip = np.empty(len(Fa), bool)
    for k in range(40):
        X = P.copy()
        X[cand] += t[:, None] * nu
        Fr = Fa[redo]
        sj[redo] = element_quality(X, Fr, ("scaled_jacobian",))["scaled_jacobian"]
        flip[redo] = np.einsum("ij,ij->i", _face_normals(X, Fr, Fr[:, 3] < 0), n0[redo]) <= 0
        bad = (sj < floor) | flip
        if not bad.any():
            break
        v = np.unique(Fa[bad])
        v = col[v[v >= 0]]
        v = v[v >= 0]
        t[v] = 0.0 if k >= 10 else 0.5 * t[v]
        halvings += 1
        moved = np.zeros(n + 1, bool)                 # slot n: the -1 corner of a triangle
        moved[cand[v]] = True
        redo = np.flatnonzero(moved[np.where(Fa >= 0, Fa, n)].any(1))
    else:
        return mesh, info
    w = w0.copy()
    w[rq] = element_quality(X, F[rq], ("warp",))["warp"]            # no other face has a moved corner
    above = int((quad & (w > warp_above)).sum())
    if above >= len(warped):
        return mesh, info
    out = mesh.with_points(X)
    info.update(applied=True, nodes=int(len(cand)), moved=int((t != 0).sum()), max_offset=float(np.abs(t).max()),
                quads_above_after=above, halvings=halvings, warp_p99_after=float(np.percentile(w[quad], 99)))
    return out, info
