"""Meshing one member's region: a constrained Delaunay triangulation in its plane
(:func:`triangulate_planar`), a kinked member panel by panel, a non-planar member through the Coons
patch of its four sides (:func:`coons_patch`)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import sparse
from scipy.interpolate import make_interp_spline
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..core.polygon import to2d
from ..errors import ImprintError, LayoutError
from ..mesh import norm_rows, reduce_short
from .info import fit_plane
from .junctions import MemberChains, plane_frame

__all__ = ["DEFAULT_MIN_ANGLE", "NARROW_STRIP", "STRIP_MIN_ANGLE", "TRIANGLE_LANDING", "tri_min_angles", "triangulate_planar",
           "connected_pieces", "coons_patch", "mesh_planar_region", "mesh_panels", "mesh_coons"]


#: Minimum angle (degrees) requested from the constrained Delaunay refinement (``q``).
DEFAULT_MIN_ANGLE = 30.0

#: a member region none of whose points is farther than this (in units of the mesh size) from
#: its segments is a strip about one element high (a spar web, a rib of a thin wing): it is
#: triangulated from its boundary nodes alone (see :func:`triangulate_planar`)
NARROW_STRIP = 0.7

#: ... if its smallest angle is at least this (degrees; sin 15 = 0.26: the quads it gives stay
#: clear of the 0.2 scaled-Jacobian limit), or no smaller than the refined mesh's
STRIP_MIN_ANGLE = 15.0
#: Median edge length over the local size that Triangle's area-bounded refinement lands at, with
#: each triangle's area bound that of the equilateral triangle of the local size: a triangle over
#: the bound is split, so the areas settle between about half the bound and the bound (0.79-0.80
#: on a square at 20 and 50 elements across). :func:`triangulate_planar` bounds the areas by the
#: local size over it, so that the edges land at the size asked for.
TRIANGLE_LANDING = 0.8
_EQ_AREA = np.sqrt(3.0) / 4.0


# ============================================================================ small helpers
def tri_min_angles(P: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Minimum corner angle (degrees) of each triangle (points of any dimension)."""
    a, b, c = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
    # the three corners' sides stacked: one pass of each numpy call (the same value per corner)
    u = np.concatenate([b - a, a - b, a - c])
    v = np.concatenate([c - a, c - b, b - c])
    cu = np.einsum("ij,ij->i", u, v) / np.maximum(norm_rows(u, axis=1) * norm_rows(v, axis=1), 1e-300)
    ang = np.degrees(np.arccos(np.clip(cu, -1.0, 1.0)))
    k = len(T)
    return np.minimum(np.minimum(ang[:k], ang[k:2 * k]), ang[2 * k:])


def _edge_keys(e: np.ndarray, n: int) -> np.ndarray:
    e = np.sort(np.asarray(e, np.int64).reshape(-1, 2), axis=1)
    return e[:, 0] * n + e[:, 1]


# ============================================================================ planar triangulation
def _sizing_field(x: np.ndarray, seg: np.ndarray, gradation: float):
    """Element size at points of the plane (units of the target size): the boundary node
    spacing near the boundary, graded at ``gradation`` towards 1 inside (finer boundary
    spacing shrinks it, coarser spacing enlarges it near the long edges)."""
    L = norm_rows(x[seg[:, 0]] - x[seg[:, 1]], axis=1)
    acc = np.bincount(seg.ravel(), weights=np.repeat(L, 2), minlength=len(x))
    cnt = np.bincount(seg.ravel(), minlength=len(x))
    used = cnt > 0
    xb, hb = x[used], acc[used] / cnt[used]
    tree = cKDTree(xb)
    k = int(min(16, len(xb)))

    def h(q):
        d, i = tree.query(q, k=k)
        d, i = d.reshape(len(q), -1), i.reshape(len(q), -1)
        down = (hb[i] + gradation * d).min(1)
        up = (hb[i] - gradation * d).max(1)
        return np.maximum(np.minimum(np.maximum(1.0, up), down), 1e-3)

    return h


