"""Tests of the skin remesher (shellmesh_mdao.remesh) on the benchmark corpus and on
small hand-made meshes (improve_triangles)."""
import numpy as np
import pytest

from shellmesh_mdao.errors import MeshValidationError, SizeError
from shellmesh_mdao.load import load_surface
from shellmesh_mdao.mesh import ShellMesh
from shellmesh_mdao.core.locator import SurfaceLocator
from shellmesh_mdao.options import RemeshOptions
from shellmesh_mdao.remesh import improve_triangles, remesh_skin, remesh_statistics

#: the deviation passes for any deviating edge, as these tests were written for (remesh_skin's
#: default before it became the remesh stage's remesh_pass_fraction)
EVERY_PASS = RemeshOptions(remesh_pass_fraction=0.0)

# final quad size H per corpus geometry (the remesher works at 2 H) and a floor under the
# smallest triangle angle of the result (docs/remesh.md). That angle is one triangle's and
# moves with the last bits of the input: on the input and seven copies with coordinates
# multiplied by 1 + 1e-10 g (fourteen for bwb) it spans straight_wing 0.0 (one copy, with
# libigl's closest points too; 11.8 otherwise) to 25.8, swept_wing 20.2-23.4, bwb 18.2-21.0
# (6.6-21.7 with libigl's closest points, before 2026-11-24), cessna210 11.2-17.4 degrees.
# The floors hold for the input itself.
SIZES = {"straight_wing": 0.04, "swept_wing": 0.02, "bwb": 0.3, "cessna210": 0.25}
MIN_ANGLE = {"straight_wing": 11.0, "swept_wing": 19.0, "bwb": 15.0, "cessna210": 10.0}
# largest edge-midpoint distance to the input, in units of max_deviation (measured:
# 2.41 / 0.96 / 1.00 / 1.08; the straight wing's revolved tip caps are thinner than the
# local edge length and get cut across)
MAX_DEV = {"straight_wing": 3.0, "swept_wing": 1.25, "bwb": 1.25, "cessna210": 1.25}


def _angles(P, F):
    a, b, c = P[F[:, 0]], P[F[:, 1]], P[F[:, 2]]

    def ang(u, v):
        return np.degrees(np.arctan2(np.linalg.norm(np.cross(u, v), axis=1), (u * v).sum(1)))
    a0, a1 = ang(b - a, c - a), ang(c - b, a - b)
    return np.stack([a0, a1, 180.0 - a0 - a1], 1)


def _best_equidistant_dot(P, T, nin, x, n, diag):
    """Largest dot product of ``n`` with the normals of the input triangles nearest to ``x``
    (all of them within 1e-12 of the model size of the least distance: the sheets of a
    zero-thickness part are equally near)."""
    from shellmesh_mdao.core.bvh import closest_on_triangles
    A, B, C = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
    d = np.linalg.norm(closest_on_triangles(np.broadcast_to(x, A.shape), A, B, C) - x, axis=1)
    return float((nin[d <= d.min() + 1e-12 * diag] @ n).max())


@pytest.fixture(scope="module")
def corpus(geometry_dir, manifest):
    cache = {}

    def get(name):
        if name not in cache:
            skin, _ = load_surface(geometry_dir / manifest["geometries"][name]["file"])
            target = 2 * SIZES[name]
            rep = {}
            out = remesh_skin(skin, target, EVERY_PASS, report=rep)
            cache[name] = (skin, out, rep, target)
        return cache[name]
    return get


