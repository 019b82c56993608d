"""Tests of the ShellMesh data model: edges, boundary, normals, validation, concatenation."""
import numpy as np
import pytest

from shellmesh_mdao.errors import MeshValidationError
from shellmesh_mdao.mesh import ShellMesh, concatenate, edge_topology, merge_close_points


def unit_cube() -> ShellMesh:
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                  [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    # outward-oriented quads
    f = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    return ShellMesh(p, f, np.arange(6) % 2, ["even", "odd"])


def t_junction() -> ShellMesh:
    """Skin plate (two quads) with a rib standing on the middle line: the junction edge has 3 faces."""
    p = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0],
                  [1, 0, 1], [1, 1, 1]], float)
    f = [[0, 1, 4, 3], [1, 2, 5, 4], [1, 6, 7, 4]]
    return ShellMesh(p, f, [0, 0, 1], ["skin", "rib"], feature_edges=[[1, 4]], feature_edge_ids=[1])


def test_mixed_faces_and_padding():
    p = np.zeros((4, 3))
    p[1, 0] = p[2, 1] = 1
    p[3] = [1, 1, 0]
    m = ShellMesh(p, np.array([[0, 1, 2]]))
    assert m.faces.shape == (1, 4) and m.faces[0, 3] == -1
    assert m.n_tris == 1 and m.n_quads == 0


def test_cube_topology_closed():
    m = unit_cube()
    t = m.topology()
    assert len(t.edges) == 12
    assert (t.valence == 2).all()
    assert m.is_closed()
    assert len(m.boundary_edges()) == 0
    assert m.n_bodies() == 1
    assert m.check().ok
    # Euler characteristic of a sphere
    assert m.n_points - len(t.edges) + m.n_faces == 2


def test_cube_normals_outward_and_area():
    m = unit_cube()
    c = m.face_centroids()
    n = m.face_normals()
    assert np.allclose((n * (c - 0.5)).sum(1), 0.5)
    assert np.allclose(m.face_areas(), 1.0)
    vn = m.vertex_normals()
    assert np.allclose(np.linalg.norm(vn, axis=1), 1)
    # corner normal points along the diagonal from the centre
    d = m.points - 0.5
    assert np.allclose(vn, d / np.linalg.norm(d, axis=1, keepdims=True))


def test_nonmanifold_junction_edge_has_three_faces():
    m = t_junction()
    t = m.topology()
    e = t.edge_ids([[4, 1]])[0]
    assert e >= 0 and t.valence[e] == 3
    assert sorted(t.faces_of(e).tolist()) == [0, 1, 2]
    assert m.nonmanifold_edges().tolist() == [[1, 4]]
    # a crossing edge with four faces
    p = np.vstack([m.points, [[1, 0, -1], [1, 1, -1]]])
    f = np.vstack([m.faces, [[1, 4, 9, 8]]])
    m4 = ShellMesh(p, f, [0, 0, 1, 2])
    t4 = m4.topology()
    assert t4.valence[t4.edge_ids([[1, 4]])[0]] == 4
    assert m4.check().ok


def test_check_finds_each_problem():
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [5, 5, 5], [1, 1, 0]], float)
    m = ShellMesh(p, [[0, 1, 2, -1], [0, 1, 1, -1], [0, 3, 2, -1]])
    c = m.check()
    assert c.duplicate_points.tolist() == [[2, 5]]
    assert c.degenerate_faces.tolist() == [1]
    assert sorted(c.unreferenced_points.tolist()) == [4, 5]
    # faces 0 and 2 run along edge 0-2 in the same direction: inconsistent orientation
    assert c.inconsistent_edges.tolist() == [[0, 2]]
    with pytest.raises(MeshValidationError, match="coincident nodes"):
        m.validate()


def test_check_finds_hanging_node():
    p = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [2, 1, 0], [3, 0, 0], [3, 2, 0]], float)
    m = ShellMesh(p, [[0, 1, 2, 3], [1, 5, 4, -1], [4, 5, 6, -1], [4, 6, 2, -1]])
    assert m.check().hanging_nodes.tolist() == [[1, 2, 4]]
    # the conforming version (left quad split at node 4) has none
    m2 = ShellMesh(p, [[0, 1, 4, 3], [3, 4, 2, -1], [1, 5, 4, -1], [4, 5, 6, -1], [4, 6, 2, -1]])
    assert len(m2.check().hanging_nodes) == 0


def test_nan_points_reported():
    p = np.array([[0, 0, 0], [1, 0, np.nan], [0, 1, 0]], float)
    c = ShellMesh(p, [[0, 1, 2]]).check()
    assert c.nonfinite_points.tolist() == [1] and not c.ok