def _cross2(y: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Twice the signed area of each 2D triangle (positive: counter-clockwise)."""
    p, q, r = y[T[:, 0]], y[T[:, 1]], y[T[:, 2]]
    return (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])


def _smooth_2d(x: np.ndarray, tris: np.ndarray, seg: np.ndarray, n_fixed: int, iters: int):
    """Move the free nodes (index >= ``n_fixed``) to improve the smallest angles: each goes to
    the mean of the apexes that would make its star's opposite edges equilateral; a move is
    kept only if its star's smallest angle does not drop (and nothing folds). The mesh is
    re-triangulated (constrained Delaunay, same nodes) after every pass."""
    import triangle as tr

    free = np.arange(len(x)) >= n_fixed
    T = tris
    for _ in range(iters):
        # opposite edge (a, b) of each corner v, counter-clockwise: ideal apex on v's side
        v = T.ravel()
        a = np.roll(T, -1, axis=1).ravel()
        b = np.roll(T, -2, axis=1).ravel()
        ab = x[b] - x[a]
        nrm = np.stack([-ab[:, 1], ab[:, 0]], 1)             # left of a->b: v's side for CCW triangles
        ideal = 0.5 * (x[a] + x[b]) + nrm * (np.sqrt(3.0) / 2.0)
        acc = np.zeros_like(x)
        np.add.at(acc, v, ideal)
        cnt = np.bincount(v, minlength=len(x))
        xn = x.copy()
        mv = free & (cnt > 0)
        xn[mv] = acc[mv] / cnt[mv, None]
        a0 = tri_min_angles(x, T)
        a1 = np.where(_cross2(xn, T) > 0, tri_min_angles(xn, T), -1.0)
        s0 = np.full(len(x), np.inf)
        s1 = np.full(len(x), np.inf)
        for c in range(3):
            np.minimum.at(s0, T[:, c], a0)
            np.minimum.at(s1, T[:, c], a1)
        ok = mv & (s1 > s0 + 1e-9)
        for _ in range(5):                                   # neighbours moving together: re-check
            y = np.where(ok[:, None], xn, x)
            ay = np.where(_cross2(y, T) > 0, tri_min_angles(y, T), -1.0)
            worse = ay < np.minimum(a0, 90.0) - 1e-9
            bad = np.unique(T[worse & reduce_short(ok[T], "any")]) if worse.any() else np.zeros(0, np.int64)
            # a triangle got worse than it was: refuse the moves of its free corners unless the
            # triangle's new angle is still above every old star minimum of them
            if not len(bad):
                break
            s_bad = np.zeros(len(x), bool)
            tri_bad = worse & reduce_short(ok[T], "any") & (ay < reduce_short(s0[T], "min") + 1e-9)
            if not tri_bad.any():
                break
            s_bad[T[tri_bad].ravel()] = True
            ok &= ~s_bad
        if not ok.any():
            break
        y = np.where(ok[:, None], xn, x)
        t = tr.triangulate({"vertices": y, "segments": seg.astype(np.int32)}, "pYYQ")
        if len(t["vertices"]) != len(y):                     # (coincident nodes) keep the last good mesh
            break
        x, T = y, np.asarray(t["triangles"], np.int64)
    return x, T


def _prune_2d(x, tris, seg, n_fixed, min_angle: float = 30.0, rounds: int = 6, smooth: int = 4):
    """Remove interior nodes that spoil the smallest angle: the free corners of the worst
    triangles (within 4 degrees of the smallest angle, and below ``min_angle``; no two
    adjacent in one round) are deleted, the rest re-triangulated and smoothed; a round is
    kept only if the mesh's smallest angle improves."""
    import triangle as tr

    cur = tri_min_angles(x, tris)
    for _ in range(rounds):
        worst = float(cur.min()) if len(cur) else 90.0
        if worst >= min_angle:
            break
        bad = tris[cur < min(min_angle, worst + 4.0)]       # the worst triangles first
        cand = np.unique(bad[bad >= n_fixed])
        if not len(cand):
            break
        # independent set: drop a candidate if a lower-numbered candidate shares a triangle with it
        e = np.vstack([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
        isc = np.zeros(len(x), bool)
        isc[cand] = True
        e = e[isc[e[:, 0]] & isc[e[:, 1]]]
        lose = np.zeros(len(x), bool)
        lose[np.maximum(e[:, 0], e[:, 1])] = True
        rm = cand[~lose[cand]]
        keep = np.ones(len(x), bool)
        keep[rm] = False
        y = x[keep]
        t = tr.triangulate({"vertices": y, "segments": seg.astype(np.int32)}, "pYYQ")
        if len(t["vertices"]) != len(y):
            break
        T = np.asarray(t["triangles"], np.int64)
        y, T = _smooth_2d(y, T, seg, n_fixed, smooth)
        new = tri_min_angles(y, T)
        if new.min() <= worst:
            break
        x, tris, cur = y, T, new
    return x, tris


def _strip_width(x: np.ndarray, seg: np.ndarray, tris: np.ndarray, step: float = 0.05) -> float:
    """Largest distance from the centroids and edge midpoints of ``tris`` to the segments (their
    nodes ``x`` sampled every ``step``): how far the region's interior reaches from its boundary
    (half the height of a strip)."""
    a, b = x[seg[:, 0]], x[seg[:, 1]]
    k = np.maximum(1, np.ceil(norm_rows(b - a, axis=1) / step).astype(np.int64))
    s = np.repeat(np.arange(len(seg)), k)
    t = (np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k)) / k[s]
    samples = np.vstack([a[s] + t[:, None] * (b[s] - a[s]), b])
    q = np.vstack([reduce_short(x[tris], "mean")] + [0.5 * (x[tris[:, i]] + x[tris[:, (i + 1) % 3]]) for i in range(3)])
    return float(cKDTree(samples).query(q)[0].max()) + 0.5 * step


def triangulate_planar(uv: np.ndarray, segments: np.ndarray, size: float, min_angle: float = DEFAULT_MIN_ANGLE,
                       name: str = "member", gradation: float = 0.3, rounds: int = 3,
                       smooth: int = 6, narrow: float = NARROW_STRIP, local=None) -> tuple[np.ndarray, np.ndarray]:
    """Constrained Delaunay triangulation of a planar straight-line graph in 2D.

    ``uv`` (n, 2) nodes, ``segments`` (s, 2) node pairs that must be triangle edges (the
    region is everything enclosed by segments; triangles outside are removed), ``size`` the
    target edge length and ``min_angle`` the refinement's minimum-angle target (``triangle``'s
    ``q``). The element size follows the segments' own spacing near them and grades (rate
    ``gradation``) to ``size`` inside: the maximum area of each triangle is that of the
    equilateral triangle of the local size over :data:`TRIANGLE_LANDING` (so that the median
    edge lands at the local size), refined in ``rounds`` passes ('r' with per-triangle areas). No Steiner point is put on any segment (``YY``), so every
    segment is exactly one triangle edge. Returns ``(uv_all, tris)``: the input nodes first
    (unchanged), then the new interior nodes, and (t, 3) counter-clockwise triangles.
    Raises :class:`ImprintError` naming ``name`` if a segment is lost (crossing segments) or
    a node is left outside the region.

    A **strip** (no point of the region farther than ``narrow * size`` from a segment: a spar web
    or rib about one element high) keeps the boundary-only triangulation, without interior
    nodes, when its smallest angle is at least :data:`STRIP_MIN_ANGLE` (15 degrees) or the refined
    mesh's: a row of triangles each with an edge on one chain, which the merge pairs into quads
    with one edge on each chain (refinement would put nodes at mid-height, whose diamonds
    subdivide into skewed quads). ``narrow=0`` always refines. ``local``: a function of points
    (k, 2) in the coordinates of ``uv`` giving the local sizes asked for there (no larger than
    ``size`` is used; None: none).
    """
    import triangle as tr

    uv = np.asarray(uv, np.float64)
    seg = np.asarray(segments, np.int64).reshape(-1, 2)
    n = len(uv)
    o = uv.mean(0)
    x = (uv - o) / size                                       # target edge length 1
    sizing = _sizing_field(x, seg, gradation)
    t = tr.triangulate({"vertices": x, "segments": seg.astype(np.int32)}, "pYYQ")
    strip = None
    t0 = np.asarray(t.get("triangles", np.zeros((0, 3))), np.int64).reshape(-1, 3)
    if narrow > 0 and len(t0) and len(t["vertices"]) == n and _strip_width(x, seg, t0) < narrow:
        strip = t0
    opts = f"rpYYq{float(min_angle):.6f}aQ"
    for _ in range(rounds):
        tris = np.asarray(t["triangles"], np.int64)
        cen = reduce_short(np.asarray(t["vertices"])[tris], "mean")
        h = sizing(cen)
        if local is not None:
            h = np.minimum(h, np.maximum(np.asarray(local(cen * size + o), float) / size, 1e-3))
        n_before = len(t["vertices"])
        t = tr.triangulate({"vertices": t["vertices"], "segments": t["segments"], "triangles": tris,
                            "triangle_max_area": _EQ_AREA * (h / TRIANGLE_LANDING) ** 2}, opts)
        if len(t["vertices"]) == n_before:
            break
    tris = np.asarray(t.get("triangles", np.zeros((0, 3))), np.int64).reshape(-1, 3)
    xo = np.asarray(t["vertices"], np.float64)
    if smooth and len(xo) > n:
        xo, tris = _smooth_2d(xo, tris, seg, n, smooth)
        xo, tris = _prune_2d(xo, tris, seg, n, smooth=smooth)
    if strip is not None and (tri_min_angles(x, strip).min()
                              >= min(STRIP_MIN_ANGLE, tri_min_angles(xo, tris).min()) - 1e-9):
        xo, tris = x, strip
    if len(xo) < n or not np.array_equal(xo[:n], x):
        raise ImprintError(f"{name}: the member triangulation changed its boundary nodes (coincident chain "
                           "vertices); use a smaller --size")
    m = len(xo)
    te = np.vstack([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    lost = ~np.isin(_edge_keys(seg, m), np.unique(_edge_keys(te, m)))
    if lost.any():
        s0 = seg[np.flatnonzero(lost)[0]]
        raise ImprintError(f"{name}: its boundary or junction segments cross each other near "
                           f"{np.round(uv[s0[0]], 6).tolist()} (member-plane coordinates), so its outline is not "
                           "a simple region; move the member so its chains and junction lines do not cross, or "
                           "use a smaller --size")
    used = np.zeros(m, bool)
    used[tris.ravel()] = True
    if not used[:n].all():
        bad = np.flatnonzero(~used[:n])[0]
        raise ImprintError(f"{name}: boundary node at {np.round(uv[bad], 6).tolist()} (member-plane coordinates) "
                           "is outside the meshed region: the member's outline is not closed; check its chains")
    a, b, c = xo[tris[:, 0]], xo[tris[:, 1]], xo[tris[:, 2]]
    cr = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    tris = np.where((cr < 0)[:, None], tris[:, [0, 2, 1]], tris)
    uv_all = np.vstack([uv, xo[n:] * size + o])
    return uv_all, tris


def connected_pieces(tris: np.ndarray, segments: np.ndarray, n_nodes: int) -> tuple[int, np.ndarray]:
    """Connected pieces of a triangulation where crossing a segment is not allowed."""
    t = len(tris)
    te = np.vstack([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    tf = np.tile(np.arange(t), 3)
    k = _edge_keys(te, n_nodes)
    blocked = np.isin(k, _edge_keys(segments, n_nodes)) if len(segments) else np.zeros(len(k), bool)
    k, tf = k[~blocked], tf[~blocked]
    o = np.argsort(k, kind="stable")
    k, tf = k[o], tf[o]
    same = k[1:] == k[:-1]
    a, b = tf[:-1][same], tf[1:][same]
    g = sparse.coo_matrix((np.ones(len(a)), (a, b)), shape=(t, t))
    return connected_components(g, directed=False)


# ============================================================================ Coons patch
def coons_patch(lower: np.ndarray, upper: np.ndarray, side0: np.ndarray, side1: np.ndarray):
    """Transfinite (Coons) interpolation of four boundary polylines fitted by B-splines.

    ``lower`` runs from corner (0,0) to (1,0), ``upper`` from (0,1) to (1,1), ``side0`` from
    (0,0) to (0,1) and ``side1`` from (1,0) to (1,1) (each (k, 3); corners shared). Each is
    interpolated by a cubic B-spline (``scipy.interpolate.make_interp_spline``; lower degree
    for fewer points) in normalised chord length. Returns ``(S, params)``: ``S(s, t)``
    evaluates the patch at arrays ``s``, ``t`` in [0, 1] and ``params`` are the chord-length
    parameters of the four polylines' nodes (``S`` reproduces the nodes there).
    """
    curves = [np.asarray(c, float) for c in (lower, upper, side0, side1)]
    ends = [(curves[0][0], curves[2][0]), (curves[0][-1], curves[3][0]), (curves[1][0], curves[2][-1]),
            (curves[1][-1], curves[3][-1])]
    for a, b in ends:
        if not np.array_equal(a, b):
            raise ImprintError("coons_patch: the four sides do not share their corners; order them as "
                               "lower (0,0)->(1,0), upper (0,1)->(1,1), side0 (0,0)->(0,1), side1 (1,0)->(1,1)")
    splines, params = [], []
    for c in curves:
        d = norm_rows(np.diff(c, axis=0), axis=1)
        if not len(d) or (d <= 0).any():
            raise ImprintError("coons_patch: a side has repeated points or a single point; remove the duplicates")
        s = np.concatenate([[0.0], np.cumsum(d)]) / d.sum()
        s[-1] = 1.0
        splines.append(make_interp_spline(s, c, k=min(3, len(c) - 1)))
        params.append(s)
    cl, cu, d0, d1 = splines
    P00, P10, P01, P11 = curves[0][0], curves[0][-1], curves[1][0], curves[1][-1]

    def S(s, t):
        s = np.asarray(s, float).reshape(-1)
        t = np.asarray(t, float).reshape(-1)
        sc, tc = s[:, None], t[:, None]
        out = (1 - tc) * cl(s) + tc * cu(s) + (1 - sc) * d0(t) + sc * d1(t)
        out -= ((1 - sc) * (1 - tc)) * P00 + (sc * (1 - tc)) * P10 + ((1 - sc) * tc) * P01 + (sc * tc) * P11
        return out

    return S, params


# ============================================================================ meshing a member
def mesh_planar_region(m: MemberChains, P, outline, inner_lines, size, min_angle, n_total, size_field=None):
    """Triangulate the planar region of ``m`` (its plane in ``m.info``) bounded by the closed node
    loop ``outline`` with the interior node lines ``inner_lines``, no coarser than ``size_field``
    (a :class:`~shellmesh_mdao.core.sizefield.SizeField` in the units of ``size``; None: none)
    asks; returns the new interior points (numbered from ``n_total``, exactly on the plane) and
    the triangles (global ids)."""
    lines = [np.append(outline, outline[0])] + list(inner_lines)
    nodes = np.unique(np.concatenate(lines))
    remap = np.full(int(nodes.max()) + 1, -1, np.int64)
    remap[nodes] = np.arange(len(nodes))
    seg = np.vstack([np.stack([remap[ln[:-1]], remap[ln[1:]]], 1) for ln in lines])
    e1, e2, origin = plane_frame(m, P, nodes)
    uv = to2d(P[nodes], e1, e2, origin)
    local = None if size_field is None else \
        (lambda q: size_field.at(origin + q[:, :1] * e1 + q[:, 1:] * e2, size))
    uv_all, tris = triangulate_planar(uv, seg, size, min_angle, f"member '{m.name}'", local=local)
    st = uv_all[len(nodes):]
    newp = origin + st[:, :1] * e1 + st[:, 1:] * e2
    gid = np.concatenate([nodes, n_total + np.arange(len(st))])
    return newp, gid[tris]


def mesh_panels(m: MemberChains, P, junctions, size, min_angle, n_total, tol, size_field=None):
    """Mesh a kinked explicit member panel by panel: panel ``p`` lies between kink line ``p - 1``
    and kink line ``p`` (the member's own ends at the first and last panel) and is bounded by
    the pieces of the upper and lower chain between them. A panel whose nodes are coplanar
    (within ``tol`` of the diagonal) is meshed in its plane (new nodes exactly on it), any
    other through the Coons patch of its four sides (both no coarser than ``size_field`` asks).
    Interior junction lines must lie inside a planar panel. Returns the new interior points (from
    ``n_total``) and the triangles."""
    U, L = m.upper, m.lower
    ku = [int(np.flatnonzero(U == a)[0]) for a, _ in m.joints]
    kl = [int(np.flatnonzero(L == b)[0]) for _, b in m.joints]
    ou, ol = np.argsort(ku, kind="stable"), np.argsort(kl, kind="stable")
    if not np.array_equal(ou, ol):
        raise ImprintError(f"member '{m.name}': the lines joining the kinks of its upper and lower curves cross each "
                           "other; give its upper and lower polylines the same number of points, in the same order")
    ku = [0] + [ku[i] for i in ou] + [len(U) - 1]
    kl = [0] + [kl[i] for i in ou] + [len(L) - 1]
    if (np.diff(ku) <= 0).any() or (np.diff(kl) <= 0).any():
        raise ImprintError(f"member '{m.name}': a kink of its upper or lower curve falls on the curve's end; remove "
                           "the repeated polyline point")
    ends = [junctions[m.closing[e]].nodes if m.closing[e] is not None else m.end_lines[e] for e in (0, 1)]
    sides = [ends[0]] + [m.kink_lines[i] for i in ou] + [ends[1]]
    diag = float(norm_rows(np.ptp(P, axis=0)))
    inner = [junctions[jx] for jx in m.interior]
    pos_u = [int(np.flatnonzero((U == J.vu) | (U == J.vl))[0]) for J in inner]
    pts, tris = [], []
    for p in range(len(ku) - 1):                       # loop over the panels
        Up, Lp = U[ku[p]:ku[p + 1] + 1], L[kl[p]:kl[p + 1] + 1]
        sd = []
        for q, (a, b) in ((p, (Up[0], Lp[0])), (p + 1, (Up[-1], Lp[-1]))):
            ln = sides[q]
            if ln is None:
                ln = np.zeros(0, np.int64) if a == b else np.array([a, b], np.int64)
            elif len(ln) and ln[0] != b:
                ln = ln[::-1]                          # from the lower corner to the upper corner
            sd.append(ln)
        outline = np.concatenate([Up, sd[1][::-1][1:-1], Lp[::-1], sd[0][1:-1]])
        outline = outline[outline != np.roll(outline, 1)]
        lines_in = [inner[i].nodes for i in range(len(inner)) if ku[p] < pos_u[i] < ku[p + 1]]
        ext = float(norm_rows(np.ptp(P[outline], axis=0)))
        pp, pn = fit_plane(P[outline], tol * diag / max(ext, 1e-300))
        panel = MemberChains(replace(m.info, plane_point=pp, plane_normal=pn), upper=Up, lower=Lp)
        if pn is not None:
            newp, t = mesh_planar_region(panel, P, outline, lines_in, size, min_angle, n_total, size_field)
        else:
            if lines_in:
                raise LayoutError(f"a member meets the non-planar panel {p} of member '{m.name}' inside it; junction "
                                  "lines inside a non-planar panel are not supported: give the member a polyline "
                                  "point at the junction, or make the panel planar")
            panel.closing, panel.end_lines = [None, None], [sd[0] if len(sd[0]) else None,
                                                            sd[1] if len(sd[1]) else None]
            newp, t = mesh_coons(panel, P, junctions, size, min_angle, n_total, size_field)
        # one orientation for all panels: the upper chain is traversed forward (Up[0] -> Up[1])
        fwd = (t == Up[0]) & (np.roll(t, -1, axis=1) == Up[1])
        if not fwd.any():
            t = t[:, ::-1]
        pts.append(newp)
        tris.append(t)
        n_total += len(newp)
    return np.vstack(pts), np.vstack(tris)


def mesh_coons(m: MemberChains, P, junctions, size, min_angle, n_total, size_field=None):
    """Mesh a non-planar open member through the Coons patch of its four sides, no coarser than
    ``size_field`` asks; returns the new interior points (numbered from ``n_total``) and the
    triangles (global indices)."""
    if m.loop is not None:
        raise LayoutError(f"member '{m.name}' is non-planar and closed; a closed (full-chord) member must be planar")
    U, L = m.upper, m.lower
    sides = []
    for e in (0, 1):
        jx = m.closing[e]
        ln = junctions[jx].nodes if jx is not None else m.end_lines[e]
        a = L[0] if e == 0 else L[-1]
        if ln is None:
            raise LayoutError(f"member '{m.name}' is non-planar with a zero-length side; give it four sides")
        if ln[0] != a:
            ln = ln[::-1]
        sides.append(ln)
    S, (sl, su, s0, s1) = coons_patch(P[L], P[U], P[sides[0]], P[sides[1]])
    len_s = 0.5 * (norm_rows(np.diff(P[U], axis=0), axis=1).sum()
                   + norm_rows(np.diff(P[L], axis=0), axis=1).sum())
    len_t = 0.5 * (norm_rows(np.diff(P[sides[0]], axis=0), axis=1).sum()
                   + norm_rows(np.diff(P[sides[1]], axis=0), axis=1).sum())
    nodes = np.concatenate([L, sides[1][1:-1], U[::-1], sides[0][1:-1][::-1]])
    uv = np.vstack([np.stack([sl * len_s, np.zeros_like(sl)], 1),
                    np.stack([np.full(len(s1) - 2, len_s), s1[1:-1] * len_t], 1),
                    np.stack([su[::-1] * len_s, np.full(len(su), len_t)], 1),
                    np.stack([np.zeros(len(s0) - 2), s0[1:-1][::-1] * len_t], 1)])
    nb = len(nodes)
    seg = np.stack([np.arange(nb), (np.arange(nb) + 1) % nb], 1)
    local = None if size_field is None else (lambda q: size_field.at(S(q[:, 0] / len_s, q[:, 1] / len_t), size))
    uv_all, tris = triangulate_planar(uv, seg, size, min_angle, f"member '{m.name}'", local=local)
    st = uv_all[nb:]
    newp = S(st[:, 0] / len_s, st[:, 1] / len_t) if len(st) else np.zeros((0, 3))
    gid = np.concatenate([nodes, n_total + np.arange(len(st))])
    return newp, gid[tris]
