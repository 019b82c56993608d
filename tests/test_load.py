"""Readers: the corpus, cleaning counts, defect reports, families, every input format, errors."""
import json
import re
import sys

import numpy as np
import pytest
import trimesh

from shellmesh_mdao.errors import InputFileError, MeshValidationError
from shellmesh_mdao.export import write_mesh
from shellmesh_mdao.load import SURFACE_FORMATS, SurfaceReport, load_mesh, load_surface
from shellmesh_mdao.mesh import ShellMesh

CORPUS = ["cessna210", "swept_wing", "straight_wing", "bwb"]


def _box(offset=(0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    b = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    return trimesh.Trimesh(b.vertices + np.asarray(offset), b.faces, process=False)


def _stl(path, vertices, faces):
    trimesh.Trimesh(np.asarray(vertices, float), np.asarray(faces), process=False).export(str(path))
    return path


# ------------------------------------------------------------------ corpus
@pytest.mark.parametrize("name", CORPUS)
def test_corpus_loads_closed_single_body(geometry_dir, manifest, name):
    mesh, rep = load_surface(geometry_dir / manifest["geometries"][name]["file"])
    # the manifest states the triangle count, e.g. "... 23,536 triangles ..."
    want = int(re.search(r"([\d,]+) triangles", manifest["geometries"][name]["what"]).group(1).replace(",", ""))
    assert rep.n_triangles == mesh.n_tris == want and rep.n_quads == 0
    assert rep.closed and mesh.is_closed()
    assert rep.n_bodies == 1
    assert rep.n_open_boundary_edges == rep.n_nonmanifold_edges == 0
    assert rep.n_inconsistent_orientation_edges == 0
    assert rep.n_removed_degenerate_faces == rep.n_removed_duplicate_faces == 0
    # a closed triangulated sphere: V - E + F = 2, E = 3F/2
    assert rep.n_vertices == want // 2 + 2
    # an STL stores every corner: 3F vertices merged down to V
    assert rep.n_merged_vertices == 3 * want - rep.n_vertices
    assert mesh.component_names == ["skin"] and (mesh.component == 0).all()
    assert mesh.check().ok


def test_cessna_report_values(geometry_dir):
    mesh, rep = load_surface(geometry_dir / "cessna210.stl")
    assert rep.n_triangles == 23536 and rep.closed and rep.n_bodies == 1
    assert np.allclose(rep.bbox_min, mesh.points.min(0)) and np.allclose(rep.bbox_max, mesh.points.max(0))
    assert rep.diagonal == pytest.approx(np.linalg.norm(np.subtract(rep.bbox_max, rep.bbox_min)))
    d = rep.to_dict()
    assert json.loads(json.dumps(d)) == d
    text = "\n".join(rep.summary_lines())
    assert "23536 triangles" in text and "closed" in text and "problems: none" in text


def test_load_is_deterministic(geometry_dir):
    a, _ = load_surface(geometry_dir / "bwb.stl")
    b, _ = load_surface(geometry_dir / "bwb.stl")
    assert np.array_equal(a.points, b.points) and np.array_equal(a.faces, b.faces)


# ------------------------------------------------------------------ cleaning counts
def test_merge_duplicate_and_degenerate_counts(tmp_path):
    b = _box()
    v = np.vstack([b.vertices, b.vertices[0] + 1e-12, b.vertices[1] + 1e-6])  # 8: merged, 9: kept
    f = np.vstack([b.faces, b.faces[0][::-1], b.faces[3], [0, 8, 2]])  # reversed copy, copy, collapsed
    row = [r for r in np.flatnonzero((f[:12] == 1).any(1)) if r not in (0, 3)][0]
    f[row] = np.where(f[row] == 1, 9, f[row])     # one face uses the 'far' copy of vertex 1
    mesh, rep = load_surface(_stl(tmp_path / "s.stl", v, f))
    assert rep.n_removed_duplicate_faces == 2
    assert rep.n_removed_degenerate_faces == 1
    assert rep.n_triangles == 12
    assert rep.n_merged_vertices == 3 * len(f) - 9
    # the far copy stays distinct: two edges at it and two at vertex 1 become open
    assert rep.n_vertices == 9 and not rep.closed and rep.n_open_boundary_edges == 4


def test_merge_tol_controls_merging(tmp_path):
    b = _box()
    v = np.vstack([b.vertices, b.vertices[0] + 1e-6])
    f = b.faces.copy()
    row = np.flatnonzero((f == 0).any(1))[0]
    f[row] = np.where(f[row] == 0, 8, f[row])
    path = _stl(tmp_path / "s.stl", v, f)
    _, tight = load_surface(path)                    # 1e-9 x diagonal: not merged, a crack
    _, loose = load_surface(path, merge_tol=1e-5)   # 1e-5 x 3.74 > 1e-6: merged, closed
    assert not tight.closed and tight.n_open_boundary_edges == 4 and tight.n_vertices == 9
    assert loose.closed and loose.n_vertices == 8


def test_defects_are_reported_not_repaired(tmp_path):
    a = _box()
    two = trimesh.util.concatenate([a, _box((5.0, 0.0, 0.0))])
    _, rep = load_surface(_stl(tmp_path / "two.stl", two.vertices, two.faces))
    assert rep.n_bodies == 2 and rep.closed
    assert "2 separate bodies" in "\n".join(rep.summary_lines())
    _, rep = load_surface(_stl(tmp_path / "open.stl", a.vertices, a.faces[1:]))
    assert not rep.closed and rep.n_open_boundary_edges == 3 and rep.n_triangles == 11
    f = a.faces.copy()
    f[0] = f[0][::-1]
    _, rep = load_surface(_stl(tmp_path / "flip.stl", a.vertices, f))
    assert rep.n_inconsistent_orientation_edges == 3 and rep.n_triangles == 12
    # a fin: third face on an existing edge
    e = a.faces[0][:2]
    v = np.vstack([a.vertices, [9.0, 9.0, 9.0]])
    f = np.vstack([a.faces, [e[0], e[1], 8]])
    _, rep = load_surface(_stl(tmp_path / "fin.stl", v, f))
    assert rep.n_nonmanifold_edges == 1 and rep.n_open_boundary_edges == 2


@pytest.mark.parametrize("ext", ["obj", "ply", "off", "stl"])
def test_trimesh_formats(tmp_path, ext):
    s = trimesh.creation.icosphere(2)
    path = tmp_path / f"s.{ext}"
    trimesh.Trimesh(s.vertices, s.faces, process=False).export(str(path))
    mesh, rep = load_surface(path)
    assert rep.n_triangles == len(s.faces) and rep.closed and rep.n_bodies == 1
    assert rep.n_vertices == len(s.vertices)
    assert mesh.is_closed()


@pytest.mark.parametrize("ext", ["vtk", "vtp", "vtu"])
def test_vtk_family_formats_from_pyvista(tmp_path, ext):
    import pyvista as pv

    s = pv.Sphere(theta_resolution=20, phi_resolution=12)
    g = s.cast_to_unstructured_grid() if ext == "vtu" else s
    g.save(str(tmp_path / f"s.{ext}"))
    mesh, rep = load_surface(tmp_path / f"s.{ext}")
    assert rep.n_triangles == s.n_cells and rep.n_vertices == 202
    assert rep.closed and rep.n_bodies == 1 and rep.n_inconsistent_orientation_edges == 0


# ------------------------------------------------------------------ families and other formats
def _families_mesh() -> ShellMesh:
    s = trimesh.creation.box()
    comp = (np.arange(12) // 4).astype(np.int32)
    return ShellMesh(s.vertices, s.faces, comp, ["skin", "rib 1", "spar"])


@pytest.mark.parametrize("ext", ["vtu", "msh", "bdf", "inp"])
def test_load_surface_keeps_families_of_our_files(tmp_path, ext):
    m = _families_mesh()
    path = write_mesh(m, tmp_path / f"m.{ext}")
    mesh, rep = load_surface(path)
    assert mesh.component_names == ["skin", "rib 1", "spar"]
    assert rep.n_components == 3 and rep.component_names == ["skin", "rib 1", "spar"]
    assert np.bincount(mesh.component).tolist() == [4, 4, 4]
    assert rep.closed and rep.n_bodies == 1


def test_bdf_with_quads_femap_names_and_degenerate_quad(tmp_path):
    text = """$ a free-field BDF from another tool
SOL 101
CEND
BEGIN BULK
GRID,1,,0.,0.,0.
GRID,2,,1.,0.,0.
GRID,3,,1.,1.,0.
GRID,4,,0.,1.,0.
GRID,5,,2.,0.,0.
GRID,6,,2.,1.,0.
$ Femap Property 7 : Upper_Skin
PSHELL,7,1,.002
PSHELL,9,1,.003
MAT1,1,7.e10,,.3
CQUAD4,10,7,1,2,3,4
CQUAD4,11,9,2,5,6,6
CQUAD4,12,9,2,5,5,6
ENDDATA
"""
    path = tmp_path / "f.bdf"
    path.write_text(text)
    mesh, rep = load_surface(path)
    assert rep.n_quads == 1 and rep.n_triangles == 1       # 11 became a triangle
    assert rep.n_removed_duplicate_faces == 1              # 12 collapses to the same triangle as 11
    assert mesh.component_names == ["Upper_Skin", "pid_9"]
    assert mesh.component.tolist() == [0, 1]
    assert any("turned into triangles" in n for n in rep.notes)


def test_foreign_inp_with_elsets(tmp_path):
    text = """*HEADING
a foreign deck
*NODE
1, 0., 0., 0.
2, 1., 0., 0.
3, 1., 1., 0.
4, 0., 1., 0.
** a comment inside data
5, 2., 0., 0.
*ELEMENT, TYPE=S4R
1, 1, 2, 3, 4
*ELEMENT, TYPE=S3, ELSET=Right
2, 2, 5, 3
*ELSET, ELSET=Left
1
*STEP
*STATIC
*END STEP
"""
    path = tmp_path / "f.inp"
    path.write_text(text)
    mesh = load_mesh(path)
    assert mesh.n_quads == 1 and mesh.n_tris == 1 and mesh.n_points == 5
    assert mesh.component_names == ["Right", "Left"]
    assert mesh.component.tolist() == [1, 0]
    assert mesh.faces.tolist() == [[0, 1, 2, 3], [1, 4, 2, -1]]


def test_gmsh_msh_physical_groups(tmp_path):
    path = _gmsh_box_msh(tmp_path / "g.msh", {"front": [0, 1], "rest": [2, 3, 4, 5]})
    mesh, rep = load_surface(path)
    assert mesh.component_names == ["front", "rest"]
    assert rep.closed and rep.n_bodies == 1 and set(np.unique(mesh.component)) == {0, 1}


def _gmsh_box_msh(path, groups):
    """A closed box written by gmsh with its faces in physical surface groups ``{name: faces}``
    (face indices 0..5)."""
    gmsh = pytest.importorskip("gmsh")
    own = not gmsh.isInitialized()
    if own:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("g")
        gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        surfs = [t for _, t in gmsh.model.getEntities(2)]
        for name, faces in groups.items():
            gmsh.model.addPhysicalGroup(2, [surfs[i] for i in faces], name=name)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.3)
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
        gmsh.model.remove()
    finally:
        if own:
            gmsh.finalize()
    return path


@pytest.mark.parametrize("groups", [{"fuselage": range(6)}, {"skin": range(6)}, {"wing": [0, 1, 2], "body": [3, 4, 5]}])
def test_physical_groups_of_an_input_mesh_are_read_as_skin(tmp_path, groups):
    from shellmesh_mdao.load import repair_surface
    from shellmesh_mdao.pipeline import stage_load

    path = _gmsh_box_msh(tmp_path / "g.msh", groups)
    mesh, rep = load_surface(path)                     # described as in the file
    assert mesh.component_names == list(groups)
    fixed, rep = repair_surface(path)                  # made ready for meshing: the skin
    assert fixed.component_names == ["skin"] and (fixed.component == 0).all() and rep.component_names == ["skin"]
    assert np.array_equal(fixed.faces, mesh.faces) and rep.closed
    lines = [r for r in rep.repairs if r.startswith("read the input's group")]
    assert len(lines) == (0 if list(groups) == ["skin"] else 1)
    if lines:
        assert all(f"'{g}' (" in lines[0] for g in groups)
    kept, _ = repair_surface(path, keep_groups=True)
    assert kept.component_names == list(groups)
    st = stage_load(path, 0.2)                         # the pipeline's load stage
    assert st.surface.component_names == ["skin"] and (st.surface.component == 0).all()


@pytest.mark.parametrize("ext", ["vtu", "bdf", "inp"])
def test_families_of_other_mesh_files_are_read_as_skin_by_repair(tmp_path, ext):
    from shellmesh_mdao.load import repair_surface

    path = write_mesh(_families_mesh(), tmp_path / f"m.{ext}")
    mesh, rep = repair_surface(path)
    assert mesh.component_names == ["skin"] and (mesh.component == 0).all() and rep.closed
    assert any("'rib 1' (4 faces)" in r and "'spar' (4 faces)" in r for r in rep.repairs)


def test_step_via_gmsh(tmp_path):
    gmsh = pytest.importorskip("gmsh")
    path = tmp_path / "box.step"
    own = not gmsh.isInitialized()
    if own:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("cad")
        gmsh.model.occ.addBox(0, 0, 0, 1, 2, 3)
        gmsh.model.occ.synchronize()
        gmsh.write(str(path))
        gmsh.model.remove()
    finally:
        if own:
            gmsh.finalize()
    mesh, rep = load_surface(path)
    assert rep.format == "STEP" and rep.closed and rep.n_bodies == 1
    assert np.allclose(rep.bbox_min, 0) and np.allclose(rep.bbox_max, [1, 2, 3])
    assert rep.n_inconsistent_orientation_edges == 0 and rep.n_triangles > 12
    assert abs(mesh.face_areas().sum() - 22.0) < 1e-9


def test_cad_without_gmsh_names_the_extra(tmp_path, monkeypatch):
    path = tmp_path / "x.step"
    path.write_text("ISO-10303-21;\n")
    monkeypatch.setitem(sys.modules, "gmsh", None)
    with pytest.raises(InputFileError, match=r"pip install shellmesh_mdao\[cad\]"):
        load_surface(path)


# ------------------------------------------------------------------ errors
def test_missing_file_and_folder(tmp_path):
    with pytest.raises(InputFileError, match="not found"):
        load_surface(tmp_path / "nope.stl")
    with pytest.raises(InputFileError, match="is a folder"):
        load_surface(tmp_path)
    with pytest.raises(InputFileError, match="not found"):
        load_mesh(tmp_path / "nope.vtu")


def test_unknown_extension_lists_supported(tmp_path):
    p = tmp_path / "x.xyz"
    p.write_text("1 2 3\n")
    with pytest.raises(InputFileError, match="unknown extension") as e:
        load_surface(p)
    for ext in SURFACE_FORMATS:
        assert ext in str(e.value)
    s = _stl(tmp_path / "s.stl", _box().vertices, _box().faces)
    with pytest.raises(InputFileError, match="use load_surface"):
        load_mesh(s)


GARBAGE = {
    "stl": b"\x13\x37" * 700,
    "obj": b"hello world\nthis is not obj\n",
    "ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n",
    "off": b"OFF\n3 1 0\n0 0 0\n1 0\n",
    "vtk": b"# vtk DataFile Version 4.2\nbroken\n",
    "vtu": b"<VTKFile><bad",
    "vtp": b"<VTKFile type='PolyData'><bad",
    "msh": b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 2",
    "bdf": b"GRID,1,,0.,0.,0.\nCTRIA3,1,1,1,2,3\n",
    "inp": b"*NODE\n1, 0, 0\n*ELEMENT, TYPE=S3\n1, 1, 2\n",
    "step": b"ISO-10303-21;\nHEADER;garbage",
}


@pytest.mark.parametrize("ext", sorted(GARBAGE))
def test_garbage_files_give_input_file_error(tmp_path, ext):
    p = tmp_path / f"g.{ext}"
    p.write_bytes(GARBAGE[ext])
    with pytest.raises(InputFileError, match="g\\." + ext):
        load_surface(p)


def test_empty_and_truncated_files(tmp_path, geometry_dir):
    p = tmp_path / "e.stl"
    p.write_bytes(b"")
    with pytest.raises(InputFileError, match="empty"):
        load_surface(p)
    data = (geometry_dir / "cessna210.stl").read_bytes()
    t = tmp_path / "t.stl"
    t.write_bytes(data[:len(data) // 2])
    with pytest.raises(InputFileError, match="truncated"):
        load_surface(t)
    inp = tmp_path / "n.inp"
    inp.write_text("*NODE\n1, 0., 0., 0.\n2, 1., 0., 0.\n")
    with pytest.raises(InputFileError, match="no triangles or quads"):
        load_surface(inp)
    # a BDF cut mid-way through the elements
    m = _families_mesh()
    bdf = write_mesh(m, tmp_path / "m.bdf")
    lines = bdf.read_text().splitlines(keepends=True)
    cut = next(i for i, line in enumerate(lines) if line.startswith("GRID*")) + 6
    bdf.write_text("".join(lines[:cut]) + "CQUAD4         1       1       1       2      99      98\n")
    with pytest.raises(InputFileError, match="m.bdf"):
        load_mesh(bdf)


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")   # trimesh's normals while writing
def test_nan_coordinates(tmp_path):
    b = _box()
    v = b.vertices.copy()
    v[2] = [np.nan, 0.0, np.inf]
    k = int((b.faces == 2).sum())        # an STL repeats the vertex at every face corner
    with pytest.raises(MeshValidationError, match=rf"\b{k} of 36 vertices have NaN/inf"):
        load_surface(_stl(tmp_path / "nan.stl", v, b.faces))


def test_report_summary_mentions_problems(tmp_path):
    a = _box()
    _, rep = load_surface(_stl(tmp_path / "open.stl", a.vertices, a.faces[2:]))
    assert isinstance(rep, SurfaceReport)
    lines = rep.summary_lines()
    assert any("open boundary edges" in line for line in lines)
    assert rep.problems and "not closed" in rep.problems[0]