def test_bad_indices_rejected():
    with pytest.raises(MeshValidationError, match="out of range"):
        ShellMesh(np.zeros((3, 3)), [[0, 1, 3]])
    with pytest.raises(MeshValidationError, match="component"):
        ShellMesh(np.zeros((3, 3)), [[0, 1, 2]], component=[0, 1])


def test_concatenate_merges_shared_nodes_and_names():
    skin = ShellMesh(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]], float),
                     [[0, 1, 4, 3], [1, 2, 5, 4]], [0, 0], ["skin"])
    rib = ShellMesh(np.array([[1, 0, 0], [1, 0, 1], [1, 1, 1], [1, 1, 0]], float),
                    [[0, 1, 2, 3]], [0], ["rib"], feature_edges=[[0, 3]], feature_edge_ids=[0])
    m = concatenate([skin, rib])
    assert m.n_points == 8
    assert m.component_names == ["skin", "rib"]
    assert m.component.tolist() == [0, 0, 1]
    assert m.nonmanifold_edges().tolist() == [[1, 4]]
    assert m.feature_edges.tolist() == [[1, 4]] and m.feature_edge_ids.tolist() == [1]
    assert m.check().ok
    # same names in a different order map to the same ids
    m2 = concatenate([rib, skin])
    assert m2.component_names == ["rib", "skin"]
    assert m2.component.tolist() == [0, 1, 1]


def test_merge_close_points_deterministic():
    p = np.array([[0, 0, 0], [1, 0, 0], [1e-12, 0, 0], [1, 1e-12, 0], [2, 0, 0]], float)
    newp, o2n = merge_close_points(p, 1e-9)
    assert o2n.tolist() == [0, 1, 0, 1, 2]
    assert np.array_equal(newp, p[[0, 1, 4]])


def test_compact_drops_unreferenced():
    p = np.array([[9, 9, 9], [0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    m, o2n = ShellMesh(p, [[1, 2, 3]], fixed_vertices=[0, 2]).compact()
    assert m.n_points == 3 and m.faces[0, :3].tolist() == [0, 1, 2]
    assert m.fixed_vertices.tolist() == [1] and o2n[0] == -1


def test_triangles_cover_quads():
    m = unit_cube()
    tris, parent = m.triangles()
    assert len(tris) == 12
    assert np.bincount(parent).tolist() == [2] * 6
    a = 0.5 * np.linalg.norm(np.cross(m.points[tris[:, 1]] - m.points[tris[:, 0]],
                                      m.points[tris[:, 2]] - m.points[tris[:, 0]]), axis=1)
    assert np.isclose(a.sum(), 6.0)


def test_edge_topology_vectorised_large():
    # a 300x300 quad grid: 90,000 faces; interior edges valence 2, boundary 1
    n = 301
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="ij")
    p = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], 1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    v = (i * n + j).ravel()
    f = np.stack([v, v + n, v + n + 1, v + 1], 1)
    t = edge_topology(f)
    assert len(t.edges) == 2 * n * (n - 1)
    assert (t.valence == 1).sum() == 4 * (n - 1)
    assert ShellMesh(p, f).n_bodies() == 1


def test_sharp_edges_of_cube_and_flat_plate():
    m = unit_cube()
    assert len(m.sharp_edges(30.0)) == 12            # every cube edge is a 90-degree crease
    assert len(m.sharp_edges(95.0)) == 0
    plate = ShellMesh(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float), [[0, 1, 2], [0, 2, 3]])
    # flat: no crease; the 4 open boundary edges are reported
    assert sorted(map(tuple, plate.sharp_edges().tolist())) == [(0, 1), (0, 3), (1, 2), (2, 3)]


def test_vertex_faces_mixed():
    from shellmesh_mdao.mesh import vertex_faces

    f = np.array([[0, 1, 2, 3], [1, 4, 2, -1], [2, 4, 5, -1]])
    ptr, idx = vertex_faces(f, 6)
    star = [idx[ptr[v]:ptr[v + 1]].tolist() for v in range(6)]
    assert star == [[0], [0, 1], [0, 1, 2], [0], [1, 2], [2]]


