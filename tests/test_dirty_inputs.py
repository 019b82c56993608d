"""Dirty CAD inputs: what :func:`repair_surface` (the pipeline's load stage) handles and what it
refuses, on small generated surfaces (see docs/troubleshooting.md, "Dirty inputs")."""
import json
import logging

import numpy as np
import pytest
import trimesh

from shellmesh_mdao.errors import MeshValidationError
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.load import (UNITS_DIAGONAL_RANGE, load_surface, repair_surface,
                                 symmetry_boundary_vertices)
from shellmesh_mdao.mesh import ShellMesh, concatenate


# ------------------------------------------------------------------ generated surfaces
def _box(extents=(2.0, 1.0, 1.0), offset=(0.0, 0.0, 0.0), name="skin") -> ShellMesh:
    b = trimesh.creation.box(extents=extents)
    return ShellMesh(np.asarray(b.vertices) + np.asarray(offset), np.asarray(b.faces), None, [name])


def _volume(m: ShellMesh, apex=(0.0, 0.0, 0.0)) -> float:
    t, _ = m.triangles()
    v = m.points[t] - np.asarray(apex)
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def _tube(radius=0.4, length=5.0, n_around=32, n_len=20, x0=-1.5, z0=0.05, name="fuselage") -> ShellMesh:
    """Closed cylinder along x with fan end caps, outward; its top and bottom lines lie at y = 0."""
    th = 2 * np.pi * np.arange(n_around) / n_around
    y, z = radius * np.cos(th), radius * np.sin(th)
    y[np.abs(y) < 1e-12] = 0.0
    x = x0 + np.linspace(0, length, n_len)
    P = np.stack([np.repeat(x, n_around), np.tile(y, n_len), np.tile(z, n_len) + z0], 1)
    i, j = np.meshgrid(np.arange(n_len - 1), np.arange(n_around), indexing="ij")
    a = (i * n_around + j).ravel()
    b = (i * n_around + (j + 1) % n_around).ravel()
    F = np.vstack([np.stack([a, b + n_around, b], 1), np.stack([a, a + n_around, b + n_around], 1)])
    c0, c1 = len(P), len(P) + 1
    P = np.vstack([P, [[x[0], 0, z0], [x[-1], 0, z0]]])
    j = np.arange(n_around)
    jn = (j + 1) % n_around
    last = (n_len - 1) * n_around
    F = np.vstack([F, np.stack([np.full(n_around, c0), j, jn], 1),
                   np.stack([np.full(n_around, c1), last + jn, last + j], 1)])
    m = ShellMesh(P, F, None, [name])
    return m if _volume(m) > 0 else ShellMesh(P, F[:, ::-1], None, [name])


def _half(m: ShellMesh) -> ShellMesh:
    """The y >= 0 half of a surface symmetric about y = 0 (faces with centroid y > 0)."""
    return m.submesh(m.face_centroids()[:, 1] > 0).compact()[0]


def _half_wing(**kw) -> ShellMesh:
    """naca_wing without its root cap: open at y = 0 (a half model of a wing through the fuselage)."""
    w = naca_wing(**kw)
    y = w.points[w.faces[:, :3], 1]
    return w.submesh(~(np.abs(y) < 1e-12).all(1)).compact()[0]


def _mobius(n=24, width=0.3) -> ShellMesh:
    th = 2 * np.pi * np.arange(n) / n
    pts = []
    for s in (-width, width):
        r = 1 + s * np.cos(th / 2)
        pts.append(np.stack([r * np.cos(th), r * np.sin(th), s * np.sin(th / 2)], 1))
    P = np.vstack(pts)            # 0..n-1 one edge, n..2n-1 the other
    i = np.arange(n - 1)
    # the half twist: the last section joins the first with its two edges swapped
    F = np.vstack([np.stack([i, i + 1, n + i + 1], 1), np.stack([i, n + i + 1, n + i], 1),
                   [[n - 1, n, 0], [n - 1, 0, 2 * n - 1]]])
    return ShellMesh(P, F)


