"""Smoothing QP (paper eq. 6-8): supports derived from a mesh, vertices kept on their
plane / surface / curve, the null-space solve equal to the literal KKT system, fold
prevention, determinism, and quality on merged + subdivided corpus skins."""
import time

import numpy as np
import pytest
import trimesh

from shellmesh_mdao.errors import MeshValidationError
from shellmesh_mdao.merge import merge_triangles
from shellmesh_mdao.mesh import ShellMesh
from shellmesh_mdao.core.locator import SurfaceLocator
from shellmesh_mdao.quad import subdivide_to_quads
from shellmesh_mdao.quality import scaled_jacobian
from shellmesh_mdao.core.supports import (CURVE, FIXED, PLANE, SURFACE, Curve, CurveSet, Supports, derive_supports,
                                          polylines_from_edges)
from shellmesh_mdao.smooth import CG_RTOL
from shellmesh_mdao.smooth import smooth as smooth_qp

#: the smooth() settings these tests were written for (its defaults before they became the smooth
#: stage's, :class:`~shellmesh_mdao.options.SmoothOptions`): 20 steps, the length energy, no
#: planarity term (and every quad in it when on), the fold guard at 0.3
PLAIN = dict(iterations=20, energy="length", warp_weight=0.0, warp_spread=180.0, min_jacobian=0.3)

#: merge_triangles() without its bonus and valence term (its defaults before they became the merge
#: stage's)
PLAIN_MERGE = dict(merge_bonus=0.0, valence_weight=0.0)


def smooth(mesh, supports, **kw):
    """:func:`~shellmesh_mdao.smooth.smooth` with :data:`PLAIN` where ``kw`` does not say."""
    return smooth_qp(mesh, supports, **{**PLAIN, **kw})


def grid(nx, ny, x0=0.0, y0=0.0, sx=1.0, sy=1.0):
    x, y = np.meshgrid(x0 + np.linspace(0, sx, nx + 1), y0 + np.linspace(0, sy, ny + 1), indexing="ij")
    P = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    idx = np.arange(len(P)).reshape(nx + 1, ny + 1)
    F = np.stack([idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()], 1)
    return P, F, idx


def t_mesh(seed=0, jitter=0.25):
    """Skin: a 6x4 quad grid on the curved surface z = 0.2 sin(x) over [0,3]x[0,2]; member:
    a 6x3 quad grid in the plane y = 1, below the skin, joined along the skin line y = 1
    (a chain of feature edges with the member's id 1). Interior nodes jittered."""
    rng = np.random.default_rng(seed)
    Ps, Fs, ids = grid(6, 4, sx=3.0, sy=2.0)
    Pm, Fm, idm = grid(6, 3, sx=3.0, sy=1.0)
    Pm = np.stack([Pm[:, 0], np.ones(len(Pm)), Pm[:, 1] - 1.0], 1)        # plane y = 1, z in [-1, 0]
    # member top row = skin row j=2 (y = 1)
    Pm[idm[:, -1]] = Ps[ids[:, 2]]
    P = np.vstack([Ps, Pm])
    off = len(Ps)
    Fm = Fm + off
    remap = np.arange(len(P))
    remap[idm[:, -1] + off] = ids[:, 2]
    Fm = remap[Fm]
    # jitter interior nodes in their own surface, then put the skin on z = 0.2 sin x
    inner_s = ids[1:-1, 1:-1].ravel()
    P[inner_s, :2] += rng.uniform(-jitter, jitter, (len(inner_s), 2)) * 0.5
    inner_m = (idm[1:-1, 1:-1] + off).ravel()
    P[inner_m, [0]] += rng.uniform(-jitter, jitter, len(inner_m)) * 0.5
    P[inner_m, 2] += rng.uniform(-jitter, jitter, len(inner_m)) * 0.3
    chain = ids[:, 2]
    P[chain, 1] = 1.0                                                      # chain stays in the member plane
    skin_nodes = np.arange(len(Ps))
    P[skin_nodes, 2] = 0.2 * np.sin(P[skin_nodes, 0])
    fe = np.stack([chain[:-1], chain[1:]], 1)
    mesh = ShellMesh(P, np.vstack([Fs, Fm]), np.r_[np.zeros(len(Fs)), np.ones(len(Fm))].astype(int),
                     ["skin", "rib"], fixed_vertices=chain, feature_edges=fe, feature_edge_ids=np.ones(len(fe)))
    mesh, _ = mesh.compact()
    # input skin: a fine triangulation of the same surface; the junction curve: exact arc
    u, v = np.meshgrid(np.linspace(-0.5, 3.5, 81), np.linspace(-0.5, 2.5, 61), indexing="ij")
    sp = np.stack([u.ravel(), v.ravel(), 0.2 * np.sin(u.ravel())], 1)
    k = np.arange(81 * 61).reshape(81, 61)
    a, b, c, d = k[:-1, :-1].ravel(), k[1:, :-1].ravel(), k[1:, 1:].ravel(), k[:-1, 1:].ravel()
    loc = SurfaceLocator(sp, np.vstack([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]))
    t = np.linspace(-0.5, 3.5, 2001)
    arc = np.stack([t, np.ones_like(t), 0.2 * np.sin(t)], 1)
    return mesh, loc, {1: ([0, 1, 0], [0, 1, 0])}, {1: arc}


def test_derive_supports_kinds():
    mesh, loc, planes, curves = t_mesh()
    sup = derive_supports(mesh, loc, planes, curves, sliding=True)
    P = mesh.points
    chain = np.unique(mesh.feature_edges)
    ends = chain[np.isin(P[chain, 0], [0.0, 3.0])]
    assert sup.kind[ends].tolist() == [FIXED, FIXED]                       # chain ends (1 feature edge)
    assert (sup.kind[np.setdiff1d(chain, ends)] == CURVE).all()            # 5 sliding chain nodes
    skin_only = np.setdiff1d(np.unique(mesh.faces[mesh.component == 0]), np.unique(mesh.faces[mesh.component == 1]))
    boundary = np.unique(mesh.boundary_edges())
    assert (sup.kind[np.setdiff1d(skin_only, boundary)] == SURFACE).all()
    member_inner = np.setdiff1d(np.unique(mesh.faces[mesh.component == 1]), np.r_[chain, boundary])
    assert len(member_inner) == 10 and (sup.kind[member_inner] == PLANE).all()
    assert (sup.kind[boundary] == FIXED).all()                              # open boundary stays
    # without sliding, imprint-fixed chain vertices stay fixed
    assert (derive_supports(mesh, loc, planes, curves).kind[chain] == FIXED).all()
    # skin components need a surface
    with pytest.raises(MeshValidationError, match="no skin surface"):
        derive_supports(mesh, None, planes, curves)


