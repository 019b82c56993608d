"""Exact plane sections of triangulated surfaces, clipped and seeded."""
import numpy as np
import pytest

from shellmesh_mdao.errors import ImprintError
from shellmesh_mdao.geometry import naca_wing
from shellmesh_mdao.core.section import Plane, plane_section, section_arc


def _point_to_tri_distance(p, a, b, c):
    """Brute-force distance from p to triangle abc (sampling-free, via projection + edges)."""
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n)
    q = p - ((p - a) @ n) * n
    # barycentric inside test
    v0, v1, v2 = b - a, c - a, q - a
    d00, d01, d11, d20, d21 = v0 @ v0, v0 @ v1, v1 @ v1, v2 @ v0, v2 @ v1
    den = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    if v >= -1e-12 and w >= -1e-12 and v + w <= 1 + 1e-12:
        return abs((p - a) @ n)
    best = np.inf
    for s, e in [(a, b), (b, c), (c, a)]:
        t = np.clip((p - s) @ (e - s) / ((e - s) @ (e - s)), 0, 1)
        best = min(best, np.linalg.norm(s + t * (e - s) - p))
    return best


@pytest.fixture(scope="module")
def wing():
    m = naca_wing(span=4.0, root_chord=1.0, tip_chord=1.0, sweep_deg=0.0, dihedral_deg=0.0, naca="0012",
                  n_chord=40, n_span=21)
    return m.points, m.faces[:, :3]


def test_full_section_is_closed_loop_of_airfoil(wing):
    P, T = wing
    arc = section_arc(P, T, Plane.make([0, 1.3, 0], [0, 1, 0]), seed=[0.3, 1.3, 0.06])
    assert arc.closed
    assert np.allclose(arc.points[:, 1], 1.3, atol=1e-15)
    # perimeter of a NACA 0012 of unit chord is about 2.03; the polygon is slightly shorter
    assert 2.0 < arc.length < 2.04


def test_section_points_on_plane_and_surface(wing):
    P, T = wing
    plane = Plane.make([0.4, 2.0, 0.0], [0.2, 1.0, 0.05])
    sec = plane_section(P, T, plane)
    assert np.abs(plane.side(sec.nodes)).max() < 1e-14
    # each link lies inside its triangle: both ends at distance ~0 from that triangle
    for li in range(0, len(sec.links), 7):
        a, b, c = P[T[sec.link_tri[li]]]
        for node in sec.links[li]:
            assert _point_to_tri_distance(sec.nodes[node], a, b, c) < 1e-12


def test_clipped_arc_runs_between_bounds_and_follows_seed(wing):
    P, T = wing
    rib = Plane.make([0, 2.0, 0], [0, 1, 0])
    front = Plane.make([0.15, 0, 0], [1, 0, 0])      # x >= 0.15
    rear = Plane.make([0.65, 0, 0], [-1, 0, 0])      # x <= 0.65
    upper = section_arc(P, T, rib, [front, rear], seed=[0.4, 2.0, 0.06], name="rib_3")
    lower = section_arc(P, T, rib, [front, rear], seed=[0.4, 2.0, -0.06], name="rib_3")
    for arc, sgn in [(upper, 1), (lower, -1)]:
        assert not arc.closed
        x = arc.points[:, 0]
        assert np.isclose(min(x[0], x[-1]), 0.15, atol=1e-14) and np.isclose(max(x[0], x[-1]), 0.65, atol=1e-14)
        assert (np.sign(arc.points[:, 2]) == sgn).all()
        assert len(arc.tri) == len(arc.points) - 1


def test_arcs_from_a_shared_section_match_fresh_ones(wing):
    # the imprint computes a member plane's section once for both its chains: the upper and
    # lower arcs cut from it must be the arcs section_arc computes on its own
    P, T = wing
    rib = Plane.make([0, 2.0, 0], [0, 1, 0])
    bounds = [Plane.make([0.15, 0, 0], [1, 0, 0]), Plane.make([0.65, 0, 0], [-1, 0, 0])]
    sec = plane_section(P, T, rib)
    for z in (0.06, -0.06):
        fresh = section_arc(P, T, rib, bounds, seed=[0.4, 2.0, z])
        shared = section_arc(P, T, rib, bounds, seed=[0.4, 2.0, z], section=sec)
        assert np.array_equal(fresh.points, shared.points) and np.array_equal(fresh.tri, shared.tri)
        assert np.sign(shared.points[:, 2]).tolist() == [np.sign(z)] * len(shared.points)
    assert len(sec.links) == len(plane_section(P, T, rib).links)       # the shared section is left as it was


def test_plane_through_vertices_has_no_zero_length_pieces(wing):
    P, T = wing
    y = P[5 * 80, 1]                                   # a row of section vertices
    arc = section_arc(P, T, Plane.make([0, y, 0], [0, 1, 0]), seed=[0.3, y, 0.06])
    assert arc.closed
    steps = np.linalg.norm(np.diff(arc.points, axis=0), axis=1)
    assert steps.min() > 1e-6
    assert 2.0 < arc.length < 2.04