# ------------------------------------------------------------------ duplicates and degenerate faces
def test_duplicate_vertices_merged_duplicate_and_degenerate_faces_dropped(tmp_path):
    b = _box()
    f = np.vstack([b.faces[:, :3], b.faces[3, :3][::-1], b.faces[5, :3], [[0, 0, 1], [2, 3, 3]]])
    path = tmp_path / "dirty.stl"
    trimesh.Trimesh(b.points, f, process=False).export(str(path))      # an STL repeats every corner
    mesh, rep = repair_surface(path)
    assert rep.n_merged_vertices == 3 * len(f) - 8
    assert rep.n_removed_duplicate_faces == 2 and rep.n_removed_degenerate_faces == 2
    assert mesh.n_faces == 12 and mesh.n_points == 8 and rep.closed and mesh.check().ok
    assert rep.repaired and rep.repairs == []          # nothing else to repair


# ------------------------------------------------------------------ orientation
def test_inconsistent_faces_are_reoriented_to_agree_with_their_body(tmp_path):
    b = _box()
    f = b.faces.copy()
    f[[0, 5]] = f[[0, 5]][:, [0, 2, 1, 3]]
    mesh, rep = repair_surface(ShellMesh(b.points, f, None, ["skin"]))
    assert np.array_equal(mesh.faces, b.faces)             # exactly the two flipped faces turned back
    assert rep.n_inconsistent_orientation_edges == 0
    assert any("re-oriented 2 faces" in r for r in rep.repairs)
    p = tmp_path / "s.obj"
    trimesh.Trimesh(b.points, f[:, :3], process=False).export(str(p))
    _, before = load_surface(p)                            # describe only: counted, not repaired
    assert before.n_inconsistent_orientation_edges == 6 and not before.repaired and before.repairs == []


def test_inside_out_bodies_are_turned_outward_each_on_its_own():
    a = _box()
    inv = _box(offset=(5.0, 0.0, 0.0))
    inv = ShellMesh(inv.points, inv.faces[:, [0, 2, 1, 3]], None, ["skin"])
    both = concatenate([a, inv], merge_tol=None)
    mesh, rep = repair_surface(both)
    assert rep.n_bodies == 2 and rep.closed
    assert np.array_equal(mesh.faces[:12], a.faces)                    # the outward box untouched
    assert np.array_equal(mesh.faces[12:, [0, 2, 1]] - 8, inv.faces[:, :3])
    assert _volume(mesh.submesh(np.arange(12))) == pytest.approx(2.0)
    assert _volume(mesh.submesh(np.arange(12, 24))) == pytest.approx(2.0)
    assert any("inside-out body" in r for r in rep.repairs)


def test_quads_are_reoriented_too():
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]], float)
    # an open plate is refused (open boundary), so allow it: orientation is what is tested
    m = ShellMesh(p, [[0, 1, 2, 3], [1, 2, 5, 4]])          # second quad runs the other way
    mesh, rep = repair_surface(m, allow_open=True)
    assert mesh.faces.tolist() == [[0, 1, 2, 3], [1, 4, 5, 2]]     # a tie: the first face's side wins
    assert len(mesh.check().inconsistent_edges) == 0
    assert rep.warnings and "open boundary" in rep.warnings[0]


def test_non_orientable_surface_is_refused():
    with pytest.raises(MeshValidationError, match="non-orientable"):
        repair_surface(_mobius(), allow_open=True)


# ------------------------------------------------------------------ several bodies
def test_intersecting_bodies_are_united():
    a = _box((2.0, 1.0, 1.0))
    b = _box((1.0, 1.0, 2.0), offset=(0.5, 0.2, 0.3))
    mesh, rep = repair_surface(concatenate([a, b], merge_tol=None))
    assert rep.n_bodies == 1 and rep.closed and rep.n_nonmanifold_edges == 0
    # union volume: 2 + 2 - overlap (x 0..1, y -0.3..0.5, z -0.5..0.5 = 1 * 0.8 * 1)
    assert _volume(mesh) == pytest.approx(2 + 2 - 0.8, rel=1e-9)
    assert any("joined 2 intersecting bodies" in r for r in rep.repairs)
    again, _ = repair_surface(concatenate([a, b], merge_tol=None))
    assert np.array_equal(again.points, mesh.points) and np.array_equal(again.faces, mesh.faces)


