"""Splitting LP (paper eq. 1-3): option tables against the paper's eq. 3 example, energy
values, known optimal splits, edge agreement on non-manifold edges, fixed edges,
projection callback, the MIP fallback, determinism and a corpus run."""
import time

import numpy as np
import pytest
import trimesh

from shellmesh_mdao.errors import ProjectionError
from shellmesh_mdao.mesh import ShellMesh
from shellmesh_mdao.merge import merge_triangles
from shellmesh_mdao.split import (N_OPTIONS, build_split_lp, polygon_energy, split_energy, split_options,
                                  split_polygons)

SQ3 = np.sqrt(3.0)


def signed_area_2d(P):
    """Shoelace area of (k, 3 or 4, 2+) polygons (xy only)."""
    x, y = P[..., 0], P[..., 1]
    return 0.5 * (x * np.roll(y, -1, -1) - np.roll(x, -1, -1) * y).sum(-1)


def assert_conforming(mesh):
    c = mesh.check()
    assert c.ok, c.problems()
    assert len(c.hanging_nodes) == 0


# ------------------------------------------------------------------ option tables
def test_option_tables_reproduce_paper_eq3_example():
    o = split_options()
    # paper: triangle side (2,0) is split by options 2, 3, 5; quad side (1,2) by options 0, 2, 6
    assert np.flatnonzero(o.splits[0, :, 2]).tolist() == [2, 3, 5]
    assert np.flatnonzero(o.splits[1, :, 1]).tolist() == [0, 2, 6]
    assert o.valid[0].tolist() == [True] * 7 + [False] * 4 and o.valid[1].all()
    assert o.keep.tolist() == [6, 10]
    # every option of every kind splits either nothing, one side, or two sides
    nsplit = o.splits.sum(2)
    assert nsplit[1].tolist() == [2, 2] + [1] * 8 + [0]
    assert nsplit[0, :7].tolist() == [1, 1, 1, 2, 2, 2, 0]


def test_paper_fig6_agreement_row():
    # Fig. 6: triangle (1,2,3) and quad (0,1,3,4) sharing edge (1,3). With the triangle
    # as face 0 and the quad as face 1, the agreement row is the first row of eq. 3.
    pts = np.array([[0, 0, 0], [1, 0, 0], [2, 0.5, 0], [1, 1, 0], [0, 1, 0]], float)
    mesh = ShellMesh(pts, [[1, 2, 3, -1], [0, 1, 3, 4]])
    lp = build_split_lp(mesh, reduce=False)
    assert lp.A.shape == (3, 2 * N_OPTIONS)
    row = lp.A[2].toarray().ravel()
    paper = [0, 0, 1, 1, 0, 1, 0, 0, 0, 0, 0, -1, 0, -1, 0, 0, 0, -1, 0, 0, 0, 0]
    assert row.tolist() == paper
    # choice rows: sum of the 11 options of each polygon = 1; padded triangle options ub 0
    assert lp.A[0].toarray().ravel().tolist() == [1] * 11 + [0] * 11
    assert lp.ub[7:11].tolist() == [0, 0, 0, 0] and lp.ub[11:].tolist() == [1] * 11


@pytest.mark.parametrize("kind", [0, 1])
def test_every_option_tiles_its_parent(kind):
    # children of every valid option cover the parent exactly (areas sum up), keep its
    # orientation (positive signed area) and use each split side's midpoint
    o = split_options()
    if kind == 1:
        corners = np.array([[0, 0], [3, 0.2], [2.6, 2.1], [0.3, 1.7]])
    else:
        corners = np.array([[0, 0], [3, 0.4], [1.1, 2.2]])
    nc = len(corners)
    mids = np.array([0.5 * (corners[k] + corners[(k + 1) % nc]) for k in range(nc)])
    local = np.full((9, 2), np.nan)
    local[:nc] = corners
    local[4:4 + nc] = mids
    parent = signed_area_2d(corners[None])[0]
    for opt in np.flatnonzero(o.valid[kind]):
        total = 0.0
        for ch in o.children[kind, opt]:
            if ch[0] < 0:
                continue
            poly = local[ch[ch >= 0]]
            assert not np.isnan(poly).any(), (kind, opt)
            a = signed_area_2d(poly[None])[0]
            assert a > 0, (kind, opt)
            total += a
        assert total == pytest.approx(parent, rel=1e-12), (kind, opt)
        used_mids = {int(v) - 4 for v in o.children[kind, opt].ravel() if 4 <= v < 8}
        assert used_mids == set(np.flatnonzero(o.splits[kind, opt]).tolist())