def test_project_kind_hints_and_triangles():
    """project_kind(return_tri=True) also gives each SURFACE row's closest input triangle (the
    locator's, -1 on the other rows); handed back as ``hint`` for points moved a little it
    changes nothing, bit for bit (the smoothing's line search does this every step); a hint of
    the wrong length is refused."""
    mesh, loc, planes, curves = t_mesh()
    sup = derive_supports(mesh, loc, planes, curves, sliding=True)
    rng = np.random.default_rng(2)
    x = mesh.points + 0.02 * rng.normal(size=mesh.points.shape)
    nrm = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    plain = sup.project_kind(x, sup.kind, sup.ref, nrm)
    out, ok, tri = sup.project_kind(x, sup.kind, sup.ref, nrm, return_tri=True)
    assert np.array_equal(out, plain[0]) and np.array_equal(ok, plain[1])
    surf = sup.kind == SURFACE
    assert surf.sum() >= 10 and (tri[~surf] == -1).all()
    assert np.array_equal(tri[surf], loc.closest(x[surf])[1])
    moved = x + 0.02 * rng.normal(size=x.shape)
    for hint in (tri, rng.integers(-5, len(loc.triangles) + 5, len(x))):
        again = sup.project_kind(moved, sup.kind, sup.ref, nrm, hint=hint, return_tri=True)
        ref = sup.project_kind(moved, sup.kind, sup.ref, nrm, return_tri=True)
        assert all(np.array_equal(a, b) for a, b in zip(again, ref))
    with pytest.raises(ValueError, match="one entry per point"):
        sup.project_kind(moved, sup.kind, sup.ref, nrm, hint=tri[:-1])


def test_chain_on_two_curves_slides_on_one():
    """A member chain lies on the member plane's exact section AND on the polyline of its own
    feature edges (the pipeline passes both): every chain edge goes to the first curve, so
    no interior chain node is fixed by rounding (edges split between the two curves made a
    node look like a crossing: 84 spar-chain nodes of a swept-wing layout were fixed)."""
    mesh, loc, planes, curves = t_mesh()
    fe = mesh.feature_edges
    chain = np.unique(fe)
    order = chain[np.argsort(mesh.points[chain, 0])]
    own = mesh.points[order]
    for first, second in ((curves[1], own), (own, curves[1])):
        sup = derive_supports(mesh, loc, planes, {1: [first, second]}, sliding=True)
        ends = order[[0, -1]]
        assert (sup.kind[np.setdiff1d(chain, ends)] == CURVE).all()
        assert (sup.curve_of_edges(fe) == 0).all()


def test_smoothing_keeps_every_vertex_on_its_support_and_improves():
    mesh, loc, planes, curves = t_mesh()
    sup = derive_supports(mesh, loc, planes, curves, sliding=True)
    # start on the supports (the input skin is a faceted version of z = 0.2 sin x)
    mesh.points = sup.project(mesh.points)[0]
    tol = 1e-9 * mesh.diagonal
    assert sup.distance(mesh.points).max() <= tol
    out, res = smooth(mesh, sup, iterations=15)
    assert res.iterations >= 1 and res.max_move > 0
    d = sup.distance(out.points)
    assert d.max() <= tol
    moved = np.linalg.norm(out.points - mesh.points, axis=1)
    assert (moved[sup.kind == FIXED] == 0).all()
    assert (moved[sup.kind == CURVE] > 0).any()                             # chain nodes slid
    # the member interior stays in y = 1, chain nodes stay on the arc (y = 1, z = 0.2 sin x)
    assert np.allclose(out.points[sup.kind == PLANE, 1], 1.0, atol=tol)
    c = out.points[sup.kind == CURVE]
    assert np.allclose(c[:, 2], 0.2 * np.sin(c[:, 0]), atol=1e-5)          # polyline chord error only
    assert res.quality_after["mean_sj"] > res.quality_before["mean_sj"]
    assert res.quality_after["min_sj"] >= min(res.quality_before["min_sj"], 0.3) - 1e-12
    # subdivide then smooth: still on the supports, all quads, conforming
    q, qs = subdivide_to_quads(out, sup)
    assert qs.distance(q.points).max() <= tol
    q2, r2 = smooth(q, qs, iterations=10)
    assert qs.distance(q2.points).max() <= tol
    assert q2.n_tris == 0 and q2.check().ok
    assert r2.quality_after["mean_sj"] >= r2.quality_before["mean_sj"]


def test_nullspace_solve_equals_literal_kkt_system():
    """One step with a big trust radius: the reduced (null-space) system and eq. 8 as a
    KKT matrix [[B, A^T], [A, 0]] give the same displacement."""
    mesh, loc, planes, curves = t_mesh(seed=3)
    sup = derive_supports(mesh, loc, planes, curves, sliding=True)
    kw = dict(iterations=1, trust=1e6, min_jacobian=-10.0, max_halvings=0)
    a, _ = smooth(mesh, sup, solver="lu", **kw)
    b, _ = smooth(mesh, sup, solver="kkt", **kw)
    c, _ = smooth(mesh, sup, solver="cg", **kw)
    assert np.abs(a.points - mesh.points).max() > 1e-3
    assert np.allclose(a.points, b.points, atol=1e-9)
    # CG stops at a relative residual of CG_RTOL (1e-3): the step within a small multiple of it
    step = np.abs(a.points - mesh.points).max()
    assert np.abs(c.points - a.points).max() <= 10 * CG_RTOL * step


def _notched_grid():
    """A 6x6 grid whose top side is a deep V notch: the harmonic (sum of squared lengths)
    optimum of the interior nodes folds elements near the notch."""
    P, F, idx = grid(6, 6)
    x = P[idx[:, -1], 0]
    P[idx[:, -1], 1] = 1 - 0.9 * (1 - np.abs(2 * x - 1))
    for i in range(7):
        col = idx[i]
        P[col, 1] = P[col[0], 1] + np.linspace(0, 1, 7) * (P[col[-1], 1] - P[col[0], 1])
    mesh = ShellMesh(P, F)
    kind = np.full(len(P), PLANE, np.int8)
    ref = np.zeros(len(P), np.int64)
    bnd = np.unique(mesh.boundary_edges())
    kind[bnd], ref[bnd] = FIXED, -1
    return mesh, Supports(kind, ref, planes=[[[0, 0, 0], [0, 0, 1]]], comp_kind=[PLANE], comp_ref=[0])


