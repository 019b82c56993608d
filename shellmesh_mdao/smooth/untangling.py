"""Untangling: raise the worst elements' scaled Jacobian by moving vertices along their supports
(pattern search, vectorised over vertices; :func:`untangle`)."""
from __future__ import annotations

import numpy as np

from ..core.supports import CURVE, Supports, support_normals
from ..core.topology import faces_of
from ..errors import MeshValidationError
from ..mesh import ShellMesh, dot_norm_rows, dot_unit_rows, vertex_faces
from .elements import face_normals, oriented_quality, tangent_basis

__all__ = ["untangle"]

# einsum's norm and unit rows (mesh.dot_norm_rows & co.: compiled for (k, 3) rows)
_norm, _unit = dot_norm_rows, dot_unit_rows


def _tangent_dirs(supports: Supports, P, verts, nrm, ndir: int):
    """(len(verts), ndir, 3) unit move directions of each vertex along its support: ``ndir``
    directions evenly spread in the tangent plane (normal ``nrm``) of a SURFACE or PLANE
    vertex, the two senses of the curve tangent for a CURVE vertex."""
    kind, ref = supports.kind[verts], supports.ref[verts]
    nn = np.where((_norm(nrm) == 0)[:, None], [0.0, 0.0, 1.0], nrm)
    t1, t2 = tangent_basis(_unit(nn))
    cv = np.flatnonzero(kind == CURVE)
    t2[cv] = 0.0
    if len(cv):
        t1[cv] = supports.curve_set.closest(P[verts[cv]], ref[cv])[2]
    th = 2.0 * np.pi * np.arange(ndir) / ndir
    d = np.cos(th)[None, :, None] * t1[:, None, :] + np.sin(th)[None, :, None] * t2[:, None, :]
    d[cv] = np.where(np.cos(th) >= 0, 1.0, -1.0)[None, :, None] * t1[cv][:, None, :]
    return d


