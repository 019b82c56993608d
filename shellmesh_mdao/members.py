"""Members: triangle meshes of the internal members that share the imprint chains' nodes.

Stage order: load -> layout -> project -> imprint -> **members** -> split -> merge -> smooth -> quad -> export.

Every internal member is a four-sided surface (the paper, Sec. IV.A): its upper and lower
sides are its imprint chains on the upper and lower skin, its two other sides are junction
lines with the members it ends on (a rib's lines with the front and rear spar) or straight
end lines where nothing closes it. The member mesh uses the chain vertices themselves (the
same point indices as the skin), so skin and member conform by construction.

Junctions between members (found as the skin vertices two members' chains share):

* a **junction line** joins the upper and lower crossing vertex of two members (both are
  skin vertices on both chains). For planar members it is the straight segment on the
  intersection line of the two planes (parallel to the wing's ``up`` in a wing box). It is
  discretised once and the same nodes are used by both members;
* **T-junction**: the line is at the end of one member's chains (a rib ends on a spar) and
  inside the other (the spar). The rib closes on it; the spar keeps it as interior edges
  and stays one component;
* **X-junction**: the line is inside both members (a rib crosses a middle spar). Both
  members are split into pieces along it, named ``<member>/seg_<j>`` with ``j`` counted
  along the member's direction (ribs front to rear, spars root to tip: a middle spar's
  ``seg_k`` is the bay between rib ``k`` and rib ``k + 1`` when it starts at rib 0). A
  member with at least one X-junction is split along all its interior junction lines;
* **L-junction**: the line ends both members (the wing-box corner rib 0 x spar 0).

Before meshing, chains are completed (edges a later cut split get their vertices back),
crossing vertices are put exactly on both planes, very uneven chain spacing is evened out
by sliding chain vertices along their exact curves, and chain edges much longer than the
member is tall are split (with the two skin triangles on them). Each planar member is then
one constrained Delaunay triangulation of its plane's 2D frame (``triangle``, no Steiner
point on any chain or junction segment), refined to a size graded from the boundary spacing
to ``size``, smoothed and pruned for its smallest angle. A kinked explicit member (one chain
piece per polyline segment on both sides, not coplanar) is split into panels by the straight
lines joining its upper and lower kinks, each meshed in its own plane; any other non-planar
member is meshed in the parameter square of a Coons patch of B-spline fits of its four sides.

See ``docs/members.md`` for the method, the numbering of the new nodes and the error
messages.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy import sparse
from scipy.interpolate import make_interp_spline
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from .errors import ImprintError, LayoutError, SizeError
from .imprint import _arc_param, _arc_point, _sub_polyline
from .mesh import ShellMesh, vertex_faces, norm_rows, reduce_short
from .section import Plane

__all__ = ["MemberInfo", "member_infos", "build_members", "member_statistics", "triangulate_planar",
           "coons_patch", "explicit_plane", "DEFAULT_MIN_ANGLE", "NARROW_STRIP",
           "STRIP_MIN_ANGLE"]

#: Minimum angle (degrees) requested from the constrained Delaunay refinement (``q``).
DEFAULT_MIN_ANGLE = 30.0
#: a closed (full-chord) member's outline may not have a corner sharper than this: a quad in
#: a corner of angle a has a scaled Jacobian of at most sin(a), and the pipeline guarantees > 0.2
MIN_LOOP_CORNER = float(np.degrees(np.arcsin(0.2)))
#: a member region none of whose points is farther than this (in units of the mesh size) from
#: its segments is a strip about one element high (a spar web, a rib of a thin wing): it is
#: triangulated from its boundary nodes alone (see :func:`triangulate_planar`)
NARROW_STRIP = 0.7
#: ... if its smallest angle is at least this (degrees; sin 15 = 0.26: the quads it gives stay
#: clear of the 0.2 scaled-Jacobian limit), or no smaller than the refined mesh's
STRIP_MIN_ANGLE = 15.0
_EQ_AREA = np.sqrt(3.0) / 4.0


# ============================================================================ member description
@dataclass
class MemberInfo:
    """What :func:`build_members` needs per member beyond its chains.

    ``name``          the member's name (``<wing>/rib_<k>``, ``<wing>/spar_<j>`` or an explicit
                      member's name); its chains (``ChainResult.member``) carry the same name.
    ``kind``          ``'rib'``, ``'spar'`` or ``'explicit'``.
    ``plane_point``, ``plane_normal``  the member plane; both None for a non-planar member
                      (meshed through a Coons patch of its four sides).
    ``up``            the wing's up vector (informative).
    ``direction``     the member's running direction (rib: front to rear, spar: root to tip;
                      ``end - start`` of its defining curve in the layout): orients the chains
                      and numbers the pieces ``seg_<j>`` along it. None: the upper chain's order.
    ``wing``, ``index`` owning wing and rib/spar number (None and position for explicit members).
    """

    name: str
    kind: str = "explicit"
    plane_point: np.ndarray | None = None
    plane_normal: np.ndarray | None = None
    up: np.ndarray | None = None
    direction: np.ndarray | None = None
    wing: str | None = None
    index: int = 0

    def __post_init__(self):
        for k in ("plane_point", "plane_normal", "up", "direction"):
            v = getattr(self, k)
            if v is not None:
                v = np.asarray(v, dtype=np.float64).reshape(3)
                if not np.isfinite(v).all():
                    raise LayoutError(f"member '{self.name}': {k} {v.tolist()} is not finite; give a finite vector")
                setattr(self, k, v)
        if (self.plane_point is None) != (self.plane_normal is None):
            raise LayoutError(f"member '{self.name}': give both plane_point and plane_normal (or neither for a "
                              "non-planar member)")
        if self.plane_normal is not None:
            n = float(np.linalg.norm(self.plane_normal))
            if n == 0:
                raise LayoutError(f"member '{self.name}': plane_normal is the zero vector; give the plane's normal")
            self.plane_normal = self.plane_normal / n

    @property
    def is_planar(self) -> bool:
        return self.plane_normal is not None

    @property
    def plane(self) -> Plane | None:
        return Plane(self.plane_point, self.plane_normal) if self.is_planar else None

    @classmethod
    def from_spec(cls, spec) -> "MemberInfo":
        """From a :class:`~shellmesh_mdao.layout.MemberSpec` (or anything with its attributes).
        An explicit member runs along its ``upper`` polyline; it gets the plane its layout spans
        when its polylines and projection directions lie in one plane (:func:`explicit_plane`),
        else none here (:func:`build_members` fits one to its imprinted chains when they are
        coplanar, as for closest-point projection, or meshes it panel by panel)."""
        kind = getattr(spec, "kind", "explicit")
        pp, pn = getattr(spec, "plane_point", None), getattr(spec, "plane_normal", None)
        direction = None
        start, end = getattr(spec, "start", None), getattr(spec, "end", None)
        if start is not None and end is not None:
            direction = np.asarray(end, float) - np.asarray(start, float)
        if kind == "explicit" and getattr(spec, "upper", None) is not None:
            up_pts = np.asarray(spec.upper, float).reshape(-1, 3)
            direction = up_pts[-1] - up_pts[0]
            if pn is None:
                pp, pn = explicit_plane(spec)
        return cls(name=spec.name, kind=kind, plane_point=pp, plane_normal=pn, up=getattr(spec, "up", None),
                   direction=direction, wing=getattr(spec, "wing", None), index=int(getattr(spec, "index", 0) or 0))


def explicit_plane(spec, tol: float = 1e-9):
    """The plane of a planar explicit member from its layout: ``(point, unit normal)`` when its
    ``upper`` and ``lower`` polylines and both projection directions lie in one plane (within
    ``tol`` times the polylines' extent), else ``(None, None)`` (a kinked or twisted member, or
    closest-point projection, whose projection directions are not known before projecting)."""
    d_up = getattr(spec, "direction", None)
    if d_up is None:
        return None, None
    up_pts = np.asarray(spec.upper, float).reshape(-1, 3)
    lo_pts = np.asarray(spec.lower, float).reshape(-1, 3)
    d_lo = getattr(spec, "lower_direction", None)
    dirs = np.asarray([d_up] + ([] if d_lo is None else [d_lo]), float)
    dirs = dirs / norm_rows(dirs, axis=1, keepdims=True)
    pts = np.vstack([up_pts, lo_pts])
    ext = float(norm_rows(np.ptp(pts, axis=0)))
    seg = np.diff(up_pts, axis=0)
    k = int(np.argmax(norm_rows(seg, axis=1)))
    n = np.cross(seg[k], dirs[0])
    ln = float(np.linalg.norm(n))
    if ext == 0 or ln <= 1e-12 * float(np.linalg.norm(seg[k])):
        return None, None
    n = n / ln
    if np.abs((pts - up_pts[0]) @ n).max() > tol * ext or np.abs(dirs @ n).max() > tol:
        return None, None
    return up_pts[0].copy(), n


def _fit_plane(pts: np.ndarray, tol: float):
    """Least-squares plane of ``pts``: ``(point, normal)``, or ``(None, None)`` when they are
    not coplanar within ``tol`` times their extent (or are collinear)."""
    c = pts.mean(0)
    ext = float(np.linalg.norm(pts.max(0) - pts.min(0)))
    if ext == 0 or len(pts) < 3:
        return None, None
    _, s, vt = np.linalg.svd(pts - c)
    if s[1] <= 1e-9 * s[0]:
        return None, None
    n = vt[2]
    if np.abs((pts - c) @ n).max() > tol * ext:
        return None, None
    return c, n


def member_infos(layout) -> list:
    """:class:`MemberInfo` of every member of a layout (a :class:`~shellmesh_mdao.layout.Layout`,
    dict or path), in :meth:`~shellmesh_mdao.layout.Layout.members` order."""
    from .layout import Layout, load_layout
    lay = layout if isinstance(layout, Layout) else load_layout(layout)
    return [MemberInfo.from_spec(s) for s in lay.members()]


# ============================================================================ small helpers
def _tri_min_angles(P: np.ndarray, T: np.ndarray) -> np.ndarray:
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


def _line_params(L: float, size: float, h0: float | None = None, h1: float | None = None) -> np.ndarray:
    """Interior parameters in (0, 1) dividing a line of length ``L`` into pieces of about
    ``size``, graded (spacing growing by at most 0.3 per unit length) from the end spacings
    ``h0``/``h1`` when these are smaller, so the first piece at a crossing matches the chain
    edges meeting there. A line shorter than about ``1.5`` pieces stays one piece."""
    if L <= 0:
        return np.zeros(0)
    h0 = size if h0 is None else min(max(h0, 1e-12 * L), size)
    h1 = size if h1 is None else min(max(h1, 1e-12 * L), size)
    # spacing function h(x) = min(size, h0 + g x, h1 + g (L - x)); place nodes at equal steps
    # of the integral of 1/h (vectorised on a fine sample)
    g = 0.3
    x = np.linspace(0.0, L, 2049)
    h = np.minimum(size, np.minimum(h0 + g * x, h1 + g * (L - x)))
    w = np.concatenate([[0.0], np.cumsum(0.5 * (1 / h[1:] + 1 / h[:-1]) * np.diff(x))])
    n = max(1, int(np.round(w[-1])))
    if n == 1:
        return np.zeros(0)
    t = np.interp(np.arange(1, n) * (w[-1] / n), w, x) / L
    return t


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
        a0 = _tri_min_angles(x, T)
        a1 = np.where(_cross2(xn, T) > 0, _tri_min_angles(xn, T), -1.0)
        s0 = np.full(len(x), np.inf)
        s1 = np.full(len(x), np.inf)
        for c in range(3):
            np.minimum.at(s0, T[:, c], a0)
            np.minimum.at(s1, T[:, c], a1)
        ok = mv & (s1 > s0 + 1e-9)
        for _ in range(5):                                   # neighbours moving together: re-check
            y = np.where(ok[:, None], xn, x)
            ay = np.where(_cross2(y, T) > 0, _tri_min_angles(y, T), -1.0)
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

    cur = _tri_min_angles(x, tris)
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
        new = _tri_min_angles(y, T)
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
                       smooth: int = 6, narrow: float = NARROW_STRIP) -> tuple[np.ndarray, np.ndarray]:
    """Constrained Delaunay triangulation of a planar straight-line graph in 2D.

    ``uv`` (n, 2) nodes, ``segments`` (s, 2) node pairs that must be triangle edges (the
    region is everything enclosed by segments; triangles outside are removed), ``size`` the
    target edge length and ``min_angle`` the refinement's minimum-angle target (``triangle``'s
    ``q``). The element size follows the segments' own spacing near them and grades (rate
    ``gradation``) to ``size`` inside: the maximum area of each triangle is that of the
    equilateral triangle of the local size, refined in ``rounds`` passes ('r' with per-triangle
    areas). No Steiner point is put on any segment (``YY``), so every
    segment is exactly one triangle edge. Returns ``(uv_all, tris)``: the input nodes first
    (unchanged), then the new interior nodes, and (t, 3) counter-clockwise triangles.
    Raises :class:`ImprintError` naming ``name`` if a segment is lost (crossing segments) or
    a node is left outside the region.

    A **strip** (no point of the region farther than ``narrow * size`` from a segment: a spar web
    or rib about one element high) keeps the boundary-only triangulation, without interior
    nodes, when its smallest angle is at least :data:`STRIP_MIN_ANGLE` (15 degrees) or the refined
    mesh's: a row of triangles each with an edge on one chain, which the merge pairs into quads
    with one edge on each chain (refinement would put nodes at mid-height, whose diamonds
    subdivide into skewed quads). ``narrow=0`` always refines.
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
        h = sizing(reduce_short(np.asarray(t["vertices"])[tris], "mean"))
        n_before = len(t["vertices"])
        t = tr.triangulate({"vertices": t["vertices"], "segments": t["segments"], "triangles": tris,
                            "triangle_max_area": _EQ_AREA * h * h}, opts)
        if len(t["vertices"]) == n_before:
            break
    tris = np.asarray(t.get("triangles", np.zeros((0, 3))), np.int64).reshape(-1, 3)
    xo = np.asarray(t["vertices"], np.float64)
    if smooth and len(xo) > n:
        xo, tris = _smooth_2d(xo, tris, seg, n, smooth)
        xo, tris = _prune_2d(xo, tris, seg, n, smooth=smooth)
    if strip is not None and (_tri_min_angles(x, strip).min()
                              >= min(STRIP_MIN_ANGLE, _tri_min_angles(xo, tris).min()) - 1e-9):
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


