"""The members stage's entry: every member meshed on its chains and split at its junctions, in one
conforming mesh with the skin (:func:`build_members`); the checks between members; per-member
statistics for the report (:func:`member_statistics`)."""
from __future__ import annotations

import numpy as np

from ..core.polygon import frame_from_normal, interior_samples, point_in_polygon, to2d
from ..errors import ImprintError, LayoutError, SizeError
from ..families import is_member, is_piece_of, segment_name
from ..imprint import MIN_LOOP_CORNER, fmt_point, loop_corner, sharp_loop_message
from ..mesh import ShellMesh, norm_rows
from .info import MemberInfo
from .junctions import (MemberChains, chain_edge_len, classify_junctions, end_spacing, exact_junction_vertices,
                        find_junctions, gather_members, orient_chains, outline_nodes)
from .meshing import DEFAULT_MIN_ANGLE, connected_pieces, mesh_coons, mesh_panels, mesh_planar_region
from .spacing import relax_chain_spacing, split_thin_chain_edges

__all__ = ["build_members", "member_statistics"]


def _line_params(L: float, size: float, h0: float | None = None, h1: float | None = None,
                 local=None) -> np.ndarray:
    """Interior parameters in (0, 1) dividing a line of length ``L`` into pieces of about
    ``size``, graded (spacing growing by at most 0.3 per unit length) from the end spacings
    ``h0``/``h1`` when these are smaller, so the first piece at a crossing matches the chain
    edges meeting there, and no longer than ``local(t)`` (the local sizes asked for at
    parameters ``t`` in [0, 1]; None: none). A line shorter than about ``1.5`` pieces stays one
    piece."""
    if L <= 0:
        return np.zeros(0)
    h0 = size if h0 is None else min(max(h0, 1e-12 * L), size)
    h1 = size if h1 is None else min(max(h1, 1e-12 * L), size)
    # spacing function h(x) = min(size, h0 + g x, h1 + g (L - x)); place nodes at equal steps
    # of the integral of 1/h (vectorised on a fine sample)
    g = 0.3
    x = np.linspace(0.0, L, 2049)
    h = np.minimum(size, np.minimum(h0 + g * x, h1 + g * (L - x)))
    if local is not None:
        h = np.minimum(h, np.maximum(local(x / L), 1e-12 * L))
    w = np.concatenate([[0.0], np.cumsum(0.5 * (1 / h[1:] + 1 / h[:-1]) * np.diff(x))])
    n = max(1, int(np.round(w[-1])))
    if n == 1:
        return np.zeros(0)
    t = np.interp(np.arange(1, n) * (w[-1] / n), w, x) / L
    return t