def test_fold_prevention():
    mesh, sup = _notched_grid()
    sj0 = scaled_jacobian(mesh.points, mesh.faces)
    assert sj0.min() > 0.4
    kw = dict(energy="squared", ortho_weight=0.0, trust=50.0, reg=0.0, iterations=10)
    unguarded, _ = smooth(mesh, sup, min_jacobian=-2.0, **kw)              # guard never triggers
    assert (scaled_jacobian(unguarded.points, unguarded.faces) <= 0).any()  # the QP step folds
    out, res = smooth(mesh, sup, min_jacobian=0.3, **kw)
    sj = scaled_jacobian(out.points, out.faces)
    assert res.n_fold_hits > 0 and res.n_step_halvings > 0
    assert (sj > 0).all() and (sj >= np.minimum(sj0, 0.3) - 1e-12).all()
    # default settings on the same input: no fold either, and better on average
    out2, _ = smooth(mesh, sup)
    sj2 = scaled_jacobian(out2.points, out2.faces)
    assert sj2.min() >= min(sj0.min(), 0.3) - 1e-12 and sj2.mean() > sj0.mean()


def test_deterministic_and_input_checks():
    mesh, loc, planes, curves = t_mesh(seed=1)
    sup = derive_supports(mesh, loc, planes, curves, sliding=True)
    a, ra = smooth(mesh, sup, iterations=5)
    b, rb = smooth(mesh, sup, iterations=5)
    assert a.points.tobytes() == b.points.tobytes()
    assert ra.n_step_halvings == rb.n_step_halvings
    assert np.array_equal(a.faces, mesh.faces) and np.array_equal(a.feature_edges, mesh.feature_edges)
    with pytest.raises(MeshValidationError, match="one entry per mesh vertex"):
        smooth(mesh, Supports(np.zeros(2, np.int8), -np.ones(2)))
    with pytest.raises(ValueError, match="energy"):
        smooth(mesh, sup, energy="bogus")


def test_curve_and_polylines():
    c = Curve(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]], float))
    x, d, t = c.closest(np.array([[0.5, 0.2, 0], [1.3, 0.5, 0], [2, 2, 0]]))
    assert np.allclose(x, [[0.5, 0, 0], [1, 0.5, 0], [1, 1, 0]])
    assert np.allclose(d, [0.2, 0.3, np.sqrt(2)])
    assert np.allclose(t, [[1, 0, 0], [0, 1, 0], [0, 1, 0]])
    # chains break at degree != 2 nodes; a loop is reported closed
    edges = np.array([[0, 1], [1, 2], [2, 3], [2, 4], [5, 6], [6, 7], [7, 5]])
    pl = polylines_from_edges(np.zeros((8, 3)), edges)
    got = sorted((tuple(ix.tolist()), cl) for ix, cl in pl)
    assert got == [((0, 1, 2), False), ((2, 3), False), ((2, 4), False), ((5, 6, 7), True)]


def test_polylines_do_not_depend_on_the_node_numbering():
    # the chains are found on the edges' own nodes: spreading the same graph over a larger
    # numbering (a member's chain among a whole mesh's nodes) by an increasing map must give
    # the same polylines, mapped, in the same order
    rng = np.random.default_rng(3)
    edges = np.array([[0, 1], [1, 2], [2, 3], [2, 4], [5, 6], [6, 7], [7, 5], [8, 9], [9, 10], [10, 8], [10, 11]])
    ref = polylines_from_edges(np.zeros((12, 3)), edges)
    spread = np.sort(rng.choice(100_000, 12, replace=False))
    got = polylines_from_edges(np.zeros((100_000, 3)), spread[edges[rng.permutation(len(edges))]])
    assert [(ix.tolist(), cl) for ix, cl in got] == [(spread[ix].tolist(), cl) for ix, cl in ref]


def _polylines_by_scipy(edges):
    """The chains as found before the compiled walk: connected components and depth-first
    order of the graph with every break node split once per incident edge."""
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components, depth_first_order
    e = np.unique(np.sort(np.asarray(edges, np.int64).reshape(-1, 2), axis=1), axis=0)
    e = e[e[:, 0] != e[:, 1]]
    used, inv = np.unique(e, return_inverse=True)
    e = inv.reshape(-1, 2)
    n, k = len(used), len(e)
    brk = np.bincount(e.ravel(), minlength=n) != 2
    he = e.ravel()
    node = np.where(brk[he], n + np.arange(2 * k), he)
    g = sparse.coo_matrix((np.ones(k), (node[0::2], node[1::2])), shape=(n + 2 * k, n + 2 * k)).tocsr()
    g = ((g + g.T) > 0).astype(np.int8).tocsr()
    ncomp, lab = connected_components(g, directed=False)
    first = np.full(ncomp, k, np.int64)
    np.minimum.at(first, lab[node[0::2]], np.arange(k))
    orig = used[np.concatenate([np.arange(n), he])]
    out = []
    for c in np.argsort(first, kind="stable"):
        if first[c] >= k:
            continue
        nodes = np.flatnonzero(lab == c)
        ends = nodes[np.diff(g.indptr)[nodes] == 1]
        start = int(ends[np.argmin(orig[ends])]) if len(ends) else int(nodes[np.argmin(orig[nodes])])
        out.append((orig[depth_first_order(g, start, directed=False, return_predecessors=False)].tolist(),
                    not len(ends)))
    return out


@pytest.mark.parametrize("seed", range(8))
def test_polylines_match_the_scipy_walks(seed):
    """polylines_from_edges (one compiled walk) gives the chains, their order and their walks
    of the components and depth-first orders it replaced: random graphs of paths, loops,
    loops through a break node, branch points and isolated edges."""
    rng = np.random.default_rng(40 + seed)
    edges = []
    nxt = 0
    for _ in range(int(rng.integers(1, 12))):
        L = int(rng.integers(1, 9))
        kind = rng.integers(0, 3)
        ids = list(range(nxt, nxt + L + 1))
        nxt += L + 1
        if kind == 1 and L >= 2:
            ids[-1] = ids[0]                               # a loop
        edges += [(ids[t], ids[t + 1]) for t in range(L)]
        if kind == 2 and nxt > 3:                          # join to an earlier node: a branch
            edges.append((ids[0], int(rng.integers(0, ids[0] + 1))))
    edges = np.array([e for e in edges if e[0] != e[1]])
    perm = rng.permutation(nxt)                           # any numbering
    edges = perm[edges]
    got = polylines_from_edges(np.zeros((nxt, 3)), edges)
    assert [(ix.tolist(), cl) for ix, cl in got] == _polylines_by_scipy(edges)