@pytest.mark.parametrize("name", ["straight_wing", "swept_wing", "bwb", "cessna210"])
def test_corpus_remesh_is_valid_and_on_size(corpus, name):
    skin, out, rep, target = corpus(name)
    # a closed, valid triangle mesh with as many bodies as the input
    assert out.n_quads == 0
    assert out.is_closed()
    assert out.check().ok, out.check().problems()
    assert out.n_bodies() == skin.n_bodies()
    # every vertex on the input surface
    loc = SurfaceLocator.from_mesh(skin)
    _, tri, d = loc.closest(out.points)
    assert d.max() <= 1e-9 * skin.diagonal
    # edge lengths: around the target where no refinement is asked for, around the local
    # (curvature / feature-size adapted) size everywhere; smallest angle as measured
    L = out.edge_lengths()
    assert 0.85 <= rep["edge_length_percentiles_unrefined"][50] <= 1.15
    assert rep["fraction_edges_unrefined"] > 0.3
    assert 0.85 <= rep["edge_to_local_size_percentiles"][50] <= 1.15
    assert L.max() <= 2.0 * target
    A = _angles(out.points, out.faces[:, :3])
    assert A.min() >= MIN_ANGLE[name]
    # no face turned against the input surface. The input normal is taken at the closest
    # point of the face centroid and at the face corners (which lie on the input): near a
    # thin trailing edge the centroid's closest point can be on the far skin, at a crease a
    # corner's closest triangle can be on the other side, so a face is flipped only if it
    # disagrees with both. Faces standing across a tip cap thinner than the local size
    # (|dot| small, straight_wing only) are counted, at most 0.1 % of the faces.
    # Where the input has two sheets at the same place (a zero-thickness fin or trailing
    # edge), several input triangles facing opposite ways are equally near: the face is
    # measured against the best of them.
    tris, _ = skin.triangles()
    Pn = skin.points
    nin = np.cross(Pn[tris[:, 1]] - Pn[tris[:, 0]], Pn[tris[:, 2]] - Pn[tris[:, 0]])
    nin /= np.linalg.norm(nin, axis=1, keepdims=True)
    fn = out.face_normals()
    corner = np.stack([np.einsum("ij,ij->i", fn, nin[tri[out.faces[:, k]]]) for k in range(3)], 1).max(1)
    _, ct, _ = loc.closest(out.face_centroids())
    centre = np.einsum("ij,ij->i", fn, nin[ct])
    best = np.maximum(corner, centre)
    for f in np.flatnonzero(best <= 0):
        pts = np.vstack([out.points[out.faces[f, :3]], out.face_centroids()[f]])
        best[f] = max(_best_equidistant_dot(Pn, tris, nin, x, fn[f], skin.diagonal) for x in pts)
    assert best.min() > -0.5
    assert (best <= 0).sum() <= 0.001 * out.n_faces
    if name != "straight_wing":
        assert best.min() > 0
    # deviation measured and reported; within max_deviation except at sub-min_edge details
    delta = RemeshOptions.remesh_deviation * target
    assert rep["max_deviation"] == pytest.approx(delta)
    assert rep["deviation_edge_midpoints"] <= MAX_DEV[name] * delta
    # feature lines are chains of mesh edges, their ends fixed
    assert len(out.feature_edges) > 0
    assert (out.feature_edge_ids == -1).all()
    assert out.topology().edge_ids(out.feature_edges).min() >= 0
    deg = np.bincount(out.feature_edges.ravel(), minlength=out.n_points)
    assert set(np.flatnonzero((deg > 0) & (deg != 2))) <= set(out.fixed_vertices.tolist())
    # components carried over (single-component corpus)
    assert (out.component == 0).all()


def test_trailing_edge_lines_of_straight_wing_are_kept(corpus, manifest):
    skin, out, _, target = corpus("straight_wing")
    P = out.points
    fe = out.feature_edges
    mid = 0.5 * (P[fe[:, 0]] + P[fe[:, 1]])
    wing = manifest["geometries"]["straight_wing"]["wings"][0]
    span = wing["tip_te"][1] - wing["root_te"][1]
    # both sharp spanwise lines of the section (x = -0.75 and x = 0.25) survive as
    # feature chains along the whole span
    for x in (wing["root_le"][0], wing["root_te"][0]):
        on = (np.abs(mid[:, 0] - x) < 1e-6) & (np.abs(mid[:, 2]) < 1e-6)
        length = np.linalg.norm(P[fe[on, 1]] - P[fe[on, 0]], axis=1).sum()
        assert length >= 0.95 * span


def test_upper_and_lower_skins_not_stitched(corpus):
    # 5 % thick wings with sharp trailing edges: no edge may run through the wing from the
    # upper to the lower skin -- ends on triangles facing opposite ways and the midpoint
    # farther than max_deviation from the surface (an edge wrapping a rounded leading edge
    # has opposite ends but stays on the surface). Only the straight wing's round tip caps,
    # thinner than the local edge length, get a few such edges, out at the tips.
    for name, allowed in (("swept_wing", 0), ("straight_wing", 30)):
        skin, out, rep, target = corpus(name)
        tris, _ = skin.triangles()
        Pn = skin.points
        nin = np.cross(Pn[tris[:, 1]] - Pn[tris[:, 0]], Pn[tris[:, 2]] - Pn[tris[:, 0]])
        nin /= np.linalg.norm(nin, axis=1, keepdims=True)
        loc = SurfaceLocator.from_mesh(skin)
        _, tri, _ = loc.closest(out.points)
        E = out.edges()
        opposite = np.einsum("ij,ij->i", nin[tri[E[:, 0]]], nin[tri[E[:, 1]]]) < -0.5
        _, _, dmid = loc.closest(0.5 * (out.points[E[:, 0]] + out.points[E[:, 1]]))
        stitched = opposite & (dmid > RemeshOptions.remesh_deviation * target)
        assert stitched.sum() <= allowed
        if stitched.any():
            span = np.abs(out.points[:, 1]).max()
            assert (np.abs(out.points[E[stitched]][:, :, 1]) > span - 0.06).all()
        s = remesh_statistics(out, skin, target)
        assert s["deviation_vertices"] <= 1e-9 * skin.diagonal