@pytest.mark.parametrize("seed", range(4))
def test_vertex_faces_match_the_numpy_grouping(seed):
    """The compiled grouping against the numpy construction it replaced (a stable argsort of
    the valid entries' vertices), on random mixed faces with padding, repeated vertices in a
    face, unused vertices and int32 input; entries out of range are refused."""
    from shellmesh_mdao.mesh import vertex_faces
    rng = np.random.default_rng(30 + seed)
    n = int(rng.integers(1, 200))
    f = rng.integers(0, n, (int(rng.integers(0, 500)), 4))
    f[rng.random(len(f)) < 0.5, 3] = -1
    for faces in (f, f[:, :3].astype(np.int32)):
        valid = faces >= 0
        fi = np.broadcast_to(np.arange(len(faces))[:, None], faces.shape)[valid]
        v = faces[valid]
        ptr, idx = vertex_faces(faces, n + 2)
        assert np.array_equal(idx, fi[np.argsort(v, kind="stable")])
        assert np.array_equal(ptr, np.concatenate([[0], np.cumsum(np.bincount(v, minlength=n + 2))]))
    with pytest.raises(ValueError, match="faces holds indices outside"):
        vertex_faces(np.array([[0, 1, n + 5]]), n + 2)
    with pytest.raises(ValueError, match="faces holds indices outside"):
        vertex_faces(np.array([[0, 1, -2]]), n + 2)


def test_norm_rows_is_bit_identical_to_np_linalg_norm():
    """The stages' fast row norm gives exactly np.linalg.norm's bits on every shape, stride
    (views, Fortran order), magnitude and special value it meets, and defers to NumPy for
    anything else (other axes, lengths, dtypes), so swapping it in changed no mesh."""
    from shellmesh_mdao.mesh import norm_rows
    rng = np.random.default_rng(11)
    for k in (1, 2, 3, 7, 8, 9, 100, 8193):
        for scale in (1e-300, 1e-20, 1.0, 1e20, 1e300):
            for a in (rng.normal(size=(k, 3)) * scale, rng.normal(size=(k, 4, 3)) * scale,
                      rng.normal(size=(k, 6))[:, ::2] * scale, np.asfortranarray(rng.normal(size=(k, 3)))):
                with np.errstate(over="ignore", under="ignore"):
                    ref = np.linalg.norm(a, axis=-1)
                    got = norm_rows(a, axis=a.ndim - 1)
                    assert np.array_equal(got, ref)
                    assert np.array_equal(norm_rows(a, keepdims=True), np.linalg.norm(a, axis=-1, keepdims=True))
    special = np.array([[np.inf, 0, 0], [np.nan, 1, 1], [0, 0, 0], [-0.0, -0.0, 0], [-3.0, 4.0, 12.0]])
    assert np.array_equal(norm_rows(special), np.linalg.norm(special, axis=1), equal_nan=True)
    assert norm_rows(special)[4] == 13.0
    b = rng.normal(size=(5, 3))
    assert np.array_equal(norm_rows(b, axis=0), np.linalg.norm(b, axis=0))          # another axis
    assert np.array_equal(norm_rows(b[:, :2]), np.linalg.norm(b[:, :2], axis=-1))   # 2-vectors
    assert np.array_equal(norm_rows(np.array([[3, 4, 12]])), [13.0])               # integers


def test_cross_rows_is_bit_identical_to_np_cross():
    """The stages' fast cross product gives exactly np.cross's bits (same arithmetic), so
    swapping it in changed no mesh (determinism across versions)."""
    from shellmesh_mdao.mesh import cross_rows
    rng = np.random.default_rng(5)
    for shape in [(1000, 3), (40, 4, 3), (1, 3)]:
        a, b = rng.normal(size=shape) * 1e3, rng.normal(size=shape) * 1e-3
        assert np.array_equal(cross_rows(a, b), np.cross(a, b))
    a = rng.normal(size=(7, 3))
    assert np.array_equal(cross_rows(a, np.array([[1.0, 2.0, 3.0]])), np.cross(a, [1.0, 2.0, 3.0]))


@pytest.mark.parametrize("seed", range(3))
def test_reduce_short_gives_numpy_bits(seed):
    """reduce_short (one elementwise operation per entry of a short axis) gives NumPy's
    reductions bit for bit: sums left to right, means, NaN-propagating min and max, counts
    and any/all of booleans, on C- and F-ordered and strided arrays with signed zeros,
    infinities and NaN."""
    from shellmesh_mdao.mesh import reduce_short
    rng = np.random.default_rng(70 + seed)
    cases = [((900, 3), 1), ((900, 4), 1), ((900, 3), -1), ((300, 4, 3), 1), ((300, 4, 3), 2), ((300, 3, 3), 1),
             ((9, 1), 1)]
    arrays = []
    for shape, axis in cases:
        a = rng.standard_normal(shape) * 10.0 ** rng.uniform(-8, 8, shape)
        arrays.append((a, axis))
    arrays += [(np.asfortranarray(rng.standard_normal((500, 4))), 1), (rng.standard_normal((500, 8))[:, ::2], 1)]
    with np.errstate(invalid="ignore"):
        for a, axis in arrays:
            a.flat[::17] = -0.0
            a.flat[::29] = np.inf
            a.flat[::31] = -np.inf
            a.flat[::37] = np.nan
            for how in ("sum", "mean", "min", "max"):
                got, ref = reduce_short(a, how, axis), getattr(a, how)(axis)
                assert got.dtype == ref.dtype and got.shape == ref.shape and got.tobytes() == ref.tobytes(), how
            b = a > 0.2
            for how in ("sum", "any", "all"):
                got, ref = reduce_short(b, how, axis), getattr(b, how)(axis)
                assert got.dtype == ref.dtype and np.array_equal(got, ref), how