@pytest.mark.parametrize("scan", [0, 40, 512])
def test_curve_set_matches_each_curve_bit_for_bit(scan, monkeypatch):
    """CurveSet answers every curve in one query and must give exactly what each Curve gives on
    its own (the smoothing's projections and so the meshes depend on it): crossing and
    touching curves (a query near another curve must still land on its own), a closed one,
    collinear segments (ties: the lowest segment wins), a curve longer than the scan limit,
    and queries far beyond the set's extent (answered curve by curve). ``scan``: the longest
    curve scanned whole by the compiled loop (0: every query through the KD-tree; 40: the
    two 40-segment curves scanned, the others through the tree)."""
    import shellmesh_mdao.core.supports as sm
    monkeypatch.setattr(sm, "SCAN_SEGMENTS", scan)
    rng = np.random.default_rng(7)
    s = np.linspace(0.0, 2.0, 41)
    u = np.linspace(0.0, 1.0, 700)
    curves = [Curve(np.c_[s, np.zeros_like(s), np.zeros_like(s)]),           # x axis
              Curve(np.c_[np.ones_like(s), s - 1.0, np.zeros_like(s)]),       # crosses it at x = 1
              Curve(np.c_[np.cos(3 * s), np.sin(3 * s), 0.01 * s], closed=True),
              Curve(np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0.5], [0, 0, 0.5]], float)),  # overlaps the x axis
              Curve(np.c_[2 * u, np.sin(9 * u), 0.2 * np.cos(5 * u)])]        # 699 segments
    cs = CurveSet(curves)
    m = 600
    cid = rng.integers(0, len(curves), m)
    q = rng.uniform(-1.5, 2.5, (m, 3)) * [1, 1, 0.3]
    q[:40] = np.array([1.0, 0.0, 0.0]) + rng.normal(scale=1e-3, size=(40, 3))   # at the crossing
    q[40:45] *= 1e9                                                              # far away
    x, d, t = cs.closest(q, cid)
    for i in range(m):
        xi, di, ti = curves[cid[i]].closest(q[i:i + 1])
        assert np.array_equal(x[i], xi[0]) and d[i] == di[0] and np.array_equal(t[i], ti[0]), i
    # its own curve, not the nearest one: on the x axis at (0.5, 0.2, 0), curve 1 (x = 1) is 0.5 away
    x, d, _ = cs.closest(np.array([[0.5, 0.2, 0.0]]), np.array([1]))
    assert np.allclose(x, [[1.0, 0.2, 0.0]]) and np.isclose(d[0], 0.5)
    assert [len(a) for a in cs.closest(np.zeros((0, 3)), np.zeros(0, np.int64))] == [0, 0, 0]


def test_section_polylines_cached_per_locator_and_plane():
    """A member's plane section is computed once per input skin: the same polylines as a fresh
    section (a unit cube cut at z = 0.3 is one closed square of perimeter 4), read-only, and a
    second skin or plane gets its own."""
    from shellmesh_mdao.core.supports import section_polylines
    from shellmesh_mdao.core.section import Plane, plane_section
    box = trimesh.creation.box()
    loc = SurfaceLocator(box.vertices, box.faces)
    got = section_polylines(loc, [0, 0, 0.3], [0, 0, 1])
    assert len(got) == 1 and got[0][1]
    nodes = got[0][0]
    assert np.allclose(nodes[:, 2], 0.3)
    assert np.isclose(np.linalg.norm(np.diff(np.vstack([nodes, nodes[:1]]), axis=0), axis=1).sum(), 4.0)
    sec = plane_section(loc.points, loc.triangles, Plane.make([0, 0, 0.3], [0, 0, 1]))
    fresh = [(sec.nodes[ix], cl) for ix, cl in polylines_from_edges(sec.nodes, sec.links)]
    assert len(fresh) == 1 and np.array_equal(fresh[0][0], nodes)
    again = section_polylines(loc, [0, 0, 0.3], [0, 0, 1])
    assert again[0][0] is nodes                                   # served from the cache
    with pytest.raises(ValueError):
        nodes[0, 0] = 1.0                                         # shared: nobody may edit it
    other = section_polylines(loc, [0, 0, -0.2], [0, 0, 1])
    assert np.allclose(other[0][0][:, 2], -0.2)
    loc2 = SurfaceLocator(box.vertices * 2.0, box.faces)
    assert np.isclose(np.abs(section_polylines(loc2, [0, 0, 0.3], [0, 0, 1])[0][0][:, 0]).max(), 1.0)


def test_section_cache_is_bounded(monkeypatch):
    """A study keeps its loaded skin while the member planes move from run to run: the cache
    keeps the most recently used SECTION_CACHE_SIZE planes per locator, not every plane ever asked."""
    import shellmesh_mdao.core.supports as S
    monkeypatch.setattr(S, "SECTION_CACHE_SIZE", 4)
    box = trimesh.creation.box()
    loc = SurfaceLocator(box.vertices, box.faces)
    first = S.section_polylines(loc, [0, 0, 0.0], [0, 0, 1])
    for z in np.linspace(-0.4, 0.4, 9):
        S.section_polylines(loc, [0, 0, z], [0, 0, 1])
        assert len(S._SECTIONS[loc]) <= 4
        assert S.section_polylines(loc, [0, 0, 0.0], [0, 0, 1])[0][0] is first[0][0]   # in use: kept
    for z in np.linspace(0.45, 0.49, 5):
        S.section_polylines(loc, [0, 0, z], [0, 0, 1])
    again = S.section_polylines(loc, [0, 0, 0.0], [0, 0, 1])                 # dropped, computed anew
    assert again[0][0] is not first[0][0] and np.array_equal(again[0][0], first[0][0])


# ------------------------------------------------------------------ corpus skins
def _corpus_quads(geometry_dir, name, feature_deg=30.0):
    tm = trimesh.load(geometry_dir / f"{name}.stl", process=True)
    fe = tm.face_adjacency_edges[np.degrees(tm.face_adjacency_angles) > feature_deg]
    mesh = ShellMesh(tm.vertices, tm.faces, feature_edges=fe)
    loc = SurfaceLocator(tm.vertices, tm.faces)
    curves = {-1: [(mesh.points[ix], cl) for ix, cl in polylines_from_edges(mesh.points, fe)]}
    merged, _ = merge_triangles(mesh, **PLAIN_MERGE)
    sup = derive_supports(merged, loc, curves=curves)
    q, qs = subdivide_to_quads(merged, sup)
    return q, qs, loc