# ------------------------------------------------------------------ energy
def test_energy_values():
    sq = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]], float)
    eq = np.array([[[0, 0, 0], [1, 0, 0], [0.5, SQ3 / 2, 0], [0, 0, 0]]], float)
    assert polygon_energy(sq, [False])[0] == pytest.approx(0, abs=1e-12)
    assert polygon_energy(eq, [True])[0] == pytest.approx(0, abs=1e-12)
    # 2:1 rectangle: sides 2,1,2,1, l_avg 1.5 -> 4 * (1/3)^2 ; angles exact
    rect = np.array([[[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]]], float)
    assert polygon_energy(rect, [False], c1=1, c2=5)[0] == pytest.approx(4 / 9)
    # right isosceles triangle: angle term (90/60-1)^2 + 2 (45/60-1)^2 = 0.375
    rt = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0]]], float)
    lav = (2 + np.sqrt(2)) / 3
    exp_len = 2 * (1 / lav - 1) ** 2 + (np.sqrt(2) / lav - 1) ** 2
    assert polygon_energy(rt, [True], c1=2, c2=3)[0] == pytest.approx(2 * exp_len + 3 * 0.375)
    # eq. 2 read literally is the same constant for any planar polygon: why the
    # deviation form is used
    P = np.vstack([sq, rect, np.array([[[0, 0, 0], [5, 0, 0], [4, 1, 0], [0, 3, 0]]], float)])
    assert np.allclose(polygon_energy(P, [False] * 3, form="literal"), 8.0)
    T = np.vstack([eq, rt])
    assert np.allclose(polygon_energy(T, [True] * 2, form="literal"), 6.0)
    # degenerate polygon: large energy, no NaN
    deg = np.array([[[0, 0, 0], [0, 0, 0], [1, 1, 0], [0, 1, 0]]], float)
    assert polygon_energy(deg, [False])[0] >= 1e3


def test_split_energy_is_sum_of_children():
    pts = np.array([[0, 0, 0], [4, 0, 0], [4, 1, 0], [0, 1, 0]], float)
    W = split_energy(pts, np.array([[0, 1, 2, 3]]))
    # option 1 (mid-mid of the long sides) -> two 2x1 rectangles, 2 * 4/9
    assert W[0, 1] == pytest.approx(8 / 9)
    assert W[0, 10] == pytest.approx(4 * 0.36)                 # 4:1 rectangle: 4 (1.6-1)^2
    assert W[0].argmin() == 1