def _fin_strip(n_along: int = 20):
    """An open inverted-U strip along x: walls at y = +-0.25 from z = 0 to 0.3, a crest at
    z = 0.4 (a fin or fairing narrower than the edges that will cross it)."""
    prof = np.array([[0.25, 0.0], [0.25, 0.3], [0.15, 0.4], [-0.15, 0.4], [-0.25, 0.3], [-0.25, 0.0]])
    xs = np.linspace(-1.0, 1.0, n_along + 1)
    P = np.array([[x, y, z] for x in xs for y, z in prof])
    n = len(prof)
    F = []
    for i in range(n_along):
        for j in range(n - 1):
            a, b = i * n + j, i * n + j + 1
            F += [[a, b, b + n], [a, b + n, a + n]]
    return P, np.array(F)


def test_split_across_a_narrow_ridge_lands_on_its_crest():
    """An edge from one foot of a ridge to the other (a face standing across a dorsal fin
    narrower than itself): its midpoint is inside the ridge and closest to a wall at the
    edge's own end, so a split there would not split. ``_across_ridge`` takes the surface
    point on the line through the midpoint across the edge instead: the crest, for a folded
    pair (normals cancelling) as for an ordinary one; other edges keep their closest point."""
    from shellmesh_mdao.remesh.operations import _across_ridge
    from shellmesh_mdao.remesh.work import Context
    P, F = _fin_strip()
    ctx = Context(locator=SurfaceLocator(P, F))
    pa = np.array([[0.0, 0.25, 0.0], [0.0, 0.25, 0.0], [0.5, 0.25, 0.0]])
    pb = np.array([[0.0, -0.25, 0.0], [0.0, -0.25, 0.0], [0.5, 0.25, 0.3]])
    mid = 0.5 * (pa + pb)
    nrm = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2.0], [0.0, 2.0, 0.0]])   # folded pair, mean up, a wall
    fn0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    pts, tri, _ = ctx.loc.closest(mid)
    foot = np.minimum(np.linalg.norm(pts - pa, axis=1), np.linalg.norm(pts - pb, axis=1))
    assert np.allclose(foot[:2], 0.0)                                   # the plain closest point: a foot
    ok = np.ones(3, bool)
    out, otri, ook = _across_ridge(ctx, pa, pb, mid, nrm, fn0, np.zeros(3, np.int64), pts, np.asarray(tri), ok)
    assert np.allclose(out[:2], [[0.0, 0.0, 0.4], [0.0, 0.0, 0.4]])     # the crest
    assert ook.all() and (otri[:2] >= 0).all()
    assert np.allclose(out[2], pts[2])                                  # on the wall already: unchanged


def test_edge_across_the_cessna_dorsal_fin_is_split(geometry_dir, manifest):
    """cessna210 at target 0.789 (stress layout seed 77 at size 0.3945): the dorsal fin near
    x = 16.8 is 0.5 wide and its faces stood across it (an edge midpoint 0.24 = 3.1 x
    max_deviation off the input, one standing face); their nodes ended up to 0.24 off the
    input in the final mesh. Splitting such edges at the crest, also below the 20-degree guard
    when an edge is more than twice max_deviation off, leaves none."""
    from shellmesh_mdao import pipeline as pl
    from shellmesh_mdao.layout import layout_from_manifest
    lay = layout_from_manifest(manifest, "cessna210", ribs=10, spars=(0.15, 0.65))
    st = pl.run_pipeline(geometry_dir / manifest["geometries"]["cessna210"]["file"], lay, 0.394485,
                         progress=False, until="project").state
    target = 2.0 * 0.394485
    rep = {}
    remesh_skin(st.surface, target, EVERY_PASS, locator=st.locator, report=rep)      # max_deviation 0.1 target
    assert rep["n_standing_faces"] == 0
    # 1.01-1.44 x max_deviation on the input and six copies perturbed by 1e-10 (the edges
    # left over it are the guarantee's exceptions: short, or splitting them would make a
    # sliver); the faces standing across the fin gave 3.1
    assert rep["deviation_edge_midpoints"] <= 1.6 * 0.1 * target