def _check_loop_corners(mems, P) -> None:
    """Refuse every closed member (full-chord rib) whose outline has a corner sharper than
    :data:`~shellmesh_mdao.imprint.MIN_LOOP_CORNER`: where the rib plane cuts a sharp leading or
    trailing edge (a wedge of the skin), every quad at that corner has a scaled Jacobian of at
    most sin(corner), below the pipeline's guarantee, whatever the element size. The imprint
    refuses the loops whose exact section has such a corner; this is the same test on the
    chain outline the member is meshed on. One error names every offender."""
    bad = []
    for m in mems:
        if m.loop is None or len(m.loop) < 3:
            continue
        a, k = loop_corner(P[m.loop])
        if a < MIN_LOOP_CORNER:
            bad.append((m.name, a, P[m.loop[k]]))
    if bad:
        raise LayoutError(sharp_loop_message(bad))


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
    on the skin (``crossing``) are layout errors naming both; one error names every such pair
    (the overlaps, or else the crossings). ``polys``: each member's outline (node indices,
    implicitly closed)."""
    planar = [k for k, m in enumerate(mems) if m.info.is_planar]
    if len(planar) < 2:
        return
    overlap, cross = [], []
    lo = np.stack([P[polys[k]].min(0) for k in planar]) - eps
    hi = np.stack([P[polys[k]].max(0) for k in planar]) + eps
    ov = (lo[:, None, :] <= hi[None, :, :]).all(2) & (lo[None, :, :] <= hi[:, None, :]).all(2)
    ia, ib = np.nonzero(np.triu(ov, 1))
    for a, b in zip(ia, ib):                         # loop over candidate member pairs
        i, j = planar[a], planar[b]
        mi, mj = mems[i], mems[j]
        ni, nj = mi.info.plane_normal, mj.info.plane_normal
        e1, e2, o = frame_from_normal(ni, mi.info.plane_point)
        pi2 = to2d(P[polys[i]], e1, e2, o)
        cr = np.linalg.norm(np.cross(ni, nj))
        if cr <= 1e-9:
            if not coplanar or abs((mj.info.plane_point - mi.info.plane_point) @ ni) > 1e3 * eps:
                continue                             # parallel, distinct planes
            pj2 = to2d(P[polys[j]], e1, e2, o)
            tol = 10 * eps
            sj = np.vstack([pj2, 0.5 * (pj2 + np.roll(pj2, -1, 0)), interior_samples(pj2)])
            si = np.vstack([pi2, 0.5 * (pi2 + np.roll(pi2, -1, 0)), interior_samples(pi2)])
            if point_in_polygon(sj, pi2, tol).any() or point_in_polygon(si, pj2, tol).any():
                overlap.append(f"'{mi.name}' and '{mj.name}'")
            continue
        if not crossing or (i, j) in joined:
            continue
        # intersection line of the two planes, in member i's frame
        dl = np.cross(ni, nj)
        dl /= np.linalg.norm(dl)
        A = np.stack([ni, nj, dl])
        rhs = np.array([ni @ mi.info.plane_point, nj @ mj.info.plane_point, dl @ mi.info.plane_point])
        q3 = np.linalg.solve(A, rhs)
        ej1, ej2, oj = frame_from_normal(nj, mj.info.plane_point)
        Ii = _line_intervals(pi2, to2d(q3[None], e1, e2, o)[0], np.array([dl @ e1, dl @ e2]))
        Ij = _line_intervals(to2d(P[polys[j]], ej1, ej2, oj), to2d(q3[None], ej1, ej2, oj)[0],
                             np.array([dl @ ej1, dl @ ej2]))
        if not len(Ii) or not len(Ij):
            continue
        over = np.minimum(Ii[:, None, 1], Ij[None, :, 1]) - np.maximum(Ii[:, None, 0], Ij[None, :, 0])
        if (over > 1e3 * eps).any():
            k = np.unravel_index(int(np.argmax(over)), over.shape)
            s0 = 0.5 * (max(Ii[k[0], 0], Ij[k[1], 0]) + min(Ii[k[0], 1], Ij[k[1], 1]))
            x = q3 + s0 * dl                         # both intervals are parameters along dl from q3
            cross.append(f"'{mi.name}' and '{mj.name}' (near {fmt_point(x)})")
    if overlap:
        raise LayoutError(f"members {'; '.join(overlap)} lie in the same plane and overlap; remove one of each pair "
                          "or move it so their areas do not overlap")
    if cross:
        raise LayoutError(f"members {'; '.join(cross)} cross each other inside the skin but do not meet on it "
                          "(their skin curves share no crossing point): move one of each pair so they do not "
                          "cross, or extend both so they meet on both skin sides")


# ============================================================================ main entry
def build_members(skin: ShellMesh, chains, members_info, size: float, *, min_angle: float = DEFAULT_MIN_ANGLE,
                  relax_chains: bool = True, split_thin: bool = True, tol: float = 1e-9,
                  size_field=None) -> ShellMesh:
    """The skin plus every member's triangle mesh, in one conforming :class:`ShellMesh`.

    ``skin`` is the imprinted triangle skin and ``chains`` its
    :class:`~shellmesh_mdao.imprint.ChainResult` list (sides 'upper' and 'lower', an explicit
    member's pieces 'upper_<s>'/'lower_<s>', or one closed chain for a full-chord member);
    ``members_info`` one :class:`MemberInfo` (or :class:`~shellmesh_mdao.layout.MemberSpec`)
    per member; ``size`` the target element size of the member meshes (the skin's working
    edge length); ``size_field`` (a :class:`~shellmesh_mdao.core.sizefield.SizeField` in the units
    of ``size``; None: none) the smaller local sizes asked for (members closer than the element
    size): the junction and end lines are divided, and the members meshed, no coarser.

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
    mems = gather_members(skin, chains, infos, tol)
    orient_chains(mems, P)
    _check_loop_corners(mems, P)
    _check_member_pairs(mems, [m.loop if m.loop is not None else np.concatenate([m.upper, m.lower[::-1]])
                               for m in mems], P, set(), eps, crossing=False)
    junctions = find_junctions(mems, P, diag)
    exact_junction_vertices(junctions, mems, P, diag, eps)
    classify_junctions(mems, junctions)
    for J in junctions:
        for k in (J.i, J.j):
            if not mems[k].info.is_planar and not mems[k].joints and J.where[k] == "interior":
                raise LayoutError(f"members '{mems[J.i].name}' and '{mems[J.j].name}' meet inside the non-planar "
                                  f"member '{mems[k].name}'; junction lines inside a non-planar member are not "
                                  "supported: split it into planar members")
    for m in mems:
        m.make_sides(P)
    if relax_chains:
        relax_chain_spacing(skin, P, mems, [(c, a) for m in mems for c, a in zip(m.sides, m.side_arcs)],
                            pinned=[v for m in mems for pair in m.joints for v in pair])
    F, C = skin.faces[:, :3].copy(), skin.component.copy()
    FE, FID = skin.feature_edges.copy(), skin.feature_edge_ids.copy()
    n_skin0 = len(P)
    if split_thin:
        fixed = np.zeros(len(P), bool)
        fixed[skin.fixed_vertices] = True
        P, F, C, FE, FID = split_thin_chain_edges(P, F, C, FE, FID, mems, size, fixed=fixed)
        for m in mems:
            m.sync_sides()
    n_skin_pts = len(P)
    # ---------------------------------------------------------------- new line nodes
    new_pts = []
    n_next = len(P)

    def add_line(a, b, h0=None, h1=None):
        nonlocal n_next
        local = None if size_field is None else (lambda t: size_field.at(P[a][None] + t[:, None] * (P[b] - P[a]), size))
        t = _line_params(float(np.linalg.norm(P[b] - P[a])), size, h0, h1, local)
        inner = P[a][None] + t[:, None] * (P[b] - P[a])[None]
        ids = n_next + np.arange(len(inner))
        n_next += len(inner)
        new_pts.append(inner)
        return np.concatenate([[a], ids, [b]]).astype(np.int64)

    for J in junctions:
        J.nodes = add_line(J.vu, J.vl, end_spacing(mems, J, J.vu, P), end_spacing(mems, J, J.vl, P))
    for m in mems:
        if m.loop is not None:
            continue
        m.end_lines = [None, None]
        for e, (a, b) in enumerate(((m.upper[0], m.lower[0]), (m.upper[-1], m.lower[-1]))):
            if m.closing[e] is None and a != b:
                m.end_lines[e] = add_line(a, b, chain_edge_len(P, m.upper, a), chain_edge_len(P, m.lower, b))
    for m in mems:                                    # kink lines of kinked (non-planar) explicit members
        m.kink_lines = []
        for a, b in m.joints:
            same = [J.nodes for J in junctions if {J.vu, J.vl} == {a, b}]
            m.kink_lines.append(same[0] if same else
                                add_line(a, b, chain_edge_len(P, m.upper, a), chain_edge_len(P, m.lower, b)))
    P = np.vstack([P] + new_pts)
    # ---------------------------------------------------------------- checks between members
    polys = [m.loop if m.loop is not None else outline_nodes(m, junctions) for m in mems]
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
            newp, gtris = mesh_planar_region(m, P, m.loop if m.loop is not None else polys[k], inner_lines, size,
                                             min_angle, n_total, size_field)
        elif m.joints:
            newp, gtris = mesh_panels(m, P, junctions, size, min_angle, n_total, tol, size_field)
        else:
            newp, gtris = mesh_coons(m, P, junctions, size, min_angle, n_total, size_field)
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
    is_mem = np.array([is_member(nm, names) for nm in mesh.component_names], bool)
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


def _piece_names(m: MemberChains, gtris, inner_lines, points, n_nodes, split: bool):
    """Component names of a member's triangles: one name, or ``seg_<j>`` pieces ordered along
    the member's direction when it is split."""
    if not split or not inner_lines:
        return [m.name], np.zeros(len(gtris), np.int64)
    iseg = np.vstack([np.stack([ln[:-1], ln[1:]], 1) for ln in inner_lines])
    npc, lab = connected_pieces(gtris, iseg, n_nodes)
    d = m.info.direction
    if d is None:
        d = points[m.upper[-1]] - points[m.upper[0]] if m.upper is not None else np.array([1.0, 0.0, 0.0])
    cen = points[gtris].mean(1) @ d
    key = np.bincount(lab, weights=cen, minlength=npc) / np.bincount(lab, minlength=npc)
    rank = np.empty(npc, np.int64)
    rank[np.argsort(key, kind="stable")] = np.arange(npc)
    return [segment_name(m.name, r) for r in range(npc)], rank[lab]


# ============================================================================ report
def member_statistics(mesh: ShellMesh, members_info) -> dict:
    """Per member: ``{name: {"nodes": n, "elements": m, "pieces": [component names]}}`` from
    the faces whose component is the member or one of its ``seg_<j>`` pieces."""
    names = [m.name if hasattr(m, "name") else str(m) for m in members_info]
    cn = mesh.component_names
    out = {}
    for nm in names:                                   # loop over members
        ids = [i for i, c in enumerate(cn) if is_piece_of(c, nm)]
        sel = np.isin(mesh.component, ids)
        f = mesh.faces[sel]
        present = sorted({cn[i] for i in np.unique(mesh.component[sel])})
        out[nm] = {"nodes": int(len(np.unique(f[f >= 0]))), "elements": int(sel.sum()), "pieces": present}
    return out
