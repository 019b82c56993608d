"""Element quality metrics against hand-computed values, Verdict (VTK) cross-checks,
summary counts and JSON shape, and a 1M-element timing run (slow)."""
import json
import math

import numpy as np
import pytest

from shellmesh_mdao.errors import MeshValidationError
from shellmesh_mdao.mesh import ShellMesh
from shellmesh_mdao.quality import (ACCEPTANCE, METRICS, acceptance_masks, aspect_ratio, element_quality,
                                    flag_elements, format_summary, interior_angles, mesh_quality,
                                    min_max_angles, quality_summary, scaled_jacobian, skew, taper, warp)

S3 = math.sqrt(3.0)
QUAD = np.array([[0, 1, 2, 3]])
TRI = np.array([[0, 1, 2, -1]])


def q1(points, faces=QUAD) -> dict:
    """Metrics of a single element as plain floats."""
    q = element_quality(np.asarray(points, float), faces)
    return {k: float(v[0]) for k, v in q.items()}


# ----------------------------------------------------------------------------- quads
def test_unit_square():
    # every edge 1 -> aspect 1; every corner 90; midlines (0,1) and (1,0) are
    # perpendicular -> skew 90 - 90 = 0; flat -> warp 0; the four corner triangles
    # all have area 1/2 -> taper 1 - 0.5/0.5 = 0; (e_next x e_prev).n = 1 at every
    # corner with unit edges -> SJ 1.
    q = q1([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    assert q == pytest.approx({"aspect": 1, "min_angle": 90, "max_angle": 90, "skew": 0, "warp": 0,
                               "taper": 0, "scaled_jacobian": 1}, abs=1e-12)


def test_rhombus_60_120():
    # unit rhombus (0,0),(1,0),(1.5,s3/2),(0.5,s3/2): corners 60,120,60,120; all edges 1.
    # SJ = min sin(corner) = sin 60 = 0.8660.  Midpoints M01=(0.5,0), M23=(1,s3/2):
    # line (0.5, s3/2) at 60 deg; M12=(1.25,s3/4), M30=(0.25,s3/4): line (1,0) at 0 deg;
    # angle between the midlines 60 -> skew 90-60 = 30.  Parallelogram: the four corner
    # triangles each have half the area -> taper 0.
    q = q1([[0, 0, 0], [1, 0, 0], [1.5, S3 / 2, 0], [0.5, S3 / 2, 0]])
    assert q["scaled_jacobian"] == pytest.approx(math.sin(math.radians(60)), abs=1e-12)
    assert q["skew"] == pytest.approx(30.0, abs=1e-9)
    assert q["min_angle"] == pytest.approx(60.0, abs=1e-9)
    assert q["max_angle"] == pytest.approx(120.0, abs=1e-9)
    assert q["aspect"] == pytest.approx(1.0)
    assert q["taper"] == pytest.approx(0.0, abs=1e-12)
    assert q["warp"] == pytest.approx(0.0, abs=1e-12)


def test_trapezoid():
    # (0,0),(2,0),(1.5,1),(0.5,1): area (2+1)/2*1 = 1.5.
    # corner triangles: A0 = |(2,0)x(0.5,1)|/2 = 1, A1 = |(-0.5,1)x(-2,0)|/2 = 1,
    # A2 = A3 = |(-1,0)x(0.5,-1)|/2 = 0.5; mean 0.75 (= half the area);
    # taper = 1 - 0.5/0.75 = 1/3 (= Nastran max(A_i/(A/2)) - 1 = 1/0.75 - 1).
    # corner 0: atan2(1, 0.5) = 63.435 deg; corner 3: 180 - 63.435 = 116.565.
    # edges 2, sqrt(1.25), 1, sqrt(1.25) -> aspect 2.  SJ = sin(63.435) = 2/sqrt5.
    # midlines (1,0)->(1,1) and (1.75,.5)->(.25,.5) are perpendicular -> skew 0.
    q = q1([[0, 0, 0], [2, 0, 0], [1.5, 1, 0], [0.5, 1, 0]])
    a = math.degrees(math.atan2(1, 0.5))
    assert q["taper"] == pytest.approx(1 / 3, abs=1e-12)
    assert q["min_angle"] == pytest.approx(a, abs=1e-9)
    assert q["max_angle"] == pytest.approx(180 - a, abs=1e-9)
    assert q["aspect"] == pytest.approx(2.0)
    assert q["scaled_jacobian"] == pytest.approx(2 / math.sqrt(5), abs=1e-12)
    assert q["skew"] == pytest.approx(0.0, abs=1e-9)
    ang = interior_angles(np.array([[0, 0, 0], [2, 0, 0], [1.5, 1, 0], [0.5, 1, 0]], float), QUAD)[0]
    assert ang == pytest.approx([a, a, 180 - a, 180 - a])
    assert ang.sum() == pytest.approx(360.0)


def test_warped_quad_one_corner_lifted():
    # unit square with corner 2 lifted to z=h=0.2.
    # split 0-2: n(0,1,2) = (1,0,0)x(1,1,h) = (0,-h,1); n(0,2,3) = (1,1,h)x(0,1,0) = (-h,0,1)
    #   cos = 1/(1+h^2) -> 15.9424 deg
    # split 1-3: n(1,2,3) = (0,1,h)x(-1,1,0) = (-h,-h,1); n(1,3,0) = (0,0,1)
    #   cos = 1/sqrt(1+2h^2) -> 15.7932 deg (smaller, since (1+h^2)^2 > 1+2h^2)
    # warp = the larger = acos(1/1.04) = 15.9424 deg.
    h = 0.2
    q = q1([[0, 0, 0], [1, 0, 0], [1, 1, h], [0, 1, 0]])
    assert q["warp"] == pytest.approx(math.degrees(math.acos(1 / (1 + h * h))), abs=1e-9)
    assert q["warp"] == pytest.approx(15.9424, abs=1e-4)
    # a small lift stays within the 10 deg acceptance, this one does not
    assert flag_elements(np.array([[0, 0, 0], [1, 0, 0], [1, 1, h], [0, 1, 0]], float), QUAD)[0]
    assert not flag_elements(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.05], [0, 1, 0]], float), QUAD)[0]