def _check_corpus(q, qs, loc, out, res):
    tol = 1e-9 * q.diagonal
    assert out.n_tris == 0 and out.check().ok
    assert qs.distance(out.points).max() <= tol
    assert loc.closest(out.points)[2].max() <= tol                          # on the ORIGINAL input
    qb, qa = res.quality_before, res.quality_after
    assert qa["quad_fraction"] == 1.0
    assert qa["mean_sj"] >= qb["mean_sj"] - 1e-3
    assert qa["n_sj_le_0.2"] <= qb["n_sj_le_0.2"]                           # no new bad elements
    assert qa["min_sj"] >= min(qb["min_sj"], 0.3) - 1e-9
    print({k: round(v, 4) for k, v in qa.items()}, f"{res.seconds:.1f}s")


def test_corpus_straight_wing(geometry_dir):
    q, qs, loc = _corpus_quads(geometry_dir, "straight_wing")
    out, res = smooth(q, qs, iterations=10)
    _check_corpus(q, qs, loc, out, res)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["bwb", "swept_wing", "cessna210"])
def test_corpus_all(geometry_dir, name):
    q, qs, loc = _corpus_quads(geometry_dir, name)
    out, res = smooth(q, qs)
    _check_corpus(q, qs, loc, out, res)
    assert res.quality_after["mean_sj"] > res.quality_before["mean_sj"]


@pytest.mark.slow
def test_timing_100k(geometry_dir):
    q, qs, loc = _corpus_quads(geometry_dir, "swept_wing")
    t = time.perf_counter()
    q2, qs2 = subdivide_to_quads(q, qs)
    t_sub = time.perf_counter() - t
    assert q2.n_faces > 100_000
    out, res = smooth(q2, qs2, iterations=10)
    print(f"subdivide {t_sub:.2f}s, smooth {res.seconds:.1f}s for {q2.n_faces} quads")
    _check_corpus(q2, qs2, loc, out, res)


def test_thin_trailing_edge_never_jumps_to_the_opposite_skin():
    """A 5 %-thick NACA 0005 wing (sharp trailing edge as a feature curve): after
    subdivision and smoothing every skin node lies on the input surface on a triangle that
    faces the same way as the mesh around it, and the trailing-edge nodes stay on the edge."""
    from shellmesh_mdao.geometry import naca_wing
    wing = naca_wing(span=2.0, root_chord=1.0, tip_chord=0.6, naca="0005", n_chord=24, n_span=12)
    loc = SurfaceLocator(wing.points, wing.faces[:, :3])
    fn = wing.face_normals()
    topo = wing.topology()
    f = topo.edge_faces.reshape(-1, 2)
    fe = topo.edges[(fn[f[:, 0]] * fn[f[:, 1]]).sum(1) < np.cos(np.radians(30))]
    mesh = ShellMesh(wing.points, wing.faces, feature_edges=fe)
    curves = {-1: [(mesh.points[ix], cl) for ix, cl in polylines_from_edges(mesh.points, fe)]}
    merged, _ = merge_triangles(mesh, **PLAIN_MERGE)
    sup = derive_supports(merged, loc, curves=curves)
    q, qs = subdivide_to_quads(merged, sup)
    out, res = smooth(q, qs, iterations=10)
    tol = 1e-9 * out.diagonal
    assert qs.distance(out.points).max() <= tol
    surf = np.flatnonzero(qs.kind == SURFACE)
    _, tri, dist = loc.closest(out.points[surf])
    assert dist.max() <= tol
    t = loc.triangles[tri]
    tn = np.cross(loc.points[t[:, 1]] - loc.points[t[:, 0]], loc.points[t[:, 2]] - loc.points[t[:, 0]])
    vn = out.vertex_normals()[surf]
    assert ((tn * vn).sum(1) > 0).all()
    assert (scaled_jacobian(out.points, out.faces) > 0).all()
    assert res.quality_after["n_sj_le_0.2"] <= res.quality_before["n_sj_le_0.2"]


def test_untangle_unfolds_along_the_supports():
    """A 4x4 grid on the curved skin z = 0.2 sin x with two interior nodes thrown across their
    neighbours (folded elements): untangle moves vertices along the skin until every element
    is above the goal; the open boundary (fixed) does not move, every node stays on the input
    surface, no element ends flipped, the result is deterministic; with ``faces`` it repairs
    only the listed elements' neighbourhood."""
    from shellmesh_mdao.smooth import untangle
    _, loc, _, _ = t_mesh()
    P, F, idx = grid(4, 4, sx=2.0, sy=2.0)
    P[:, 2] = 0.2 * np.sin(P[:, 0])
    mesh0 = ShellMesh(P, F)
    sup = derive_supports(mesh0, loc)
    ref = mesh0.face_normals()
    bad = P.copy()
    for a, b in ((idx[1, 1], idx[2, 2]), (idx[3, 2], idx[2, 1])):        # past the diagonal neighbour
        bad[a] = P[a] + 1.3 * (P[b] - P[a])
    bad[:, 2] = 0.2 * np.sin(bad[:, 0])
    mesh = ShellMesh(bad, F)
    assert scaled_jacobian(mesh.points, mesh.faces).min() < 0
    out, info = untangle(mesh, sup, goal=0.3, ref_normals=ref)
    sj = scaled_jacobian(out.points, out.faces)
    assert sj.min() > 0.3 and info["n_bad_after"] == 0 and info["n_bad_before"] >= 4
    assert info["min_before"] < 0 < 0.3 < info["min_after"]
    assert ((out.face_normals() * ref).sum(1) > 0).all()
    fixed = sup.kind == FIXED
    assert fixed.sum() == 16 and np.array_equal(out.points[fixed], bad[fixed])
    assert sup.distance(out.points).max() <= 1e-9 * out.diagonal
    again, _ = untangle(mesh, sup, goal=0.3, ref_normals=ref)
    assert np.array_equal(again.points, out.points)
    # only the faces around the first node: the second fold is left (and gets no worse)
    near = np.flatnonzero((F == idx[1, 1]).any(1))
    part, pinfo = untangle(mesh, sup, goal=0.3, ref_normals=ref, faces=near)
    sjp = scaled_jacobian(part.points, part.faces)
    assert sjp[near].min() > 0.3 and pinfo["n_bad_after"] == 0
    far = np.flatnonzero((F == idx[3, 2]).any(1))
    assert 0 > sjp[far].min() >= scaled_jacobian(mesh.points, mesh.faces)[far].min() - 1e-12
    with pytest.raises(MeshValidationError, match="untangle needs Supports"):
        untangle(mesh, Supports(np.zeros(3, np.int8), -np.ones(3)))