def test_plane_missing_surface_is_an_error(wing):
    P, T = wing
    with pytest.raises(ImprintError, match="rib_9.*does not cut"):
        section_arc(P, T, Plane.make([0, 10.0, 0], [0, 1, 0]), name="rib_9")


def test_seed_selects_wing_not_other_body(wing):
    """Two bodies cut by one plane: the seed decides which loop is returned."""
    P, T = wing
    P2 = np.vstack([P, P + [0, 0, 3.0]])                # a second wing 3 units above ("tail")
    T2 = np.vstack([T, T + len(P)])
    plane = Plane.make([0, 1.0, 0], [0, 1, 0])
    low = section_arc(P2, T2, plane, seed=[0.3, 1.0, 0.06])
    high = section_arc(P2, T2, plane, seed=[0.3, 1.0, 3.06])
    assert low.points[:, 2].max() < 1 and high.points[:, 2].min() > 2


def test_corpus_sections_exact(geometry_dir, manifest):
    import trimesh

    from shellmesh_mdao.load import load_surface

    for name, g in manifest["geometries"].items():
        # every format of the corpus (STL, VTK, IGES through gmsh) read as the pipeline reads it
        skin, _ = load_surface(geometry_dir / g["file"])
        P, T = skin.points, skin.faces[:, :3]
        m = trimesh.Trimesh(P, T, process=False)
        w = g["wings"][0]
        up = np.asarray(w.get("up", g["up"]), float)
        rle, rte, tle, tte = (np.asarray(w[k], float) for k in ("root_le", "root_te", "tip_le", "tip_te"))
        span = (tle + tte) / 2 - (rle + rte) / 2
        span -= (span @ up) * up
        le, te = rle + 0.5 * (tle - rle), rte + 0.5 * (tte - rte)
        rib = Plane.make(le, span)
        mid = le + 0.4 * (te - le)
        hits, _, tri = m.ray.intersects_location([mid], [up], multiple_hits=False)

        def spar(c, inward):
            a, b = rle + c * (rte - rle), tle + c * (tte - tle)
            n = np.cross(b - a, up)
            return Plane.make(a, n if n @ inward > 0 else -n)

        arc = section_arc(P, T, rib, [spar(0.15, te - le), spar(0.65, le - te)],
                          seed=hits[0], seed_tri=int(tri[0]), name=f"{name}/rib")
        diag = np.linalg.norm(P.max(0) - P.min(0))
        assert np.abs(rib.side(arc.points)).max() < 1e-9 * diag
        d = m.nearest.on_surface(arc.points)[1]
        assert d.max() < 1e-9 * diag, name
        # upper side: every point on the +up side of the chord line
        assert ((arc.points - le) @ up).min() > -1e-9 * diag, name


@pytest.mark.parametrize("seed", range(6))
def test_arc_kernels_match_the_scipy_graph_walk(seed):
    """section_arc's link component (kernels.arc_links) and walk (kernels.arc_order) give what
    scipy's connected components, depth-first order and summed link matrix gave: on paths,
    loops, branches (a walk that backtracks) and a link repeated between two nodes."""
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components, depth_first_order

    from shellmesh_mdao.core.kernels import arc_links, arc_order
    rng = np.random.default_rng(60 + seed)
    nn = 80
    u, v = [], []
    for _ in range(6):
        k = int(rng.integers(2, 12))
        nodes = rng.choice(nn, k, replace=False)
        for t in range(k - 1):
            u.append(nodes[t])
            v.append(nodes[t + 1])
        if rng.random() < 0.5:
            u.append(nodes[-1])
            v.append(nodes[0])
    u.append(u[0])
    v.append(v[0])                                            # a repeated link
    u, v = np.array(u), np.array(v)
    g = sparse.coo_matrix((np.ones(len(u)), (u, v)), shape=(nn, nn)).tocsr()
    _, label = connected_components(g + g.T, directed=False)
    for best in range(0, len(u), 3):
        got = arc_links(u, v, nn, best)
        assert np.array_equal(got, label[u] == label[u[best]])
        lu, lv = u[got], v[got]
        sub = sparse.coo_matrix((np.arange(1, len(lu) + 1), (lu, lv)), shape=(nn, nn)).tocsr()
        sub = sub + sub.T
        for start in np.unique(np.concatenate([lu, lv]))[:4]:
            order = depth_first_order(sub, start, directed=False, return_predecessors=False)
            link = np.asarray(sub[order[:-1], order[1:]]).ravel().astype(np.int64) - 1
            o2, l2 = arc_order(lu, lv, nn, start)
            assert np.array_equal(o2, order) and np.array_equal(l2, link)