def untangle(mesh: ShellMesh, supports: Supports, *, goal: float = 0.3, iterations: int = 100,
             faces=None, ref_normals=None, ndir: int = 8, nstep: int = 6, patience: int = 10,
             min_dot: float = 0.0) -> tuple[ShellMesh, dict]:
    """Raise the worst elements' scaled Jacobian by moving vertices ALONG THEIR SUPPORTS
    (optimisation-based untangling by pattern search, vectorised over vertices).

    Every element at or below ``goal`` (scaled Jacobian with its own normal; an element whose
    normal points against its reference normal counts as folded) makes its movable vertices
    and their neighbours candidates. Each iteration tries, for every candidate vertex at once,
    ``ndir`` tangent directions times ``nstep`` step lengths (the vertex's mean edge
    length, halved ``nstep - 1`` times) plus moves towards the centroid of its faces, each
    projected onto the vertex's support (skin: closest point on the input surface restricted
    to triangles facing the vertex's way; planes; curves) and dropped if the projection jumps
    farther than the move. A vertex takes the candidate with the smallest penalty
    ``sum over its faces of max(0, goal + 0.1 - q)^2`` among those that keep the minimum over
    its faces at or above ``min(current minimum, goal)``; vertices that share a face never move
    in the same round (the worst-placed one moves), so no element below ``goal`` ever gets
    worse. Stops when no element is at or below ``goal``, no vertex can improve, or
    ``patience`` iterations in a row brought neither fewer elements at or below ``goal`` nor
    a better worst element.

    ``faces``: ids of the elements to repair (default all); the others only constrain the
    moves (none at or below ``goal`` gets worse, none above falls to it).
    ``ref_normals`` (m, 3): the orientation each face must keep (default: its own normal on
    entry; pass e.g. the parent faces' normals where the entry mesh is folded).

    Returns ``(mesh with moved points, info)`` with ``info`` = ``{"iterations", "moves",
    "min_before", "min_after", "n_bad_before", "n_bad_after"}`` (over ``faces``; ``n_bad`` =
    elements at or below ``goal``, flipped ones included).
    """
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("untangle needs a ShellMesh; build one with ShellMesh(points, faces)")
    if not isinstance(supports, Supports) or supports.n != mesh.n_points:
        raise MeshValidationError("untangle needs Supports with one entry per mesh vertex: build them with "
                                  "derive_supports(mesh, ...) for this mesh")
    n = mesh.n_points
    P = mesh.points.copy()
    F = mesh.faces
    is_tri = mesh.is_tri
    m = len(F)
    info = {"iterations": 0, "moves": 0, "min_before": None, "min_after": None, "n_bad_before": 0,
            "n_bad_after": 0}
    if not m:
        return mesh, info
    nref = face_normals(P, F, is_tri) if ref_normals is None else \
        _unit(np.asarray(ref_normals, np.float64).reshape(m, 3))
    Fc = np.where(F >= 0, F, F[:, :1])

    def quality(sel):
        return oriented_quality(P[Fc[sel]], is_tri[sel], nref[sel])

    q = quality(np.arange(m))
    region = np.arange(m) if faces is None else np.unique(np.asarray(faces, np.int64).reshape(-1))
    info["min_before"] = float(q[region].min(initial=np.inf))
    info["n_bad_before"] = int((q[region] <= goal).sum())
    movable = supports.dof() > 0
    vptr, vface = vertex_faces(F, n)
    hi = goal + 0.1
    it = 0
    best = (np.inf, -np.inf)
    since = 0
    for it in range(1, iterations + 1):
        bad = region[q[region] <= goal]
        if not len(bad):
            it -= 1
            break
        # stalled: neither fewer elements at or below the goal nor a better worst one lately
        now = (len(bad), float(q[bad].min()))
        if now[0] < best[0] or now[1] > best[1] + 1e-6:
            best, since = (min(best[0], now[0]), max(best[1], now[1])), 0
        else:
            since += 1
            if since >= patience:
                break
        # candidates: movable vertices of the bad faces and of the faces around them
        v0 = np.unique(F[bad][F[bad] >= 0])
        ring = faces_of(vptr, vface, v0, m)
        cand = np.unique(F[ring][F[ring] >= 0])
        cand = cand[movable[cand]]
        if not len(cand):
            break
        # incidences (vertex, face), grouped by vertex
        cnt = vptr[cand + 1] - vptr[cand]
        inc_v = np.repeat(np.arange(len(cand)), cnt)
        inc_f = vface[np.repeat(vptr[cand], cnt) + np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)]
        start = np.cumsum(cnt) - cnt
        Cf = P[Fc[inc_f]]                                              # (k, 4, 3)
        slot = Fc[inc_f] == cand[inc_v][:, None]
        slot[is_tri[inc_f], 3] = False
        qf = q[inc_f]
        cur_min = np.minimum.reduceat(qf, start)
        cur_pen = np.add.reduceat(np.maximum(0.0, hi - qf) ** 2, start)
        # mean edge length at each vertex (its two sides in each face)
        pos = np.argmax(slot, axis=1)
        k4 = np.where(is_tri[inc_f], 3, 4)
        nx = np.take_along_axis(Cf, ((pos + 1) % k4)[:, None, None].repeat(3, 2), 1)[:, 0]
        pv = np.take_along_axis(Cf, ((pos - 1) % k4)[:, None, None].repeat(3, 2), 1)[:, 0]
        me = P[cand[inc_v]]
        h = np.add.reduceat(_norm(nx - me) + _norm(pv - me), start) / (2 * cnt)
        # centroid of the vertex's faces
        fsum = Cf[:, :3].sum(1) + np.where(is_tri[inc_f][:, None], 0.0, Cf[:, 3])
        fcen = np.add.reduceat(fsum / k4[:, None], start) / cnt[:, None]
        snrm = support_normals(supports, P, cand)
        dirs = _tangent_dirs(supports, P, cand, snrm, ndir)              # (c, ndir, 3)
        steps = 0.5 ** np.arange(0, nstep)
        moves = (dirs[:, :, None, :] * steps[None, None, :, None]).reshape(len(cand), -1, 3) * h[:, None, None]
        to_c = (fcen - P[cand])[:, None, :] * np.array([1.0, 0.5, 0.25])[None, :, None]
        moves = np.concatenate([moves, to_c], 1)
        K = moves.shape[1]
        Y = P[cand][:, None, :] + moves
        kind = np.repeat(supports.kind[cand], K)
        refs = np.repeat(supports.ref[cand], K)
        vnrm = np.repeat(snrm, K, axis=0)
        Yp, ok = supports.project_kind(Y.reshape(-1, 3), kind, refs, vnrm, min_dot)
        Yp = Yp.reshape(len(cand), K, 3)
        ok = ok.reshape(len(cand), K) & (_norm((Yp - Y).reshape(-1, 3)).reshape(len(cand), K)
                                         <= _norm(moves.reshape(-1, 3)).reshape(len(cand), K) + 1e-12 * h[:, None])
        # every candidate of every vertex at once: (K, incidences) qualities
        Ck = np.broadcast_to(Cf, (K,) + Cf.shape).copy()
        Ck[:, slot] = np.swapaxes(Yp[inc_v], 0, 1)
        qk = oriented_quality(Ck.reshape(-1, 4, 3), np.tile(is_tri[inc_f], K),
                           np.tile(nref[inc_f], (K, 1))).reshape(K, -1)
        mn = np.minimum.reduceat(qk, start, axis=1)                       # (K, c)
        pen = np.add.reduceat(np.maximum(0.0, hi - qk) ** 2, start, axis=1)
        # every face of the vertex keeps min(its quality, goal): none at or below the goal gets
        # worse, none above falls to it
        keep = np.logical_and.reduceat(qk >= np.minimum(qf, goal)[None, :] - 1e-12, start, axis=1)
        feas = ok.T & keep & (
            (pen < cur_pen - 1e-12) | ((pen <= cur_pen) & (mn > cur_min + 1e-12)))
        pen = np.where(feas, pen, np.inf)
        low = pen == pen.min(0)
        best_k = np.argmax(np.where(low & feas, mn, -np.inf), axis=0)
        best_k[~feas.any(0)] = -1
        imp = np.flatnonzero(best_k >= 0)
        if not len(imp):
            break
        # independent set: a vertex moves when it has the best priority among the improving
        # vertices of each of its faces (priority: lowest current minimum, then index)
        rank = np.full(len(cand), np.iinfo(np.int64).max)
        order = np.lexsort((cand[imp], cur_min[imp]))
        rank[imp[order]] = np.arange(len(imp))
        uf, finv = np.unique(inc_f, return_inverse=True)
        frank = np.full(len(uf), np.iinfo(np.int64).max)
        np.minimum.at(frank, finv, rank[inc_v])
        lose = np.zeros(len(cand), bool)
        np.logical_or.at(lose, inc_v, frank[finv] < rank[inc_v])
        go = imp[~lose[imp]]
        P[cand[go]] = Yp[go, best_k[go]]
        info["moves"] += len(go)
        fs = faces_of(vptr, vface, cand[go], m)
        q[fs] = quality(fs)
    info["iterations"] = it
    info["min_after"] = float(q[region].min(initial=np.inf))
    info["n_bad_after"] = int((q[region] <= goal).sum())
    out = mesh.with_points(P)
    return out, info
