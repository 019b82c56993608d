"""SurfaceLocator exactness (against brute force) and projection of layouts onto the corpus."""
import json
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh

from shellmesh_mdao.errors import ProjectionError
from shellmesh_mdao.layout import layout_from_manifest, load_layout
from shellmesh_mdao.mesh import ShellMesh, norm_rows
from shellmesh_mdao.core.locator import SurfaceLocator, closest_point_on_triangles, ray_triangle_intersect
from shellmesh_mdao.project import project_layout, project_polyline, project_wing_stations

DOC = Path(__file__).resolve().parents[1] / "docs" / "layout.md"
GEOMS = ["cessna210", "swept_wing", "straight_wing", "bwb"]


# ----------------------------------------------------------------------------- brute force
def brute_closest(P, T, q):
    """Exact closest distance by checking every triangle (float64)."""
    a, b, c = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
    out = np.empty(len(q))
    for i, x in enumerate(q):
        p = closest_point_on_triangles(np.broadcast_to(x, a.shape), a, b, c)
        out[i] = np.sqrt(((p - x) ** 2).sum(1).min())
    return out


def brute_ray(P, T, o, d):
    a, b, c = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
    dist = np.full(len(o), np.inf)
    tri = np.full(len(o), -1)
    for i in range(len(o)):
        dd = d[i] / np.linalg.norm(d[i])
        t, u, v, det = ray_triangle_intersect(np.broadcast_to(o[i], a.shape), np.broadcast_to(dd, a.shape), a, b, c)
        with np.errstate(invalid="ignore"):
            ok = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        if ok.any():
            j = np.flatnonzero(ok)[np.argmin(t[ok])]
            dist[i], tri[i] = t[j], j
    return dist, tri


def on_triangle_dist(P, T, tri, x):
    t = T[tri]
    p = closest_point_on_triangles(x, P[t[:, 0]], P[t[:, 1]], P[t[:, 2]])
    return np.linalg.norm(p - x, axis=1)


def sphere(sub=2):
    m = trimesh.creation.icosphere(subdivisions=sub)
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)