def _warp_energy(term, x):
    """1/2 sum w r^2 of a planarity term with its frozen normals, at positions x."""
    r = term.s * np.einsum("mj,mj->m", term.n, (x[term.q] * term.SIGMA[None, :, None]).sum(1))
    return 0.5 * float((term.w * r ** 2).sum())


def test_warp_term_gradient_and_hessian_are_those_of_its_energy():
    """The quad planarity term (smooth.energy.WarpTerm): with zero support normals its gradient and its
    Hessian (identity tangent columns) are the exact derivatives of 1/2 sum w r^2; planar quads
    (warp below warp_from) are not in it."""
    from shellmesh_mdao.smooth.energy import WarpTerm
    rng = np.random.default_rng(4)
    P, F, _ = grid(4, 3)
    P[:, 2] = rng.uniform(-0.15, 0.15, len(P))                     # twisted quads
    flat, _, _ = grid(4, 3, y0=5.0)                                # planar: never in the term
    P2 = np.vstack([P, flat])
    F2 = np.vstack([F, F + len(P)])
    n = len(P2)
    term = WarpTerm(P2, F2, np.ones(len(F2), bool), 0.7, lambda v: np.zeros((len(v), 3)), 1.0)
    assert 0 < len(term) <= len(F) and (term.q < len(P)).all()
    g = term.gradient(P2, n)
    eps = 1e-6
    fd = np.zeros_like(P2)
    for i in range(n):
        for d in range(3):
            e = np.zeros_like(P2)
            e[i, d] = eps
            fd[i, d] = (_warp_energy(term, P2 + e) - _warp_energy(term, P2 - e)) / (2 * eps)
    assert np.abs(g - fd).max() <= 1e-7 * max(1.0, np.abs(fd).max())
    # the Hessian the smoothing assembles (kernels.ReducedHessian), in full 3D columns
    from shellmesh_mdao.smooth.kernels import ReducedHessian
    none = np.zeros(0, np.int64)
    hess = ReducedHessian(none, none, F2, np.full(n, 3), 3 * np.arange(n))
    H = hess.matrix(hess.values(np.tile(np.eye(3), (n, 1)), np.zeros(0), np.zeros(3 * n), warp=term.terms())).toarray()
    Hfd = np.zeros((3 * n, 3 * n))
    for c in range(3 * n):
        e = np.zeros(3 * n)
        e[c] = eps
        Hfd[:, c] = (term.gradient(P2 + e.reshape(n, 3), n) - term.gradient(P2 - e.reshape(n, 3), n)).ravel() / (2 * eps)
    assert np.abs(H - Hfd).max() <= 1e-6 * np.abs(Hfd).max()
    assert np.array_equal(H, H.T)


def _roof(kink_deg=24.0, n=8, twist=0.0):
    """A quad grid draped over a roof (two planes meeting at a ridge along the diagonal
    x = y, each tilted by kink/2): the quads on the ridge are folded along it. Input skin: the
    roof as a fine triangulation; the grid's boundary nodes are fixed. ``twist`` adds
    ``twist (x - 1/2) (y - 1/2)`` to the height: a saddle, on which every quad is warped."""
    t = np.tan(np.radians(kink_deg / 2))

    def z(x, y):
        return -t * np.abs(x - y) / np.sqrt(2) + twist * (x - 0.5) * (y - 0.5)

    P, F, idx = grid(n, n)
    P[:, 2] = z(P[:, 0], P[:, 1])
    u, v = np.meshgrid(np.linspace(-0.2, 1.2, 57), np.linspace(-0.2, 1.2, 57), indexing="ij")
    k = np.arange(57 * 57).reshape(57, 57)
    a, b, c, d = k[:-1, :-1].ravel(), k[1:, :-1].ravel(), k[1:, 1:].ravel(), k[:-1, 1:].ravel()
    sp = np.stack([u.ravel(), v.ravel(), z(u.ravel(), v.ravel())], 1)
    loc = SurfaceLocator(sp, np.vstack([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]))
    mesh = ShellMesh(P, F)
    return mesh, derive_supports(mesh, loc)


def test_warp_weight_flattens_quads_over_a_kink_and_keeps_them_on_the_surface():
    """smooth(warp_weight > 0): the corners of the quads folded over the roof's ridge slide along
    the roof's facets until the quads are flatter (on this grid the plain smoothing keeps the
    ridge quads folded by the full 24 degrees; with the term the worst quad without a fixed
    corner has 13.4 degrees, and the sum of squared warps, which the term lowers, is 57 % of
    the plain smoothing's); every node stays on the input surface, no element falls below
    min(its own, 0.3), and warp_weight 0 is the plain smoothing."""
    from shellmesh_mdao.quality import element_quality
    mesh, sup = _roof()
    w0 = element_quality(mesh.points, mesh.faces)["warp"]
    assert w0.max() > 15.0
    plain, _ = smooth(mesh, sup, iterations=10)
    zero, _ = smooth(mesh, sup, iterations=10, warp_weight=0.0)
    assert plain.points.tobytes() == zero.points.tobytes()
    flat, res = smooth(mesh, sup, iterations=10, warp_weight=300.0, warp_from=2.0)
    wp, wf = (element_quality(m.points, m.faces)["warp"] for m in (plain, flat))
    inner = ~(sup.kind[mesh.faces] == FIXED).any(1)                # quads free to move
    assert wp[inner].max() > 23.0 and wf[inner].max() < 0.65 * wp[inner].max()
    assert (wf ** 2).sum() < 0.65 * (wp ** 2).sum()
    assert wf[inner].sum() < 0.95 * wp[inner].sum()
    assert sup.distance(flat.points).max() <= 1e-9 * mesh.diagonal
    sj0 = scaled_jacobian(mesh.points, mesh.faces)
    assert (scaled_jacobian(flat.points, flat.faces) >= np.minimum(sj0, 0.3) - 1e-12).all()
    with pytest.raises(ValueError, match="warp_weight"):
        smooth(mesh, sup, warp_weight=-1.0)
    with pytest.raises(ValueError, match="kkt"):
        smooth(mesh, sup, warp_weight=1.0, solver="kkt")