def test_deviation_split_does_not_land_on_the_vertex_across(geometry_dir, manifest):
    """straight_wing at target 0.08 with its coordinates multiplied by 1 + 1e-10 g (seed 0): a
    deviation split across the round tip cap (thinner than the edge) had its midpoint projected
    onto the vertex across the edge, leaving two nodes 1e-11 apart (a triangle with a 0-degree
    angle; after the whole pipeline at size 0.04, an element of scaled Jacobian 0.18 and 7 skin
    nodes off the surface). A split whose projection carries the new point onto the vertex
    across the edge is not made: no edge is shorter than a twentieth of min_edge."""
    skin = load_surface(geometry_dir / manifest["geometries"]["straight_wing"]["file"])[0]
    P = skin.points * (1 + 1e-10 * np.random.default_rng(0).standard_normal(skin.points.shape))
    skin = ShellMesh(P, skin.faces, skin.component, list(skin.component_names))
    rep = {}
    out = remesh_skin(skin, 0.08, EVERY_PASS, report=rep)
    assert out.edge_lengths().min() > 0.05 * rep["min_edge"]
    assert _angles(out.points, out.faces[:, :3]).min() > 1.0
    assert out.check().ok, out.check().problems()


@pytest.fixture(scope="module")
def supersonic_skin(geometry_dir, manifest):
    return load_surface(geometry_dir / manifest["geometries"]["supersonic_wing_body"]["file"])[0]


@pytest.mark.parametrize("size, pinched", [(0.0723668, False), (0.075, True), (0.0752471, False), (0.07562, True),
                                            (0.076, True)])
def test_thin_tip_trailing_edge_corner_keeps_no_needle(supersonic_skin, size, pinched):
    """supersonic_wing_body: the sharp trailing edge ends at the tip in a half-round cap whose
    radius falls to 0 there, thinner than max_deviation. The corner was left with three
    neighbours, the trailing edge's next node and one node on each side of the flat cap, and a
    needle between the two (smallest angle 0.0-1.9 degrees at these sizes; at 0.076 the pipeline
    then missed the scaled-Jacobian guarantee) that no edge operation could remove. Collapsing
    several of the corner's neighbours into it at once leaves no triangle below 12 degrees
    within four sizes of the tip's trailing-edge corners, on a closed manifold skin. At 0.0724
    and 0.0752 the corner is not left pinched (the turning bound asks for no less than min_edge
    beside the trailing-edge wedge); at 0.075, 0.0756 and 0.076 it is and the contraction mends
    it. (Not at every size: of 21 sizes from 0.070 to 0.080, two leave a triangle below 12 degrees
    there, the smallest 7.7; 0.074 is one of them.)"""
    rep = {}
    out = remesh_skin(supersonic_skin, 2 * size, report=rep)
    if pinched:
        assert rep["n_pinched_contracted"] > 0
    F = out.faces[:, :3]
    corners = np.array([[-4.79848623, 3.0, 0.0], [-4.79848623, -3.0, 0.0]])
    centre = out.points[F].mean(1)
    near = np.linalg.norm(centre[:, None, :] - corners[None], axis=2).min(1) < 4 * size
    assert near.sum() > 10
    assert _angles(out.points, F)[near].min() > 12.0
    chk = out.check()
    assert chk.ok, chk.problems()
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    assert (np.unique(E, axis=0, return_counts=True)[1] == 2).all()


def test_remesh_is_deterministic(geometry_dir, manifest):
    skin, _ = load_surface(geometry_dir / manifest["geometries"]["straight_wing"]["file"])
    a = remesh_skin(skin, 0.08, EVERY_PASS)
    b = remesh_skin(skin, 0.08, EVERY_PASS)
    assert np.array_equal(a.points, b.points)
    assert np.array_equal(a.faces, b.faces)
    assert np.array_equal(a.feature_edges, b.feature_edges)
    assert np.array_equal(a.fixed_vertices, b.fixed_vertices)
    assert np.array_equal(a.component, b.component)


def test_deviation_passes_run_only_above_their_fraction(geometry_dir, manifest):
    # cessna210 at 0.5: 89 of about 16,500 edges (0.5 %) deviate more than max_deviation after
    # the sweeps. With remesh_pass_fraction 0.01 no pass runs (the same mesh as without
    # passes, bit for bit), with 0.005 they do (another mesh). The deviation splits keep the
    # bound either way, but for the edges they may not split (a new angle below 20 degrees):
    # 8 of them without the passes, up to 1.91 max_deviation; none with them. Without the
    # passes that figure is one edge's and moves with the last bits of the input: on the input
    # and seven copies with coordinates multiplied by 1 + 1e-10 g it spans 1.32-1.91 (1.32-2.46
    # before the remesh's turning bound, 1.34 on the input itself)
    skin, _ = load_surface(geometry_dir / manifest["geometries"]["cessna210"]["file"])
    target = 0.5
    delta = RemeshOptions.remesh_deviation * target
    r0, r1, r2 = {}, {}, {}
    none = remesh_skin(skin, target, EVERY_PASS, deviation_passes=0, report=r0)
    above = remesh_skin(skin, target, RemeshOptions(remesh_pass_fraction=0.01), report=r1)
    ran = remesh_skin(skin, target, RemeshOptions(remesh_pass_fraction=0.005), report=r2)
    assert np.array_equal(none.points, above.points) and np.array_equal(none.faces, above.faces)
    assert ran.n_faces != none.n_faces or not np.array_equal(ran.points, none.points)
    assert r2["deviation_edge_midpoints"] <= MAX_DEV["cessna210"] * delta
    assert r0["deviation_edge_midpoints"] <= 2.5 * delta and r0["n_edges_over_deviation"] <= 20


