"""A member's chains gathered from the imprint (pieces joined, chain edges a later cut split given
their vertices back, checked to run in order along the exact curve) and the junctions between
members: the crossing vertices two members' chains share, classified as T, X or L, put exactly on
both planes."""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra

from ..core.polyline import arc_param, sub_polyline
from ..errors import ImprintError, LayoutError
from ..imprint import fmt_point
from ..mesh import ShellMesh, norm_rows
from .info import MemberInfo, fit_plane

__all__ = ["MemberChains", "Junction", "gather_members", "orient_chains", "find_junctions",
           "exact_junction_vertices", "classify_junctions", "chain_edge_len", "end_spacing", "outline_nodes",
           "plane_frame"]


@dataclass
class MemberChains:
    """One member while the members stage builds it: its :class:`MemberInfo`, its chains (upper
    and lower, or one closed loop) with their exact arcs, the junctions closing its ends and
    lying inside it, its end lines, its two sides and, for a kinked explicit member, its kinks."""

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
        s, p, cum = arc_param(P[[lp[ia], lp[ib]] + [A[len(A) // 2]]], arc.points, True)
        tot = cum[-1]
        pp = np.vstack([p[:-1], p[:-1] + 0.0, p[:1]])          # the loop twice (parameters 0 .. 2 tot)
        cc = np.concatenate([cum[:-1], cum[:-1] + tot, [2 * tot]])
        s0, s1, sm = s
        fwd = ((sm - s0) % tot) < ((s1 - s0) % tot)             # A runs with the parameter from s0 to s1
        a0, a1 = (s0, s0 + (s1 - s0) % tot) if fwd else (s1, s1 + (s0 - s1) % tot)
        b0, b1 = (a1, a0 + tot)
        self.side_arcs = [sub_polyline(pp, cc, a0, a1), sub_polyline(pp, cc, b0 % tot, b0 % tot + (b1 - b0))]

    def sync_sides(self) -> None:
        """Write the (possibly refined) sides back into the chains."""
        if self.loop is None:
            self.upper, self.lower = self.sides
        else:
            A, B = self.sides
            self.loop = np.concatenate([A, B[1:-1]])


@dataclass
class Junction:
    """The junction line of members ``i`` and ``j``: their upper and lower crossing vertices, the
    line's nodes, and where it lies in each member (``'end'`` or ``'interior'``)."""

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
    along the member's feature edges (the shortest path of at most 16 of them)."""
    v = np.asarray(verts, np.int64)
    if len(v) < 2:
        raise ImprintError(f"member '{name}': its {side} chain has {len(v)} vertex; the member is shorter than one "
                           "element there: move it or use a smaller --size")
    lost = v[(v < 0) | (v >= skin.n_points)]
    if len(lost):
        raise ImprintError(f"member '{name}': its {side} chain lists {len(lost)} vertex id(s) that are not skin "
                           f"vertices ({lost[:4].tolist()}): the imprint lost track of them; please report it with "
                           "the layout and --size")
    pairs = np.stack([v, np.roll(v, -1)], 1) if closed else np.stack([v[:-1], v[1:]], 1)
    ok = skin.topology().edge_ids(pairs) >= 0
    if ok.all():
        return v
    g = _member_feature_graph(skin, name)
    out = [v[:1]]
    for i, (a, b) in enumerate(pairs.tolist()):  # loop over the few missing pairs' neighbours
        if ok[i]:
            out.append(np.asarray([b], np.int64))
            continue
        dist, pred = dijkstra(g, directed=False, indices=a, unweighted=True, limit=16,
                              return_predecessors=True)
        if not np.isfinite(dist[b]):
            where = fmt_point(0.5 * (skin.points[a] + skin.points[b]))
            raise ImprintError(f"member '{name}': its {side} chain is broken between skin vertices {a} and {b} "
                               f"near {where} (no mesh edge joins them); another member or a sharp edge of the "
                               "skin is closer to it there than the element size: move the member in the layout, "
                               "or use a smaller --size")
        path = [b]
        for _ in range(int(dist[b])):           # dist[b] steps lead back to a
            path.append(int(pred[path[-1]]))
        out.append(np.asarray(path[::-1][1:], np.int64))
    w = np.concatenate(out)
    return w[:-1] if closed else w


def _exact_crossing(P, v, mem: MemberChains, other: MemberInfo):
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
    s = arc_param(skin.points[ch], arc.points, False)[0]
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
                               "skin vertex; move its polyline points so that each projects onto the skin (a "
                               "point whose projection misses the skin or lands on another part of it splits the "
                               "chain), or use a smaller --size")
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


def gather_members(skin: ShellMesh, chains, infos, tol: float) -> list:
    """One :class:`MemberChains` per member of ``infos`` from the imprint's ``chains``: pieces
    joined, chain edges completed (:func:`_complete_chain`), open chains checked in order along
    their exact curve; a non-planar member gets the plane its chains fit (within ``tol`` of the
    diagonal), or its kink vertices when it is a kinked explicit member."""
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
            mem = MemberChains(info)
            mem.loop = _complete_chain(skin, c.vertices, True, info.name, c.side)
            mem.arcs = (c.arc,)
        else:
            if set(g) != {"upper", "lower"}:
                raise ImprintError(f"member '{info.name}' has chains {sorted(g)}; it needs an 'upper' and a 'lower' "
                                   "chain (or one closed 'loop' chain): imprint both skin sides")
            mem = MemberChains(info)
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
            pp, pn = fit_plane(skin.points[mem.chain_vertices()], tol * diag / max(
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


def orient_chains(mems, P):
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


def find_junctions(mems, P, diag) -> list:
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
        out.append(Junction(i, j, vu, vl))
    return out


def exact_junction_vertices(junctions, mems, P, diag, eps):
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
                    raise ImprintError(f"members '{mi.name}' and '{mj.name}' share skin vertex {v} at "
                                       f"{fmt_point(P[v])}, off the intersection "
                                       "of their planes (they pass closer than an element there without crossing): "
                                       "move one of them in the layout, or use a smaller --size")
                continue
            P[v] = x


def classify_junctions(mems, junctions):
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


def chain_edge_len(P, chain, v, closed=False):
    """Mean length of the chain edges at vertex ``v`` of ``chain``."""
    p = np.flatnonzero(chain == v)
    if not len(p):
        return None
    p = int(p[0])
    n = len(chain)
    nb = [(p - 1) % n, (p + 1) % n] if closed else [q for q in (p - 1, p + 1) if 0 <= q < n]
    return float(np.mean([np.linalg.norm(P[chain[q]] - P[v]) for q in nb]))


def end_spacing(mems, J, v, P):
    """Chain spacing at crossing vertex ``v`` for the junction line of ``J``: the geometric
    mean of the chain-edge lengths there, over both members."""
    hs = []
    for k in (J.i, J.j):
        m = mems[k]
        for ch in ((m.loop,) if m.loop is not None else (m.upper, m.lower)):
            h = chain_edge_len(P, ch, v, closed=m.loop is not None)
            if h is not None:
                hs.append(h)
    return float(np.exp(np.mean(np.log(np.maximum(hs, 1e-300))))) if hs else None


def outline_nodes(m: MemberChains, junctions) -> list:
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


def plane_frame(m: MemberChains, P: np.ndarray, nodes: np.ndarray):
    """An orthonormal frame ``(e1, e2, origin)`` of member ``m``'s plane for meshing its ``nodes``:
    ``e1`` along the member's direction (or its upper chain, else the nodes' main axis)."""
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