def test_bow_tie_is_folded():
    # (0,0),(2,0),(0.5,1),(1.5,1): edges 1-2 and 3-0 cross.  Diagonals (0.5,1) x (-0.5,1)
    # -> n = +z.  Corner 2: e_next = (1,0), e_prev = (1.5,-1): cross z = -1 < 0, and
    # |e_next||e_prev| = sqrt(3.25) -> SJ = -1/sqrt(3.25) = -0.5547 (same at corner 3).
    q = q1([[0, 0, 0], [2, 0, 0], [0.5, 1, 0], [1.5, 1, 0]])
    assert q["scaled_jacobian"] == pytest.approx(-1 / math.sqrt(3.25), abs=1e-12)
    assert q["scaled_jacobian"] < 0
    assert q["warp"] == pytest.approx(0.0, abs=1e-12)   # flat: folding is not warp


def test_dart_nonconvex_quad():
    # arrow (0,0),(2,-1),(1,0),(2,1), counter-clockwise, area 1; reflex corner at (1,0).
    # Diagonals (1,0) x (0,2) -> n = +z.
    # corner 0: e_next (2,-1), e_prev (2,1): cross 4, dot 3 -> 53.130 deg, SJ 4/5
    # corner 1: e_next (-1,1), e_prev (-2,1): cross 1, dot 3 -> 18.435 deg
    # corner 2: e_next (1,1), e_prev (1,-1): cross -2 < 0 -> reflex, 360-90 = 270, SJ -2/2 = -1
    # corner 3: mirror of corner 1 -> 18.435 deg; sum 360.
    # signed corner areas 2, 0.5, -1, 0.5 (mean 0.5) -> taper 1 - (-1)/0.5 = 3
    pts = np.array([[0, 0, 0], [2, -1, 0], [1, 0, 0], [2, 1, 0]], float)
    q = q1(pts)
    assert q["max_angle"] == pytest.approx(270.0, abs=1e-9)
    assert q["max_angle"] > 180
    assert q["min_angle"] == pytest.approx(math.degrees(math.atan2(1, 3)), abs=1e-9)
    assert q["scaled_jacobian"] == pytest.approx(-1.0, abs=1e-12)
    assert q["taper"] == pytest.approx(3.0, abs=1e-12)
    ang = interior_angles(pts, QUAD)[0]
    assert ang == pytest.approx([math.degrees(math.atan2(4, 3)), 18.43494882, 270.0, 18.43494882])
    assert ang.sum() == pytest.approx(360.0)
    # node order reversed (clockwise): the element normal flips with it, same answer
    assert q1(pts[::-1]) == pytest.approx(q)