def test_input_resolution_does_not_set_output_resolution(corpus):
    skin, out, _, target = corpus("straight_wing")
    import trimesh
    v, f = trimesh.remesh.subdivide(skin.points, skin.faces[:, :3])
    fine = ShellMesh(v, f)
    assert fine.n_faces == 4 * skin.n_faces
    out2 = remesh_skin(fine, target, EVERY_PASS)
    assert abs(out2.n_faces - out.n_faces) <= 0.15 * out.n_faces
    assert np.median(out2.edge_lengths()) == pytest.approx(np.median(out.edge_lengths()), rel=0.1)


def test_components_follow_the_input(corpus):
    skin, _, _, target = corpus("straight_wing")
    comp = (skin.face_centroids()[:, 1] > 0).astype(np.int32)
    two = ShellMesh(skin.points, skin.faces, comp, ["left", "right"])
    out = remesh_skin(two, target, EVERY_PASS)
    assert out.component_names[:2] == ["left", "right"]
    c = out.face_centroids()
    # the border y = 0 is kept as a feature line, so every face is on one side
    assert (out.component[c[:, 1] > 1e-9] == 1).all()
    assert (out.component[c[:, 1] < -1e-9] == 0).all()
    assert out.is_closed() and out.check().ok


def test_bad_sizes_and_bad_input_raise(corpus):
    skin, _, _, _ = corpus("straight_wing")
    for bad in (0.0, -1.0, float("nan"), float("inf"), 1e6):
        with pytest.raises(SizeError):
            remesh_skin(skin, bad)
    with pytest.raises(SizeError):
        remesh_skin(skin, 1e-6)          # far too many triangles
    # three triangles on one edge
    P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1.0]])
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    with pytest.raises(MeshValidationError, match="non-manifold"):
        remesh_skin(ShellMesh(P, F), 0.5)


# ------------------------------------------------------------------ improve_triangles
def _grid(k=8, z=lambda x, y: 0.0 * x):
    x, y = np.meshgrid(np.linspace(0, 1, k), np.linspace(0, 1, k), indexing="ij")
    P = np.c_[x.ravel(), y.ravel(), z(x.ravel(), y.ravel())]
    idx = np.arange(k * k).reshape(k, k)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.vstack([np.c_[a, b, c], np.c_[a, c, d]])
    inner = (x.ravel() > 0) & (x.ravel() < 1) & (y.ravel() > 0) & (y.ravel() < 1)
    return P, F, inner


def test_improve_triangles_raises_the_worst_angle_without_inversion():
    def bump(x, y):
        return 0.1 * np.sin(np.pi * x) * np.sin(np.pi * y)
    P, F, inner = _grid(9, bump)
    loc = SurfaceLocator(P, F)
    rng = np.random.default_rng(3)
    Q = P.copy()
    Q[inner, :2] += rng.uniform(-0.05, 0.05, (inner.sum(), 2))
    Q[inner] = loc.closest(Q[inner])[0]
    m = ShellMesh(Q, F)
    before = _angles(m.points, m.faces[:, :3]).min()
    out = improve_triangles(m, loc, target_edge=1 / 8, iterations=4, max_dihedral=10.0)
    after = _angles(out.points, out.faces[:, :3]).min()
    assert before < 10.0
    assert after > before + 10.0
    # every face still faces up, every vertex on the surface, boundary untouched
    assert (out.face_normals()[:, 2] > 0).all()
    assert loc.closest(out.points)[2].max() < 1e-12
    assert np.array_equal(out.points[~inner], Q[~inner])
    assert out.is_closed() is False and out.check().ok