# ------------------------------------------------------------------ known optima
def _grid(nx, ny, dx, dy, tri=False):
    x, y = np.meshgrid(np.arange(nx + 1) * dx, np.arange(ny + 1) * dy, indexing="ij")
    pts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    idx = np.arange(pts.shape[0]).reshape(nx + 1, ny + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    if tri:
        f = np.vstack([np.stack([a, b, c, -np.ones_like(a)], 1), np.stack([a, c, d, -np.ones_like(a)], 1)])
    else:
        f = np.stack([a, b, c, d], 1)
    return pts, f


@pytest.mark.parametrize("long_x", [True, False])
def test_long_thin_quad_splits_its_long_edges(long_x):
    pts = np.array([[0, 0, 0], [4, 0, 0], [4, 1, 0], [0, 1, 0]], float)
    if not long_x:
        pts = np.array([[0, 0, 0], [1, 0, 0], [1, 4, 0], [0, 4, 0]], float)
    mesh = ShellMesh(pts, [[0, 1, 2, 3]])
    out, res = split_polygons(mesh)
    assert res.status == "Optimal" and res.is_integral and not res.used_mip
    assert res.choice.tolist() == [1 if long_x else 0]
    assert out.n_quads == 2 and out.n_tris == 0
    # the two new nodes are the midpoints of the long edges
    new = out.points[res.new_nodes]
    long_mids = [[2, 0, 0], [2, 1, 0]] if long_x else [[1, 2, 0], [0, 2, 0]]
    assert sorted(map(tuple, new.tolist())) == sorted(map(tuple, long_mids))
    assert np.allclose(out.face_areas(), 2.0)
    assert res.objective == pytest.approx(8 / 9)


def test_square_and_equilateral_meshes_are_kept():
    pts, f = _grid(3, 3, 1.0, 1.0)
    out, res = split_polygons(ShellMesh(pts, f))
    assert res.n_split_edges == 0 and np.array_equal(out.faces, f)
    assert res.option_counts[1, 10] == 9


def test_stack_of_thin_quads_splits_together_and_conforms():
    # 3 columns x 5 rows of 4:1 quads: every quad wants its long sides split; the shared
    # long sides force whole columns to agree; result conforming, no hanging node
    pts, f = _grid(3, 5, 4.0, 1.0)
    mesh = ShellMesh(pts, f)
    out, res = split_polygons(mesh)
    assert res.status == "Optimal"
    assert out.n_faces == 2 * mesh.n_faces and out.n_tris == 0
    assert_conforming(out)
    assert out.face_areas().sum() == pytest.approx(mesh.face_areas().sum())
    assert np.allclose(out.face_areas(), 2.0)
    # agreement: every split edge is split in all its faces -> every edge of the output
    # has its two end nodes as face corners on both sides (checked by conformity) and
    # the number of new nodes equals the number of long edges (3 x 6)
    assert res.n_split_edges == 18


def test_mixed_tri_quad_agreement_no_hanging_nodes():
    # a thin quad next to a triangle on its long side: any split of the shared edge must
    # be taken by the triangle too
    pts = np.array([[0, 0, 0], [4, 0, 0], [4, 1, 0], [0, 1, 0], [2, 2.5, 0]], float)
    mesh = ShellMesh(pts, [[0, 1, 2, 3], [3, 2, 4, -1]])
    out, res = split_polygons(mesh)
    assert res.choice[0] == 1          # quad splits its long sides
    # the triangle's side 0 is the shared edge (3,2): it must take an option splitting it
    assert split_options().splits[0, res.choice[1], 0]
    assert res.choice[1] == 0          # here: from the apex, two triangles
    assert_conforming(out)
    assert out.face_areas().sum() == pytest.approx(mesh.face_areas().sum())


def test_component_ids_carried_to_children():
    pts, f = _grid(2, 3, 4.0, 1.0)
    comp = np.array([0, 0, 0, 1, 1, 1])
    mesh = ShellMesh(pts, f, comp, ["a", "b"])
    out, res = split_polygons(mesh)
    assert np.array_equal(out.component, comp[res.parent_face])
    assert out.component_names == ["a", "b"]
    assert res.n_split_edges > 0


# ------------------------------------------------------------------ fixed / non-manifold
def test_fixed_edge_is_never_split():
    pts = np.array([[0, 0, 0], [4, 0, 0], [4, 1, 0], [0, 1, 0]], float)
    mesh = ShellMesh(pts, [[0, 1, 2, 3]], feature_edges=[[0, 1]], fixed_vertices=[0, 1])
    out, res = split_polygons(mesh)
    assert not (res.parent_edges == [0, 1]).all(1).any()
    assert out.feature_edges.tolist() == [[0, 1]]
    assert out.fixed_vertices.tolist() == [0, 1]
    # the two options splitting side 0 plus the mid-mid option 1 were bounded to 0
    assert res.choice[0] not in (1, 5, 9)
    assert_conforming(out)


def _t_junction(feature: bool):
    """Two skin 4x1 quads (z = 0) and a rib 4x1 quad (in z) sharing the edge (0,0,0)-(4,0,0)."""
    pts = np.array([[0, 0, 0], [4, 0, 0],
                    [4, 1, 0], [0, 1, 0],      # skin +y
                    [4, -1, 0], [0, -1, 0],    # skin -y
                    [4, 0, 1], [0, 0, 1]], float)  # rib
    faces = [[0, 1, 2, 3], [1, 0, 5, 4], [0, 1, 6, 7]]
    return ShellMesh(pts, faces, [0, 0, 1], ["skin", "rib"],
                     feature_edges=[[0, 1]] if feature else None,
                     feature_edge_ids=[1] if feature else None)


def test_nonmanifold_feature_edge_never_split():
    mesh = _t_junction(feature=True)
    assert mesh.topology().valence.max() == 3
    out, res = split_polygons(mesh)
    assert not (np.sort(res.parent_edges, 1) == [0, 1]).all(1).any()
    assert_conforming(out)
    assert out.nonmanifold_edges().tolist() == [[0, 1]]


def test_nonmanifold_edge_split_ties_all_three_faces():
    # not fixed: all three 4:1 quads want the long edges split; the 3-face edge's
    # midpoint must be shared by all three (one node, used by six faces)
    mesh = _t_junction(feature=False)
    out, res = split_polygons(mesh, fixed_edges=np.zeros((0, 2)))
    assert res.choice.tolist() == [1, 1, 1]
    k = np.flatnonzero((res.parent_edges == [0, 1]).all(1))
    assert len(k) == 1
    mid = res.new_nodes[k[0]]
    assert np.allclose(out.points[mid], [2, 0, 0])
    assert (out.faces == mid).any(1).sum() == 6
    assert_conforming(out)
    assert len(out.nonmanifold_edges()) == 2          # the two halves of the junction


def test_split_fixed_keeps_chain_shared():
    # beyond the paper: a fixed junction may be split by all its faces together; the
    # feature edge becomes two halves with the same owner and the midpoint is fixed
    mesh = _t_junction(feature=True)
    out, res = split_polygons(mesh, split_fixed=True)
    mid = res.new_nodes[np.flatnonzero((res.parent_edges == [0, 1]).all(1))[0]]
    assert sorted(out.feature_edges.tolist()) == sorted([[0, mid], [1, mid]])
    assert out.feature_edge_ids.tolist() == [1, 1]
    assert mid in out.fixed_vertices
    assert_conforming(out)


# ------------------------------------------------------------------ projection
def test_project_callback_moves_new_nodes_and_gets_parent_edges():
    pts, f = _grid(2, 2, 4.0, 1.0)
    mesh = ShellMesh(pts, f)
    seen = {}

    def project(p, parent):
        seen["p"], seen["parent"] = p.copy(), parent.copy()
        q = p.copy()
        q[:, 2] = 0.25
        return q

    out, res = split_polygons(mesh, project=project)
    assert len(seen["p"]) == res.n_split_edges > 0
    assert np.allclose(seen["p"], 0.5 * (pts[seen["parent"][:, 0]] + pts[seen["parent"][:, 1]]))
    assert np.array_equal(seen["parent"], res.parent_edges)
    assert np.allclose(out.points[res.new_nodes, 2], 0.25)
    assert np.array_equal(out.points[:mesh.n_points], pts)
    with pytest.raises(ProjectionError, match="one finite 3-D point"):
        split_polygons(mesh, project=lambda p, e: p[:1])


# ------------------------------------------------------------------ MIP path, determinism
def test_mip_path_gives_the_same_optimum():
    pts, f = _grid(3, 4, 3.0, 1.0)
    mesh = ShellMesh(pts, f)
    out_lp, r_lp = split_polygons(mesh)
    # an integrality tolerance below zero makes every LP answer "fractional"
    out_mip, r_mip = split_polygons(mesh, integrality_tol=-1.0)
    assert r_mip.used_mip and not r_lp.used_mip
    assert r_mip.status == "Optimal"
    assert r_mip.objective == pytest.approx(r_lp.objective)
    assert_conforming(out_mip)


def test_time_limit_gives_a_feasible_split_no_worse_than_keeping(geometry_dir):
    """Stopped at the time limit, the LP (started from keeping every polygon) hands back its
    last feasible vertex: a conforming split whose energy is at most that of keeping all."""
    from shellmesh_mdao import split as sp

    mesh = _corpus_mesh(geometry_dir, "swept_wing")
    out, res = split_polygons(mesh, time_limit=1e-6)
    assert "Time limit" in res.status
    assert_conforming(out)
    lp = build_split_lp(mesh)
    keep = np.zeros(lp.energy.shape)
    keep[np.arange(mesh.n_faces), sp._KEEP[lp.kind]] = 1.0
    assert res.objective <= float(lp.c @ keep.ravel()) + 1e-9


def _corpus_mesh(geometry_dir, name, feature_deg=30.0):
    tm = trimesh.load(geometry_dir / f"{name}.stl", process=False)
    tm.merge_vertices()
    fe = tm.face_adjacency_edges[np.degrees(tm.face_adjacency_angles) > feature_deg]
    return ShellMesh(tm.vertices, tm.faces, feature_edges=fe)


def test_corpus_merge_then_split_deterministic(geometry_dir):
    mesh = _corpus_mesh(geometry_dir, "straight_wing")
    q, _ = merge_triangles(mesh, time_limit=float("inf"), merge_bonus=0.0, valence_weight=0.0)
    t = time.perf_counter()
    a, ra = split_polygons(q, time_limit=float("inf"))      # no time limit: optimal and equal under any load
    dt = time.perf_counter() - t
    b, rb = split_polygons(q, time_limit=float("inf"))
    print(f"\nstraight_wing split: {q.n_faces} polygons -> {a.n_faces}, status {ra.status}, "
          f"objective {ra.objective:.2f}, integral LP {ra.is_integral}, {dt:.2f} s")
    assert ra.status == "Optimal"
    assert np.array_equal(a.faces, b.faces) and np.array_equal(a.points, b.points)
    assert ra.objective == rb.objective
    assert_conforming(a)
    # feature edges untouched (all still mesh edges), objective no worse than keeping all
    assert (a.topology().edge_ids(a.feature_edges) >= 0).all()
    keep = split_energy(q.points, q.faces)[np.arange(q.n_faces), np.where(q.is_tri, 6, 10)].sum()
    assert ra.objective <= keep + 1e-9


@pytest.mark.slow
def test_split_timing_100k(geometry_dir):
    tm = trimesh.load(geometry_dir / "cessna210.stl", process=False)
    tm.merge_vertices()
    tm = tm.subdivide()
    fe = tm.face_adjacency_edges[np.degrees(tm.face_adjacency_angles) > 30]
    mesh = ShellMesh(tm.vertices, tm.faces, feature_edges=fe)
    out, res = split_polygons(mesh)
    print(f"\ncessna210 x4: {mesh.n_faces} triangles -> {out.n_faces}, {res.status}, "
          f"LP {res.lp_seconds:.1f} s, MIP {res.mip_seconds:.1f} s, total {res.seconds:.1f} s")
    assert res.status == "Optimal"
    assert_conforming(out)


def test_highs_solve_prints_nothing(capfd):
    """A solve writes nothing to standard output or error: HiGHS's banner and log would land in
    the middle of the CLI's progress lines and of a caller's own output."""
    from scipy import sparse

    from shellmesh_mdao.core.highs import highs_solve
    A = sparse.csr_matrix(np.array([[1.0, 1.0]]))
    for integer in (False, True):
        res = highs_solve(np.array([1.0, 2.0]), A, np.array([1.0]), np.array([1.0]), np.ones(2), integer=integer,
                          time_limit=10.0)
        assert res.status == "Optimal" and np.allclose(res.x, [1.0, 0.0])
    out, err = capfd.readouterr()
    assert out == "" and err == ""


def test_highs_mip_with_start_skips_feasibility_jump_and_stays_optimal(monkeypatch):
    """With a start solution the MIP turns HiGHS's feasibility-jump heuristic off (the start is
    the incumbent it would look for; the merge's solve takes half the time) and HiGHS accepts
    the option; from a poor start the solve still reaches the optimum found by enumeration."""
    import itertools

    import highspy
    from scipy import sparse

    from shellmesh_mdao.core import highs as H

    set_calls = []
    base = H._highs_core(highspy)

    class Recording(base):
        def setOptionValue(self, name, value):
            status = super().setOptionValue(name, value)
            set_calls.append((name, value, status))
            return status

    monkeypatch.setattr(H, "_highs_core", lambda hp: Recording)
    # a weighted matching on a 6-cycle with a chord: one binary per edge, at most one chosen
    # edge at each node; minimise the (negative) weights
    edges = [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (5, 0), (1, 4)]
    w = -np.array([3.0, 1.0, 2.5, 1.0, 2.0, 1.5, 4.0])
    rows = np.array([i for e in edges for i in e])
    cols = np.repeat(np.arange(len(edges)), 2)
    A = sparse.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(6, len(edges)))
    start = np.zeros(len(edges))
    start[1] = 1.0                                       # a feasible but poor matching
    res = H.highs_solve(w, A, np.full(6, -np.inf), np.ones(6), np.ones(len(edges)), integer=True,
                        time_limit=10.0, mip_gap=0.0, start=start)
    best = min(float(w @ np.array(x)) for x in itertools.product((0, 1), repeat=len(edges))
               if (A @ np.array(x, float) <= 1).all())
    assert res.status == "Optimal" and res.objective == pytest.approx(best)
    jump = [c for c in set_calls if c[0] == "mip_heuristic_run_feasibility_jump"]
    assert jump and jump[0][1] is False and jump[0][2] == highspy.HighsStatus.kOk
    # without a start (the LP, or a MIP with nothing to start from) the option is left alone
    set_calls.clear()
    H.highs_solve(w, A, np.full(6, -np.inf), np.ones(6), np.ones(len(edges)), integer=True, time_limit=10.0)
    assert not [c for c in set_calls if c[0] == "mip_heuristic_run_feasibility_jump"]