def test_union_keeps_components_and_untouched_bodies():
    wing = naca_wing(n_chord=16, n_span=8)
    wing.component_names = ["wing"]
    fus = _tube(name="fuselage")
    far = _box((0.5, 0.5, 0.5), offset=(20.0, 0.0, 0.0), name="pod")
    mesh, rep = repair_surface(concatenate([wing, fus, far], merge_tol=None), keep_groups=True)
    assert rep.n_bodies == 2 and rep.closed
    names = {mesh.component_names[i] for i in np.unique(mesh.component)}
    assert names == {"wing", "fuselage", "pod"}
    pod = mesh.submesh(mesh.component == mesh.component_id("pod")).compact()[0]
    assert np.array_equal(pod.points, far.points) and np.array_equal(pod.faces, far.faces)   # untouched
    # no wing face is left inside the fuselage: every wing vertex near the root is outside the tube
    wv = np.unique(mesh.faces[mesh.component == mesh.component_id("wing")][:, :3])
    r = np.hypot(mesh.points[wv, 1], mesh.points[wv, 2] - 0.05)
    inside_x = (mesh.points[wv, 0] > -1.5) & (mesh.points[wv, 0] < 3.5)
    assert (r[inside_x] >= 0.4 * np.cos(np.pi / 32) - 1e-9).all()


def test_union_false_and_disjoint_bodies_are_kept():
    a = _box()
    b = _box(offset=(0.5, 0.2, 0.3))
    m = concatenate([a, b], merge_tol=None)
    mesh, rep = repair_surface(m, union=False)
    assert rep.n_bodies == 2 and np.array_equal(mesh.faces, m.faces)
    far = concatenate([a, _box(offset=(9.0, 0, 0))], merge_tol=None)
    mesh, rep = repair_surface(far)
    assert rep.n_bodies == 2 and rep.repairs == [] and np.array_equal(mesh.faces, far.faces)


def test_nested_body_is_swallowed_by_the_union():
    outer = _box((4.0, 4.0, 4.0))
    inner = _box((1.0, 1.0, 1.0))
    mesh, rep = repair_surface(concatenate([outer, inner], merge_tol=None))
    assert rep.n_bodies == 1 and _volume(mesh) == pytest.approx(64.0)


# ------------------------------------------------------------------ non-manifold
def test_non_manifold_edges_are_refused_naming_where():
    b = _box()
    e = b.faces[0, :2]
    p = np.vstack([b.points, [[9.0, 9.0, 9.0]]])
    m = ShellMesh(p, np.vstack([b.faces[:, :3], [[e[0], e[1], 8]]]))
    mid = 0.5 * (p[e[0]] + p[e[1]])
    with pytest.raises(MeshValidationError, match="1 non-manifold edges") as ei:
        repair_surface(m)
    msg = str(ei.value)
    assert "(" + ", ".join(f"{v:.6g}" for v in mid) + ")" in msg and "remove internal faces" in msg


# ------------------------------------------------------------------ open boundaries: half models
def test_half_wing_is_a_half_model_with_a_symmetry_plane():
    hw = _half_wing(n_chord=24, n_span=16)
    mesh, rep = repair_surface(hw)
    sp = rep.symmetry_plane
    assert sp is not None and sp["axis"] == "y" and sp["normal"] == [0.0, -1.0, 0.0] and sp["offset"] == 0.0
    bv = np.unique(mesh.boundary_edges())
    assert rep.symmetry_vertices == bv.tolist() and len(bv) == 48
    assert np.all(mesh.points[bv, 1] == 0.0)
    assert not rep.closed and rep.n_boundary_loops == 1
    assert any("symmetry plane y = 0" in r for r in rep.repairs)
    assert "half model" in rep.problems[0]
    # a half wing with the cap side pointing away: volume measured from the plane is half a wing's
    assert _volume(mesh) == pytest.approx(_volume(naca_wing(n_chord=24, n_span=16)), rel=1e-12)
    json.dumps(rep.to_dict())