def test_quad_metrics_invariant_under_rigid_motion_and_scale():
    rng = np.random.default_rng(3)
    pts = np.array([[0, 0, 0], [2, 0.1, 0], [1.7, 1.2, 0.1], [0.2, 0.9, -0.05]])
    base = q1(pts)
    A, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    moved = 3.7 * pts @ A.T + np.array([10.0, -4.0, 2.5])
    assert q1(moved) == pytest.approx(base, rel=1e-9, abs=1e-9)
    # cyclic renumbering of the corners leaves every metric unchanged
    assert q1(np.roll(pts, 1, axis=0)) == pytest.approx(base, rel=1e-9, abs=1e-9)


# ----------------------------------------------------------------------------- triangles
def test_equilateral_triangle():
    # all angles 60; SJ = 2/sqrt3 * sin 60 = 1; every median is perpendicular to the
    # midline of the two adjacent edges -> skew 0; warp and taper 0 for triangles.
    q = q1([[0, 0, 0], [1, 0, 0], [0.5, S3 / 2, 0]], TRI)
    assert q == pytest.approx({"aspect": 1, "min_angle": 60, "max_angle": 60, "skew": 0, "warp": 0,
                               "taper": 0, "scaled_jacobian": 1}, abs=1e-9)


def test_needle_triangle():
    # (0,0),(10,-0.25),(10,0.25): edges 0.5 and sqrt(100.0625) = 10.0031 (x2)
    # aspect = 10.0031/0.5 = 20.006; apex angle 2*atan(0.025) = 2.8642 deg, base angles
    # (180 - 2.8642)/2 = 88.568; SJ = 2/sqrt3 * sin(2.8642 deg) = 0.05770.
    # skew: at (10,-0.25) the median to (5,0.125) has slope -0.075 (line angle atan .075 =
    # 4.2892 from the x axis, other side), the midline (5,-0.125)->(10,0) slope 0.025
    # (1.4321): angle 5.7213 -> skew 90 - 5.7213 = 84.2787 (the apex median is
    # perpendicular to its midline, 90, so the base corners give the minimum).
    q = q1([[0, 0, 0], [10, -0.25, 0], [10, 0.25, 0]], TRI)
    apex = 2 * math.degrees(math.atan(0.025))
    assert q["aspect"] == pytest.approx(math.sqrt(100.0625) / 0.5, rel=1e-12)
    assert q["aspect"] > 20
    assert q["min_angle"] == pytest.approx(apex, abs=1e-9)
    assert q["max_angle"] == pytest.approx((180 - apex) / 2, abs=1e-9)
    assert q["scaled_jacobian"] == pytest.approx(2 / S3 * math.sin(math.radians(apex)), abs=1e-12)
    sk = 90 - math.degrees(math.atan(0.075) + math.atan(0.025))
    assert q["skew"] == pytest.approx(sk, abs=1e-9)
    assert flag_elements(np.array([[0, 0, 0], [10, -0.25, 0], [10, 0.25, 0]], float), TRI)[0]


