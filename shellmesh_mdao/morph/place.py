"""Where the morph puts each node: skin nodes on the input surface (along their reference normal),
on their crease, slid into their member's plane; member nodes at their relative height between the
skins; and the discrete choices (input triangles, crease segments) that the complex step holds."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.locator import ray_triangle_intersect
from ..errors import ShellMeshError
from .plan import dot

__all__ = ["Choices", "NoSkinError", "tri_frame", "regions", "constrain", "skin_positions", "crease_positions",
           "surface_positions", "onto_planes", "on_surface", "member_rays", "refine_hits",
           "choose_skin", "side_choices", "skin_heights", "SKIN_NODE", "CHAIN_NODE", "MEMBER_NODE", "SIDE_STEP",
           "EDGE_TOL"]

#: the step (in element sizes) that picks the input triangle on either side of a node for the
#: derivatives: larger than the rounding of a node on an input edge, moved nearly along it
SIDE_STEP = 1e-6
#: barycentric coordinate below which a closest point is on the triangle's edge (vertex)
EDGE_TOL = 1e-9

SKIN_NODE, CHAIN_NODE, MEMBER_NODE = 0, 1, 2


@dataclass
class Choices:
    """The discrete choices of one morph (from its real evaluation), held for the complex step."""

    moved: np.ndarray            # (n,) bool
    skin_tri: np.ndarray         # (n,) input triangle of moved skin / chain nodes (-1 else)
    region: np.ndarray           # (n,) 0 interior, 1..3 edge (opposite vertex + 1), 4..6 vertex, -1
    ray_lo: np.ndarray           # (n,) input triangle below / above a moved member node
    ray_hi: np.ndarray
    closest: np.ndarray = None   # (n,) bool: a skin node off the features placed by its closest point

    def __post_init__(self):
        if self.closest is None:
            self.closest = np.zeros(len(self.moved), bool)


def tri_frame(ref, tri):
    L = ref.locator
    T = L.triangles[tri]
    a, b, c = L.points[T[:, 0]], L.points[T[:, 1]], L.points[T[:, 2]]
    nrm = np.cross(b - a, c - a)
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    return a, b, c, nrm


def regions(ref, q, tri):
    """Where on its triangle each closest point ``q`` lies: 0 interior, 1..3 on the edge opposite
    vertex 0..2, 4..6 at vertex 0..2."""
    a, b, c, _ = tri_frame(ref, tri)
    v0, v1, v2 = b - a, c - a, q - a
    d00, d01, d11 = dot(v0, v0), dot(v0, v1), dot(v1, v1)
    d20, d21 = dot(v2, v0), dot(v2, v1)
    den = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    bar = np.stack([1 - v - w, v, w], 1)
    small = bar < EDGE_TOL
    ns = small.sum(1)
    reg = np.zeros(len(q), np.int64)
    one = ns == 1
    reg[one] = 1 + np.argmax(small[one], 1)
    two = ns >= 2
    reg[two] = 4 + np.argmax(~small[two], 1)
    return reg


def constrain(q, rows_n, rows_d):
    """Least-norm move of ``q`` (k, 3) onto the constraints ``rows_n[:, i] . x = rows_d[:, i]``
    (k, m, 3), (k, m): ``x = q - A^T (A A^T)^-1 (A q - d)``; complex allowed."""
    A = rows_n
    res = np.einsum("kmi,ki->km", A, q) - rows_d
    G = np.einsum("kmi,kli->kml", A, A)
    lam = np.linalg.solve(G, res[..., None])[..., 0]
    return q - np.einsum("kmi,km->ki", A, lam)


class NoSkinError(ShellMeshError):
    def __init__(self, node):
        super().__init__(f"morph: member node {node} finds no skin above or below it at its new place")
        self.node = node


def skin_positions(ref, ch, skin, y, pp, pn):
    """The skin nodes ``skin`` asked to move to ``y`` (complex allowed): along their crease
    (:func:`crease_positions`) or on the input surface (:func:`surface_positions`)."""
    q = np.zeros(y.shape, y.dtype)
    cr = ref.feature[skin] & ~ch.closest[skin]
    if cr.any():
        q[cr] = crease_positions(ref, ch, skin[cr], y[cr], pp, pn)
    if (~cr).any():
        q[~cr] = surface_positions(ref, ch, skin[~cr], y[~cr], pp, pn)
    return q


def crease_positions(ref, ch, rows, y, pp, pn):
    """Nodes of the input's creases: the arc length along their crease moves by the plan move's
    component along the crease (no sticking at the crease's vertices, as a closest point would); a
    member's node on a crease goes to where the crease crosses the member's new plane."""
    C = ref.creases
    seg = ch.skin_tri[rows]
    d = C.b[ref.crease_seg[rows]] - C.a[ref.crease_seg[rows]]
    t = d / np.linalg.norm(d, axis=1, keepdims=True)
    s = ref.crease_s[rows] + dot(y - ref.mesh.points[rows], t)
    x = C.point(seg, s)
    chain = ref.kind[rows] == CHAIN_NODE
    if chain.any():
        m0 = ref.planes[rows[chain], 0]
        x[chain] = C.crossing(seg[chain], pn[m0], dot(pp[m0], pn[m0]))
    return x


def surface_positions(ref, ch, skin, y, pp, pn):
    """Skin nodes off the creases: on the input surface (:func:`on_surface`), a member's skin nodes
    slid on their triangle's plane (on an edge: its line) into the member's plane (into both planes
    at a crossing). Complex allowed."""
    q, tri, reg, a, nt, verts = on_surface(ref, ch, skin, y)
    # chain nodes: slide on their support (the triangle's plane; on an edge, its line) into the
    # member plane(s): two or three constraints
    rows = np.flatnonzero((ref.kind[skin] == CHAIN_NODE) & (reg < 4))
    if len(rows):
        m0 = ref.planes[skin[rows], 0]
        m1 = ref.planes[skin[rows], 1]
        edge = (reg[rows] >= 1) & (m1 < 0)
        n2 = np.zeros((len(rows), 3))
        d2 = np.zeros(len(rows))
        if edge.any():
            e = np.flatnonzero(edge)
            i0 = reg[rows][e] % 3
            i1 = (reg[rows][e] + 1) % 3
            p0 = verts[rows[e], i0]
            v = np.cross(nt[rows[e]], verts[rows[e], i1] - p0)
            n2[e] = v / np.linalg.norm(v, axis=1, keepdims=True)
            d2[e] = dot(p0, n2[e])
        zero = 0.0 * pn[m0][:, 0]
        third_n = np.where((m1 >= 0)[:, None], pn[np.maximum(m1, 0)], n2 + 0.0 * pn[m0])
        third_d = np.where(m1 >= 0, dot(pp[np.maximum(m1, 0)], pn[np.maximum(m1, 0)]), d2 + zero)
        A = np.stack([nt[rows] + 0.0 * pn[m0], pn[m0], third_n], 1)
        d = np.stack([dot(a[rows], nt[rows]) + zero, dot(pp[m0], pn[m0]), third_d], 1)
        three = (m1 >= 0) | edge
        out = q[rows].copy()
        if three.any():
            out[three] = constrain(q[rows][three], A[three], d[three])
        if (~three).any():
            out[~three] = constrain(q[rows][~three], A[~three][:, :2], d[~three][:, :2])
        q[rows] = out
    return q


def onto_planes(x, planes, pp, pn, two):
    """Points ``x`` (k, 3) projected onto their member plane ``planes[:, 0]`` (``two``: onto the line
    of ``planes[:, 0]`` and ``planes[:, 1]``). Complex allowed."""
    m0 = planes[:, 0]
    cons_n, cons_d = [pn[m0]], [dot(pp[m0], pn[m0])]
    if two:
        m1 = planes[:, 1]
        cons_n.append(pn[m1])
        cons_d.append(dot(pp[m1], pn[m1]))
    return constrain(x, np.stack(cons_n, 1), np.stack(cons_d, 1))


def on_surface(ref, ch, skin, y):
    """The surface points of the skin nodes ``skin`` asked to move to ``y`` (complex allowed), on the
    input triangles of the choices ``ch``: along the reference normal (off the features), the
    closest point on the triangle, its edge or vertex (on the features). Returns ``(q, tri, region,
    first vertex, triangle normal, vertices (k, 3, 3))``."""
    if (ch.skin_tri[skin] < 0).any():
        raise NoSkinError(skin[ch.skin_tri[skin] < 0][0])
    tri = ch.skin_tri[skin]
    reg = ch.region[skin]
    a, b, c, nt = tri_frame(ref, tri)
    verts = np.stack([a, b, c], 1)
    feat = ch.closest[skin]
    nr = ref.skin_normals[skin]
    t_ray = dot(a - y, nt) / dot(nr, nt)
    q = np.where(feat[:, None], y - dot(y - a, nt)[:, None] * nt, y + t_ray[:, None] * nr)
    e = np.flatnonzero((reg >= 1) & (reg <= 3))
    if len(e):
        i0 = reg[e] % 3                                            # the edge opposite vertex reg-1
        i1 = (reg[e] + 1) % 3
        p0 = verts[e, i0]
        d = verts[e, i1] - p0
        t = dot(y[e] - p0, d) / dot(d, d)
        q[e] = p0 + t[:, None] * d
    vx = np.flatnonzero(reg >= 4)
    if len(vx):
        q[vx] = verts[vx, reg[vx] - 4]
    return q, tri, reg, a, nt, verts


def member_rays(ref, o, up):
    """Input triangles below and above the points ``o`` (k, 3) along ``up``: ``(lo, hi)``, -1 for none."""
    dirs = np.broadcast_to(up, o.shape)
    _, hi, _ = ref.locator.raycast(o, dirs)
    _, lo, _ = ref.locator.raycast(o, -dirs)
    return refine_hits(ref, o, dirs, lo), refine_hits(ref, o, dirs, hi)


def refine_hits(ref, o, d, tri):
    """The input triangle the line ``o + t d`` crosses near its hit on ``tri`` (k,), decided in float64
    among the triangles around ``tri``'s vertices: the one whose barycentric coordinates of the
    crossing are the most inside (the ray cast's own pick is only float32-exact, so a hit within
    about 1e-7 of the model's size of an edge could be either triangle, with another slope)."""
    out = tri.copy()
    rows = np.flatnonzero(tri >= 0)
    if not len(rows):
        return out
    L = ref.locator
    owner, cand = L.triangle_neighbourhoods(tri[rows])
    T = L.triangles[cand]
    P = L.points
    t, u, v, det = ray_triangle_intersect(o[rows][owner], d[rows][owner], P[T[:, 0]], P[T[:, 1]], P[T[:, 2]])
    score = np.where(det != 0, np.minimum(np.minimum(u, v), 1.0 - u - v), -np.inf)
    score = np.where(np.isfinite(score), score, -np.inf)
    o_ = np.lexsort((cand, -score, owner))
    first = np.ones(len(o_), bool)
    first[1:] = owner[o_][1:] != owner[o_][:-1]
    pick = o_[first]
    out[rows[owner[pick]]] = np.where(score[pick] > -np.inf, cand[pick], tri[rows[owner[pick]]])
    return out


def choose_skin(ref, ch, rows, y, pp, pn):
    """Input triangles (segments) of the skin nodes ``rows`` at their moved places ``y`` (real): the
    crease segment for nodes of a crease (where it crosses the member's plane for a member's node);
    the triangle hit along the reference normal (the nearer of the two directions) for the others,
    the closest point's triangle and where on it (interior, edge, vertex) where that ray misses."""
    feat = ref.feature[rows]
    ch.closest[rows] = False
    f = np.flatnonzero(feat)
    if len(f):
        C = ref.creases
        r = rows[f]
        d = C.b[ref.crease_seg[r]] - C.a[ref.crease_seg[r]]
        t = d / np.linalg.norm(d, axis=1, keepdims=True)
        s_new = ref.crease_s[r] + dot(y[f] - ref.mesh.points[r], t)
        seg = C.segment_at(C.line[ref.crease_seg[r]], s_new)
        chain = ref.kind[r] == CHAIN_NODE
        if chain.any():
            m0 = ref.planes[r[chain], 0]
            seg[chain] = C.crossing_segment(seg[chain], pn[m0], dot(pp[m0], pn[m0]))
        ch.skin_tri[r] = seg
        ch.region[r] = -1
    o = np.flatnonzero(~feat)
    if len(o):
        nr = ref.skin_normals[rows[o]]
        _, t1, d1 = ref.locator.raycast(y[o], nr)
        _, t2, d2 = ref.locator.raycast(y[o], -nr)
        tri = refine_hits(ref, y[o], nr, np.where(d2 < d1, t2, t1))
        ch.skin_tri[rows[o]] = tri
        ch.region[rows[o]] = 0
        miss = np.flatnonzero(tri < 0)
        if len(miss):                            # no hit along the normal (at a tip's edge): closest point
            cl, t3, _ = ref.locator.closest(y[o][miss])
            ch.skin_tri[rows[o][miss]] = t3
            ch.region[rows[o][miss]] = regions(ref, cl, t3)
            ch.closest[rows[o][miss]] = True


def side_choices(ref, ch, delta, delta_dir, side, pp, pn):
    """The choices for a derivative along ``delta_dir`` (n, 3) (the plan move per unit parameter)
    from the side ``side`` (+1 or -1): every node that moves with the parameter takes the input
    triangle (and its place on it) of a point :data:`SIDE_STEP` element sizes from its real place
    (``P + delta``) that way, so a node on an input edge or vertex takes the side it moves to."""
    P = ref.mesh.points
    st, rg, lo, hi = ch.skin_tri.copy(), ch.region.copy(), ch.ray_lo.copy(), ch.ray_hi.copy()
    nd = np.linalg.norm(delta_dir, axis=1)
    moving = nd > 0
    out = Choices(ch.moved | moving, st, rg, lo, hi, ch.closest.copy())
    step = (side * SIDE_STEP * ref.size) * delta_dir / np.maximum(nd, 1e-300)[:, None]
    add = np.flatnonzero(moving & (ref.kind != MEMBER_NODE))
    if len(add):
        choose_skin(ref, out, add, P[add] + delta[add] + step[add], pp, pn)
    addm = np.flatnonzero(moving & (ref.kind == MEMBER_NODE))
    for wi, W in enumerate(ref.wings):
        rows = addm[ref.wing_of[addm] == wi]
        if not len(rows):
            continue
        o = P[rows] - (P[rows] @ W.up)[:, None] * W.up + delta[rows] + ref.mid[rows][:, None] * W.up + step[rows]
        lo[rows], hi[rows] = member_rays(ref, o, W.up)
    return out


def skin_heights(locator, x, up, h_start):
    """Heights along ``up`` of the input surface below and above the points ``x`` (rays from them)."""
    o = x
    _, tu, du = locator.raycast(o, np.broadcast_to(up, o.shape))
    _, td, dd = locator.raycast(o, np.broadcast_to(-up, o.shape))
    return h_start - dd, h_start + du