def test_improve_triangles_keeps_feature_edges_and_fixed_vertices():
    # two flat slivers on the long diagonal 0-1 of a rhombus: flipping it to 2-3 would lift
    # the smallest angle from 16.7 to 73.3 degrees, but 0-1 is a member chain
    P = np.array([[0, 0, 0], [2, 0, 0], [1, 0.3, 0], [1, -0.3, 0.0]])
    F = np.array([[0, 1, 2], [1, 0, 3]])
    loc = SurfaceLocator(P, F)
    m = ShellMesh(P, F, feature_edges=[[0, 1]], feature_edge_ids=[0])
    out = improve_triangles(m, loc, target_edge=1.0)
    assert out.topology().edge_ids(np.array([[0, 1]]))[0] >= 0
    assert np.array_equal(out.feature_edges, m.feature_edges)
    assert np.array_equal(out.feature_edge_ids, m.feature_edge_ids)
    # without the constraint the flip happens and the worst angle goes up
    free = improve_triangles(ShellMesh(P, F), loc, target_edge=1.0)
    assert free.topology().edge_ids(np.array([[0, 1]]))[0] == -1
    assert free.topology().edge_ids(np.array([[2, 3]]))[0] >= 0
    assert _angles(free.points, free.faces[:, :3]).min() > 30.0
    # ... but not across a fold: lift vertex 3 so the pair is 30 degrees from coplanar
    P3 = P.copy()
    P3[3, 2] = 0.3 * np.tan(np.radians(30.0))
    bent = improve_triangles(ShellMesh(P3, F), SurfaceLocator(P3, F), target_edge=1.0)
    assert bent.topology().edge_ids(np.array([[0, 1]]))[0] >= 0
    # fixed vertices never move
    P2, F2, inner = _grid(7)
    loc2 = SurfaceLocator(P2, F2)
    Q = P2.copy()
    Q[inner, :2] += np.random.default_rng(0).uniform(-0.04, 0.04, (inner.sum(), 2))
    fixed = np.flatnonzero(inner)[::3]
    out2 = improve_triangles(ShellMesh(Q, F2, fixed_vertices=fixed), loc2, target_edge=1 / 6)
    assert np.array_equal(out2.points[fixed], Q[fixed])
    assert not np.array_equal(out2.points[inner], Q[inner])


def test_improve_triangles_leaves_quads_alone():
    P, F, inner = _grid(5)
    Q = P.copy()
    Q[inner, :2] += np.random.default_rng(1).uniform(-0.05, 0.05, (inner.sum(), 2))
    quad = np.array([[0, 5, 6, 1]])
    faces = np.vstack([np.c_[F[2:], np.full(len(F) - 2, -1)], quad])   # drop the 2 tris of that cell
    m = ShellMesh(Q, faces)
    out = improve_triangles(m, SurfaceLocator(P, F), target_edge=0.25)
    assert np.array_equal(out.faces[-1], quad[0])
    assert np.array_equal(out.points[quad[0]], Q[quad[0]])
    assert np.array_equal(out.component, m.component)