def test_triangle_sj_bound_matches_min_angle_bound():
    # (20, 80, 80) triangle: SJ = 2/sqrt3 sin 20 = 0.39493 -> exactly at both bounds; passes
    c = math.cos(math.radians(20)); s = math.sin(math.radians(20))
    pts = np.array([[0, 0, 0], [1, 0, 0], [c, s, 0]])
    q = q1(pts, TRI)
    assert q["min_angle"] == pytest.approx(20.0)
    assert q["scaled_jacobian"] == pytest.approx(2 / S3 * s)
    assert not flag_elements(pts, TRI)[0]


# ----------------------------------------------------------------------------- Verdict
def _pv_quality(pts, faces, measure):
    pv = pytest.importorskip("pyvista")
    k = (faces >= 0).sum(1)
    cells = np.concatenate([np.concatenate([[kk], f[:kk]]) for kk, f in zip(k, faces)])
    poly = pv.PolyData(pts, cells)
    return np.asarray(poly.cell_quality(measure).cell_data[measure])


def test_matches_verdict_on_random_convex_quads_and_triangles():
    # Verdict (VTK vtkCellQuality) quad scaled Jacobian, min/max angle and skew
    # (|cos| of the angle between the principal axes = sin of our skew angle), and
    # triangle scaled Jacobian and angles, on random flat elements.
    rng = np.random.default_rng(7)
    n = 150
    base = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    P = base[None] + rng.uniform(-0.25, 0.25, (n, 4, 2))
    tri = np.array([[0, 0], [1, 0], [0.5, 0.8]]) [None] + rng.uniform(-0.3, 0.3, (n, 3, 2))
    pts = np.vstack([np.concatenate([P, np.zeros((n, 4, 1))], 2).reshape(-1, 3),
                     np.concatenate([tri, np.zeros((n, 3, 1))], 2).reshape(-1, 3)])
    quads = np.arange(4 * n).reshape(n, 4)
    tris = np.hstack([4 * n + np.arange(3 * n).reshape(n, 3), np.full((n, 1), -1)])
    faces = np.vstack([quads, tris])
    q = element_quality(pts, faces)
    for name, ours in [("scaled_jacobian", q["scaled_jacobian"]), ("min_angle", q["min_angle"]),
                       ("max_angle", q["max_angle"])]:
        assert np.abs(_pv_quality(pts, faces, name) - ours).max() < 1e-9, name
    vsk = _pv_quality(pts, quads, "skew")
    assert np.abs(vsk - np.sin(np.radians(q["skew"][:n]))).max() < 1e-12


def test_corpus_triangulation_matches_verdict(geometry_dir, manifest):
    trimesh = pytest.importorskip("trimesh")
    name = "straight_wing"
    tm = trimesh.load(geometry_dir / manifest["geometries"][name]["file"], force="mesh")
    pts, tri = np.asarray(tm.vertices), np.asarray(tm.faces)
    q = element_quality(pts, tri)
    assert all(np.isfinite(v).all() for v in q.values())
    for name in ("scaled_jacobian", "min_angle", "max_angle"):
        assert np.abs(_pv_quality(pts, np.hstack([tri, -np.ones((len(tri), 1), int)]), name)
                      - q[name]).max() < 1e-8, name
    s = quality_summary((pts, tri))
    assert s["n_tris"] == len(tri) and s["n_quads"] == 0
    assert s["scaled_jacobian"]["max"] <= 1 + 1e-12


# ----------------------------------------------------------------------------- arrays, masks
def _small_mixed():
    """Unit square (comp 0), equilateral tri on top (comp 1), dart quad (comp 1), needle tri (comp 2)."""
    pts = np.array([
        [0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],          # 0-3 square
        [0.5, 1 + S3 / 2, 0],                                # 4 apex over edge 3-2
        [3, 0, 0], [5, -1, 0], [4, 0, 0], [5, 1, 0],         # 5-8 dart
        [6, 0, 0], [16, -0.25, 0], [16, 0.25, 0],            # 9-11 needle
    ], float)
    faces = np.array([[0, 1, 2, 3], [3, 2, 4, -1], [5, 6, 7, 8], [9, 10, 11, -1]])
    comp = np.array([0, 1, 1, 2])
    return pts, faces, comp