def _edge_table_by_unique(he_face, he_from, he_to):
    """The edge table of the half-edges as edge_topology built it before its counting sorts:
    np.unique of the int64 keys lo * n + hi, edge_faces by lexsort."""
    lo, hi = np.minimum(he_from, he_to), np.maximum(he_from, he_to)
    n = int(hi.max()) + 1
    ukey, he_edge = np.unique(lo * n + hi, return_inverse=True)
    edges = np.stack([ukey // n, ukey % n], 1)
    return edges, he_edge.reshape(-1), he_face[np.lexsort((he_face, he_edge.reshape(-1)))]


def test_edge_topology_matches_the_unique_keys():
    """edge_topology's counting sorts give np.unique's edges (sorted by node pair), each
    half-edge's edge and the faces of each edge in face order, on mixed meshes with
    non-manifold edges, repeated faces and unused nodes; an empty face array has no edges."""
    rng = np.random.default_rng(8)
    for _ in range(30):
        n = int(rng.integers(4, 60))
        m = int(rng.integers(1, 80))
        faces = np.stack([rng.choice(n, 4, replace=False) for _ in range(m)])
        faces[rng.random(m) < 0.4, 3] = -1                                  # triangles
        faces = np.vstack([faces, faces[: m // 5]])                          # repeated faces
        t = edge_topology(faces)
        assert len(t.he_face) == 4 * len(faces) - int((faces[:, 3] < 0).sum())
        edges, he_edge, edge_faces = _edge_table_by_unique(t.he_face, t.he_from, t.he_to)
        assert np.array_equal(t.edges, edges) and np.array_equal(t.he_edge, he_edge)
        assert np.array_equal(t.edge_faces, edge_faces)
        assert np.array_equal(t.valence, np.bincount(he_edge, minlength=len(edges)))
    t = edge_topology(np.zeros((0, 4), np.int64))
    assert t.edges.shape == (0, 2) and len(t.edge_faces) == 0


def test_unique_edges_matches_numpys_row_unique():
    """unique_edges: the distinct pairs, each (lower, higher), in sorted order, as np.unique of
    the sorted rows gives them (self-pairs and repeats included; nothing for no pairs)."""
    from shellmesh_mdao.mesh import unique_edges
    rng = np.random.default_rng(12)
    for _ in range(200):
        k, n = int(rng.integers(1, 60)), int(rng.integers(1, 40))
        a, b = rng.integers(0, n, k), rng.integers(0, n, k)
        ref = np.unique(np.sort(np.stack([a, b], 1), axis=1), axis=0)
        got = unique_edges(a, b)
        assert got.dtype == np.int64 and np.array_equal(got, ref)
    assert unique_edges([], []).shape == (0, 2)


def test_with_points_keeps_everything_but_the_points():
    """ShellMesh.with_points: the same faces, components, names, fixed vertices and feature
    edges (ids included) on new points; the original is unchanged."""
    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], float)
    m = ShellMesh(P, np.array([[0, 1, 2, 3], [1, 4, 2, -1]]), np.array([0, 1]), ["a", "b"], [0, 4],
                  np.array([[0, 1], [1, 4]]), np.array([1, -1]))
    Q = P + np.array([0.0, 0.0, 1.0])
    m2 = m.with_points(Q)
    assert np.array_equal(m2.points, Q) and np.array_equal(m.points, P)
    assert np.array_equal(m2.faces, m.faces) and np.array_equal(m2.component, m.component)
    assert m2.component_names == ["a", "b"] and np.array_equal(m2.fixed_vertices, [0, 4])
    assert np.array_equal(m2.feature_edges, m.feature_edges)
    assert np.array_equal(m2.feature_edge_ids, m.feature_edge_ids)
    with pytest.raises(MeshValidationError):
        m.with_points(P[:3])                            # faces index points 3 and 4