def test_half_wing_runs_through_the_pipeline_with_its_symmetry_boundary():
    from shellmesh_mdao.pipeline import run_pipeline

    mesh, rep = repair_surface(_half_wing(n_chord=24, n_span=16))
    res = run_pipeline(mesh, naca_wing_layout(ribs=4), 0.15, until="imprint", progress=False)
    out = res.mesh
    sym = symmetry_boundary_vertices(out, rep.symmetry_plane)
    bv = np.unique(out.boundary_edges())
    assert len(bv) >= 10 and np.array_equal(sym, bv)      # the open boundary stays in the plane
    assert np.abs(out.points[bv, 1]).max() <= 1e-9
    assert len(out.nonmanifold_edges()) == 0


def test_half_wing_and_half_fuselage_are_united_and_cut_back_at_the_plane():
    wing, fus = _half_wing(n_chord=24, n_span=16), _half(_tube())
    mesh, rep = repair_surface(concatenate([wing, fus], merge_tol=None))
    assert rep.n_bodies == 1 and rep.n_nonmanifold_edges == 0
    assert rep.symmetry_plane["axis"] == "y"
    bv = np.unique(mesh.boundary_edges())
    assert np.all(mesh.points[bv, 1] == 0.0) and rep.symmetry_vertices == bv.tolist()
    # no cap left: no face lies in the plane
    assert (np.abs(mesh.points[mesh.faces[:, :3], 1]).max(1) > 0).all()
    # the closed wing's root cap lies inside the fuselage, so union(closed wing, tube) is the
    # half model's solid plus the y < 0 half of the tube (volumes from a point of the plane)
    full, rep2 = repair_surface(concatenate([naca_wing(n_chord=24, n_span=16), _tube()], merge_tol=None))
    assert rep2.closed and rep2.n_bodies == 1
    assert _volume(mesh) == pytest.approx(_volume(full) - 0.5 * _volume(_tube()), rel=1e-9)


def test_load_surface_reports_the_symmetry_plane_without_repairing(tmp_path, capsys):
    from shellmesh_mdao.cli import main

    hw = _half_wing(n_chord=16, n_span=8)
    p = tmp_path / "half.obj"
    trimesh.Trimesh(hw.points, hw.faces[:, :3], process=False).export(str(p))
    mesh, rep = load_surface(p)
    assert rep.symmetry_plane["axis"] == "y" and not rep.repaired and len(rep.symmetry_vertices) == 32
    assert main(["info", str(p)]) == 0
    assert "symmetry plane y = 0 (half model)" in capsys.readouterr().out


# ------------------------------------------------------------------ other open boundaries: refused
def _open_trailing_edge_wing(n_chord=16, n_span=8):
    w = naca_wing(n_chord=n_chord, n_span=n_span)
    k = 2 * n_chord
    f = w.faces[:, :3]
    j, sec = f % k, f // k
    slot = np.isin(j, [0, k - 1]).all(1) & (sec.min(1) != sec.max(1))
    return w.submesh(~slot).compact()[0]