def test_mixed_mesh_arrays_aligned_with_faces():
    pts, faces, _ = _small_mixed()
    q = element_quality(pts, faces)
    assert set(q) == set(METRICS)
    assert all(v.shape == (4,) and v.dtype == np.float64 for v in q.values())
    # each row equals the metric of that face measured alone
    for i in range(4):
        alone = element_quality(pts, faces[i:i + 1])
        for k in METRICS:
            assert q[k][i] == pytest.approx(alone[k][0], abs=1e-12), (i, k)
    assert q["scaled_jacobian"][[0, 1]] == pytest.approx([1, 1])
    assert q["max_angle"][2] == pytest.approx(270)
    assert q["aspect"][3] > 20
    # the convenience functions agree
    assert np.array_equal(aspect_ratio(pts, faces), q["aspect"])
    assert np.array_equal(skew(pts, faces), q["skew"])
    assert np.array_equal(warp(pts, faces), q["warp"])
    assert np.array_equal(taper(pts, faces), q["taper"])
    assert np.array_equal(scaled_jacobian(pts, faces), q["scaled_jacobian"])
    mn, mx = min_max_angles(pts, faces)
    assert np.array_equal(mn, q["min_angle"]) and np.array_equal(mx, q["max_angle"])
    ia = interior_angles(pts, faces)
    assert np.isnan(ia[[1, 3], 3]).all() and np.isfinite(ia[[0, 2]]).all()
    assert np.nanmin(ia, 1) == pytest.approx(q["min_angle"])
    # ShellMesh convenience
    mesh = ShellMesh(pts, faces)
    for k in METRICS:
        assert np.array_equal(mesh_quality(mesh)[k], q[k])
        assert np.array_equal(element_quality(mesh)[k], q[k])
    # (m, 3) triangle input equals the -1 padded form
    t3 = element_quality(pts, faces[[1, 3], :3])
    assert all(np.array_equal(t3[k], q[k][[1, 3]]) for k in METRICS)


def test_flags_and_masks():
    pts, faces, _ = _small_mixed()
    masks = acceptance_masks(pts, faces)
    flags = flag_elements(pts, faces)
    assert flags.tolist() == [False, False, True, True]
    assert masks["scaled_jacobian"].tolist() == [True, True, False, False]
    assert masks["max_angle"].tolist() == [True, True, False, True]   # needle max angle 88.6 is fine
    assert masks["aspect"].tolist() == [True, True, True, False]
    # triangles are judged by the triangle ranges: a 30-40-110 triangle passes although
    # its 30 deg corner would fail the quad minimum of 45
    A, B = math.radians(30), math.radians(40)
    b = math.sin(B) / math.sin(math.pi - A - B)
    t = np.array([[0, 0, 0], [1, 0, 0], [b * math.cos(A), b * math.sin(A), 0]])
    assert element_quality(t, TRI)["min_angle"][0] == pytest.approx(30)
    assert not flag_elements(t, TRI)[0]
    # custom acceptance: tightening quad aspect to 0.5 flags the square
    tight = {t_: dict(ACCEPTANCE[t_]) for t_ in ACCEPTANCE}
    tight["quad"]["aspect"] = (None, 0.5)
    assert flag_elements(pts, faces, acceptance=tight)[0]


def test_degenerate_elements_have_no_nan():
    # quad with a repeated node (zero-length edge) and a zero-area triangle
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [2, 0, 0]], float)
    faces = np.array([[0, 1, 1, 2], [0, 1, 3, -1]])
    q = element_quality(pts, faces)
    assert not any(np.isnan(v).any() for v in q.values())
    assert np.isinf(q["aspect"][0])
    assert (q["scaled_jacobian"] <= 0).all()
    assert flag_elements(pts, faces).all()
    s = quality_summary((pts, faces))
    assert s["n_folded"] == 2
    json.dumps(s, allow_nan=False)          # infinities become null