def test_lp_starts_from_keeping_every_polygon_and_reaches_the_cold_optimum(monkeypatch):
    """The split LP's simplex starts from the basis of keeping every polygon (HiGHS accepts it):
    on a mesh where a few polygons want splitting it takes a few pivots instead of about one
    per polygon, and ends at the optimum HiGHS reaches from its own start."""
    import highspy

    from shellmesh_mdao.core import highs as H

    runs = []
    base = H._highs_core(highspy)

    class Recording(base):
        basis_status = None

        def setBasis(self, b):
            self.basis_status = super().setBasis(b)
            return self.basis_status

        def run(self):
            status = super().run()
            runs.append((self.basis_status, self.getInfo().simplex_iteration_count))
            return status

    monkeypatch.setattr(H, "_highs_core", lambda hp: Recording)
    rng = np.random.default_rng(3)
    # a jittered 12 x 12 grid of quads with two columns stretched to 4:1: their quads gain
    # from a split, the others are best kept
    pts, f = _grid(12, 12, 1.0, 1.0)
    pts[:, :2] += rng.uniform(-0.1, 0.1, (len(pts), 2))
    pts[:, 0] += 3.0 * (pts[:, 0] > 4.5) + 3.0 * (pts[:, 0] > 7.5)
    mesh = ShellMesh(pts, f)
    out, res = split_polygons(mesh)
    assert res.status == "Optimal" and not res.used_mip and res.n_split_edges > 0
    assert_conforming(out)
    (warm_status, warm_its), = runs
    assert warm_status == highspy.HighsStatus.kOk
    lp = build_split_lp(mesh)
    act = np.flatnonzero(lp.ub > 0)
    cold = H.highs_solve(lp.c[act], lp.A[:, act], lp.rhs, lp.rhs, lp.ub[act], integer=False, time_limit=10.0)
    cold_its = runs[-1][1]
    assert res.objective == pytest.approx(cold.objective, rel=1e-12)
    assert warm_its < cold_its / 3, (warm_its, cold_its)


