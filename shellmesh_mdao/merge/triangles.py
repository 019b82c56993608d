"""Merging optimisation (Li & Hwang, paper Sec. IV.C.2, eq. 4-5): the candidate edges, their energies, the
exact reduction, the MIP and the merge stage's entry :func:`merge_mesh`. The method (variables, weights,
guards, the valence term) is described in the package docstring, :mod:`shellmesh_mdao.merge`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from ..core.highs import highs_solve, highs_solve_halves
from ..core.supports import PLANE, SURFACE, Supports, pipeline_supports, supports_hold
from ..core.topology import fixed_edge_mask
from ..errors import MeshValidationError
from .kernels import safe_matching_rounds
from ..mesh import ShellMesh, norm_rows
from ..options import MergeOptions
from ..split import polygon_energy

__all__ = ["MergeResult", "interior_vertices", "merge_candidates", "merge_triangles", "merge_mesh", "quad_energy"]


@dataclass
class MergeResult:
    """Outcome of :func:`merge_triangles`.

    ``status``        HiGHS model status ("Optimal", "Time limit reached", ...; "No candidates"
                      when there was nothing to merge).
    ``objective``     summed weight of the merged edges (energy change, <= 0).
    ``mip_gap``       relative MIP gap HiGHS reports for the returned solution.
    ``n_merged``      number of quads created.
    ``seconds``       wall time of the whole call; ``solve_seconds`` of HiGHS alone.
    ``n_candidates``  edges offered to the solver (negative weight, passing the guards).
    ``merged_edges``  (n_merged, 2) node pairs of the removed edges.
    ``quad_fraction`` fraction of output faces that are quads.
    """

    status: str
    objective: float
    mip_gap: float
    n_merged: int
    seconds: float
    n_candidates: int = 0
    solve_seconds: float = 0.0
    quad_fraction: float = 0.0
    merged_edges: np.ndarray = field(repr=False, default=None)


def quad_energy(corners, *, c1: float = 1.0, c2: float = 1.0, c3: float = 1.0,
                form: str = "squared") -> np.ndarray:
    """Eq. 5 for a batch of quads ``corners`` (k, 4, 3): the eq.-2 terms plus
    ``c3 * sum_i |e_i . n_q|`` (warping / dihedral term)."""
    Q = np.asarray(corners, dtype=np.float64)
    if not len(Q):
        return np.zeros(0)
    e = polygon_energy(Q, np.zeros(len(Q), bool), c1, c2, form)
    nq = _unit(np.cross(Q[:, 2] - Q[:, 0], Q[:, 3] - Q[:, 1]))
    s = _unit(np.roll(Q, -1, axis=1) - Q)
    return e + c3 * np.abs((s * nq[:, None, :]).sum(2)).sum(1)


def _unit(v):
    n = norm_rows(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def merge_candidates(mesh: ShellMesh, *, c1: float = 1.0, c2: float = 1.0, c3: float = 1.0,
                     fixed_edges=None, min_angle: float = 20.0, max_angle: float = 160.0,
                     max_dihedral: float = 30.0, min_jacobian: float = 0.3,
                     form: str = "squared") -> dict:
    """Edges that may be merged and their eq.-5 weights (all vectorised).

    Returns a dict with ``edge`` (edge ids into ``mesh.topology().edges``), ``f0``/``f1``
    (the two triangles, ``f0 < f1``), ``quad`` (k, 4) node ids of the merged quad oriented
    like ``f0``, ``weight`` (e_quad - e_f0 - e_f1) and ``allowed`` (passes the guards).
    Only valence-2 edges between two triangles of the same component, not in
    ``fixed_edges`` (default ``mesh.feature_edges``), with consistent orientation are listed.
    """
    topo = mesh.topology()
    faces = mesh.faces
    fixed = fixed_edge_mask(topo, mesh.feature_edges if fixed_edges is None else fixed_edges)
    order = np.lexsort((topo.he_face, topo.he_edge))
    he_e = topo.he_edge[order]
    first = np.flatnonzero(np.r_[True, he_e[1:] != he_e[:-1]]) if len(he_e) else np.zeros(0, np.int64)
    e_of = he_e[first]
    two = topo.valence[e_of] == 2
    first, e_of = first[two], e_of[two]
    h0, h1 = order[first], order[first + 1]
    f0, f1 = topo.he_face[h0], topo.he_face[h1]
    tri = faces[:, 3] < 0
    ok = (tri[f0] & tri[f1] & (f0 != f1) & ~fixed[e_of]
          & (mesh.component[f0] == mesh.component[f1])
          & (topo.he_from[h0] == topo.he_to[h1]))
    h0, h1, f0, f1, e_of = h0[ok], h1[ok], f0[ok], f1[ok], e_of[ok]
    s0, s1 = topo.he_side[h0], topo.he_side[h1]
    a = faces[f0, s0]
    b = faces[f0, (s0 + 1) % 3]
    c = faces[f0, (s0 + 2) % 3]
    d = faces[f1, (s1 + 2) % 3]
    keep = (c != d)
    a, b, c, d, f0, f1, e_of = a[keep], b[keep], c[keep], d[keep], f0[keep], f1[keep], e_of[keep]
    quad = np.stack([b, c, a, d], axis=1)            # f0 = (a, b, c) -> quad (b, c, a, d)
    P = mesh.points
    Q = P[quad]
    # ---- guards
    nq = _unit(np.cross(Q[:, 2] - Q[:, 0], Q[:, 3] - Q[:, 1]))
    nxt = np.roll(Q, -1, axis=1) - Q
    prv = np.roll(Q, 1, axis=1) - Q
    un, up = _unit(nxt), _unit(prv)
    sj = (np.cross(un, up) * nq[:, None, :]).sum(2)  # scaled Jacobian at each corner
    cosang = (un * up).sum(2)
    ang = np.degrees(np.arccos(np.clip(cosang, -1, 1)))
    n0 = _unit(np.cross(P[b] - P[a], P[c] - P[a]))
    n1 = _unit(np.cross(P[a] - P[b], P[d] - P[b]))
    dih = np.degrees(np.arccos(np.clip((n0 * n1).sum(1), -1, 1)))
    allowed = ((sj > max(min_jacobian, 0.0)).all(1) & (ang >= min_angle).all(1) & (ang <= max_angle).all(1)
               & (dih <= max_dihedral) & (norm_rows(n0, axis=1) > 0) & (norm_rows(n1, axis=1) > 0))
    # ---- weights: e(quad) - e(t0) - e(t1)
    e_q = quad_energy(Q, c1=c1, c2=c2, c3=c3, form=form)
    T = np.zeros((len(f0), 4, 3))
    is_t = np.ones(len(f0), bool)
    T[:, :3] = P[faces[f0, :3]]
    e_t0 = polygon_energy(T, is_t, c1, c2, form)
    T[:, :3] = P[faces[f1, :3]]
    e_t1 = polygon_energy(T, is_t, c1, c2, form)
    return dict(edge=e_of, f0=f0, f1=f1, quad=quad, weight=e_q - e_t0 - e_t1, allowed=allowed,
                dihedral=dih, angles=ang, scaled_jacobian=sj.min(1))


def _greedy_matching(f0, f1, w, n_faces, max_rounds: int = 200) -> np.ndarray:
    """Locally-dominant matching (vectorised rounds): an edge is taken when it is the best
    (lowest weight, then lowest index) remaining edge of both its triangles.  Used as
    the MIP start; any matching is feasible."""
    k = len(w)
    x = np.zeros(k)
    rank = np.empty(k, dtype=np.int64)
    rank[np.lexsort((np.arange(k), w))] = np.arange(k)
    active = np.ones(k, bool)
    matched = np.zeros(n_faces, bool)
    for _ in range(max_rounds):
        idx = np.flatnonzero(active)
        if not len(idx):
            break
        best = np.full(n_faces, k, dtype=np.int64)
        np.minimum.at(best, f0[idx], rank[idx])
        np.minimum.at(best, f1[idx], rank[idx])
        take = idx[(best[f0[idx]] == rank[idx]) & (best[f1[idx]] == rank[idx])]
        x[take] = 1.0
        matched[f0[take]] = True
        matched[f1[take]] = True
        active &= ~(matched[f0] | matched[f1])
    return x


def _safe_reduction(f0, f1, w, n_faces, max_rounds: int = 100):
    """Edges that belong to some optimal matching, fixed before the MIP (exact).

    With gains ``g = -w > 0``: if ``g(uv) >= best other gain at u + best other gain at v``
    then replacing, in any optimal matching, the edges at u and v by uv loses nothing, so
    uv can be fixed to 1 and u, v removed.  In rounds (compiled:
    :func:`~shellmesh_mdao.merge.kernels.safe_matching_rounds`); within a round only safe edges
    that are the best-ranked safe edge at both their triangles are taken, so they form a
    matching.  Returns ``(taken, remaining)`` boolean masks over the edges."""
    return safe_matching_rounds(f0, f1, w, n_faces, max_rounds)


def interior_vertices(mesh: ShellMesh) -> np.ndarray:
    """Vertices of ``mesh`` (ids) on no boundary, non-manifold or feature edge and not fixed: those
    whose ideal valence in a quad mesh is 4 (the default ``valence_vertices`` of
    :func:`merge_triangles`)."""
    topo = mesh.topology()
    out = np.zeros(mesh.n_points, bool)
    out[np.unique(mesh.faces[mesh.faces >= 0])] = True
    out[topo.edges[topo.valence != 2].reshape(-1)] = False
    if len(mesh.feature_edges):
        out[np.asarray(mesh.feature_edges, np.int64).reshape(-1)] = False
    if len(mesh.fixed_vertices):
        out[np.asarray(mesh.fixed_vertices, np.int64).reshape(-1)] = False
    return np.flatnonzero(out)


def _matching_rows(f0, f1, n_cols):
    """The rows ``A x <= 1`` of a matching over edges ``f0``-``f1`` (columns 0..k-1 of
    ``n_cols``): one row per triangle with two or more candidate edges, in triangle order (a
    triangle with one is held by the edge's upper bound 1)."""
    k = len(f0)
    tri_ids = np.concatenate([f0, f1])
    col = np.concatenate([np.arange(k), np.arange(k)])
    sel = np.bincount(tri_ids)[tri_ids] >= 2
    need, row = np.unique(tri_ids[sel], return_inverse=True)
    return sparse.csr_matrix((np.ones(int(sel.sum())), (row.reshape(-1), col[sel])), shape=(len(need), n_cols))


def _counted(vids, vmask, n_points):
    """The vertices among ``vids`` that ``vmask`` counts (sorted, once each) and their numbering
    (n_points,), -1 for the others."""
    vids = np.unique(vids)
    vids = vids[vmask[vids]]
    vid = np.full(n_points, -1, np.int64)
    vid[vids] = np.arange(len(vids))
    return vids, vid


def _valence_model(E, f0, f1, w, vid, rhs, lam):
    """The LP/MIP of the valence-aware merge over candidate edges ``E`` (k, 2) between the
    triangles ``f0``/``f1`` with weights ``w``: columns ``x`` (k), then ``p``, ``q`` (nv each);
    rows: at most one merged edge per triangle (triangles with two or more candidates), and per
    counted vertex ``v`` (``vid[v] >= 0``) ``sum_{e at v} x_e + p_v - q_v = rhs_v`` (its valence
    in the merged mesh minus 4 is ``q_v - p_v``); cost ``w x + lam (p + q)``."""
    k, nv = len(w), len(rhs)
    A1 = _matching_rows(f0, f1, k + 2 * nv)
    nr = A1.shape[0]
    col = np.concatenate([np.arange(k), np.arange(k)])
    ev = np.concatenate([E[:, 0], E[:, 1]])
    ok = vid[ev] >= 0
    rv, cv = vid[ev[ok]], col[ok]
    Bv = sparse.csr_matrix((np.concatenate([np.ones(len(rv)), np.ones(nv), -np.ones(nv)]),
                            (np.concatenate([rv, np.arange(nv), np.arange(nv)]),
                             np.concatenate([cv, k + np.arange(nv), k + nv + np.arange(nv)]))),
                           shape=(nv, k + 2 * nv))
    A = sparse.vstack([A1, Bv]).tocsr()
    lo = np.concatenate([np.full(nr, -np.inf), rhs])
    hi = np.concatenate([np.ones(nr), rhs])
    c = np.concatenate([w, np.full(2 * nv, float(lam))])
    ub = np.concatenate([np.ones(k), np.full(2 * nv, np.inf)])
    return A, c, lo, hi, ub


#: largest number of candidate edges the valence term's LP takes in one piece (every corpus case:
#: straight_wing has 24k), and the size of the blocks a larger one is solved in: the dual simplex
#: grows faster than the problem (cessna210 at 0.25: 15.4k edges 0.2 s, straight_wing 24k 0.4 s;
#: cessna210 at 0.1, 83k edges: 4.7 s in one piece, 2.0-2.5 s in six blocks, 0.5 % above it)
VALENCE_ONE_PIECE = 30000
VALENCE_BLOCK = 16000


def _valence_block(E, f0, f1, w, n_points, n_faces, valence, vmask, lam, time_limit, done):
    """One block of :func:`_valence_matching`: the LP relaxation over its candidates, the 0/1
    edges kept, an exact MIP over the fractional rest (the kept merges' triangles taken and their
    valence changes in the right-hand sides). ``done`` (n_points,) merges already fixed at each
    vertex (earlier blocks). Returns ``(x, lp_objective, lp_status, status, seconds)``; ``x`` None
    when the LP found no solution."""
    k = len(w)
    V, vid = _counted(E.reshape(-1), vmask, n_points)
    A, c, lo, hi, ub = _valence_model(E, f0, f1, w, vid, valence[V] - 4.0 - done[V], lam)
    sol = highs_solve_halves(c, A, lo, hi, ub, time_limit=time_limit)
    seconds = sol.seconds
    if sol.x is None:
        return None, float("nan"), sol.status, sol.status, seconds
    status = sol.status
    x = np.round(sol.x[:k])
    frac = np.abs(sol.x[:k] - x) > 1e-7
    x[frac] = 0.0
    taken = np.zeros(n_faces, bool)
    taken[f0[x > 0.5]] = True
    taken[f1[x > 0.5]] = True
    rest = np.flatnonzero(frac & ~taken[f0] & ~taken[f1])
    if len(rest):
        now = done + np.bincount(E[x > 0.5].reshape(-1), minlength=n_points)
        V2, vid2 = _counted(E[rest].reshape(-1), vmask, n_points)
        A2, c2, lo2, hi2, ub2 = _valence_model(E[rest], f0[rest], f1[rest], w[rest], vid2,
                                               valence[V2] - 4.0 - now[V2], lam)
        sub = highs_solve(c2, A2, lo2, hi2, ub2, integer=True, time_limit=time_limit, mip_gap=0.0)
        seconds += sub.seconds
        status = sub.status
        if sub.x is not None:
            x[rest] = np.round(sub.x[:len(rest)])
        else:
            status += " (no solution: fractional edges left unmerged)"
    return x, float(sol.objective), sol.status, status, seconds


def _valence_matching(E, f0, f1, w, n_points, n_faces, valence, vmask, lam, time_limit):
    """The merges of the valence-aware merge (:func:`_valence_block`; in one block up to
    :data:`VALENCE_ONE_PIECE` candidates, else in blocks of about :data:`VALENCE_BLOCK`, of
    consecutive triangles of a reverse Cuthill-McKee order of the candidates' triangle graph, each
    with the merges of the blocks before it fixed). Returns ``(x, objective, status, gap,
    solve_seconds)``: ``objective`` the weights of the merged edges plus ``lam`` times the counted
    vertices' summed ``|valence - 4|``;
    ``gap`` relative to the LP's objective, a lower bound on every matching's (inf when the LP
    stopped short of its optimum; NaN with more than one block, whose LPs bound nothing together);
    ``status`` HiGHS's status of the (last block's) MIP, or of its LP when nothing was fractional."""
    k = len(w)
    x = np.zeros(k)
    done = np.zeros(n_points, np.int64)
    nblocks = 1 if k <= VALENCE_ONE_PIECE else -(-k // VALENCE_BLOCK)
    if nblocks == 1:
        blocks = [np.arange(k)]
    else:
        from scipy.sparse.csgraph import reverse_cuthill_mckee
        G = sparse.csr_matrix((np.ones(2 * k), (np.concatenate([f0, f1]), np.concatenate([f1, f0]))),
                              shape=(n_faces, n_faces))
        rank = np.empty(n_faces, np.int64)
        rank[reverse_cuthill_mckee(G, symmetric_mode=True)] = np.arange(n_faces)
        last = np.maximum(rank[f0], rank[f1])             # an edge joins the block of its later triangle
        cuts = np.quantile(last, np.linspace(0, 1, nblocks + 1)[1:-1], method="lower")
        which = np.searchsorted(cuts, last, side="left")
        blocks = [np.flatnonzero(which == b) for b in range(nblocks)]
    taken = np.zeros(n_faces, bool)
    lp_obj, lp_status, status, seconds = 0.0, "Optimal", "Optimal", 0.0
    for idx in blocks:
        idx = idx[~taken[f0[idx]] & ~taken[f1[idx]]]
        if not len(idx):
            continue
        xb, ob, ls, st, sec = _valence_block(E[idx], f0[idx], f1[idx], w[idx], n_points, n_faces, valence, vmask,
                                             lam, time_limit, done)
        seconds += sec
        status = st
        if xb is None:
            lp_status = ls
            status = ls + " (no LP solution: nothing merged in a block)"
            continue
        lp_obj += ob
        if ls != "Optimal":
            lp_status = ls
        x[idx] = xb
        m = idx[xb > 0.5]
        taken[f0[m]] = True
        taken[f1[m]] = True
        done += np.bincount(E[m].reshape(-1), minlength=n_points)
    V, _ = _counted(E.reshape(-1), vmask, n_points)
    obj = float(w @ x) + lam * float(np.abs(valence[V] - done[V] - 4).sum())
    if lp_status != "Optimal":
        gap = float("inf")
    elif len(blocks) > 1:
        gap = float("nan")
        status += f" ({len(blocks)} blocks)"
    else:
        gap = 0.0 if obj <= lp_obj else (obj - lp_obj) / max(abs(obj), 1e-300)
    return x, obj, status, gap, seconds


def merge_triangles(mesh: ShellMesh, *, c1: float = 1.0, c2: float = 1.0, c3: float = 1.0,
                    fixed_edges=None, time_limit: float = MergeOptions.merge_time_limit,
                    mip_gap: float = MergeOptions.merge_mip_gap, min_angle: float = 20.0, max_angle: float = 160.0,
                    max_dihedral: float = 30.0, min_jacobian: float = 0.3,
                    merge_bonus: float = MergeOptions.merge_bonus,
                    valence_weight: float = MergeOptions.merge_valence_weight, valence_vertices=None,
                    form: str = "squared") -> tuple[ShellMesh, MergeResult]:
    """Merge pairs of triangles into quads (paper eq. 4-5), solved as a HiGHS MIP.

    Parameters
    ----------
    mesh : the whole conforming mesh (non-manifold edges allowed; they are never merged).
    c1, c2, c3 : weights of the length, angle and warping terms of eq. 5 (and of eq. 2
        for the triangles' energy before merging).
    fixed_edges : (k, 2) node pairs never merged; default ``mesh.feature_edges``.
    time_limit, mip_gap : HiGHS ``time_limit`` (s; with the valence term, of each of its two
        solves) and ``mip_rel_gap``; default the solver options ``merge_time_limit`` and
        ``merge_mip_gap`` (:class:`~shellmesh_mdao.options.MergeOptions`, as the other defaults
        named after an option below).
    min_angle, max_angle : allowed corner angles of a merged quad in degrees (default 20-160:
        a planar quad inside it has scaled Jacobian >= sin 20 deg = 0.34).
    max_dihedral : largest angle (degrees) between the two triangles' normals.
    merge_bonus : subtracted from every weight (beyond the paper; default the solver option
        ``merge_bonus``, 0 drops it): a positive value makes merging worthwhile even for pairs
        of near-equilateral triangles (a 60/120 rhombus costs 4/9 c2 more than its two
        triangles), for a more quad-dominant result; the guards still apply.
    min_jacobian : smallest allowed corner scaled Jacobian of the merged quad, measured
        against the diagonal-cross-product normal (any value > 0 forbids non-convex and
        folded quads; a non-positive value still forbids them).
    valence_weight : ``lam`` of the valence term (beyond the paper; default the solver option
        ``merge_valence_weight``; 0: off): the objective adds ``lam |valence - 4|`` for each
        vertex of ``valence_vertices``, its valence counted in the merged mesh (its faces; the
        subdivision keeps it), since the subdivided quads around a vertex of valence 3, 5 or 6
        cannot all be square. Solved as the LP relaxation of that MIP, whose 0/1 merges are
        kept, and an exact MIP over the edges it leaves fractional (a few hundred at most on
        the corpus); ``mip_gap`` of the result is measured against the LP's objective, a lower
        bound on every matching's, and ``status`` is that MIP's (or the LP's when nothing was
        fractional). ``mip_gap`` the option is not used on this path. An edge joins the candidates while its weight is
        below ``2 lam`` (its merge can pay at both ends).
    valence_vertices : vertex ids counted by the valence term; default :func:`interior_vertices`
        (not on a boundary, non-manifold or feature edge, not fixed).

    Only two triangles of the same component across a valence-2, non-fixed edge are
    merged, and only when the merge lowers the objective (the energy, and the valence term
    when it is on).  The quad replaces the
    lower-index triangle (orientation of that triangle; the other triangle, which runs
    the shared edge the opposite way, agrees), the other triangle is removed; all other
    faces keep their order.  Nodes, fixed vertices and feature edges are unchanged.
    """
    t0 = time.perf_counter()
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("merge_triangles needs a ShellMesh; build one with ShellMesh(points, faces)")
    if not (0.0 <= min_angle < 90.0 < max_angle <= 180.0):
        raise ValueError(f"need 0 <= min_angle < 90 < max_angle <= 180, got {min_angle}, {max_angle}")
    cand = merge_candidates(mesh, c1=c1, c2=c2, c3=c3, fixed_edges=fixed_edges, min_angle=min_angle,
                            max_angle=max_angle, max_dihedral=max_dihedral, min_jacobian=min_jacobian,
                            form=form)
    weight = cand["weight"] - float(merge_bonus)
    lam = float(valence_weight)
    if not (np.isfinite(lam) and lam >= 0):
        raise ValueError(f"valence_weight must be a finite number >= 0, got {valence_weight!r}")
    # with the valence term an edge can pay off by up to lam at each end
    use = cand["allowed"] & (weight < 2.0 * lam)
    f0, f1, w = cand["f0"][use], cand["f1"][use], weight[use]
    quad, edge = cand["quad"][use], cand["edge"][use]
    k = len(w)
    m = mesh.n_faces
    x = np.zeros(k)
    status, obj, gap, solve_s = "No candidates", 0.0, 0.0, 0.0
    if k and lam > 0:
        n = mesh.n_points
        valence = np.bincount(mesh.faces[mesh.faces >= 0], minlength=n)
        vmask = np.zeros(n, bool)
        vmask[interior_vertices(mesh) if valence_vertices is None else
              np.asarray(valence_vertices, np.int64).reshape(-1)] = True
        E = mesh.topology().edges[edge]
        x, obj, status, gap, solve_s = _valence_matching(E, f0, f1, w, n, m, valence, vmask, lam, time_limit)
    elif k:
        fixed1, rest = _safe_reduction(f0, f1, w, m)
        x[fixed1] = 1.0
        status = "Optimal"
        ridx = np.flatnonzero(rest)
        if len(ridx):
            r0, r1, rw = f0[ridx], f1[ridx], w[ridx]
            A = _matching_rows(r0, r1, len(ridx))
            nr = A.shape[0]
            if nr == 0:
                x[ridx] = 1.0
            else:
                start = _greedy_matching(r0, r1, rw, m)
                sol = highs_solve(rw, A, np.full(nr, -np.inf), np.ones(nr),
                                   np.ones(len(ridx)), integer=True, time_limit=time_limit,
                                   mip_gap=mip_gap, start=start, presolve=False)
                solve_s = sol.seconds
                status = sol.status
                if sol.x is None:
                    xr, status = start, sol.status + " (no solution: used greedy start)"
                else:
                    xr = np.round(sol.x)
                x[ridx] = xr
                # gap of the whole problem: the reduction is exact, so the absolute gap
                # of the reduced MIP is the absolute gap of the whole problem
                abs_gap = max(0.0, float(rw @ xr) - sol.dual_bound) if np.isfinite(sol.dual_bound) \
                    else float("inf")
                tot = abs(float(w @ x))
                gap = 0.0 if abs_gap == 0.0 else (abs_gap / tot if tot > 0 else float("inf"))
        obj = float(w @ x)
    take = np.flatnonzero(x > 0.5)
    # safety: a triangle in two merges would make a pentagon
    used = np.bincount(np.concatenate([f0[take], f1[take]]), minlength=m)
    if (used > 1).any():
        from ..errors import SolverError
        raise SolverError(f"merge solution uses {int((used > 1).sum())} triangles twice "
                          f"(status {status}); report this with the input mesh")
    faces = mesh.faces.copy()
    faces[f0[take]] = quad[take]
    keep = np.ones(m, bool)
    keep[f1[take]] = False
    out = ShellMesh(mesh.points, faces[keep], mesh.component[keep], list(mesh.component_names),
                    mesh.fixed_vertices, mesh.feature_edges, mesh.feature_edge_ids)
    nq = out.n_quads
    res = MergeResult(status=status, objective=obj, mip_gap=gap, n_merged=len(take),
                      seconds=time.perf_counter() - t0, n_candidates=k, solve_seconds=solve_s,
                      quad_fraction=nq / max(out.n_faces, 1),
                      merged_edges=mesh.topology().edges[edge[take]])
    return out, res


def merge_mesh(mesh: ShellMesh, supports: Supports | None, locator, infos,
               options: MergeOptions = MergeOptions()) -> tuple[ShellMesh, Supports, dict]:
    """The pipeline's merge stage: :func:`merge_triangles` on the whole mesh, the valence term
    counting the nodes free to move within their surface or member plane (``supports``' SURFACE
    and PLANE nodes), and the supports of the result: the split stage's ``supports`` where they
    hold, else derived again (:func:`~shellmesh_mdao.core.supports.pipeline_supports` with the
    input skin ``locator`` and the members ``infos``). ``options``: the stage's
    :class:`~shellmesh_mdao.options.MergeOptions` (``merge_time_limit``, ``merge_mip_gap``,
    ``merge_bonus``, ``merge_valence_weight``: :func:`merge_triangles`' ``time_limit``,
    ``mip_gap``, ``merge_bonus``, ``valence_weight``).

    Returns ``(mesh, supports, report)``, ``report`` the pipeline report's ``merge`` entry."""
    # the valence term counts the nodes free to move within their surface or member plane: on
    # chains, feature lines and junctions the best valence is not 4
    sp = supports
    free = (np.flatnonzero(np.isin(sp.kind, (SURFACE, PLANE)))
            if sp is not None and sp.n == mesh.n_points else None)
    o = options
    out, res = merge_triangles(mesh, time_limit=o.merge_time_limit, mip_gap=o.merge_mip_gap,
                               merge_bonus=o.merge_bonus, valence_weight=o.merge_valence_weight,
                               valence_vertices=free)
    # a merge joins two triangles of one component across an edge that is no feature edge: no
    # point, feature edge or fixed vertex changes, nor any vertex's set of incident supports, so
    # the split stage's supports hold as they are (the same arrays as deriving them again)
    same = supports is not None and supports.n == out.n_points and supports_hold(mesh, out)
    sup = supports if same else pipeline_supports(out, locator, infos)
    # a gap that is not a number (no bound: the valence term in blocks; a solve cut short) is null
    gap = float(res.mip_gap) if np.isfinite(res.mip_gap) else None
    report = {"status": res.status, "objective": float(res.objective), "mip_gap": gap,
              "n_merged": int(res.n_merged), "n_candidates": int(res.n_candidates),
              "quad_fraction": round(float(res.quad_fraction), 4), "seconds": round(res.seconds, 4),
              "solve_seconds": round(res.solve_seconds, 4), "valence_weight": o.merge_valence_weight}
    return out, sup, report