def test_bad_input_raises():
    pts = np.zeros((3, 3))
    with pytest.raises(MeshValidationError, match="out of range"):
        element_quality(pts, np.array([[0, 1, 5, -1]]))
    with pytest.raises(MeshValidationError, match="shape"):
        element_quality(pts, np.array([[0, 1]]))
    with pytest.raises(MeshValidationError, match="NaN"):
        element_quality(np.array([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]]), np.array([[0, 1, 2]]))
    with pytest.raises(MeshValidationError):
        quality_summary("mesh.vtu")


def test_empty_mesh():
    q = element_quality(np.zeros((0, 3)), np.zeros((0, 4), int))
    assert all(len(v) == 0 for v in q.values())
    s = quality_summary((np.zeros((0, 3)), np.zeros((0, 4), int)))
    assert s["n_elements"] == 0 and s["aspect"]["min"] is None
    json.dumps(s, allow_nan=False)


# ----------------------------------------------------------------------------- summary
def test_summary_counts_stats_and_components():
    pts, faces, comp = _small_mixed()
    mesh = ShellMesh(pts, faces, comp, ["skin", "rib_1", "spar_front"])
    s = quality_summary(mesh, by_component=True)
    text = json.dumps(s, allow_nan=False)
    assert json.loads(text) == s
    assert (s["n_elements"], s["n_quads"], s["n_tris"]) == (4, 2, 2)
    assert s["quad_fraction"] == 0.5
    assert s["n_folded"] == 1                    # the dart
    assert s["n_flagged"] == 2                   # dart and needle
    assert s["quad_angles_ok_fraction"] == 0.5   # square yes, dart no
    for k in METRICS:
        for key in ("min", "p1", "mean", "median", "max", "p99", "fraction_within"):
            assert key in s[k]
    q = element_quality(pts, faces)
    assert s["scaled_jacobian"]["min"] == pytest.approx(-1.0)
    assert s["max_angle"]["max"] == pytest.approx(270.0)
    assert s["aspect"]["median"] == pytest.approx(float(np.median(q["aspect"])))
    assert s["min_angle"]["mean"] == pytest.approx(float(np.mean(q["min_angle"])))
    assert s["scaled_jacobian"]["fraction_within"] == 0.5
    assert s["acceptance"]["quad"]["aspect"] == [None, 5.0]
    c = s["components"]
    assert list(c) == ["skin", "rib_1", "spar_front"]
    assert (c["skin"]["n_quads"], c["skin"]["n_tris"]) == (1, 0)
    assert (c["rib_1"]["n_quads"], c["rib_1"]["n_tris"], c["rib_1"]["n_folded"]) == (1, 1, 1)
    assert (c["spar_front"]["n_tris"], c["spar_front"]["n_flagged"]) == (1, 1)
    assert c["spar_front"]["quad_angles_ok_fraction"] is None
    assert c["skin"]["scaled_jacobian"]["min"] == pytest.approx(1.0)
    assert sum(v["n_elements"] for v in c.values()) == s["n_elements"]
    assert "components" not in quality_summary(mesh)
    # tuple input with component ids gives the same numbers
    s2 = quality_summary((pts, faces, comp, ["skin", "rib_1", "spar_front"]), by_component=True)
    assert s2 == s


def test_summary_percentiles_on_a_known_distribution():
    # 100 rectangles 1 x a, a = 1..100: aspect = a exactly
    a = np.arange(1, 101, dtype=float)
    x0 = np.arange(100) * 200.0
    pts = np.concatenate([np.stack([x0, 0 * a, 0 * a], 1), np.stack([x0 + 1, 0 * a, 0 * a], 1),
                          np.stack([x0 + 1, a, 0 * a], 1), np.stack([x0, a, 0 * a], 1)])
    faces = np.stack([np.arange(100) + 100 * k for k in range(4)], 1)
    s = quality_summary((pts, faces))
    assert s["aspect"]["min"] == 1 and s["aspect"]["max"] == 100
    assert s["aspect"]["median"] == pytest.approx(50.5)
    assert s["aspect"]["p1"] == pytest.approx(1.99)       # numpy linear: 1 + 0.99*1
    assert s["aspect"]["p99"] == pytest.approx(99.01)
    assert s["aspect"]["fraction_within"] == pytest.approx(0.05)   # a <= 5


