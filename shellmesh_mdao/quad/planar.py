"""Flattening of the skin quads still warped after the final smoothing: their free skin nodes
move along their normals, off the input facets by a bounded offset (:func:`planarize`; a
box-constrained sparse least-squares problem)."""
from __future__ import annotations

import numpy as np
from scipy import sparse

from ..core.supports import SURFACE, Supports, support_normals
from ..core.topology import face_rings
from ..errors import MeshValidationError
from ..mesh import ShellMesh, cross_rows, norm_rows, vertex_faces
from ..options import QuadOptions
from ..quality import element_quality
from ..smooth import LDL, draped_vertices, face_normals

__all__ = ["planarize"]


def _unit(a):
    n = norm_rows(a, axis=1, keepdims=True)
    return np.divide(a, n, out=np.zeros_like(a), where=n > 0)



_TWIST = np.array([1.0, -1.0, 1.0, -1.0])


def _bounded_least_squares(A, b, reg, bound, max_rounds: int = 50, start=None, ldl: LDL | None = None):
    """``t`` minimising ``|A t - b|^2 + sum(reg t^2)`` with ``|t| <= bound``: the primal-dual
    active-set method for box-constrained QPs (Hintermueller, Ito and Kunisch, SIAM J. Optim.
    13, 2003), until the active sets repeat (at most ``max_rounds`` rounds; the result is
    clipped to the box either way). Each round solves for the free unknowns with the bound
    ones held: the normal matrix with the held unknowns' rows and columns replaced by the
    identity's, whose pattern is the same every round, so one :class:`LDL` (``ldl``, reused
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
    ldl = LDL() if ldl is None else ldl
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


def planarize(mesh: ShellMesh, supports: Supports, *, max_offset: float,
              warp_above: float = QuadOptions.warp_goal, local_fraction: float = 0.15, guard_jacobian: float = 0.3,
              iterations: int = 6, regularisation: float = 1e-3, rings: int = 2, aim: float | None = None,
              flat_angle: float = 0.5, draped_angle: float = 60.0, vertices=None) -> tuple[ShellMesh, dict]:
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
    before. ``warp_above``: default the solver option ``warp_goal``
    (:class:`~shellmesh_mdao.options.QuadOptions`), as the quad stage passes. ``vertices``: ids
    of the nodes that may move (default None: every node the rules above allow); the others
    keep their positions. Same input, same offsets.

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
        nrm[verts] = support_normals(supports, P, verts)
        draped = draped_vertices(F[near], nrm, draped_angle)
        bent = draped_vertices(F[near], nrm, flat_angle)
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
    ldl = LDL()                     # every round's normal matrix has the same pattern
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
    n0 = face_normals(P, Fa, Fa[:, 3] < 0)
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
        flip[redo] = np.einsum("ij,ij->i", face_normals(X, Fr, Fr[:, 3] < 0), n0[redo]) <= 0
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