def test_time_limited_lp_vertex_worse_than_keeping_is_not_used(monkeypatch):
    """Should the LP stop at its time limit on a vertex of higher energy than keeping every
    polygon, every polygon is kept and the status says why."""
    from shellmesh_mdao import split as sp
    from shellmesh_mdao.core.highs import HighsResult

    pts, f = _grid(3, 3, 1.0, 1.0)
    mesh = ShellMesh(pts, f)
    real = sp.highs_solve

    def stopped(c, *a, **k):
        sol = real(c, *a, **k)
        worse = np.zeros_like(sol.x)
        worse[np.argmax(c)] = 1.0                  # costlier than the optimum, kept or not
        assert c @ worse > sol.objective
        return HighsResult(worse, "Time limit reached", float(c @ worse), 0.0, sol.seconds)

    monkeypatch.setattr(sp, "highs_solve", stopped)
    out, res = split_polygons(mesh)
    assert "Time limit" in res.status and "kept all polygons" in res.status
    assert np.array_equal(out.faces, mesh.faces) and res.n_split_edges == 0


def test_polygon_energy_one_kind_batches_match_mixed_ones():
    """A batch of one kind (split_energy's) gathers its corners by plain column indices: the
    same energies, bit for bit, as the same polygons in a batch mixing triangles and quads."""
    rng = np.random.default_rng(4)
    P = rng.normal(size=(500, 4, 3))
    P[7, 1] = P[7, 0]                                   # a zero-length side: the large energy
    for t in (True, False):
        tri = np.full(len(P), t)
        mixed = polygon_energy(np.concatenate([P, P[:1]]), np.concatenate([tri, [not t]]))[:len(P)]
        got = polygon_energy(P, tri)
        assert np.array_equal(got, mixed) and got[7] == 1e3