def _pieces(tris: np.ndarray, segments: np.ndarray, n_nodes: int) -> tuple[int, np.ndarray]:
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


# ============================================================================ chains and crossings
@dataclass
class _Member:
    info: MemberInfo
    upper: np.ndarray | None = None      # ordered chain vertices (open members)
    lower: np.ndarray | None = None
    loop: np.ndarray | None = None       # closed chain (full-chord rib)
    arcs: tuple = ()                     # exact SectionArcs of its chains
    closing: list = field(default_factory=lambda: [None, None])   # per end: junction index or None
    interior: list = field(default_factory=list)                  # junction indices inside it
    end_lines: list = field(default_factory=list)                 # node arrays of its own end lines
    sides: list = field(default_factory=list)        # two open chains (upper/lower, or a loop's halves)
    side_arcs: list = field(default_factory=list)    # their exact curves (open polylines or None)
    joints: list = field(default_factory=list)       # non-planar explicit member: (upper, lower) kink vertices
    kink_lines: list = field(default_factory=list)   # node arrays of the lines joining the kink vertices

    @property
    def name(self) -> str:
        return self.info.name

    def chain_vertices(self) -> np.ndarray:
        return self.loop if self.loop is not None else np.concatenate([self.upper, self.lower])

    def make_sides(self, P: np.ndarray) -> None:
        """Two open chains: the upper and lower chain, or a closed chain cut at its extreme
        points along the member direction (leading and trailing edge of a full-chord rib)."""
        if self.loop is None:
            self.sides = [self.upper, self.lower]
            self.side_arcs = [None if a is None else a.points for a in self.arcs]
            return
        lp = self.loop
        d = self.info.direction
        X = P[lp] - P[lp].mean(0)
        if d is None:
            d = np.linalg.svd(X, full_matrices=False)[2][0]
        proj = X @ d
        ia, ib = int(np.argmin(proj)), int(np.argmax(proj))
        n = len(lp)
        A = lp[(ia + np.arange((ib - ia) % n + 1)) % n]
        B = lp[(ib + np.arange((ia - ib) % n + 1)) % n]
        self.sides = [A, B]
        arc = self.arcs[0]
        if arc is None or len(A) < 2 or len(B) < 2:
            self.side_arcs = [None, None]
            return
        s, p, cum = _arc_param(P[[lp[ia], lp[ib]] + [A[len(A) // 2]]], arc.points, True)
        tot = cum[-1]
        pp = np.vstack([p[:-1], p[:-1] + 0.0, p[:1]])          # the loop twice (parameters 0 .. 2 tot)
        cc = np.concatenate([cum[:-1], cum[:-1] + tot, [2 * tot]])
        s0, s1, sm = s
        fwd = ((sm - s0) % tot) < ((s1 - s0) % tot)             # A runs with the parameter from s0 to s1
        a0, a1 = (s0, s0 + (s1 - s0) % tot) if fwd else (s1, s1 + (s0 - s1) % tot)
        b0, b1 = (a1, a0 + tot)
        self.side_arcs = [_sub_polyline(pp, cc, a0, a1), _sub_polyline(pp, cc, b0 % tot, b0 % tot + (b1 - b0))]

    def sync_sides(self) -> None:
        """Write the (possibly refined) sides back into the chains."""
        if self.loop is None:
            self.upper, self.lower = self.sides
        else:
            A, B = self.sides
            self.loop = np.concatenate([A, B[1:-1]])


@dataclass
class _Junction:
    i: int                     # member indices (i < j)
    j: int
    vu: int                    # upper and lower crossing vertices
    vl: int
    nodes: np.ndarray | None = None      # vu, interior nodes, vl
    where: dict = field(default_factory=dict)   # member index -> 'end' | 'interior'

    @property
    def kind(self) -> str:
        w = sorted(self.where.values())
        return {("interior", "interior"): "X", ("end", "interior"): "T", ("end", "end"): "L"}[tuple(w)]


def _member_feature_graph(skin: ShellMesh, name: str):
    fe = skin.feature_edges
    if name in skin.component_names:
        sel = fe[skin.feature_edge_ids == skin.component_names.index(name)]
        if len(sel):
            fe = sel
    n = skin.n_points
    g = sparse.coo_matrix((np.ones(len(fe)), (fe[:, 0], fe[:, 1])), shape=(n, n)).tocsr()
    return (g + g.T).tocsr()


def _complete_chain(skin: ShellMesh, verts: np.ndarray, closed: bool, name: str, side: str) -> np.ndarray:
    """Make every consecutive pair of chain vertices a mesh edge: a chain edge split later by
    another member's cut (a middle spar crossing a rib) gets its split nodes back, found
    along the member's feature edges."""
    v = np.asarray(verts, np.int64)
    if len(v) < 2:
        raise ImprintError(f"member '{name}': its {side} chain has {len(v)} vertex; re-run the imprint")
    pairs = np.stack([v, np.roll(v, -1)], 1) if closed else np.stack([v[:-1], v[1:]], 1)
    ok = skin.topology().edge_ids(pairs) >= 0
    if ok.all():
        return v
    g = _member_feature_graph(skin, name)
    out = [v[:1]]
    for i, (a, b) in enumerate(pairs):          # loop over the few missing pairs' neighbours
        if ok[i]:
            out.append(np.asarray([b], np.int64))
            continue
        dist, pred = dijkstra(g, directed=False, indices=int(a), unweighted=True, limit=16,
                              return_predecessors=True)
        if not np.isfinite(dist[b]):
            raise ImprintError(f"member '{name}': its {side} chain is broken between skin vertices {a} and {b} "
                               "(no mesh edge joins them); imprint this member again, or use a smaller --size")
        path = [int(b)]
        while path[-1] != a:
            path.append(int(pred[path[-1]]))
        out.append(np.asarray(path[::-1][1:], np.int64))
    w = np.concatenate(out)
    return w[:-1] if closed else w


def _exact_crossing(P, v, mem: _Member, other: MemberInfo):
    """Point where ``mem``'s exact chain arcs cross ``other``'s plane, nearest to ``P[v]``."""
    best, bd = None, np.inf
    for arc in mem.arcs:
        if arc is None:
            continue
        a = np.vstack([arc.points, arc.points[:1]]) if arc.closed else arc.points
        s = other.plane.side(a)
        i = np.flatnonzero((s[:-1] >= 0) != (s[1:] >= 0))
        if not len(i):
            continue
        den = s[i] - s[i + 1]
        t = s[i] / np.where(den != 0, den, 1.0)
        x = a[i] + t[:, None] * (a[i + 1] - a[i])
        d = norm_rows(x - P[v], axis=1)
        j = int(np.argmin(d))
        if d[j] < bd:
            best, bd = x[j], d[j]
    return best


def _check_chain_order(skin: ShellMesh, ch: np.ndarray, arc, name: str, side: str) -> None:
    """An open chain's vertices must run along its exact curve in order; a vertex placed
    behind its predecessor means the imprint folded the skin there."""
    if arc is None or arc.closed or len(ch) < 3:
        return
    s = _arc_param(skin.points[ch], arc.points, False)[0]
    ds = np.diff(s) * (1.0 if s[-1] >= s[0] else -1.0)
    back = np.flatnonzero(ds < -1e-9 * skin.diagonal)
    if len(back):
        v = int(ch[back[0] + 1])
        raise ImprintError(f"member '{name}': its {side} chain runs backwards along the member's curve at skin vertex "
                           f"{v} {np.round(skin.points[v], 6).tolist()} (the imprint folded the skin there); "
                           "use a smaller --size, or remesh the skin before imprinting")


def _side_of(side: str) -> tuple:
    """('upper', 0) for 'upper' or 'upper_0' (an explicit member's chain piece)."""
    base, _, tail = side.rpartition("_")
    if base and tail.isdigit():
        return base, int(tail)
    return side, 0


def _join_pieces(pieces: list, name: str, side: str) -> np.ndarray:
    """Join chain pieces that share end vertices into one chain (in piece order)."""
    out = np.asarray(pieces[0], np.int64)
    for k, p in enumerate(pieces[1:], 1):
        p = np.asarray(p, np.int64)
        if k == 1 and out[0] in (p[0], p[-1]) and out[-1] not in (p[0], p[-1]):
            out = out[::-1]
        if p[0] == out[-1]:
            out = np.concatenate([out, p[1:]])
        elif p[-1] == out[-1]:
            out = np.concatenate([out, p[::-1][1:]])
        else:
            raise ImprintError(f"member '{name}': pieces {k - 1} and {k} of its {side} chain do not meet at a "
                               "skin vertex; imprint the member again (its polyline points must lie on the skin)")
    return out


@dataclass
class _Arc:
    points: np.ndarray
    closed: bool = False


def _join_arcs(arcs: list):
    """One open polyline through the exact curves of a chain's pieces (None if one is missing)."""
    if any(a is None or a.closed for a in arcs):
        return None
    out = np.asarray(arcs[0].points, float)
    for k, a in enumerate(arcs[1:], 1):
        p = np.asarray(a.points, float)
        if k == 1:
            d = [np.linalg.norm(out[i] - p[j]) for i in (0, -1) for j in (0, -1)]
            if int(np.argmin(d)) < 2:
                out = out[::-1]
        if np.linalg.norm(out[-1] - p[-1]) < np.linalg.norm(out[-1] - p[0]):
            p = p[::-1]
        out = np.vstack([out, p[1:]])
    return _Arc(out)


def _gather(skin: ShellMesh, chains, infos, tol: float) -> list:
    by_name = {m.name: i for i, m in enumerate(infos)}
    grouped = [dict() for _ in infos]
    for c in chains:
        if c.member not in by_name:
            raise LayoutError(f"chain of member '{c.member}' ({c.side}) has no MemberInfo; pass one MemberInfo per "
                              f"member (given: {[m.name for m in infos][:6]}{'...' if len(infos) > 6 else ''})")
        side, piece = _side_of(c.side)
        g = grouped[by_name[c.member]].setdefault(side, {})
        if piece in g:
            raise ImprintError(f"member '{c.member}' has two '{c.side}' chains; imprint each side once")
        g[piece] = c
    mems = []
    diag = skin.diagonal
    for info, g in zip(infos, grouped):
        if not g:
            raise ImprintError(f"member '{info.name}' has no imprint chain: it was not imprinted into the skin; "
                               "imprint every member before building the member meshes")
        closed = [side for side, pcs in g.items() for c in pcs.values()
                  if (c.arc.closed if c.arc is not None else side == "loop")]
        if closed:
            if len(g) != 1 or len(g[closed[0]]) != 1:
                raise ImprintError(f"member '{info.name}' has a closed chain and other chains; a full-chord member "
                                   "has exactly one closed chain")
            c = next(iter(g[closed[0]].values()))
            mem = _Member(info)
            mem.loop = _complete_chain(skin, c.vertices, True, info.name, c.side)
            mem.arcs = (c.arc,)
        else:
            if set(g) != {"upper", "lower"}:
                raise ImprintError(f"member '{info.name}' has chains {sorted(g)}; it needs an 'upper' and a 'lower' "
                                   "chain (or one closed 'loop' chain): imprint both skin sides")
            mem = _Member(info)
            sides, arcs, joints = [], [], []
            for side in ("upper", "lower"):
                pcs = [g[side][k] for k in sorted(g[side])]
                piece_ch = [_complete_chain(skin, c.vertices, False, info.name, c.side) for c in pcs]
                ch = _join_pieces(piece_ch, info.name, side)
                arc = pcs[0].arc if len(pcs) == 1 else _join_arcs([c.arc for c in pcs])
                _check_chain_order(skin, ch, arc, info.name, side)
                sides.append(ch)
                arcs.append(arc)
                joints.append([_shared_end(a, b) for a, b in zip(piece_ch[:-1], piece_ch[1:])])
            mem.upper, mem.lower = sides
            mem.arcs = tuple(arcs)
        if not info.is_planar:
            pp, pn = _fit_plane(skin.points[mem.chain_vertices()], tol * diag / max(
                float(norm_rows(np.ptp(skin.points[mem.chain_vertices()], axis=0))), 1e-300))
            if pn is not None:
                mem.info = replace(info, plane_point=pp, plane_normal=pn)
            elif mem.loop is None and len(joints[0]) == len(joints[1]) and len(joints[0]):
                # a kinked explicit member (one chain piece per polyline segment on both sides):
                # meshed as panels between the lines joining its kink vertices
                mem.joints = list(zip(joints[0], joints[1]))
        mems.append(mem)
    return mems


def _shared_end(a: np.ndarray, b: np.ndarray) -> int:
    """The end vertex two consecutive chain pieces share (they were joined on it)."""
    for x in (a[0], a[-1]):
        if x in (b[0], b[-1]):
            return int(x)
    raise ImprintError("internal error: consecutive chain pieces share no end vertex; report this")


def _orient(mems, P):
    """Orient each open member's upper chain along its direction and its lower chain to match."""
    for m in mems:
        if m.loop is not None:
            continue
        U, L = m.upper, m.lower
        d = m.info.direction
        if d is not None and (P[U[-1]] - P[U[0]]) @ d < 0:
            U = U[::-1]
        same = np.linalg.norm(P[U[0]] - P[L[0]]) + np.linalg.norm(P[U[-1]] - P[L[-1]])
        swap = np.linalg.norm(P[U[0]] - P[L[-1]]) + np.linalg.norm(P[U[-1]] - P[L[0]])
        if swap < same:
            L = L[::-1]
        m.upper, m.lower = U, L


def _find_junctions(mems, P, diag) -> list:
    """Junctions = pairs of members whose chains share skin vertices (vectorised incidence)."""
    verts = [m.chain_vertices() for m in mems]
    vid = np.concatenate(verts)
    mid = np.repeat(np.arange(len(mems)), [len(v) for v in verts])
    vm = np.unique(np.stack([vid, mid], 1), axis=0)          # sorted by vertex then member
    cnt = np.bincount(vm[:, 0], minlength=len(P))
    multi = vm[cnt[vm[:, 0]] >= 2]
    shared: dict = {}
    starts = np.flatnonzero(np.concatenate([[True], multi[1:, 0] != multi[:-1, 0]])) if len(multi) else \
        np.zeros(0, np.int64)
    bounds = np.append(starts, len(multi))
    for s, e in zip(bounds[:-1], bounds[1:]):                # loop over crossing vertices
        v, ms = int(multi[s, 0]), multi[s:e, 1]
        for a in range(len(ms)):
            for b in range(a + 1, len(ms)):
                shared.setdefault((int(ms[a]), int(ms[b])), []).append(v)
    out = []
    for (i, j), vs in sorted(shared.items()):
        mi, mj = mems[i], mems[j]
        if len(vs) == 1:
            raise ImprintError(f"members '{mi.name}' and '{mj.name}' meet on one skin side only, at "
                               f"{np.round(P[vs], 6).tolist()}: they cross each other inside the skin and the end "
                               "line of one passes through the other; move or extend one so that they cross on both "
                               "skin sides (or not at all), or use a smaller --size")
        if len(vs) != 2:
            raise ImprintError(f"members '{mi.name}' and '{mj.name}' meet at {len(vs)} skin point(s) "
                               f"{np.round(P[vs], 6).tolist()}; two members must meet at exactly two (one on each "
                               "skin side): move one of them, or use a smaller --size")
        vu, vl = vs
        for m in (mi, mj):                                    # upper crossing: on an upper chain
            if m.upper is not None:
                if vl in set(m.upper.tolist()) and vu not in set(m.upper.tolist()):
                    vu, vl = vl, vu
                break
        out.append(_Junction(i, j, vu, vl))
    return out


def _exact_junction_vertices(junctions, mems, P, diag, eps):
    """Move crossing vertices that are not on both planes (within 1e-12 of the diagonal) to
    the exact crossing of the input surface with both planes."""
    for J in junctions:
        mi, mj = mems[J.i], mems[J.j]
        if not (mi.info.is_planar and mj.info.is_planar):
            continue
        for v in (J.vu, J.vl):
            off = max(abs(mi.info.plane.side(P[v])), abs(mj.info.plane.side(P[v])))
            if off <= 1e-12 * diag:
                continue
            x = _exact_crossing(P, v, mi, mj.info)
            if x is None:
                x = _exact_crossing(P, v, mj, mi.info)
            if x is None or np.linalg.norm(x - P[v]) > 1e-3 * diag:
                if off > eps:
                    raise ImprintError(f"members '{mi.name}' and '{mj.name}' share skin vertex {v} off the "
                                       "intersection of their planes; imprint them again (their crossing was "
                                       "not inserted)")
                continue
            P[v] = x


def _classify(mems, junctions):
    """For every member: which junction closes each end, which lie inside it."""
    for jx, J in enumerate(junctions):
        for k in (J.i, J.j):
            m = mems[k]
            other = mems[J.j if k == J.i else J.i].name
            if m.loop is not None:
                if not ((m.loop == J.vu).any() and (m.loop == J.vl).any()):
                    raise ImprintError(f"member '{m.name}' meets '{other}' on one skin side only; imprint both")
                J.where[k] = "interior"
                m.interior.append(jx)
                continue
            U, L = m.upper, m.lower
            pu = np.flatnonzero(U == J.vu)
            pl = np.flatnonzero(L == J.vl)
            if not (len(pu) and len(pl)):
                pu, pl = np.flatnonzero(U == J.vl), np.flatnonzero(L == J.vu)
            if not (len(pu) and len(pl)):
                raise ImprintError(f"member '{m.name}' meets '{other}' twice on the same skin side; its upper and "
                                   "lower chains must each cross the other member once: check the layout (the "
                                   "member may run along the other one)")
            iu, il = int(pu[0]), int(pl[0])
            eu = 0 if iu == 0 else (1 if iu == len(U) - 1 else -1)
            el = 0 if il == 0 else (1 if il == len(L) - 1 else -1)
            if eu >= 0 and el >= 0 and eu == el:
                if m.closing[eu] is not None:
                    raise ImprintError(f"member '{m.name}' ends on two members at the same end "
                                       f"('{mems[_other(junctions[m.closing[eu]], k)].name}' and '{other}'); "
                                       "move one of them")
                m.closing[eu] = jx
                J.where[k] = "end"
            elif eu < 0 and el < 0:
                m.interior.append(jx)
                J.where[k] = "interior"
            else:
                raise ImprintError(
                    f"member '{m.name}': its chains do not close into panels at its junction with '{other}' (the "
                    f"{'upper' if eu >= 0 else 'lower'} chain ends there but the "
                    f"{'lower' if eu >= 0 else 'upper'} chain runs on); the crossing on the other skin side is "
                    "missing: check that both members reach both skin sides, or use a smaller --size")
    # interior junctions must come in the same order along the upper and the lower chain
    for k, m in enumerate(mems):
        if m.loop is not None or len(m.interior) < 2:
            continue
        iu, il = [], []
        for jx in m.interior:
            J = junctions[jx]
            a, b = (J.vu, J.vl) if (m.upper == J.vu).any() else (J.vl, J.vu)
            iu.append(int(np.flatnonzero(m.upper == a)[0]))
            il.append(int(np.flatnonzero(m.lower == b)[0]))
        o = np.argsort(iu, kind="stable")
        if (np.diff(np.asarray(il)[o]) <= 0).any():
            raise ImprintError(f"member '{m.name}': the members crossing it do so in a different order on the upper "
                               "and on the lower skin, so their junction lines would cross inside it; check the "
                               "layout")
        m.interior = [m.interior[q] for q in o]


def _other(J, k):
    return J.j if k == J.i else J.i


def _chain_edge_len(P, chain, v, closed=False):
    """Mean length of the chain edges at vertex ``v`` of ``chain``."""
    p = np.flatnonzero(chain == v)
    if not len(p):
        return None
    p = int(p[0])
    n = len(chain)
    nb = [(p - 1) % n, (p + 1) % n] if closed else [q for q in (p - 1, p + 1) if 0 <= q < n]
    return float(np.mean([np.linalg.norm(P[chain[q]] - P[v]) for q in nb]))


def _end_spacing(mems, J, v, P):
    """Chain spacing at crossing vertex ``v`` for the junction line of ``J``: the geometric
    mean of the chain-edge lengths there, over both members."""
    hs = []
    for k in (J.i, J.j):
        m = mems[k]
        for ch in ((m.loop,) if m.loop is not None else (m.upper, m.lower)):
            h = _chain_edge_len(P, ch, v, closed=m.loop is not None)
            if h is not None:
                hs.append(h)
    return float(np.exp(np.mean(np.log(np.maximum(hs, 1e-300))))) if hs else None


def _outline_nodes(m: _Member, junctions) -> list:
    """Ordered boundary loop (node indices) of an open member: upper, end 1, lower reversed, end 0."""
    U, L = m.upper, m.lower
    parts = [U]
    for e in (1, 0):
        jx = m.closing[e]
        ln = junctions[jx].nodes if jx is not None else m.end_lines[e]
        if ln is None:
            ln = np.zeros(0, np.int64)
        a = U[-1] if e == 1 else L[0]
        if len(ln) and ln[0] != a:
            ln = ln[::-1]
        parts.append(ln[1:-1] if len(ln) else ln)
        if e == 1:
            parts.append(L[::-1])
    loop = np.concatenate(parts)
    keep = loop != np.roll(loop, 1)              # zero-length sides: drop repeated corners
    return loop[keep]


def _plane_frame(m: _Member, P: np.ndarray, nodes: np.ndarray):
    n = m.info.plane_normal
    d = m.info.direction
    if d is None and m.upper is not None:
        d = P[m.upper[-1]] - P[m.upper[0]]
    e1 = None
    if d is not None:
        e1 = d - (d @ n) * n
        e1 = e1 / np.linalg.norm(e1) if np.linalg.norm(e1) > 1e-12 * max(np.linalg.norm(d), 1e-300) else None
    if e1 is None:
        X = P[nodes] - P[nodes].mean(0)
        X = X - np.outer(X @ n, n)
        _, _, vt = np.linalg.svd(X, full_matrices=False)
        e1 = vt[0] - (vt[0] @ n) * n
        e1 /= np.linalg.norm(e1)
        if e1[np.argmax(np.abs(e1))] < 0:
            e1 = -e1
    e2 = np.cross(n, e1)
    c = P[nodes].mean(0)
    origin = c - ((c - m.info.plane_point) @ n) * n
    return e1, e2, origin


# ============================================================================ chain spacing
def _relax_chains(skin: ShellMesh, P: np.ndarray, mems, chains_arcs, ratio: float = 0.67, rounds: int = 20,
                  min_skin_angle: float = 10.0, pinned=None) -> int:
    """Even out uneven chain spacing by sliding chain vertices along their exact arcs.

    ``chains_arcs``: (open chain, its exact curve as an open polyline) pairs. A chain vertex
    (not a crossing, not a chain end, not on a geometric feature line) whose
    two chain edges differ by more than ``1/ratio`` moves half-way towards the arc-length
    midpoint of its neighbours. The point stays on the exact curve (input surface and member
    plane); moves that would fold a skin triangle or drop its smallest angle below
    ``min(current, min_skin_angle)`` are refused; ``pinned`` (vertex ids) never move (the kinks
    of a kinked member). Updates ``P`` in place; returns the number of vertices moved."""
    F = skin.faces[:, :3]
    n = len(P)
    count = np.zeros(n, np.int64)
    for m in mems:
        np.add.at(count, np.unique(m.chain_vertices()), 1)
    geo = np.zeros(n, bool)
    geo[skin.feature_edges[skin.feature_edge_ids < 0].ravel()] = True
    if pinned is not None and len(pinned):
        geo[np.asarray(pinned, np.int64)] = True
    # per chain: parameters along its arc, ordered; collect movable interior vertices
    recs = []
    for ch, poly in chains_arcs:                     # loop over chains
        if poly is None or len(ch) < 3:
            continue
        s, p, cum = _arc_param(P[ch], poly, False)
        if s[-1] < s[0]:
            ch = ch[::-1]
            s = s[::-1]
        if (np.diff(s) <= 0).any():
            continue
        recs.append((ch, s, p, cum))
    if not recs:
        return 0
    ptr, vf = vertex_faces(F, n)
    moved_total = np.zeros(n, bool)

    def tri_state(X, fids):
        t = F[fids]
        a, b, c = X[t[:, 0]], X[t[:, 1]], X[t[:, 2]]
        nrm = np.cross(b - a, c - a)
        return nrm, _tri_min_angles(X, t)

    for _ in range(rounds):
        prop_v, prop_x = [], []
        for ch, s, p, cum in recs:                   # loop over chains (vectorised inside)
            sp, sc, sn = s[:-2], s[1:-1], s[2:]
            lp, ln = sc - sp, sn - sc
            v = ch[1:-1]
            mov = (count[v] == 1) & ~geo[v] & (np.minimum(lp, ln) < ratio * np.maximum(lp, ln))
            if not mov.any():
                continue
            target = sc + 0.5 * (0.5 * (sp + sn) - sc)
            prop_v.append(v[mov])
            prop_x.append(_arc_point(p, cum, target[mov]))
        if not prop_v:
            break
        v = np.concatenate(prop_v)
        x = np.vstack(prop_x)
        ok = np.ones(len(v), bool)
        for _ in range(6):                           # refuse moves that spoil a skin triangle
            vv = v[ok]
            if not len(vv):
                break
            k = ptr[vv + 1] - ptr[vv]
            fids = np.unique(vf[np.repeat(ptr[vv], k) + np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k)])
            X = P.copy()
            X[vv] = x[ok]
            n0, a0 = tri_state(P, fids)
            n1, a1 = tri_state(X, fids)
            fold = np.einsum("ij,ij->i", n0, n1) <= 0.5 * norm_rows(n0, axis=1) * norm_rows(n1, axis=1)
            # a move may not make its vertex's star worse than it was (or than min_skin_angle)
            worst = np.full(n, np.inf)
            for c in range(3):
                np.minimum.at(worst, F[fids, c], a0)
            floor = np.where(np.isin(F[fids], vv), np.minimum(worst[F[fids]], min_skin_angle), np.inf).min(1)
            bad = fold | (a1 < floor - 1e-9)
            if not bad.any():
                break
            badv = np.unique(F[fids[bad]])
            ok &= ~np.isin(v, badv)
        if not ok.any():
            break
        P[v[ok]] = x[ok]
        moved_total[v[ok]] = True
        # refresh parameters of the moved chains
        new = []
        for ch, s, p, cum in recs:
            m = np.isin(ch, v[ok])
            if m.any():
                s = s.copy()
                s[m] = _arc_param(P[ch[m]], p, False)[0]
            new.append((ch, s, p, cum))
        recs = new
    return int(moved_total.sum())


def _dist_to_polyline(q: np.ndarray, poly: np.ndarray) -> np.ndarray:
    if len(poly) < 2:
        return norm_rows(q - poly[0], axis=1)
    s, p, cum = _arc_param(q, poly, False)
    return norm_rows(_arc_point(p, cum, s) - q, axis=1)


def _check_loop_corners(mems, P) -> None:
    """Refuse a closed member (full-chord rib) whose outline has a corner sharper than
    :data:`MIN_LOOP_CORNER`: where the rib plane cuts a sharp leading or trailing edge (a
    wedge of the skin), every quad at that corner has a scaled Jacobian of at most
    sin(corner), below the pipeline's guarantee, whatever the element size."""
    for m in mems:
        if m.loop is None or len(m.loop) < 3:
            continue
        L = P[m.loop]
        u, v = np.roll(L, 1, axis=0) - L, np.roll(L, -1, axis=0) - L
        cosv = np.einsum("ij,ij->i", u, v) / np.maximum(norm_rows(u, axis=1) * norm_rows(v, axis=1),
                                                        1e-300)
        ang = np.degrees(np.arccos(np.clip(cosv, -1.0, 1.0)))
        k = int(np.argmin(ang))
        if ang[k] < MIN_LOOP_CORNER:
            p = ", ".join(f"{x:.6g}" for x in L[k])
            raise LayoutError(
                f"member '{m.name}' cuts a sharp edge of the skin: its outline has a {ang[k]:.1f} deg corner at "
                f"[{p}] (the upper and lower skin meet there at that angle), and any quad in that corner has a "
                f"scaled Jacobian of at most sin({ang[k]:.1f} deg) = {np.sin(np.radians(ang[k])):.3f}, below the "
                f"0.2 guarantee at any element size; end the rib on spars (with two or more spars every rib "
                f"runs between them) or round that edge of the surface")


def _opposite_angle(P, tri, a, b):
    """Angle (degrees) of each triangle ``tri`` (k, 3) at its corner that is neither ``a`` nor ``b``."""
    c = np.where((tri[:, 0] != a) & (tri[:, 0] != b), tri[:, 0],
                 np.where((tri[:, 1] != a) & (tri[:, 1] != b), tri[:, 1], tri[:, 2]))
    u, v = P[a] - P[c], P[b] - P[c]
    cosv = np.einsum("ij,ij->i", u, v) / np.maximum(norm_rows(u, axis=1) * norm_rows(v, axis=1), 1e-300)
    return np.degrees(np.arccos(np.clip(cosv, -1.0, 1.0)))


def _apex(F, f, a_, b_):
    """The corner of each face ``F[f]`` that is neither ``a_`` nor ``b_``."""
    t = F[f]
    return np.where((t[:, 0] != a_) & (t[:, 0] != b_), t[:, 0], np.where((t[:, 1] != a_) & (t[:, 1] != b_), t[:, 1], t[:, 2]))


def _fan_fractions(P, a_, b_, apices, ck):
    """Where along each edge ``a_-b_`` its ``ck - 1`` split points go (fractions, concatenated):
    the mean over the apices of the points that divide each apex's angle into ``ck`` equal
    parts (the ray at angle ``phi`` from ``c-a`` meets ``a-b`` at ``t = |ca| sin(phi) /
    (|ca| sin(phi) + |cb| sin(theta - phi))``); equal pieces when the apices face the middle."""
    nnew = ck - 1
    rep = np.repeat(np.arange(len(ck)), nnew)
    j = (np.arange(len(rep)) - np.repeat(np.cumsum(nnew) - nnew, nnew) + 1) / ck[rep]
    t = np.zeros(len(rep))
    for c in apices:
        ca, cb = P[a_] - P[c], P[b_] - P[c]
        la, lb = norm_rows(ca, axis=1), norm_rows(cb, axis=1)
        th = np.arccos(np.clip(np.einsum("ij,ij->i", ca, cb) / np.maximum(la * lb, 1e-300), -1.0, 1.0))
        phi = j * th[rep]
        num = la[rep] * np.sin(phi)
        t += num / np.maximum(num + lb[rep] * np.sin(th[rep] - phi), 1e-300)
    return t / len(apices)


def _fan_points(P, mems, cm, cw, a_, b_, ck, frac=None):
    """The ``ck - 1`` points splitting each chain edge ``a_-b_`` (side ``cw`` of member ``cm``)
    into ``ck`` pieces along the side's exact arc, concatenated edge by edge: at the arc-length
    fractions ``frac`` (concatenated) or, by default, equal pieces."""
    nnew = ck - 1
    off = np.concatenate([[0], np.cumsum(nnew)[:-1]])
    X = np.zeros((int(nnew.sum()), 3))
    for mi, w in sorted(set(zip(cm.tolist(), cw.tolist()))):   # one arc query per member side
        sel = np.flatnonzero((cm == mi) & (cw == w))
        s, p, cum = _arc_param(P[np.concatenate([a_[sel], b_[sel]])], mems[mi].side_arcs[w], False)
        sa, sb = s[:len(sel)], s[len(sel):]
        rep = np.repeat(np.arange(len(sel)), nnew[sel])
        j = np.arange(len(rep)) - np.repeat(np.cumsum(nnew[sel]) - nnew[sel], nnew[sel]) + 1
        pos = np.repeat(off[sel], nnew[sel]) + j - 1
        tpar = sa[rep] + (sb[rep] - sa[rep]) * (j / ck[sel][rep] if frac is None else frac[pos])
        X[pos] = _arc_point(p, cum, tpar)
    return X


def _fan_sequences(a_, b_, ck, first):
    """Node sequences ``a, new..., b`` of every split edge (new nodes numbered from ``first``),
    concatenated; with each sequence's start and length."""
    seq_len = ck + 1
    seq_start = np.concatenate([[0], np.cumsum(seq_len)[:-1]])
    rep = np.repeat(np.arange(len(ck)), seq_len)
    j = np.arange(len(rep)) - seq_start[rep]
    seq = np.where(j == 0, a_[rep], np.where(j == ck[rep], b_[rep], first[rep] + j - 1))
    return seq, seq_start, seq_len


def _fan_min_angles(P, F, mems, cm, cw, a_, b_, f0, f1, ck, frac=None, fixed=None, fixed_floor: float = 0.0):
    """Smallest angle of the fan triangles that splitting each chain edge ``a_-b_`` into ``ck``
    pieces (at the arc fractions ``frac``, concatenated; default: dividing the apex angles
    evenly) would make in its two skin faces ``f0``, ``f1``; -1 where a fan triangle's angle at
    an apex that is ``fixed`` (bool per point) is below ``fixed_floor`` degrees (no smoothing
    can open that corner: its quad after the subdivision keeps it)."""
    c0, c1 = _apex(F, f0, a_, b_), _apex(F, f1, a_, b_)
    if frac is None:
        frac = _fan_fractions(P, a_, b_, (c0, c1), ck)
    X = _fan_points(P, mems, cm, cw, a_, b_, ck, frac)
    Q = np.vstack([P, X])
    first = len(P) + np.concatenate([[0], np.cumsum(ck - 1)[:-1]])
    seq, seq_start, seq_len = _fan_sequences(a_, b_, ck, first)
    e_of = np.repeat(np.arange(len(ck)), ck)
    jj = np.arange(len(e_of)) - np.repeat(np.cumsum(ck) - ck, ck)
    s0 = seq[seq_start[e_of] + jj]
    s1 = seq[seq_start[e_of] + jj + 1]
    worst = np.full(len(ck), np.inf)
    for f in (f0, f1):
        t = F[f]
        c = np.where((t[:, 0] != a_) & (t[:, 0] != b_), t[:, 0], np.where((t[:, 1] != a_) & (t[:, 1] != b_), t[:, 1], t[:, 2]))
        tri = np.stack([s0, s1, c[e_of]], 1)
        ang = _tri_min_angles(Q, tri)
        if fixed is not None and fixed_floor > 0:
            at = np.flatnonzero(fixed[c[e_of]])
            if len(at):
                ang[at[_opposite_angle(Q, tri[at], s0[at], s1[at]) < fixed_floor]] = -1.0
        np.minimum.at(worst, e_of, ang)
    return worst


def _mirror_fractions(P, ch, other, L, thin, min_len: float, max_pieces: int):
    """Ladder split points of the thin chain edges of one member side: the closest points on
    the side (chain ``ch``, edge lengths ``L``) of the opposite side's vertices (``other``) that
    fall inside an edge flagged ``thin`` and lie across the member from it (no farther than the
    edge is long), at least ``max(min_len, 0.3 x their distance)`` from the edge's ends and from
    each other. Returns ``(count, frac)``: points per edge and an (edges, max_pieces - 1) array
    of arc fractions along the edge (NaN-padded, increasing)."""
    ne = len(L)
    frac = np.full((ne, max(max_pieces - 1, 1)), np.nan)
    cnt = np.zeros(ne, np.int64)
    if not thin.any() or len(other) == 0:
        return cnt, frac
    s, p, cum = _arc_param(P[other], P[ch], False)
    d = norm_rows(_arc_point(p, cum, s) - P[other], axis=1)
    e = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, ne - 1)
    t = (s - cum[e]) * L[e] / np.maximum((cum[e + 1] - cum[e]) * L[e], 1e-300)   # fraction along the edge
    margin = np.maximum(min_len, 0.3 * d) / np.maximum(L[e], 1e-300)
    ok = thin[e] & (d <= L[e]) & (t > margin) & (t < 1.0 - margin)
    e, t, margin = e[ok], t[ok], margin[ok]
    o = np.lexsort((t, e))
    e, t, margin = e[o], t[o], margin[o]
    close = np.zeros(len(e), bool)                   # too close to the previous point on the same edge
    close[1:] = (e[1:] == e[:-1]) & (t[1:] - t[:-1] < np.maximum(margin[1:], margin[:-1]))
    e, t = e[~close], t[~close]
    cnt = np.bincount(e, minlength=ne).astype(np.int64)
    j = np.arange(len(e)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    fit = j < frac.shape[1]
    frac[e[fit], j[fit]] = t[fit]
    cnt = np.where(cnt <= frac.shape[1], cnt, 0)     # too many: no ladder for that edge
    return cnt, frac


def _split_thin_chain_edges(P, F, C, FE, FID, mems, size, ratio: float = 1.5, max_pieces: int = 16,
                            min_piece: float = 0.02, min_height: float = 0.1, rounds: int = 3,
                            min_fan_angle: float = 15.0, min_skin_angle: float = 10.0, fixed=None):
    """Split chain edges that are long compared with the member's local height.

    Where a member is thinner than its chain spacing (the spars of a thin wing), no
    triangle joining its upper and lower chains can have good angles: a chain edge longer
    than ``ratio`` times the distance from its midpoint to the member's opposite chain is
    split into equal pieces along its exact arc (new points on the input surface and the
    member plane), and the two skin triangles on that edge are split into fans. Pieces are
    never shorter than ``min_piece * size`` and at most ``max_pieces``; where the member is
    thinner than ``min_height * size`` (the tip of a wedge, a trailing edge) nothing is
    split. A fan of ``k`` pieces divides the skin angle opposite the edge (in each of its
    two skin triangles) into ``k``: ``k`` is at most that angle over ``min_fan_angle``
    degrees, so no skin triangle is fanned into slivers (near the sharp leading or trailing
    edge of a full-chord rib the height drops to zero and the old rule split the chain edges
    into up to 16 pieces: skin angles of 3 degrees that no later stage could repair). The
    split points divide each skin face's apex angle evenly (the mean of the two faces' points)
    rather than the edge: with an apex off to one side (an obtuse skin corner at a chain
    vertex, common where a full-chord rib meets a spar) equal pieces leave a sliver of that
    angle in the far piece. Then ``k`` drops until no fan triangle has an angle below the
    smaller of ``min_skin_angle`` (the imprint's own floor) and the smallest angle of the face
    it replaces, and no fan triangle whose apex is one of the ``fixed`` skin vertices (bool per
    point; a chain's crossing with a crease, say) has an angle there below ``min_fan_angle``:
    the subdivision's quad at that corner keeps the angle, whose sine bounds its scaled
    Jacobian (a ladder had split a 38-degree corner at a rib's trailing-edge crossing into
    17.2, 10.5 and 10.3 degrees: a final quad of 0.183 on cessna210 stress seed 41).
    Ladder: a thin edge (longer than ``ratio`` times the height) with vertices of the opposite
    side across it is split at their closest points instead (:func:`_mirror_fractions`), also
    where the height is below ``min_height * size``: in the thin trailing-edge wedge of a
    full-chord rib the two sides then have matching vertices, so the corner triangle and the
    triangles along the wedge are not slivers (a long edge opposite short ones left 8-degree rib
    triangles). The ladder is taken when its fans keep the floor above, else its best single
    point, else the even split.
    Returns the updated ``(P, F, C, FE, FID)``; the members' sides get the new vertices
    (call ``sync_sides`` afterwards)."""
    for _ in range(rounds):
        if fixed is not None and len(fixed) < len(P):       # the points of the rounds before are free
            fixed = np.concatenate([fixed, np.zeros(len(P) - len(fixed), bool)])
        # ------------------------------------------------ candidates, per member side
        cm, cw, ci, ck, ck_old, cfr = [], [], [], [], [], []
        for mi, m in enumerate(mems):                 # loop over members
            for w in (0, 1):
                ch, other, arc = m.sides[w], m.sides[1 - w], m.side_arcs[w]
                if arc is None or len(ch) < 2:
                    continue
                a, b = P[ch[:-1]], P[ch[1:]]
                L = norm_rows(b - a, axis=1)
                H = _dist_to_polyline(0.5 * (a + b), P[other])
                thin = (L > ratio * H) & (L >= 2 * min_piece * size)
                want = np.where(H >= min_height * size, np.ceil(L / np.maximum(ratio * H, 1e-300)), 1)
                k = np.minimum(np.minimum(want, max_pieces), np.floor(L / (min_piece * size))).astype(np.int64)
                # ladder: the opposite side's vertices across a thin edge (also near a wedge tip,
                # where the height rule splits nothing)
                nm, mf = _mirror_fractions(P, ch, other, L, thin, min_piece * size, max_pieces)
                k_lad = np.where(nm > 0, nm + 1, k)
                i = np.flatnonzero(k_lad >= 2)
                cm.append(np.full(len(i), mi))
                cw.append(np.full(len(i), w))
                ci.append(i)
                ck.append(k_lad[i])
                ck_old.append(np.maximum(k[i], 1))
                cfr.append(np.where((nm > 0)[i, None], mf[i], np.nan))
        if not cm or not sum(len(x) for x in ci):
            break
        cm, cw, ci, ck, ck_old = (np.concatenate(x).astype(np.int64) for x in (cm, cw, ci, ck, ck_old))
        cfr = np.vstack(cfr)
        lad = ~np.isnan(cfr[:, 0])
        a_ = np.array([mems[m].sides[w][i] for m, w, i in zip(cm, cw, ci)], np.int64)
        b_ = np.array([mems[m].sides[w][i + 1] for m, w, i in zip(cm, cw, ci)], np.int64)
        # ------------------------------------------------ the two skin faces of every candidate edge
        n = len(P)
        ek = np.minimum(a_, b_) * n + np.maximum(a_, b_)
        fk = (np.minimum(F, np.roll(F, -1, axis=1)) * n + np.maximum(F, np.roll(F, -1, axis=1))).ravel()
        o = np.argsort(fk, kind="stable")
        sk = fk[o]
        lo, hi = np.searchsorted(sk, ek, "left"), np.searchsorted(sk, ek, "right")
        if ((hi - lo) != 2).any():
            bad = int(np.flatnonzero((hi - lo) != 2)[0])
            raise ImprintError(f"member '{mems[cm[bad]].name}': chain edge {a_[bad]}-{b_[bad]} is not an edge between "
                               "two skin triangles; imprint the member again")
        f0, f1 = o[lo] // 3, o[lo + 1] // 3
        # no fan triangle below min_skin_angle, nor below the smallest angle of the face it replaces
        floor_ang = np.minimum(min_skin_angle, np.minimum(_tri_min_angles(P, F[f0]), _tri_min_angles(P, F[f1])))
        # a ladder split is taken as it is when its fans keep the floor below, else the edge
        # falls back to the even split
        wl = cfr.shape[1]
        if lad.any():
            lv = np.flatnonzero(lad)
            fr = cfr[lv][np.arange(wl)[None, :] < (ck[lv] - 1)[:, None]]
            worst = _fan_min_angles(P, F, mems, cm[lv], cw[lv], a_[lv], b_[lv], f0[lv], f1[lv], ck[lv], fr,
                                       fixed=fixed, fixed_floor=min_fan_angle)
            fail = lv[worst < floor_ang[lv] - 1e-9]
            if len(fail):
                # else the single ladder point whose fans are best, if they keep the floor
                nf = ck[fail] - 1
                rep = np.repeat(fail, nf)
                j = np.arange(len(rep)) - np.repeat(np.cumsum(nf) - nf, nf)
                one = np.ones(len(rep), np.int64) * 2
                w1 = _fan_min_angles(P, F, mems, cm[rep], cw[rep], a_[rep], b_[rep], f0[rep], f1[rep], one,
                                     cfr[rep, j], fixed=fixed, fixed_floor=min_fan_angle)
                o = np.lexsort((-w1, rep))
                best = o[np.concatenate([[True], rep[o][1:] != rep[o][:-1]])]
                good = w1[best] >= floor_ang[rep[best]] - 1e-9
                gi = rep[best][good]
                chosen = cfr[gi, j[best][good]]
                cfr[gi] = np.nan
                cfr[gi, 0] = chosen
                ck[gi] = 2
                fail = np.setdiff1d(fail, gi)
            lad[fail] = False
            ck[fail] = ck_old[fail]
        # a fan of k pieces splits the skin angle opposite the edge into k: no fan angle below
        # min_fan_angle (or, when that angle is already smaller, no split at all)
        apex = np.minimum(_opposite_angle(P, F[f0], a_, b_), _opposite_angle(P, F[f1], a_, b_))
        ck = np.where(lad, ck, np.minimum(ck, np.floor(apex / min_fan_angle))).astype(np.int64)
        # ... but equal pieces along the edge divide that angle evenly only when the apex faces
        # the edge's middle: the split points divide the two apex angles evenly instead (mean of
        # the two), and fewer pieces are used until every fan triangle keeps the smaller of
        # min_skin_angle and the smallest angle of the face it replaces.
        for _k in range(max_pieces):
            live = np.flatnonzero((ck >= 2) & ~lad)
            if not len(live):
                break
            worst = _fan_min_angles(P, F, mems, cm[live], cw[live], a_[live], b_[live], f0[live], f1[live], ck[live],
                                   fixed=fixed, fixed_floor=min_fan_angle)
            bad = live[worst < floor_ang[live] - 1e-9]
            if not len(bad):
                break
            ck[bad] -= 1
        keep_c = ck >= 2
        cm, cw, ci, ck, a_, b_, f0, f1, lad, cfr = (x[keep_c] for x in (cm, cw, ci, ck, a_, b_, f0, f1, lad, cfr))
        if not len(cm):
            break
        # face-disjoint subset: a candidate is taken when it is the first to claim both its faces
        idx = np.arange(len(cm))
        owner = np.full(len(F), len(cm))
        np.minimum.at(owner, f0, idx)
        np.minimum.at(owner, f1, idx)
        take = (owner[f0] == idx) & (owner[f1] == idx)
        cm, cw, ci, ck, a_, b_, f0, f1, lad, cfr = (x[take] for x in (cm, cw, ci, ck, a_, b_, f0, f1, lad, cfr))
        # ------------------------------------------------ new points on the exact arcs
        nnew = ck - 1
        first = len(P) + np.concatenate([[0], np.cumsum(nnew)[:-1]])
        frac = _fan_fractions(P, a_, b_, (_apex(F, f0, a_, b_), _apex(F, f1, a_, b_)), ck)
        use = np.arange(wl)[None, :] < nnew[:, None]
        frac = np.where(np.repeat(lad, nnew), cfr[use], frac)
        X = _fan_points(P, mems, cm, cw, a_, b_, ck, frac)
        # ------------------------------------------------ node sequences a, new..., b of every split edge
        seq, seq_start, seq_len = _fan_sequences(a_, b_, ck, first)
        # ------------------------------------------------ fans replacing the two faces
        new_faces, new_C = [], []
        for f in (f0, f1):
            t = F[f]
            fwd = np.zeros(len(f), bool)
            c = np.zeros(len(f), np.int64)
            for q in range(3):
                u, v = t[:, q], t[:, (q + 1) % 3]
                hit_f = (u == a_) & (v == b_)
                hit_r = (u == b_) & (v == a_)
                fwd |= hit_f
                c = np.where(hit_f | hit_r, t[:, (q + 2) % 3], c)
            e_of = np.repeat(np.arange(len(ck)), ck)          # k fan triangles per face
            jj = np.arange(len(e_of)) - np.repeat(np.cumsum(ck) - ck, ck)
            s0 = seq_start[e_of] + np.where(fwd[e_of], jj, ck[e_of] - jj)
            s1 = seq_start[e_of] + np.where(fwd[e_of], jj + 1, ck[e_of] - jj - 1)
            new_faces.append(np.stack([seq[s0], seq[s1], c[e_of]], 1))
            new_C.append(C[f][e_of])
        drop = np.zeros(len(F), bool)
        drop[f0] = drop[f1] = True
        # ------------------------------------------------ feature edges: (a, b) -> its pieces, same owner
        m_fe = len(P) + len(X)
        fe_key = FE[:, 0] * m_fe + FE[:, 1]
        sp_key = np.minimum(a_, b_) * m_fe + np.maximum(a_, b_)
        hit = np.isin(fe_key, sp_key)
        okey = np.argsort(fe_key, kind="stable")
        pos = okey[np.clip(np.searchsorted(fe_key[okey], sp_key), 0, len(okey) - 1)]
        owner_id = np.where(fe_key[pos] == sp_key, FID[pos], -1).astype(np.int32)
        pieces = np.sort(np.stack([seq[:-1], seq[1:]], 1), axis=1)
        valid = np.ones(len(seq) - 1, bool)
        valid[(seq_start + seq_len - 1)[:-1]] = False             # no piece joins two edges' sequences
        P = np.vstack([P, X])
        F = np.vstack([F[~drop]] + new_faces)
        C = np.concatenate([C[~drop]] + new_C)
        FE = np.vstack([FE[~hit], pieces[valid]])
        FID = np.concatenate([FID[~hit], np.repeat(owner_id, ck)])
        # ------------------------------------------------ chains get the new vertices
        for mi, w in sorted(set(zip(cm.tolist(), cw.tolist()))):   # loop over refined member sides
            sel = np.flatnonzero((cm == mi) & (cw == w))
            ch = mems[mi].sides[w]
            cnt = np.ones(len(ch), np.int64)
            cnt[ci[sel]] += nnew[sel]
            out = np.repeat(ch, cnt)
            start = np.concatenate([[0], np.cumsum(cnt)[:-1]])
            k = nnew[sel]
            within = np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k)
            out[np.repeat(start[ci[sel]] + 1, k) + within] = np.repeat(first[sel], k) + within
            mems[mi].sides[w] = out
    return P, F, C, FE, FID


# ============================================================================ pair checks
def _to2d(pts, e1, e2, o):
    X = pts - o
    return np.stack([X @ e1, X @ e2], 1)


def _point_in_polygon(q: np.ndarray, poly: np.ndarray, tol: float, chunk: int = 2048) -> np.ndarray:
    """Points of ``q`` strictly inside the closed polygon ``poly`` (farther than ``tol`` from
    its boundary), even-odd rule, vectorised over points x edges in chunks of points."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    out = np.zeros(len(q), bool)
    for s in range(0, len(q), chunk):
        qq = q[s:s + chunk]
        qx, qy = qq[:, None, 0], qq[:, None, 1]
        cond = (a[None, :, 1] > qy) != (b[None, :, 1] > qy)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = a[None, :, 0] + (qy - a[None, :, 1]) * ab[None, :, 0] / ab[None, :, 1]
        inside = (np.count_nonzero(cond & (qx < xc), axis=1) % 2) == 1
        t = np.clip(np.einsum("qij,ij->qi", qq[:, None] - a[None], ab) / np.where(L2 > 0, L2, 1.0), 0, 1)
        d = norm_rows(a[None] + t[..., None] * ab[None] - qq[:, None], axis=2).min(1)
        out[s:s + chunk] = inside & (d > tol)
    return out


def _line_intervals(poly: np.ndarray, q: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Parameter intervals of the line ``q + s d`` inside the closed 2D polygon (even-odd)."""
    nrm = np.array([-d[1], d[0]])
    s = (poly - q) @ nrm
    a, b = s, np.roll(s, -1)
    cross = (a >= 0) != (b >= 0)
    if not cross.any():
        return np.zeros((0, 2))
    pa, pb = poly[cross], np.roll(poly, -1, axis=0)[cross]
    t = a[cross] / (a[cross] - b[cross])
    x = pa + t[:, None] * (pb - pa)
    u = np.sort((x - q) @ d)
    return u[: len(u) // 2 * 2].reshape(-1, 2)


def _check_member_pairs(mems, polys, P, joined: set, eps: float, coplanar: bool = True, crossing: bool = True):
    """Coplanar members that overlap (``coplanar``) and members that cross without meeting
    on the skin (``crossing``) are layout errors naming both. ``polys``: each member's
    outline (node indices, implicitly closed)."""
    planar = [k for k, m in enumerate(mems) if m.info.is_planar]
    if len(planar) < 2:
        return
    lo = np.stack([P[polys[k]].min(0) for k in planar]) - eps
    hi = np.stack([P[polys[k]].max(0) for k in planar]) + eps
    ov = (lo[:, None, :] <= hi[None, :, :]).all(2) & (lo[None, :, :] <= hi[:, None, :]).all(2)
    ia, ib = np.nonzero(np.triu(ov, 1))
    for a, b in zip(ia, ib):                         # loop over candidate member pairs
        i, j = planar[a], planar[b]
        mi, mj = mems[i], mems[j]
        ni, nj = mi.info.plane_normal, mj.info.plane_normal
        e1, e2, o = _frame_from_normal(ni, mi.info.plane_point)
        pi2 = _to2d(P[polys[i]], e1, e2, o)
        cr = np.linalg.norm(np.cross(ni, nj))
        if cr <= 1e-9:
            if not coplanar or abs((mj.info.plane_point - mi.info.plane_point) @ ni) > 1e3 * eps:
                continue                             # parallel, distinct planes
            pj2 = _to2d(P[polys[j]], e1, e2, o)
            tol = 10 * eps
            sj = np.vstack([pj2, 0.5 * (pj2 + np.roll(pj2, -1, 0)), _interior_samples(pj2)])
            si = np.vstack([pi2, 0.5 * (pi2 + np.roll(pi2, -1, 0)), _interior_samples(pi2)])
            if _point_in_polygon(sj, pi2, tol).any() or _point_in_polygon(si, pj2, tol).any():
                raise LayoutError(f"members '{mi.name}' and '{mj.name}' lie in the same plane and overlap; remove "
                                  "one of them or move it so their areas do not overlap")
            continue
        if not crossing or (i, j) in joined:
            continue
        # intersection line of the two planes, in member i's frame
        dl = np.cross(ni, nj)
        dl /= np.linalg.norm(dl)
        A = np.stack([ni, nj, dl])
        rhs = np.array([ni @ mi.info.plane_point, nj @ mj.info.plane_point, dl @ mi.info.plane_point])
        q3 = np.linalg.solve(A, rhs)
        ej1, ej2, oj = _frame_from_normal(nj, mj.info.plane_point)
        Ii = _line_intervals(pi2, _to2d(q3[None], e1, e2, o)[0], np.array([dl @ e1, dl @ e2]))
        Ij = _line_intervals(_to2d(P[polys[j]], ej1, ej2, oj), _to2d(q3[None], ej1, ej2, oj)[0],
                             np.array([dl @ ej1, dl @ ej2]))
        if not len(Ii) or not len(Ij):
            continue
        over = np.minimum(Ii[:, None, 1], Ij[None, :, 1]) - np.maximum(Ii[:, None, 0], Ij[None, :, 0])
        if (over > 1e3 * eps).any():
            raise LayoutError(f"members '{mi.name}' and '{mj.name}' cross each other inside the skin but do not "
                              "meet on it (their skin curves share no crossing point): move one so they do not "
                              "cross, or extend both so they meet on both skin sides")


def _frame_from_normal(n, p):
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1), np.asarray(p, float)


def _interior_samples(poly2: np.ndarray) -> np.ndarray:
    """Centroids of a coarse constrained triangulation of a simple polygon (points strictly inside)."""
    import triangle as tr

    n = len(poly2)
    if n < 3:
        return np.zeros((0, 2))
    seg = np.stack([np.arange(n), (np.arange(n) + 1) % n], 1)
    try:
        t = tr.triangulate({"vertices": poly2, "segments": seg.astype(np.int32)}, "pQ")
    except Exception:                                 # pragma: no cover - degenerate outline
        return np.zeros((0, 2))
    T = np.asarray(t.get("triangles", np.zeros((0, 3))), np.int64).reshape(-1, 3)
    V = np.asarray(t["vertices"])
    return V[T].mean(1) if len(T) else np.zeros((0, 2))


# ============================================================================ main entry
def build_members(skin: ShellMesh, chains, members_info, size: float, *, min_angle: float = DEFAULT_MIN_ANGLE,
                  relax_chains: bool = True, split_thin: bool = True, tol: float = 1e-9) -> ShellMesh:
    """The skin plus every member's triangle mesh, in one conforming :class:`ShellMesh`.

    ``skin`` is the imprinted triangle skin and ``chains`` its
    :class:`~shellmesh_mdao.imprint.ChainResult` list (sides 'upper' and 'lower', an explicit
    member's pieces 'upper_<s>'/'lower_<s>', or one closed chain for a full-chord member);
    ``members_info`` one :class:`MemberInfo` (or :class:`~shellmesh_mdao.layout.MemberSpec`)
    per member; ``size`` the target element size of the member meshes (the skin's working
    edge length).

    The member meshes use the chain vertices by index (no coordinate merging). Two local
    repairs of the chains run first (both keep every skin vertex on the input surface and
    the skin closed and conforming): ``relax_chains`` slides chain vertices along their exact
    curve to even out very uneven chain spacing (skin vertex positions change, indices do
    not), and ``split_thin`` splits chain edges much longer than the member is tall (a thin
    wing's spars) into pieces, splitting the two skin triangles on each such edge (new skin
    vertices are appended after the skin's).

    Output numbering: the skin's points (then the points ``split_thin`` added), then every
    junction line's interior nodes (junctions in order of their member pair), then the
    members' own end-line nodes, then each member's interior nodes (in ``members_info``
    order). Faces: the skin's triangles first (the same ones unless ``split_thin`` split some:
    those are replaced by their pieces at the end of the skin block), then the members'
    triangles, with component names ``<member>`` or ``<member>/seg_<j>`` for a member split at
    X-junctions. Junction-line edges are added to ``feature_edges`` tagged with the component
    id of the member that ends there (the rib of a T-junction) or, for X- and L-junctions, of
    the member that comes first in ``members_info``; end-line edges are tagged with their
    member. Junction nodes, end-line nodes and new chain vertices are added to
    ``fixed_vertices``. A crossing vertex that is not on both member planes (a crossing the
    imprint made by splitting a chain edge) is moved to the exact crossing of the input
    surface with both planes (from the chains' exact arcs).

    Raises :class:`ImprintError` when a member's chains do not close into panels (a missing or
    inconsistent crossing, a chain that doubles back), :class:`LayoutError` for coplanar
    members that overlap, members that cross inside the skin without meeting on it, or a
    junction inside a non-planar member (a Coons patch; a kinked member takes junctions inside
    its planar panels), and :class:`SizeError` for a bad ``size``.
    """
    if size is None or not np.isfinite(size) or size <= 0:
        raise SizeError(f"member element size must be a positive length, got {size}; pass the skin's target edge "
                        "length")
    infos = [m if isinstance(m, MemberInfo) else MemberInfo.from_spec(m) for m in members_info]
    names = [m.name for m in infos]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise LayoutError(f"members_info names members more than once: {dup}; give one MemberInfo per member")
    if skin.n_points == 0:
        raise ImprintError("the skin is empty; build members on an imprinted skin")
    if skin.n_quads:
        raise ImprintError("build_members works on the imprinted triangle skin; got quads (build the members "
                           "before merging triangles into quads)")
    diag = skin.diagonal
    eps = tol * diag
    if size > diag:
        raise SizeError(f"member element size {size:g} is larger than the whole model ({diag:g}); give a size "
                        "well below the wing's thickness")
    P = skin.points.copy()
    mems = _gather(skin, chains, infos, tol)
    _orient(mems, P)
    _check_loop_corners(mems, P)
    _check_member_pairs(mems, [m.loop if m.loop is not None else np.concatenate([m.upper, m.lower[::-1]])
                               for m in mems], P, set(), eps, crossing=False)
    junctions = _find_junctions(mems, P, diag)
    _exact_junction_vertices(junctions, mems, P, diag, eps)
    _classify(mems, junctions)
    for J in junctions:
        for k in (J.i, J.j):
            if not mems[k].info.is_planar and not mems[k].joints and J.where[k] == "interior":
                raise LayoutError(f"members '{mems[J.i].name}' and '{mems[J.j].name}' meet inside the non-planar "
                                  f"member '{mems[k].name}'; junction lines inside a non-planar member are not "
                                  "supported: split it into planar members")
    for m in mems:
        m.make_sides(P)
    if relax_chains:
        _relax_chains(skin, P, mems, [(c, a) for m in mems for c, a in zip(m.sides, m.side_arcs)],
                      pinned=[v for m in mems for pair in m.joints for v in pair])
    F, C = skin.faces[:, :3].copy(), skin.component.copy()
    FE, FID = skin.feature_edges.copy(), skin.feature_edge_ids.copy()
    n_skin0 = len(P)
    if split_thin:
        fixed = np.zeros(len(P), bool)
        fixed[skin.fixed_vertices] = True
        P, F, C, FE, FID = _split_thin_chain_edges(P, F, C, FE, FID, mems, size, fixed=fixed)
        for m in mems:
            m.sync_sides()
    n_skin_pts = len(P)
    # ---------------------------------------------------------------- new line nodes
    new_pts = []
    n_next = len(P)

    def add_line(a, b, h0=None, h1=None):
        nonlocal n_next
        t = _line_params(float(np.linalg.norm(P[b] - P[a])), size, h0, h1)
        inner = P[a][None] + t[:, None] * (P[b] - P[a])[None]
        ids = n_next + np.arange(len(inner))
        n_next += len(inner)
        new_pts.append(inner)
        return np.concatenate([[a], ids, [b]]).astype(np.int64)

    for J in junctions:
        J.nodes = add_line(J.vu, J.vl, _end_spacing(mems, J, J.vu, P), _end_spacing(mems, J, J.vl, P))
    for m in mems:
        if m.loop is not None:
            continue
        m.end_lines = [None, None]
        for e, (a, b) in enumerate(((m.upper[0], m.lower[0]), (m.upper[-1], m.lower[-1]))):
            if m.closing[e] is None and a != b:
                m.end_lines[e] = add_line(a, b, _chain_edge_len(P, m.upper, a), _chain_edge_len(P, m.lower, b))
    for m in mems:                                    # kink lines of kinked (non-planar) explicit members
        m.kink_lines = []
        for a, b in m.joints:
            same = [J.nodes for J in junctions if {J.vu, J.vl} == {a, b}]
            m.kink_lines.append(same[0] if same else
                                add_line(a, b, _chain_edge_len(P, m.upper, a), _chain_edge_len(P, m.lower, b)))
    P = np.vstack([P] + new_pts)
    # ---------------------------------------------------------------- checks between members
    polys = [m.loop if m.loop is not None else _outline_nodes(m, junctions) for m in mems]
    joined = {(J.i, J.j) for J in junctions}
    _check_member_pairs(mems, polys, P, joined, eps, coplanar=False)
    # ---------------------------------------------------------------- mesh every member
    comp_names = list(skin.component_names)

    def cid(nm):
        if nm in comp_names:
            return comp_names.index(nm)
        comp_names.append(nm)
        return len(comp_names) - 1

    pts_parts, face_parts, comp_parts = [P], [], []
    n_total = len(P)
    for k, m in enumerate(mems):
        inner_lines = [junctions[jx].nodes for jx in m.interior]
        if m.info.is_planar:
            newp, gtris = _mesh_planar_region(m, P, m.loop if m.loop is not None else polys[k], inner_lines, size,
                                              min_angle, n_total)
        elif m.joints:
            newp, gtris = _mesh_panels(m, P, junctions, size, min_angle, n_total, tol)
        else:
            newp, gtris = _mesh_coons(m, P, junctions, size, min_angle, n_total)
        pts_parts.append(newp)
        n_total += len(newp)
        names_k = _piece_names(m, gtris, inner_lines, np.vstack(pts_parts), n_total,
                               split=any(junctions[jx].kind == "X" for jx in m.interior))
        comp_parts.append(np.array([cid(s) for s in names_k[0]], np.int32)[names_k[1]])
        face_parts.append(gtris)
    points = np.vstack(pts_parts)
    # ---------------------------------------------------------------- feature edges and fixed nodes
    fe, fid, fixed = [FE], [FID], [skin.fixed_vertices, np.arange(n_skin0, n_skin_pts)]
    for J in junctions:
        owner = J.i
        if J.kind == "T":
            owner = J.i if J.where[J.i] == "end" else J.j
        ln = J.nodes
        fe.append(np.stack([ln[:-1], ln[1:]], 1))
        fid.append(np.full(len(ln) - 1, cid(mems[owner].name), np.int32))
        fixed.append(ln)
    for m in mems:
        for ln in list(m.end_lines) + [k for k in m.kink_lines if not any(k is J.nodes for J in junctions)]:
            if ln is not None:
                fe.append(np.stack([ln[:-1], ln[1:]], 1))
                fid.append(np.full(len(ln) - 1, cid(m.name), np.int32))
                fixed.append(ln)
    mf = np.vstack(face_parts) if face_parts else np.zeros((0, 3), np.int64)
    sf = np.hstack([F, np.full((len(F), 1), -1, np.int64)])
    faces = np.vstack([sf, np.hstack([mf, np.full((len(mf), 1), -1, np.int64)])])
    comp = np.concatenate([C] + comp_parts)
    out = ShellMesh(points, faces, comp, comp_names, np.concatenate(fixed), np.vstack(fe), np.concatenate(fid))
    _check_junction_edges(out, [m.name for m in mems])
    return out


def _check_junction_edges(mesh: ShellMesh, member_names) -> None:
    """Every edge with a skin face has at most two skin faces (one on an open boundary) and at
    most one member face (a chain edge); an edge without skin faces has at most four (two
    members crossing). Anything else (a member's own mesh running along a skin edge, found on
    a spar a fraction of an element behind a rounded leading edge) is not a shell mesh: an
    :class:`ImprintError` naming the member and the place, instead of a mesh no solver can
    use."""
    topo = mesh.topology()
    names = set(member_names)
    is_mem = np.array([nm.split("/seg_")[0] in names for nm in mesh.component_names], bool)
    fm = is_mem[mesh.component[topo.he_face]]
    ne = len(topo.edges)
    n_mem = np.bincount(topo.he_edge, weights=fm, minlength=ne).astype(np.int64)
    n_skin = topo.valence - n_mem
    bad = np.flatnonzero(((n_skin > 0) & ((n_skin > 2) | (n_mem > 1))) | ((n_skin == 0) & (topo.valence > 4)))
    if not len(bad):
        return
    e = int(bad[0])
    fs = topo.edge_faces[topo.edge_faces_ptr[e]:topo.edge_faces_ptr[e + 1]]
    who = sorted({mesh.component_names[c] for c in mesh.component[fs] if is_mem[c]})
    where = np.array2string(mesh.points[topo.edges[e]].mean(0), precision=4)
    raise ImprintError(f"{', '.join(who) or 'a member'}: {len(bad)} edge(s) where the member mesh runs along a skin "
                       f"edge or more than two members meet (first near {where}); the member is closer to a sharp "
                       "or rounded edge of the skin, or to another member, than the element size there: move it "
                       "or use a smaller --size")


def _piece_names(m: _Member, gtris, inner_lines, points, n_nodes, split: bool):
    """Component names of a member's triangles: one name, or ``seg_<j>`` pieces ordered along
    the member's direction when it is split."""
    if not split or not inner_lines:
        return [m.name], np.zeros(len(gtris), np.int64)
    iseg = np.vstack([np.stack([ln[:-1], ln[1:]], 1) for ln in inner_lines])
    npc, lab = _pieces(gtris, iseg, n_nodes)
    d = m.info.direction
    if d is None:
        d = points[m.upper[-1]] - points[m.upper[0]] if m.upper is not None else np.array([1.0, 0.0, 0.0])
    cen = points[gtris].mean(1) @ d
    key = np.bincount(lab, weights=cen, minlength=npc) / np.bincount(lab, minlength=npc)
    rank = np.empty(npc, np.int64)
    rank[np.argsort(key, kind="stable")] = np.arange(npc)
    return [f"{m.name}/seg_{r}" for r in range(npc)], rank[lab]


def _mesh_planar_region(m: _Member, P, outline, inner_lines, size, min_angle, n_total):
    """Triangulate the planar region of ``m`` (its plane in ``m.info``) bounded by the closed node
    loop ``outline`` with the interior node lines ``inner_lines``; returns the new interior
    points (numbered from ``n_total``, exactly on the plane) and the triangles (global ids)."""
    lines = [np.append(outline, outline[0])] + list(inner_lines)
    nodes = np.unique(np.concatenate(lines))
    remap = np.full(int(nodes.max()) + 1, -1, np.int64)
    remap[nodes] = np.arange(len(nodes))
    seg = np.vstack([np.stack([remap[ln[:-1]], remap[ln[1:]]], 1) for ln in lines])
    e1, e2, origin = _plane_frame(m, P, nodes)
    uv = _to2d(P[nodes], e1, e2, origin)
    uv_all, tris = triangulate_planar(uv, seg, size, min_angle, f"member '{m.name}'")
    st = uv_all[len(nodes):]
    newp = origin + st[:, :1] * e1 + st[:, 1:] * e2
    gid = np.concatenate([nodes, n_total + np.arange(len(st))])
    return newp, gid[tris]


def _mesh_panels(m: _Member, P, junctions, size, min_angle, n_total, tol):
    """Mesh a kinked explicit member panel by panel: panel ``p`` lies between kink line ``p - 1``
    and kink line ``p`` (the member's own ends at the first and last panel) and is bounded by
    the pieces of the upper and lower chain between them. A panel whose nodes are coplanar
    (within ``tol`` of the diagonal) is meshed in its plane (new nodes exactly on it), any
    other through the Coons patch of its four sides. Interior junction lines must lie inside
    a planar panel. Returns the new interior points (from ``n_total``) and the triangles."""
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
        pp, pn = _fit_plane(P[outline], tol * diag / max(ext, 1e-300))
        panel = _Member(replace(m.info, plane_point=pp, plane_normal=pn), upper=Up, lower=Lp)
        if pn is not None:
            newp, t = _mesh_planar_region(panel, P, outline, lines_in, size, min_angle, n_total)
        else:
            if lines_in:
                raise LayoutError(f"a member meets the non-planar panel {p} of member '{m.name}' inside it; junction "
                                  "lines inside a non-planar panel are not supported: give the member a polyline "
                                  "point at the junction, or make the panel planar")
            panel.closing, panel.end_lines = [None, None], [sd[0] if len(sd[0]) else None,
                                                            sd[1] if len(sd[1]) else None]
            newp, t = _mesh_coons(panel, P, junctions, size, min_angle, n_total)
        # one orientation for all panels: the upper chain is traversed forward (Up[0] -> Up[1])
        fwd = (t == Up[0]) & (np.roll(t, -1, axis=1) == Up[1])
        if not fwd.any():
            t = t[:, ::-1]
        pts.append(newp)
        tris.append(t)
        n_total += len(newp)
    return np.vstack(pts), np.vstack(tris)


def _mesh_coons(m: _Member, P, junctions, size, min_angle, n_total):
    """Mesh a non-planar open member through the Coons patch of its four sides; returns the
    new interior points (numbered from ``n_total``) and the triangles (global indices)."""
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
    uv_all, tris = triangulate_planar(uv, seg, size, min_angle, f"member '{m.name}'")
    st = uv_all[nb:]
    newp = S(st[:, 0] / len_s, st[:, 1] / len_t) if len(st) else np.zeros((0, 3))
    gid = np.concatenate([nodes, n_total + np.arange(len(st))])
    return newp, gid[tris]


# ============================================================================ report
def member_statistics(mesh: ShellMesh, members_info) -> dict:
    """Per member: ``{name: {"nodes": n, "elements": m, "pieces": [component names]}}`` from
    the faces whose component is the member or one of its ``seg_<j>`` pieces."""
    names = [m.name if hasattr(m, "name") else str(m) for m in members_info]
    cn = mesh.component_names
    out = {}
    for nm in names:                                   # loop over members
        ids = [i for i, c in enumerate(cn) if c == nm or c.startswith(nm + "/seg_")]
        sel = np.isin(mesh.component, ids)
        f = mesh.faces[sel]
        present = sorted({cn[i] for i in np.unique(mesh.component[sel])})
        out[nm] = {"nodes": int(len(np.unique(f[f >= 0]))), "elements": int(sel.sum()), "pieces": present}
    return out