def test_open_blunt_trailing_edge_is_closed_by_a_strip():
    w = naca_wing(n_chord=16, n_span=8)
    m = _open_trailing_edge_wing()
    mesh, rep = repair_surface(m)
    assert rep.closed and rep.n_bodies == 1 and rep.symmetry_plane is None and mesh.check().ok
    # the strip is the trailing-edge face the wing lost: the same triangles, the same area and volume
    assert sorted(map(sorted, mesh.faces[:, :3].tolist())) == sorted(map(sorted, w.faces[:, :3].tolist()))
    assert mesh.face_areas().sum() == pytest.approx(w.face_areas().sum(), rel=1e-12)
    assert _volume(mesh) == pytest.approx(_volume(w), rel=1e-12)
    (g,) = rep.closed_gaps
    k = 2 * 16
    te = np.linalg.norm(w.points[0::k] - w.points[k - 1::k], axis=1)        # TE thickness per section
    assert g["n_triangles"] == 2 * (8 - 1) and g["length"] == pytest.approx(6.0, rel=0.01)
    assert te.min() <= g["width_min"] <= te[-2] + 1e-12 and te[1] <= g["width_max"] <= te.max() + 1e-12
    assert g["area"] == pytest.approx(w.face_areas().sum() - m.face_areas().sum(), rel=1e-9)
    assert [r for r in rep.repairs if r.startswith("closed an open gap (an open blunt trailing edge) 6.013 long, 0.0111 to 0.0195 wide")]
    json.dumps(rep.to_dict())


def test_open_trailing_edge_is_refused_with_close_gaps_false_or_kept_with_allow_open():
    m = _open_trailing_edge_wing()
    with pytest.raises(MeshValidationError, match=r"an open gap 6.013 long, .* wide, from \(.*\) to \(.*\): an open "
                       r"blunt trailing edge .*close_gaps=True"):
        repair_surface(m, close_gaps=False)
    mesh, rep = repair_surface(m, allow_open=True, close_gaps=False)
    assert rep.n_open_boundary_edges == 2 * (8 - 1) + 2 and rep.symmetry_plane is None and not rep.closed_gaps
    assert "not a symmetry plane" in rep.warnings[0]


def test_open_trailing_edge_of_a_half_wing_is_closed_and_the_root_stays_open():
    """The corpus CAD wing's case on a generated wing: the trailing edge open from the root (in
    the symmetry plane) to mid-span, where a trailing-edge face begins."""
    w = _half_wing(n_chord=16, n_span=9)
    k = 2 * 16
    f = w.faces[:, :3]
    j, sec = f % k, f // k
    slot = np.isin(j, [0, k - 1]).all(1) & (sec.min(1) != sec.max(1)) & (sec.max(1) <= 4)
    mesh, rep = repair_surface(w.submesh(~slot).compact()[0])
    (g,) = rep.closed_gaps
    assert g["n_triangles"] == 2 * 4 and g["start"][1] == 0.0 and g["end"][1] == pytest.approx(3.0)
    assert rep.symmetry_plane["axis"] == "y" and rep.n_boundary_loops == 1
    bv = np.unique(mesh.boundary_edges())
    assert np.all(mesh.points[bv, 1] == 0.0) and rep.symmetry_vertices == bv.tolist()
    assert _volume(mesh) == pytest.approx(_volume(w), rel=1e-12)


def test_open_gaps_that_are_not_trailing_edges_stay_refused():
    # a half wing with an open tip too (its tip cap removed): an airfoil-shaped opening off the
    # symmetry plane, not two parallel sides
    w = _half_wing(n_chord=16, n_span=8)
    tip = (w.points[w.faces[:, :3], 1] == 6.0).all(1)
    with pytest.raises(MeshValidationError, match=r"open boundary edges \(2 loops\).*do not lie in one plane"):
        repair_surface(w.submesh(~tip).compact()[0])
    # a missing panel of the upper skin: a wide hole
    w = naca_wing(n_chord=16, n_span=8)
    c = w.face_centroids()
    panel = (np.abs(c[:, 1] - 3.0) < 0.5) & (c[:, 2] > 0.05) & (np.abs(c[:, 1] - 6.0) > 1e-9)
    with pytest.raises(MeshValidationError, match=r"open boundary edges \(\d loops?\) .*do not lie in one plane"):
        repair_surface(w.submesh(~panel).compact()[0])


def test_hole_in_a_flat_face_is_not_a_symmetry_plane():
    b = _box()
    with pytest.raises(MeshValidationError, match="faces next to it lie in that plane too"):
        repair_surface(ShellMesh(b.points, b.faces[1:]))