def test_warp_spread_leaves_out_quads_draped_over_a_tight_crease():
    """WarpTerm(warp_spread=s): a warped quad that shares a vertex with a face (itself included)
    whose corners' support normals are more than s degrees apart (draped over a crease much
    tighter than itself) is not in the term; corners on curves or fixed (zero normal) do not
    count. On a roof with a 100 degree ridge every ridge quad is left out at spread 75, so the
    smoothing is the plain one bit for bit, while without the limit the term pulls at them; on
    the 24 degree roof the limit changes nothing, bit for bit."""
    from shellmesh_mdao.smooth.energy import WarpTerm
    rng = np.random.default_rng(5)
    quads = [grid(1, 1, x0=3.0 * k)[0] for k in range(4)]            # four separate quads
    P = np.vstack(quads)
    P[:, 2] = rng.uniform(-0.2, 0.2, len(P))                        # all twisted
    F = np.arange(16).reshape(4, 4)[:, [0, 2, 3, 1]]
    up = np.array([0.0, 0.0, 1.0])

    def tilted(deg):
        return np.array([np.sin(np.radians(deg)), 0.0, np.cos(np.radians(deg))])

    nrm = np.tile(up, (len(P), 1))
    nrm[F[0, :2]] = tilted(80)                                       # quad 0: corners 80 deg apart
    nrm[F[1, :2]] = tilted(20)                                       # quad 1: 20 deg apart
    nrm[F[2, 2]] = 0.0                                               # quad 2: one corner on a curve
    nrm[F[3, 1]] = 0.0                                               # quad 3: a fixed corner, and
    nrm[F[3, 2]] = tilted(80)                                        # 80 deg between two others
    assert len(WarpTerm(P, F, np.ones(4, bool), 1.0, lambda v: nrm[v], 1.0)) == 4
    term = WarpTerm(P, F, np.ones(4, bool), 1.0, lambda v: nrm[v], 1.0, warp_spread=75.0)
    assert np.array_equal(term.q, F[[1, 2]])
    sharp, sup = _roof(kink_deg=100.0)
    plain, _ = smooth(sharp, sup, iterations=10)
    kept, _ = smooth(sharp, sup, iterations=10, warp_weight=300.0, warp_from=2.0, warp_spread=75.0)
    pulled, _ = smooth(sharp, sup, iterations=10, warp_weight=300.0, warp_from=2.0)
    assert kept.points.tobytes() == plain.points.tobytes()
    assert not np.array_equal(pulled.points, plain.points)
    mesh, sup = _roof()
    a, _ = smooth(mesh, sup, iterations=10, warp_weight=300.0, warp_from=2.0, warp_spread=75.0)
    b, _ = smooth(mesh, sup, iterations=10, warp_weight=300.0, warp_from=2.0)
    assert a.points.tobytes() == b.points.tobytes()
    with pytest.raises(ValueError, match="warp_spread"):
        smooth(mesh, sup, warp_spread=0.0)