def test_format_summary_table():
    pts, faces, comp = _small_mixed()
    s = quality_summary(ShellMesh(pts, faces, comp, ["skin", "rib_1", "spar_front"]), by_component=True)
    text = format_summary(s)
    lines = text.splitlines()
    header = next(ln for ln in lines if ln.startswith("metric"))
    for col in ("min", "p1", "mean", "median", "p99", "max", "within", "range"):
        assert col in header
    rows = [ln for ln in lines if ln.split() and ln.split()[0] in METRICS]
    assert len(rows) == 4 * len(METRICS)                  # all elements + 3 components
    # right-aligned columns: every row has a non-blank character where each header label ends
    for col in ("min", "p1 ", "mean", "median", "p99", "max", "within"):
        end = header.index(col) + len(col.strip())
        assert all(r[end - 1] != " " and r[end] == " " for r in rows), col
    assert all(r[header.index("within") + len("within") - 1] in "%-" for r in rows)
    assert "component skin" in text and "component spar_front" in text
    aspect_row = rows[0]
    assert "<= 5" in aspect_row and "%" in aspect_row
    assert "2 quads, 2 tris" in lines[0]
    assert format_summary(quality_summary((pts, faces))).count("metric") == 1


def test_deterministic():
    pts, faces, comp = _small_mixed()
    a = quality_summary((pts, faces, comp), by_component=True)
    b = quality_summary((pts.copy(), faces.copy(), comp.copy()), by_component=True)
    assert json.dumps(a) == json.dumps(b)


# ----------------------------------------------------------------------------- performance
def _random_grid(n):
    rng = np.random.default_rng(0)
    x, y = np.meshgrid(np.arange(n + 1, dtype=float), np.arange(n + 1, dtype=float), indexing="ij")
    pts = np.stack([x, y, np.zeros_like(x)], -1).reshape(-1, 3)
    pts[:, :2] += rng.uniform(-0.2, 0.2, (len(pts), 2))
    pts[:, 2] += rng.uniform(-0.05, 0.05, len(pts))
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    v = (i * (n + 1) + j).ravel()
    return pts, np.stack([v, v + n + 1, v + n + 2, v + 1], 1)


def test_grid_vectorised_medium():
    pts, faces = _random_grid(200)                     # 40,000 quads
    q = element_quality(pts, faces)
    assert (q["scaled_jacobian"] > 0).all() and (q["min_angle"] > 30).all()


@pytest.mark.slow
def test_one_million_quads():
    """A 1M-quad mesh is summarised with the right counts (speed is measured in the benchmark)."""
    pts, faces = _random_grid(1000)                    # 1,000,000 quads
    s = quality_summary((pts, faces))
    assert s["n_quads"] == 1_000_000 and s["n_folded"] == 0


def test_metrics_asked_alone_are_the_same_bits():
    """element_quality(..., metrics=...) computes only the metrics asked for, with the values
    of the full computation bit for bit, on quads, triangles and a mix (warped, folded and
    degenerate elements among them); an unknown metric is refused."""
    rng = np.random.default_rng(8)
    P = rng.normal(size=(60, 3))
    P[5] = P[6]                                          # a zero-length edge
    quads = np.array([rng.choice(60, 4, replace=False) for _ in range(80)])
    quads[0, 1] = 5
    quads[0, 2] = 6
    tris = np.column_stack([np.array([rng.choice(60, 3, replace=False) for _ in range(40)]), np.full(40, -1)])
    for F in (quads, tris, np.vstack([quads, tris])[rng.permutation(120)]):
        full = element_quality(P, F)
        for k in METRICS:
            alone = element_quality(P, F, (k,))
            assert list(alone) == [k] and alone[k].tobytes() == full[k].tobytes(), k
        two = element_quality(P, F, ("warp", "min_angle"))
        assert list(two) == ["warp", "min_angle"]
        assert two["warp"].tobytes() == full["warp"].tobytes()
    with pytest.raises(ValueError, match="unknown quality metric"):
        element_quality(P, quads, ("jacobian",))