@pytest.mark.parametrize("seed", range(5))
def test_collapse_apply_gives_the_numpy_update(seed):
    """A batch of collapses applied in one compiled pass (kernels.collapse_apply) against the
    numpy update it replaced: remap, face filter, set_features of the remapped feature edges
    (with duplicates, reversed rows and chain ids from -1), then the renumbering without the
    removed vertices."""
    from scipy.spatial import Delaunay

    from shellmesh_mdao.core.kernels import edge_table
    from shellmesh_mdao.remesh.kernels import collapse_apply, edge_neighbours
    from shellmesh_mdao.remesh.work import WorkMesh
    rng = np.random.default_rng(60 + seed)
    n = int(rng.integers(30, 300))
    F = Delaunay(rng.random((n, 2))).simplices.astype(np.int64)
    _, _, _, _, E, _ = edge_table(F, n)
    nptr, nbr = edge_neighbours(E, n)
    # independent collapses: edges whose closed 1-rings do not meet
    used = np.zeros(n, bool)
    a, b = [], []
    for e in rng.permutation(len(E)):
        u, v = E[e]
        ring = np.concatenate([[u, v], nbr[nptr[u]:nptr[u + 1]], nbr[nptr[v]:nptr[v + 1]]])
        if not used[ring].any():
            used[ring] = True
            a.append(u) if rng.random() < 0.5 else a.append(v)
            b.append(v if a[-1] == u else u)
    a, b = np.array(a, np.int64), np.array(b, np.int64)
    # feature edges as they come: repeated, reversed and degenerate rows, and for some
    # collapses both (a, x) and (b, x) for a common neighbour x, which the collapse makes one
    # pair (the lower chain id stays)
    fe = [E[rng.choice(len(E), 40)], E[rng.choice(len(E), 10)][:, ::-1], np.array([[3, 3]])]
    for u, v in zip(a[:8], b[:8]):
        x = np.intersect1d(nbr[nptr[u]:nptr[u + 1]], nbr[nptr[v]:nptr[v + 1]])[0]
        fe.append(np.array([[u, x], [x, v], [u, v]]))
    fe = np.vstack(fe)
    ch = rng.integers(-1, 4, len(fe))

    def work():
        return WorkMesh(rng.random((n, 3)), F.copy(), rng.integers(0, 3, len(F)), np.zeros(n, np.int64), np.zeros(n),
                     np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64), fe, ch, np.ones(n))
    W = work()
    remap = np.arange(n)
    remap[a] = b
    F2 = remap[W.F]
    keepf = (F2[:, 0] != F2[:, 1]) & (F2[:, 1] != F2[:, 2]) & (F2[:, 0] != F2[:, 2])
    patch = W.fpatch
    W.F, W.fpatch = F2[keepf], W.fpatch[keepf]
    W.set_features(remap[fe], ch)
    keepv = np.ones(n, bool)
    keepv[a] = False
    o2n = np.cumsum(keepv) - 1                          # WorkMesh.subset_vertices before the kernel
    W.F = o2n[W.F]
    ok = keepv[W.fe[:, 0]] & keepv[W.fe[:, 1]]
    W.set_features(o2n[W.fe[ok]], W.fe_chain[ok])
    W0 = work()
    F3, p3, fe3, ch3, keep3 = collapse_apply(W0.F, patch, fe, ch, a, b, n)
    # the collapses made pairs meet, with another chain id each time at least once
    assert len(np.unique(np.sort(remap[fe], axis=1), axis=0)) < len(np.unique(np.sort(fe, axis=1), axis=0))
    assert len(a) and keepf.sum() < len(F)
    assert np.array_equal(F3, W.F) and np.array_equal(p3, W.fpatch) and np.array_equal(keep3, keepv)
    assert np.array_equal(fe3, W.fe) and np.array_equal(ch3, W.fe_chain)
    for aa, bb in (([a[0], a[0]], [b[0], b[0]]), ([a[0], a[1]], [a[1], b[1]])):
        with pytest.raises(ValueError, match="at most once and none into a removed one"):
            collapse_apply(W0.F, patch, fe, ch, aa, bb, n)


def test_midpoint_distances_reuse_only_unchanged_midpoints():
    """The remesh's last steps remember edge-midpoint distances by the midpoint's coordinates:
    after some vertices move and edges change, the answers are the same bits as asking the
    locator for every edge, and only the new midpoints are asked for."""
    from shellmesh_mdao.remesh.driver import _MidpointDistances

    rng = np.random.default_rng(3)
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 40, endpoint=False), np.linspace(0.2, np.pi - 0.2, 20))
    S = np.stack([np.sin(v) * np.cos(u), np.sin(v) * np.sin(u), np.cos(v)], -1).reshape(-1, 3)
    idx = np.arange(800).reshape(20, 40)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
    T = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    loc = SurfaceLocator(S, T)
    asked = []
    real = loc.closest

    def counting(q, hint=None):
        asked.append(len(q))
        return real(q, hint=hint)
    loc.closest = counting
    P = S * 1.01 + 0.003 * rng.standard_normal(S.shape)
    E = np.unique(np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1), axis=0)
    vtri = np.full(len(P), -1, np.int64)
    mids = _MidpointDistances(loc)
    d0 = mids(P, E, vtri)
    assert asked == [len(E)]
    assert np.array_equal(d0, real(0.5 * (P[E[:, 0]] + P[E[:, 1]]))[2])
    # move five vertices, drop some edges and add others
    P2 = P.copy()
    moved = np.array([5, 77, 300, 512, 799])
    P2[moved] += 0.01
    E2 = np.concatenate([E[7:], [[0, 400], [10, 700]]])
    d2 = mids(P2, E2, vtri)
    assert np.array_equal(d2, real(0.5 * (P2[E2[:, 0]] + P2[E2[:, 1]]))[2])
    new = int(np.isin(E2, moved).any(1).sum()) + 2
    assert asked == [len(E), new]
    # keys that collide everywhere: rows are compared in full, so nothing wrong is reused
    mids_c = _MidpointDistances(loc)
    mids_c._keys = lambda X: np.zeros(len(X), np.uint64)
    mids_c(P, E, vtri)
    assert np.array_equal(mids_c(P2, E2, vtri), d2)