def test_planar_boundary_with_the_surface_on_both_sides_is_refused():
    hw = _half_wing(n_chord=16, n_span=8)
    crossing = _box((0.5, 2.0, 0.5), offset=(10.0, 0.0, 0.0))     # a closed body across y = 0
    with pytest.raises(MeshValidationError, match="lies on both sides of it"):
        repair_surface(concatenate([hw, crossing], merge_tol=None))


def test_crack_is_refused_and_merge_tol_closes_it(tmp_path):
    b = _box()
    p = np.vstack([b.points, b.points[0] + [1e-7, 0, 0]])
    f = b.faces[:, :3].copy()
    row = np.flatnonzero((f == 0).any(1))[0]
    f[row] = np.where(f[row] == 0, 8, f[row])
    path = tmp_path / "crack.stl"
    trimesh.Trimesh(p, f, process=False).export(str(path))
    with pytest.raises(MeshValidationError, match="merge_tol"):
        repair_surface(path)
    mesh, rep = repair_surface(path, merge_tol=1e-6)
    assert rep.closed and mesh.n_points == 8


# ------------------------------------------------------------------ units and degenerate geometry
@pytest.mark.parametrize("scale,word", [(1e-5, "kilometres"), (1e6, "micrometres"), (1.0, None)])
def test_units_warning(scale, word):
    b = _box()
    records = []
    h = logging.Handler(logging.WARNING)
    h.emit = records.append
    log = logging.getLogger("shellmesh_mdao")
    log.addHandler(h)
    try:
        mesh, rep = repair_surface(ShellMesh(b.points * scale, b.faces))
    finally:
        log.removeHandler(h)
    lo, hi = UNITS_DIAGONAL_RANGE
    if word is None:
        assert lo <= rep.diagonal <= hi and rep.warnings == [] and not records
    else:
        assert len(rep.warnings) == 1 and word in rep.warnings[0] and f"{rep.diagonal:.3g}" in rep.warnings[0]
        assert any(word in r.getMessage() for r in records)
        assert mesh.n_faces == 12       # a warning, not a refusal


def test_all_zero_area_faces_are_refused():
    p = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], float)
    with pytest.raises(MeshValidationError, match="every face has zero area"):
        repair_surface(ShellMesh(p, [[0, 1, 2], [1, 2, 3]]))


def test_nonfinite_shellmesh_is_refused():
    b = _box()
    p = b.points.copy()
    p[3] = np.nan
    with pytest.raises(MeshValidationError, match="NaN/inf"):
        repair_surface(ShellMesh(p, b.faces))


def test_corpus_surface_repairs_to_itself_up_to_orientation(geometry_dir):
    """The benchmark surfaces are clean: repair only turns inside-out bodies outward."""
    m0, r0 = load_surface(geometry_dir / "straight_wing.stl")
    m1, r1 = repair_surface(geometry_dir / "straight_wing.stl")
    assert np.array_equal(m0.points, m1.points) and np.array_equal(m0.faces, m1.faces) and r1.repairs == []
    m2, r2 = repair_surface(geometry_dir / "swept_wing.stl")       # stored with inward normals
    assert r2.repairs == ["turned 1 inside-out body (12792 faces) to face outward"]
    assert _volume(m2, m2.points.mean(0)) > 0