def _block_lp(sizes, seed):
    """A packing LP ``min c x, A x <= 1, 0 <= x <= 1`` whose rows fall apart into blocks of the
    given column counts (each block a random sparse pattern with every column in a row), the
    blocks' columns interleaved so that no block is a contiguous range, plus one empty row."""
    from scipy import sparse

    rng = np.random.default_rng(seed)
    n = sum(sizes)
    perm = rng.permutation(n)
    rows, cols, r0 = [], [], 0
    start = 0
    for k in sizes:
        cb = perm[start:start + k]
        start += k
        nr = max(1, k // 2)
        for j, col in enumerate(cb):           # every column in two rows of its block
            for r in {j % nr, int(rng.integers(nr))}:
                rows.append(r0 + r)
                cols.append(col)
        r0 += nr
    A = sparse.csr_matrix((rng.uniform(0.5, 2.0, len(rows)), (rows, cols)), shape=(r0 + 1, n))
    c = -rng.uniform(1.0, 2.0, n)              # distinct costs: a unique optimum
    return c, A, np.full(r0 + 1, -np.inf), np.ones(r0 + 1), np.ones(n)


def test_independent_halves_share_no_row_and_keep_blocks_whole():
    from shellmesh_mdao.core.highs import _independent_halves

    sizes = [40, 30, 12, 9, 5, 3, 1]
    c, A, lo, hi, ub = _block_lp(sizes, 0)
    (c0, r0), (c1, r1) = _independent_halves(A)
    n, m = A.shape[1], A.shape[0]
    assert np.array_equal(np.sort(np.concatenate([c0, c1])), np.arange(n))
    assert np.array_equal(np.sort(np.concatenate([r0, r1])), np.arange(m))
    # no row of one half touches a column of the other
    assert A[r0][:, c1].nnz == 0 and A[r1][:, c0].nnz == 0
    # the largest block alone in the first half (its middle, 20, is below half of 100); every
    # block after it in the second; the empty row in the first
    assert len(c0) == 40 and len(c1) == 60 and (m - 1) in r0
    # the same halves every time
    again = _independent_halves(A)
    assert all(np.array_equal(a, b) for h, g in zip(again, ((c0, r0), (c1, r1))) for a, b in zip(h, g))


def test_lp_in_halves_gives_the_one_piece_optimum_from_two_threads(monkeypatch):
    import threading

    from shellmesh_mdao.core import highs as H

    c, A, lo, hi, ub = _block_lp([60, 50, 20, 15], 1)
    one = H.highs_solve(c, A, lo, hi, ub, integer=False, time_limit=10.0)
    threads = []
    real = H.highs_solve

    def recording(*a, **k):
        threads.append((threading.get_ident(), a[1].shape[1]))
        return real(*a, **k)

    monkeypatch.setattr(H, "highs_solve", recording)
    # below LP_HALF_MIN columns in the smaller half: one piece, in the caller's thread
    res = H.highs_solve_halves(c, A, lo, hi, ub, time_limit=10.0)
    assert threads == [(threading.get_ident(), 145)]
    assert np.array_equal(res.x, one.x)
    threads.clear()
    monkeypatch.setattr(H, "LP_HALF_MIN", 20)
    res = H.highs_solve_halves(c, A, lo, hi, ub, time_limit=10.0)
    assert sorted(k for _, k in threads) == [60, 85] and len({t for t, _ in threads}) == 2
    assert res.status == "Optimal" and res.mip_gap == 0.0
    assert np.allclose(res.x, one.x, atol=1e-9, rtol=0)
    assert res.objective == pytest.approx(one.objective, rel=1e-12) and res.dual_bound == res.objective
    # an infeasible half: no solution, HiGHS's status of that half
    lo2 = lo.copy()
    (c0, r0), (c1, r1) = H._independent_halves(A)
    lo2[r1[0]] = 1e6                         # a row of the second half that no x in [0, 1] meets
    bad = H.highs_solve_halves(c, A, lo2, np.maximum(hi, lo2), ub, time_limit=10.0)
    assert bad.x is None and bad.status == "Infeasible"