def soup(n=300, seed=1):
    """Random triangles of very different sizes, some slivers and one degenerate."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(-1, 1, (n, 3))
    s = 10 ** rng.uniform(-3, 0, n)
    P = (c[:, None, :] + s[:, None, None] * rng.normal(size=(n, 3, 3))).reshape(-1, 3)
    P[5] = P[4] + 1e-9 * (P[3] - P[4])     # a sliver
    P[8] = P[7] = P[6]                      # a degenerate triangle
    return P, np.arange(3 * n, dtype=np.int64).reshape(n, 3)


# ----------------------------------------------------------------------------- locator: exactness
@pytest.mark.parametrize("make", [sphere, soup])
def test_closest_matches_brute_force(make):
    P, T = make()
    loc = SurfaceLocator(P, T)
    rng = np.random.default_rng(7)
    q = np.vstack([rng.uniform(-2, 2, (150, 3)),            # around
                   P[rng.integers(0, len(P), 20)],           # on vertices
                   0.5 * (P[T[:20, 0]] + P[T[:20, 1]]),      # on edges
                   rng.uniform(-50, 50, (10, 3))])           # far away
    cp, tri, dist = loc.closest(q)
    ref = brute_closest(P, T, q)
    diag = loc.diagonal
    assert np.abs(dist - ref).max() <= 1e-12 * diag
    np.testing.assert_allclose(np.linalg.norm(cp - q, axis=1), dist, rtol=0, atol=1e-14 * diag)
    # the returned point lies on the returned triangle
    assert on_triangle_dist(P, T, tri, cp).max() <= 1e-13 * diag


@pytest.mark.parametrize("make", [sphere, soup])
def test_raycast_matches_brute_force(make):
    P, T = make()
    loc = SurfaceLocator(P, T)
    rng = np.random.default_rng(3)
    o = rng.uniform(-1.5, 1.5, (400, 3))
    d = rng.normal(size=(400, 3))
    hp, tri, dist = loc.raycast(o, d)
    ref_d, ref_t = brute_ray(P, T, o, d)
    assert np.array_equal(tri >= 0, ref_t >= 0)
    h = tri >= 0
    assert h.sum() > 50
    diag = loc.diagonal
    assert np.abs(dist[h] - ref_d[h]).max() <= 1e-9 * diag
    # the hit point is on the hit triangle (float64) and on the ray, ahead of the origin
    assert on_triangle_dist(P, T, tri[h], hp[h]).max() <= 1e-12 * diag
    dn = d[h] / np.linalg.norm(d[h], axis=1)[:, None]
    off = hp[h] - o[h]
    assert np.linalg.norm(off - (off * dn).sum(1)[:, None] * dn, axis=1).max() <= 1e-12 * diag
    assert ((off * dn).sum(1) > 0).all()
    np.testing.assert_allclose(np.linalg.norm(off, axis=1), dist[h], rtol=1e-14, atol=0)
    assert np.all(np.isinf(dist[~h])) and np.all(np.isnan(hp[~h]))


def test_raycast_through_edges_and_vertices_hits_exactly():
    """Rays aimed exactly at shared edges and vertices of a closed sphere: embree's float32
    triangle may be a neighbour, the float64 refinement must still return a point on a
    triangle it really hits."""
    P, T = sphere(2)
    loc = SurfaceLocator(P, T)
    targets = np.vstack([0.5 * (P[T[:, 0]] + P[T[:, 1]]), P[::3]])
    o = np.zeros_like(targets)                       # from the centre, inside
    hp, tri, dist = loc.raycast(o, targets)
    assert (tri >= 0).all()
    np.testing.assert_allclose(hp, targets, atol=1e-12)
    assert on_triangle_dist(P, T, tri, hp).max() <= 1e-12
    # ties are broken by a fixed rule: a ray through a vertex reports the lowest-index
    # triangle around it, whatever embree picked
    nv = len(P[::3])
    vid = np.arange(len(P))[::3]
    lowest = np.array([np.flatnonzero((T == v).any(1)).min() for v in vid])
    assert np.array_equal(tri[-nv:], lowest)
    # and from outside, aimed inward at the same points
    o2 = 3.0 * targets
    hp2, tri2, _ = loc.raycast(o2, -targets)
    assert (tri2 >= 0).all()
    np.testing.assert_allclose(hp2, targets, atol=1e-12)
    # rays passing 1e-8..1e-10 beside an edge: below float32 resolution, so embree may name
    # the neighbour triangle; the returned point must still lie on the returned triangle
    mid = 0.5 * (P[T[:, 0]] + P[T[:, 1]])
    side = P[T].mean(1) - mid
    side /= np.linalg.norm(side, axis=1)[:, None]
    for eps in (1e-8, 1e-10):
        tg = np.vstack([mid + eps * side, mid - eps * side])
        hp, tri, dist = loc.raycast(np.zeros_like(tg), tg)
        assert (tri >= 0).all()
        assert on_triangle_dist(P, T, tri, hp).max() <= 1e-14
        np.testing.assert_allclose(hp, tg / np.linalg.norm(tg, axis=1)[:, None] * dist[:, None], atol=1e-15)
        assert np.abs(hp - tg).max() < 1e-3


def test_large_offset_and_scale_do_not_lose_precision():
    P, T = sphere(2)
    rng = np.random.default_rng(0)
    o = rng.uniform(-0.5, 0.5, (200, 3))
    d = rng.normal(size=(200, 3))
    base_loc = SurfaceLocator(P, T)
    h0, t0, d0 = base_loc.raycast(o, d)
    c0, ct0, cd0 = base_loc.closest(o)
    for s, shift in ((1e-3, 0.0), (1e3, 0.0), (1.0, 1e5), (1e-3, 10.0)):
        loc = SurfaceLocator(P * s + shift, T)
        h, t, dd = loc.raycast(o * s + shift, d)
        assert np.array_equal(t, t0)
        # float64 error of the shifted coordinates is ~1e-16 * shift
        tol = 1e-12 * s + 4e-16 * shift
        assert np.abs(h - (h0 * s + shift)).max() <= tol
        c, ct, cd = loc.closest(o * s + shift)
        assert np.abs(cd - cd0 * s).max() <= tol


def test_deterministic_and_from_mesh_with_quads():
    P, T = sphere(1)
    loc1, loc2 = SurfaceLocator(P, T), SurfaceLocator(P.copy(), T.copy())
    rng = np.random.default_rng(5)
    q = rng.uniform(-2, 2, (500, 3))
    d = rng.normal(size=(500, 3))
    for a, b in zip(loc1.closest(q) + loc1.raycast(q, d), loc2.closest(q) + loc2.raycast(q, d)):
        assert np.array_equal(a, b, equal_nan=True)
    # a unit cube of 6 quads: closest point of (2, 0.5, 0.5) is on the x=1 face
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    quads = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
    loc = SurfaceLocator.from_mesh(ShellMesh(pts, quads))
    assert len(loc.triangles) == 12
    cp, tri, dist = loc.closest([[2.0, 0.5, 0.4]])
    np.testing.assert_allclose(cp, [[1.0, 0.5, 0.4]], atol=1e-15)
    assert loc.face_of_triangle[tri[0]] == 3 and dist[0] == pytest.approx(1.0)
    hp, tri, dist = loc.raycast([[0.5, 0.5, 0.5]], [[0.0, 0.0, -1.0]])
    assert loc.face_of_triangle[tri[0]] == 0 and dist[0] == pytest.approx(0.5, abs=1e-15)


def test_bad_queries_raise():
    P, T = sphere(1)
    loc = SurfaceLocator(P, T)
    with pytest.raises(ProjectionError, match="zero length"):
        loc.raycast([[0, 0, 0]], [[0, 0, 0]])
    with pytest.raises(ProjectionError, match="NaN"):
        loc.closest([[np.nan, 0, 0]])
    with pytest.raises(ProjectionError, match="no triangles"):
        SurfaceLocator(P, np.zeros((0, 3), int))


def test_first_hit_is_the_inner_body():
    """Seeds inside a small 'wing' box enclosed by a big 'fuselage' box: the wing is hit."""
    small = trimesh.creation.box(extents=[2.0, 6.0, 0.2])
    big = trimesh.creation.box(extents=[10.0, 10.0, 10.0])
    P = np.vstack([small.vertices, big.vertices])
    T = np.vstack([small.faces, big.faces + len(small.vertices)])
    loc = SurfaceLocator(P, T)
    seeds = np.array([[x, 1.0, 0.0] for x in np.linspace(-0.9, 0.9, 5)])
    (up, ut), (lo, lt) = project_wing_stations(loc, [0, 0, 1], seeds, name="w/rib_0")
    np.testing.assert_allclose(up[:, 2], 0.1, atol=1e-14)
    np.testing.assert_allclose(lo[:, 2], -0.1, atol=1e-14)
    assert (ut < 12).all() and (lt < 12).all()
    # from outside the wing box the first hit along +up is the fuselage and along -up the wing
    with pytest.raises(ProjectionError, match=r"member 'w/rib_0': rays miss the skin upward"):
        project_wing_stations(SurfaceLocator(small.vertices, small.faces), [0, 0, 1], [[0, 0, 0], [0, 0, 5.0]],
                              name="w/rib_0")


# ----------------------------------------------------------------------------- corpus
@pytest.fixture(scope="module")
def locators(geometry_dir, manifest):
    out = {}
    for g in GEOMS:
        m = trimesh.load(geometry_dir / manifest["geometries"][g]["file"], process=False)
        out[g] = SurfaceLocator(np.asarray(m.vertices), np.asarray(m.faces))
    return out


@pytest.mark.parametrize("g", GEOMS)
def test_manifest_corners_lie_on_the_skin(g, manifest, locators):
    loc = locators[g]
    for w in manifest["geometries"][g]["wings"]:
        corners = np.array([w["root_le"], w["root_te"], w["tip_le"], w["tip_te"]], float)
        chord = np.linalg.norm(corners[1] - corners[0])
        cp, tri, dist = loc.closest(corners)
        assert dist.max() < 2e-3 * chord, (g, w["name"], dist / chord)


@pytest.mark.parametrize("g", GEOMS)
def test_every_station_projects_above_and_below(g, manifest, locators):
    loc = locators[g]
    lay = layout_from_manifest(manifest, g, ribs=10, spars=[0.15, 0.65])
    proj = project_layout(loc, lay, n_seeds=7)
    specs = {m.name: m for m in lay.members()}
    assert list(proj) == [m.name for m in lay.members()]
    assert len(proj) == 12 * len(manifest["geometries"][g]["wings"])
    diag = loc.diagonal
    for name, p in proj.items():
        up = specs[name].up
        assert ((p.upper - p.seeds) @ up > 0).all(), name
        assert ((p.lower - p.seeds) @ up < 0).all(), name
        # hits lie on the input surface
        _, _, d_up = loc.closest(p.upper)
        _, _, d_lo = loc.closest(p.lower)
        assert max(d_up.max(), d_lo.max()) <= 1e-9 * diag, name
        assert on_triangle_dist(loc.points, loc.triangles, p.upper_tri, p.upper).max() <= 1e-9 * diag
        # and in the member plane (the rays run along up, which the plane contains)
        m = specs[name]
        assert np.abs((p.upper - m.plane_point) @ m.plane_normal).max() <= 1e-9 * diag


def test_cessna_root_rays_hit_the_wing_not_the_fuselage(manifest, locators):
    loc = locators["cessna210"]
    lay = layout_from_manifest(manifest, "cessna210", ribs=10, spars=[0.15, 0.65])
    proj = project_layout(loc, lay, n_seeds=9)
    for wing in ("right_wing", "left_wing"):
        w = lay.wing(wing)
        chord = np.linalg.norm(np.subtract(w.root_te, w.root_le))
        for name in (f"{wing}/rib_0", f"{wing}/spar_0", f"{wing}/spar_1"):
            p = proj[name]
            up = np.array([0, 0, 1.0])
            h_up = (p.upper - p.seeds) @ up
            h_lo = (p.seeds - p.lower) @ up
            # within the wing's thickness (15 % section): the fuselage is metres away
            assert (h_up < 0.12 * chord).all() and (h_lo < 0.12 * chord).all(), (name, h_up, h_lo)
            assert ((h_up + h_lo) > 0.01 * chord).all()


def test_project_polyline_and_doc_example_on_cessna(locators):
    loc = locators["cessna210"]
    ex = json.loads(re.findall(r"```json\n(.*?)```", DOC.read_text(), flags=re.S)[0])
    lay = load_layout(ex)
    proj = project_layout(loc, lay)
    b = proj["bulkhead_1"]
    # upper curve drawn above the cabin, projected down onto its roof; lower projected up onto the belly
    assert (b.upper[:, 2] < 8.0).all() and (b.lower[:, 2] > -3.0).all() and (b.upper[:, 2] > b.lower[:, 2]).all()
    np.testing.assert_allclose(b.upper[:, :2], np.asarray(ex["members"][0]["upper"])[:, :2], atol=1e-12)
    _, _, d = loc.closest(np.vstack([b.upper, b.lower]))
    assert d.max() <= 1e-9 * loc.diagonal
    # closest-point projection
    pts = np.array([[4.0, 0.0, 8.0], [4.0, 0.0, -3.0]])
    cp, tri = project_polyline(loc, pts)
    ref, _, _ = loc.closest(pts)
    assert np.array_equal(cp, ref)
    # a projection that misses names the member and the points
    with pytest.raises(ProjectionError, match=r"member 'frame_9'.*\[4, 0, 8\]"):
        project_polyline(loc, pts[:1], direction=[0, 0, 1], name="frame_9")
    bad = dict(ex)
    bad["members"] = [dict(ex["members"][0], name="frame_9", direction=[0, 0, 1])]
    with pytest.raises(ProjectionError, match="member 'frame_9'"):
        project_layout(loc, bad)


def test_wing_member_missing_the_skin_is_named(manifest, locators):
    g = manifest["geometries"]["straight_wing"]
    w = dict(g["wings"][0])
    # push the root corners 1 chord below the wing: the ribs' chord-plane points are outside
    for k in ("root_le", "root_te"):
        w[k] = [w[k][0], w[k][1], w[k][2] - 1.0]
    lay = load_layout({"up": g["up"], "wings": [dict(w, ribs={"count": 3})]})
    with pytest.raises(ProjectionError, match=r"member 'wing/rib_0': rays miss the skin .*\[-0.75"):
        project_layout(locators["straight_wing"], lay)


def test_a_spar_too_thin_for_the_element_size_is_meshed_with_smaller_elements(manifest, locators, geometry_dir):
    """A spar close to the thin edge of the straight wing (c=0.03: web 0.0036 tall) at size 0.02
    (0.18 element sizes): the project stage asks for elements of its height over THIN_HEIGHT around it
    (the report's size field names it), the mesh passes the gate, and the skin along the spar is
    meshed at that local size (median edge within 15 % of it); at size 0.2 (0.018 element sizes, below
    the finest local size of 0.1 sizes) it is refused with its name and the largest size that works.
    The benchmark spars are tall enough at the benchmark size: no field, meshes unchanged."""
    from shellmesh_mdao.errors import LayoutError
    from shellmesh_mdao.layout import MIN_LOCAL_SIZE
    from shellmesh_mdao.pipeline import run_pipeline
    from shellmesh_mdao.project import MIN_MEMBER_HEIGHT, THIN_HEIGHT, check_member_heights, thin_member_field
    loc = locators["straight_wing"]
    lay = layout_from_manifest(manifest, "straight_wing", ribs=10, spars=[0.03, 0.5])
    h = check_member_heights(loc, lay, 1e-6)
    web = h["wing/spar_0"][0]
    assert 0.003 < web < 0.004 and h["wing/spar_1"][0] > 0.04
    check_member_heights(loc, lay, 0.02)
    field = thin_member_field(loc, lay, 0.02)
    assert [r["members"] for r in field.reasons] == [["wing/spar_0"]]
    assert field.reasons[0]["size"] == pytest.approx(field.reasons[0]["height"] / THIN_HEIGHT)
    assert field.sizes.min() == pytest.approx(web / THIN_HEIGHT, rel=0.02) and field.sizes.max() <= 0.02
    with pytest.raises(LayoutError, match=r"spar 'wing/spar_0' \(c=0.03\) is only 0.00\d+ tall near \[.*\], "
                                          r"0.017 element sizes: a web of quads needs elements of at most 0.011\d+ "
                                          r"there .*below the smallest local size the mesh refines to \(0.1 element "
                                          r"sizes, 0.02\); move the spar away from the leading edge .*or use an "
                                          r"element size below 0.1186"):
        check_member_heights(loc, lay, 0.2)
    check_member_heights(loc, lay, 0.999 * web / (MIN_MEMBER_HEIGHT * MIN_LOCAL_SIZE))
    tall = layout_from_manifest(manifest, "straight_wing", ribs=10, spars=[0.15, 0.65])
    assert min(v[0] for v in check_member_heights(loc, tall, 0.02).values()) > MIN_MEMBER_HEIGHT * 0.02
    assert thin_member_field(loc, tall, 0.02).empty
    path = geometry_dir / manifest["geometries"]["straight_wing"]["file"]
    with pytest.raises(LayoutError, match=r"spar 'wing/spar_0' \(c=0.03\) is only"):
        run_pipeline(path, lay, 0.2, until="project", progress=False)
    # meshed, through the gate (run_pipeline refuses a mesh that misses a guarantee)
    r = run_pipeline(path, lay, 0.02, progress=False)
    assert any(x["why"] == "thin member" and x["members"] == ["wing/spar_0"] for x in r.report["size_field"]["reasons"])
    m = r.mesh
    spar = np.flatnonzero(m.component == m.component_names.index("wing/spar_0"))
    nodes = np.unique(m.faces[spar])
    skin = np.flatnonzero(np.char.find(np.array(m.component_names)[m.component], "skin") >= 0)
    beside = skin[np.isin(m.faces[skin], nodes).any(1)]
    q = m.points[m.faces[beside]]
    edges = norm_rows(np.roll(q, -1, axis=1) - q, axis=2)
    assert len(beside) > 1000 and np.median(edges) <= 1.15 * web / THIN_HEIGHT


def brute_pick(P, T, x):
    """The rule of SurfaceLocator.closest by checking every triangle: the least squared
    distance (numpy's row-norm sum), then the lowest triangle index; and that point."""
    a, b, c = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
    p = closest_point_on_triangles(np.broadcast_to(x, a.shape), a, b, c)
    e = p - x
    d2 = (e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1]) + e[:, 2] * e[:, 2]
    j = int(np.flatnonzero(d2 == d2.min())[0])
    return j, p[j]


@pytest.mark.parametrize("make", [sphere, soup])
def test_closest_picks_the_lowest_of_equidistant_triangles(make):
    """On a vertex or an edge several triangles are equally near: the locator's answer is the
    brute-force rule's (least distance, lowest index), triangle and point, bit for bit."""
    P, T = make()
    loc = SurfaceLocator(P, T)
    rng = np.random.default_rng(11)
    q = np.vstack([P[T[:40, 1]],                                          # on vertices
                   0.5 * (P[T[:40, 1]] + P[T[:40, 2]]),                   # on edges
                   P[T[:40, 0]] + 1e-3 * rng.normal(size=(40, 3)),        # just off vertices
                   rng.uniform(-1.2, 1.2, (80, 3))])
    cp, tri, _ = loc.closest(q)
    ref = [brute_pick(loc._local, T, x - loc._center) for x in q]
    assert np.array_equal(tri, [j for j, _ in ref])
    assert np.array_equal(cp, np.array([x for _, x in ref]) + loc._center)
    # ties really occur here: the vertices are shared by five or six triangles of the sphere
    if make is sphere:
        assert (tri[:40] != np.arange(40)).any()


def test_closest_does_not_depend_on_threads_batches_or_order():
    """The answers are the same for one thread and two, for a batch answered in blocks and
    the points one by one, and for the points in reverse order."""
    from shellmesh_mdao.core.bvh import TriangleBVH
    P, T = sphere(4)                                              # 5120 triangles
    rng = np.random.default_rng(5)
    q = np.vstack([P[rng.integers(0, len(P), 3000)], rng.uniform(-1.5, 1.5, (3000, 3))])
    bvh = TriangleBVH(P, T)
    one = bvh.closest(q, threads=1)
    two = bvh.closest(q, threads=2)                               # two blocks of 3000
    rev = bvh.closest(q[::-1], threads=2)
    for a, b in zip(one, two):
        assert np.array_equal(a, b)
    for a, b in zip(one, rev):
        assert np.array_equal(a, b[::-1])
    # batches just at and above the smallest that two threads share
    for k in (2 * bvh.MIN_BLOCK, 2 * bvh.MIN_BLOCK + 1, 3 * bvh.MIN_BLOCK - 1):
        part = bvh.closest(q[-k:], threads=2)
        assert np.array_equal(part[0], one[0][-k:]) and np.array_equal(part[1], one[1][-k:])
    single = [bvh.closest(q[i:i + 1]) for i in range(0, len(q), 97)]
    assert np.array_equal(np.vstack([s[0] for s in single]), one[0][::97])
    assert np.array_equal(np.concatenate([s[1] for s in single]), one[1][::97])
    # and a leaf size of 1 (a deeper tree) gives the same answers
    deep = TriangleBVH(P, T, leaf=1).closest(q)
    assert np.array_equal(deep[1], one[1]) and np.array_equal(deep[0], one[0])


@pytest.mark.parametrize("make", [sphere, soup])
def test_closest_with_a_hint_gives_the_same_answers(make):
    """A hint (a triangle to try first) only starts the search: with the right triangle, a
    neighbour, a far or random one, none (-1) or one out of range, the answer is the
    unhinted one bit for bit, ties on vertices and edges (least distance, lowest index)
    included; a hint of the wrong length is refused."""
    from shellmesh_mdao.core.bvh import TriangleBVH
    P, T = make()
    rng = np.random.default_rng(3)
    q = np.vstack([P[T[:200, 1]], 0.5 * (P[T[:200, 1]] + P[T[:200, 2]]),   # ties on vertices, edges
                   P[T[:200, 0]] + 1e-3 * rng.normal(size=(200, 3)), rng.uniform(-1.2, 1.2, (400, 3))])
    loc = SurfaceLocator(P, T)
    cp, tri, d = loc.closest(q)
    k = len(q)
    for hint in (tri, (tri + 1) % len(T), np.full(k, len(T) - 1), rng.integers(0, len(T), k),
                 np.full(k, -1), rng.integers(-3 * len(T), 3 * len(T), k)):
        cp2, tri2, d2 = loc.closest(q, hint=hint)
        assert np.array_equal(tri2, tri) and np.array_equal(cp2, cp) and np.array_equal(d2, d)
    bvh = TriangleBVH(P, T)
    plain = bvh.closest(q, threads=2)
    hinted = bvh.closest(q, threads=2, hint=rng.integers(0, len(T), k))
    assert np.array_equal(plain[0], hinted[0]) and np.array_equal(plain[1], hinted[1])
    with pytest.raises(ValueError, match="one entry per query"):
        bvh.closest(q, hint=tri[:-1])