# ------------------------------------------------------------------ half models with thin features
def _half_fin(chord=1.0, thickness=0.06, height=1.0, x0=2.0, z0=0.3, n=32, m=8, sliver=False) -> ShellMesh:
    """The y >= 0 half of a thin vertical fin (NACA 00xx sections with a sharp trailing edge, in x-y
    planes, stacked along z from ``z0``) with flat caps: open along its leading and trailing edges
    and its caps' chords, all in y = 0. Its trailing edge meets y = 0 at about 4 degrees;
    ``sliver`` adds a row 1e-4 chord before the trailing edge whose faces lie within the plane
    tolerance of y = 0."""
    u = (1.0 - np.cos(np.pi * np.arange(n + 1) / n)) / 2.0
    if sliver:
        u = np.sort(np.append(u, 1.0 - 1e-4))
    yt = 5 * thickness * (0.2969 * np.sqrt(u) - 0.1260 * u - 0.3516 * u ** 2 + 0.2843 * u ** 3 - 0.1036 * u ** 4)
    yt[[0, -1]] = 0.0
    k = len(u)
    z = z0 + height * np.linspace(0.0, 1.0, m + 1)
    P = np.stack([np.tile(x0 + chord * u, m + 1), np.tile(chord * yt, m + 1), np.repeat(z, k)], 1)
    i, j = np.meshgrid(np.arange(m), np.arange(k - 1), indexing="ij")
    a = (i * k + j).ravel()
    F = [np.stack([a, a + 1, a + k + 1], 1), np.stack([a, a + k + 1, a + k], 1)]
    for row in (0, m):
        c = np.arange(1, k - 1) + row * k
        F.append(np.stack([np.full(len(c), row * k), c + 1, c] if row == 0 else [np.full(len(c), row * k), c, c + 1], 1))
    return ShellMesh(P, np.vstack(F), None, ["fin"])


@pytest.mark.parametrize("sliver", [False, True])
def test_half_model_with_a_thin_fin_meeting_the_plane_at_a_shallow_angle_is_accepted(sliver):
    fus, fin = _half(_tube()), _half_fin(sliver=sliver)
    m = concatenate([fus, fin], merge_tol=None)
    # the case: faces next to the fin's trailing edge lie within 25 degrees of the plane (some in it)
    t = fin.topology()
    te = t.edges[(t.valence == 1) & (fin.points[t.edges, 0] == 3.0).all(1)]
    fb = t.edge_faces[t.edge_faces_ptr[t.edge_ids(te)]]
    assert (np.abs(fin.face_normals()[fb, 1]) > 0.99).all()
    if sliver:
        assert (np.abs(fin.points[fin.faces[fb, :3], 1]).max(1) < 1e-5 * m.diagonal).all()   # in the plane
    mesh, rep = repair_surface(m)
    assert rep.symmetry_plane["axis"] == "y" and rep.symmetry_plane["offset"] == 0.0
    assert rep.n_bodies == 1 and rep.n_nonmanifold_edges == 0 and mesh.check().ok
    assert any("joined 2 intersecting bodies" in r for r in rep.repairs)
    bv = np.unique(mesh.boundary_edges())
    assert np.abs(mesh.points[bv, 1]).max() <= 1e-12 and rep.symmetry_vertices == bv.tolist()
    # the fin's trailing edge, from the fuselage top (z = 0.45 at x = 3) to its tip, is symmetry boundary
    be = mesh.boundary_edges()
    on_te = np.isclose(mesh.points[be, 0], 3.0).all(1)
    assert np.linalg.norm(np.diff(mesh.points[be[on_te]], axis=1), axis=2).sum() == pytest.approx(1.3 - 0.45, abs=0.01)
    assert mesh.points[:, 2].max() == pytest.approx(1.3)
    fin_alone, rep2 = repair_surface(fin)
    assert rep2.symmetry_plane["axis"] == "y" and rep2.n_open_boundary_edges == fin.boundary_edges().shape[0]


def test_hole_in_the_flat_root_face_of_a_wing_is_refused():
    w = naca_wing(n_chord=16, n_span=8)
    c = w.face_centroids()
    root = np.flatnonzero(np.abs(c[:, 1]) < 1e-12)
    hole = root[np.argsort(np.abs(c[root, 0] - 0.6))[:3]]          # three cap triangles mid-chord
    keep = np.ones(w.n_faces, bool)
    keep[hole] = False
    with pytest.raises(MeshValidationError, match=r"faces next to it lie in that plane too .*: a hole in a flat face"):
        repair_surface(w.submesh(keep).compact()[0])


def test_flat_sheet_with_its_boundary_in_its_plane_is_not_a_half_model():
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]], float)
    with pytest.raises(MeshValidationError, match="a hole in a flat face"):
        repair_surface(ShellMesh(p, [[0, 1, 2, 3], [1, 4, 5, 2]]))