# ----------------------------------------------------------------------------- remesh cache
def test_run_pipeline_remeshes_once_per_surface_size_and_options():
    """A Python loop over layouts (a DOE) remeshes the skin once: the second run on the same
    surface, size and options takes the skin from the cache, and it is the skin a run without the
    cache makes, bit for bit; another size or option misses; the cache keeps its last skins only."""
    from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
    from shellmesh_mdao.layout import load_layout
    from shellmesh_mdao.pipeline import run_pipeline
    from shellmesh_mdao.remesh import RemeshCache

    cache = RemeshCache(2)
    lay = load_layout(naca_wing_layout())
    moved = lay.with_parameters(spar_chord={w.name: [0.2, 0.6] for w in lay.wings})
    first = run_pipeline(naca_wing(), lay, 0.2, until="remesh", progress=False, remesh_cache=cache)
    assert cache.stats["misses"] == 1 and "remesh_cache" not in first.report
    second = run_pipeline(naca_wing(), moved, 0.2, until="imprint", progress=False, remesh_cache=cache)
    assert cache.stats["hits"] == 1 and second.report["remesh_cache"]["hit"]
    fresh = run_pipeline(naca_wing(), moved, 0.2, until="imprint", progress=False, remesh_cache=False)
    for a in ("points", "faces", "component", "feature_edges"):
        assert np.array_equal(getattr(second.mesh, a), getattr(fresh.mesh, a)), a
    skin = cache.skins()[0].mesh
    assert not skin.points.flags.writeable and not skin.faces.flags.writeable
    run_pipeline(naca_wing(), lay, 0.2, until="remesh", progress=False, remesh_cache=cache,
                 options={"remesh_deviation": 0.2})
    run_pipeline(naca_wing(), lay, 0.25, until="remesh", progress=False, remesh_cache=cache)
    assert cache.stats["misses"] == 3 and len(cache) == 2
    with pytest.raises(ValueError, match="at least 1"):
        RemeshCache(0)


@pytest.mark.parametrize("target", [0.2, 0.4])
def test_leading_edge_nose_is_resolved_not_cut_across(target):
    """The bundled wing (NACA 2412, leading-edge radius r = 16-32 mm) at target edges 0.2 and 0.4
    (sizes 0.1 and 0.2): the chord bound (deviation 0.1 target) lets an edge cut across a nose of
    radius below 2 max_deviation, which deviates by at most r from any chord. Before the turning
    bound 11 faces stood more than 90 degrees from the input normal across the nose at both
    targets, and the mid-span nose (within r / 2 of the leading edge) held 79 and 2 edges; the
    remesh now follows the nose, with edges of about 1.7 r there."""
    from shellmesh_mdao.geometry import naca_wing
    skin = naca_wing()
    out = remesh_skin(skin, target)
    loc = SurfaceLocator.from_mesh(skin)
    tris, _ = skin.triangles()
    P = skin.points
    nin = np.cross(P[tris[:, 1]] - P[tris[:, 0]], P[tris[:, 2]] - P[tris[:, 0]])
    nin /= np.linalg.norm(nin, axis=1, keepdims=True)
    _, ct, _ = loc.closest(out.face_centroids())
    assert (np.einsum("ij,ij->i", out.face_normals(), nin[ct]) > 0).all()
    E = out.edges()
    mid = 0.5 * (out.points[E[:, 0]] + out.points[E[:, 1]])
    y = mid[:, 1]
    r = 1.1019 * 0.12 ** 2 * (2.0 - y / 6.0)                  # nose radius of the local chord
    nose = (mid[:, 0] - y * np.tan(np.radians(10.0)) < 0.5 * r) & (y > 1.5) & (y < 4.5)
    assert nose.sum() >= 100
    L = np.linalg.norm(out.points[E[:, 0]] - out.points[E[:, 1]], axis=1)
    assert np.median(L[nose] / r[nose]) < 2.0


def test_thin_fin_nose_keeps_the_remesh_bounded_and_valid():
    """Random family seed 4 (a fin whose leading edge narrows to a 15 mm radius at its tip; the
    turning bound asks for edges of 19 mm there, target 0.6): the projections of split midpoints
    across the nose met at input vertices of its crest, coincident nodes fed more splits (16k ->
    376k triangles in two sweeps, then > 10 min and 9 GB), and nodes projected onto the crest
    left faces of three nodes in a line. No split lands on a node already there, and degenerate
    faces are flipped or, two flat against each other, collapsed: the skin the sizing asks for
    (about 12,500 triangles) on a valid mesh."""
    from shellmesh_mdao.benchmarks.random_family import draw_case
    from shellmesh_mdao.geometry.aircraft import aircraft_surface
    case = draw_case(4)
    rep = {}
    out = remesh_skin(aircraft_surface(case["params"]), 2 * case["size"], iterations=2, deviation_passes=0,
                      report=rep)
    assert out.n_faces < 25_000
    chk = out.check()
    assert chk.ok, chk.problems()
    assert out.edge_lengths().min() > 1e-6 * out.diagonal
    assert rep["n_degenerate_flipped"] > 0