def test_smooth_vertices_moves_only_those_and_keeps_them_on_the_surface():
    """smooth(vertices=ids): only those vertices move (the others hold still bit for bit, as
    with Supports.held(ids), which makes every other vertex FIXED, and the result is that
    smoothing's bit for bit although only the faces around the ids take part); the moved ones
    stay on the input surface and no element falls below min(its own, 0.3)."""
    mesh, sup = _roof()
    free = np.flatnonzero(sup.kind != FIXED)
    some = free[: len(free) // 2]
    held = sup.held(some)
    assert (held.kind[some] == sup.kind[some]).all() and (held.ref[some] == sup.ref[some]).all()
    rest = np.setdiff1d(np.arange(sup.n), some)
    assert (held.kind[rest] == FIXED).all() and (held.ref[rest] == -1).all()
    part, _ = smooth(mesh, sup, iterations=10, warp_weight=300.0, warp_from=2.0, vertices=some)
    same, _ = smooth(mesh, held, iterations=10, warp_weight=300.0, warp_from=2.0)
    assert part.points.tobytes() == same.points.tobytes()
    # smooth(vertices=) works on the faces at them only: with the pipeline's energy, diagonals,
    # the orthogonality term and a small region, still the whole-mesh smoothing with the others
    # held, bit for bit
    # and with the planarity term on a twisted roof (every quad warped), where warp_spread
    # leaves out the quads beside draped ones
    twisted, tsup = _roof(twist=0.8)
    off = np.abs(mesh.points[free, 0] - mesh.points[free, 1])
    few = free[np.abs(off - 3 / 8) < 1e-9][:6]
    for m, s, opts in ((mesh, sup, {"energy": "squared", "target_edge": 0.1, "ortho_weight": 3.0,
                                    "diagonal_weight": 0.5}),
                       (twisted, tsup, {"energy": "squared", "target_edge": 0.1, "warp_weight": 300.0,
                                        "warp_from": 0.5, "warp_spread": 20.0})):
        region, _ = smooth(m, s, iterations=6, vertices=few, **opts)
        whole, _ = smooth(m, s.held(few), iterations=6, **opts)
        assert region.points.tobytes() == whole.points.tobytes()
        assert np.any(region.points[few] != m.points[few])
    moved = np.flatnonzero(np.any(part.points != mesh.points, axis=1))
    assert len(moved) > len(some) // 2 and np.isin(moved, some).all()
    assert sup.distance(part.points).max() <= 1e-9 * mesh.diagonal
    sj0 = scaled_jacobian(mesh.points, mesh.faces)
    assert (scaled_jacobian(part.points, part.faces) >= np.minimum(sj0, 0.3) - 1e-12).all()
    with pytest.raises(ValueError, match="vertices must be ids"):
        smooth(mesh, sup, vertices=[mesh.n_points])


def test_smooth_fills_the_figures_asked_for():
    """``figures`` selects which quality summaries are computed; the mesh does not depend on it."""
    from shellmesh_mdao.smooth import mesh_figures

    m, loc, planes, curves = t_mesh()
    sup = derive_supports(m, loc, planes, curves, sliding=True)
    out, res = smooth(m, sup, iterations=3, figures="both")
    assert res.quality_before == mesh_figures(m, sup) and res.quality_after == mesh_figures(out, sup)
    assert res.quality_before != res.quality_after
    for which in ("before", "after", "none"):
        o2, r2 = smooth(m, sup, iterations=3, figures=which)
        assert np.array_equal(o2.points, out.points)
        assert (r2.quality_before == res.quality_before) == (which == "before")
        assert (r2.quality_after == res.quality_after) == (which == "after")
        assert r2.quality_before == {} or which == "before"
    with pytest.raises(ValueError):
        smooth(m, sup, figures="all")


def test_trust_radius_query_in_its_own_thread():
    """The smoothing asks its trust radius (distance to the nearest other vertex) of a grid in a
    second thread: the distances are a brute-force scan's, coincident points give 0, and an
    exception in the thread reaches the caller."""
    from shellmesh_mdao.smooth.kernels import nearest_other_distance
    from shellmesh_mdao.core.threads import Background

    rng = np.random.default_rng(5)
    P = rng.normal(size=(400, 3))
    P[7] = P[3]                                            # a coincident pair
    verts = np.arange(0, 400, 3)
    d = np.linalg.norm(P[verts, None, :] - P[None, :, :], axis=2)
    d[np.arange(len(verts)), verts] = np.inf
    job = Background(nearest_other_distance, P, verts)
    got = job.result()
    assert np.allclose(got, d.min(1), rtol=0, atol=1e-12) and got[1] == 0.0
    assert job.result() is got                             # asked twice, one value
    with pytest.raises(ValueError, match="verts holds indices outside"):
        Background(nearest_other_distance, P, np.array([400])).result()


def test_ldl_reuses_the_ordering_with_the_same_bits():
    """LDL keeps qdldl's ordering and symbolic factorisation while the pattern repeats (the
    smoothing's refreshed matrices, planarize's rounds): each solve has the bits of a fresh
    factorisation of that matrix, and a new pattern gets a fresh one."""
    import qdldl
    from scipy import sparse

    from shellmesh_mdao.smooth import LDL, LinearSolver
    rng = np.random.default_rng(8)
    n = 400
    A = sparse.random(n, n, density=0.02, random_state=3, format="csr")
    pattern = (A + A.T + sparse.eye(n)).tocsr()
    ldl = LDL()
    b = rng.normal(size=n)
    solvers = []
    for k in range(3):
        M = pattern.copy()
        M.data = rng.random(len(M.data))
        M = ((M + M.T) * 0.5 + sparse.eye(n) * n).tocsr()          # SPD, symmetric bit for bit
        U = sparse.triu(M, format="csc")
        s = ldl.factor(U.indptr, U.indices, U.data)
        solvers.append(s)
        fresh = qdldl.Solver(U, upper=True)
        assert np.array_equal(s.solve(b), fresh.solve(b))
        lin = LinearSolver(M, "lu", ldl)
        assert np.array_equal(lin.solve(b), LinearSolver(M, "lu").solve(b))
    assert solvers[0] is solvers[1] is solvers[2]                     # one ordering for the pattern
    other = sparse.triu((sparse.eye(n) * 2.0).tocsr(), format="csc")
    assert ldl.factor(other.indptr, other.indices, other.data) is not solvers[0]


def _fragile_layout(seed):
    """The bundled wing's layout with its nine ribs jittered by up to 0.03 of the span and the
    front spar between 0.12 and 0.2 of the chord (the layouts of issue 41's 20 seeds)."""
    from shellmesh_mdao.geometry import naca_wing_layout
    rng = np.random.default_rng(seed)
    lay = naca_wing_layout()
    w = lay["wings"][0]
    eta = np.linspace(0, 1, 9)
    eta[1:-1] += rng.uniform(-0.03, 0.03, 7)
    w["ribs"] = {"eta": [float(e) for e in eta]}
    w["spars"] = {"chord_fractions": [float(rng.uniform(0.12, 0.2)), 0.65]}
    return lay


def test_smoothing_turns_no_face_across_a_leading_edge():
    """The bundled wing at size 0.1, layout seed 2 of issue 41: the leading-edge nose (16-32 mm
    radius) lies under faces of about the remesh edge (0.2). The smoothing's edges aim at that
    length, so it dragged the nose's nodes aft until faces stood across the nose, from the lower
    to the upper skin (normals along the span); the subdivision's midpoints of those faces lay
    inside the wing and the final mesh kept a skin node 0.06 off the input. No step may now turn
    a face further than 60 degrees from the support normal at every one of its corners (nor
    further where it was already)."""
    from shellmesh_mdao.core.supports import support_normals
    from shellmesh_mdao.geometry import naca_wing
    from shellmesh_mdao.pipeline import run_pipeline, run_stage
    from shellmesh_mdao.smooth.elements import face_normals, facing
    from shellmesh_mdao.smooth.qp import COS_STAND
    st = run_pipeline(naca_wing(), _fragile_layout(2), 0.1, until="merge", progress=False).state
    out = run_stage(st, "smooth")
    sup, F, tri = st.supports, st.mesh.faces, st.mesh.is_tri
    before = facing(F, face_normals(st.mesh.points, F, tri), support_normals(sup, st.mesh.points, np.arange(sup.n)))
    after = facing(F, face_normals(out.mesh.points, F, tri), support_normals(sup, out.mesh.points, np.arange(sup.n)))
    assert ((after > COS_STAND) | (after >= before - 1e-12)).all()
    assert out.report["smooth"]["iterations"] > 0


def test_smooth_stage_keeps_the_leading_edge_grading():
    """Issue 41: the remesh grades the bundled wing's skin finer at the leading-edge nose (edges of
    0.03-0.06 under a 0.2 remesh edge at size 0.1). With every edge aiming at the one remesh edge
    length the smoothing stretched the nose's edges up to 2.05 times (a tenth of them by more than
    1.5), spreading each face over more of the nose, and their children came out long, thin and
    warped. Each edge now aims at the local size at its ends (local_edge_size)."""
    from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
    from shellmesh_mdao.pipeline import run_pipeline, run_stage
    from shellmesh_mdao.smooth import local_edge_size
    st = run_pipeline(naca_wing(), naca_wing_layout(), 0.1, until="merge", progress=False).state
    h = local_edge_size(st.mesh, 0.2)
    assert h.max() <= 0.2 and np.median(h) < 0.15             # graded: most of the mesh below the target
    out = run_stage(st, "smooth")
    E = st.mesh.edges()
    mid = st.mesh.points[E].mean(1)
    y = mid[:, 1]
    # the nose at mid-span (bundled wing: chord 2 - y/6, leading edge swept 10 degrees)
    nose = (y > 0.5) & (y < 5.0) & (mid[:, 0] - y * np.tan(np.radians(10.0)) < 0.03 * (2.0 - y / 6.0))
    r = out.mesh.edge_lengths()[nose] / st.mesh.edge_lengths()[nose]
    assert nose.sum() > 300
    assert np.percentile(r, 90) < 1.25 and r.max() < 1.6
