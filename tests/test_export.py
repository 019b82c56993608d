"""Writers: round trips through every format, the readers of other tools, atomicity, errors."""
import json
import os
from pathlib import Path

import numpy as np
import pytest

from shellmesh_mdao.errors import OutputError
from shellmesh_mdao.export import (DEFAULT_MATERIAL, DEFAULT_THICKNESS, bdf_family_name, export_order,
                                   inp_elset_names, inp_mesh_lines, resolve_thickness, write_mesh)
import shellmesh_mdao.export as export_mod
import shellmesh_mdao.load.readers as load_readers
from shellmesh_mdao.load import load_mesh, load_surface
from shellmesh_mdao.mesh import ShellMesh

FORMATS = ["bdf", "inp", "vtu", "msh"]
NAMES = ["skin", "rib 1", "spar_front"]


def mixed_mesh() -> ShellMesh:
    """4x3 node grid, bent, with quads and triangles of 3 components interleaved (not in
    export order), two feature edges and two fixed nodes."""
    xs, ys = np.meshgrid(np.arange(4.0), np.arange(3.0))
    pts = np.c_[xs.ravel() * 0.37 - 0.1, ys.ravel() * 1.3 + 1e-7, np.sin(xs.ravel()) * 12.345678901234567]
    q = lambda i, j: [j * 4 + i, j * 4 + i + 1, (j + 1) * 4 + i + 1, (j + 1) * 4 + i]  # noqa: E731
    faces = [q(0, 0), [2, 3, 7, -1], q(0, 1), q(1, 0), [2, 7, 6, -1], q(1, 1), [6, 7, 11, -1], [6, 11, 10, -1]]
    comp = [0, 2, 1, 0, 2, 1, 0, 2]
    return ShellMesh(pts, faces, comp, list(NAMES), fixed_vertices=[0, 5],
                     feature_edges=[[0, 1], [5, 6], [6, 7]], feature_edge_ids=[-1, 1, 2])


def _coord_tol(ext: str, pts: np.ndarray) -> float:
    """Precision each format promises: VTU/MSH exact; BDF 16-char fixed-point fields;
    INP 20-char fields (CalculiX reads reals as f20.0)."""
    big = max(1.0, float(np.abs(pts).max()))
    return {"vtu": 0.0, "msh": 0.0, "bdf": 1e-12 * big, "inp": 1e-15 * big}[ext]


@pytest.fixture(scope="module")
def cessna(geometry_dir):
    return load_surface(geometry_dir / "cessna210.stl")[0]


# ------------------------------------------------------------------ round trips
def test_export_order_groups_by_component_quads_first():
    m = mixed_mesh()
    o = export_order(m)
    c = m.component[o]
    assert (np.diff(c) >= 0).all()
    tri = m.is_tri[o]
    for k in range(3):
        t = tri[c == k]
        assert (np.diff(t.astype(int)) >= 0).all()       # quads then triangles
    assert sorted(o.tolist()) == list(range(m.n_faces))


@pytest.mark.parametrize("ext", FORMATS)
def test_round_trip_mixed_mesh(tmp_path, ext):
    m = mixed_mesh()
    out = write_mesh(m, tmp_path / f"m.{ext}")
    assert out == tmp_path / f"m.{ext}" and out.is_file()
    b = load_mesh(out)
    o = export_order(m)
    assert b.points.shape == m.points.shape
    assert np.abs(b.points - m.points).max() <= _coord_tol(ext, m.points)
    assert np.array_equal(b.faces, m.faces[o])
    assert np.array_equal(b.component, m.component[o])
    assert b.component_names == NAMES
    if ext == "vtu":      # VTU also carries feature edges and fixed nodes
        assert np.array_equal(b.feature_edges, m.feature_edges)
        assert np.array_equal(b.feature_edge_ids, m.feature_edge_ids)
        assert np.array_equal(b.fixed_vertices, m.fixed_vertices)


@pytest.mark.parametrize("ext", FORMATS)
def test_round_trip_keeps_empty_component_and_odd_names(tmp_path, ext):
    m = mixed_mesh()
    m.component_names = ["skin", "rib 1 / pyNastran", 'spar "front" é', "unused stringer"]
    b = load_mesh(write_mesh(m, tmp_path / f"m.{ext}"))
    names = list(m.component_names)
    if ext == "msh":   # gmsh names are quoted: a double quote becomes a single quote
        names[2] = names[2].replace('"', "'")
    assert b.component_names == names
    assert np.array_equal(b.component, m.component[export_order(m)])


@pytest.mark.parametrize("ext", FORMATS)
def test_round_trip_cessna(tmp_path, cessna, ext):
    path = write_mesh(cessna, tmp_path / f"c.{ext}")
    b = load_mesh(path)
    tol = _coord_tol(ext, cessna.points)
    assert np.abs(b.points - cessna.points).max() <= tol
    assert np.array_equal(b.faces, cessna.faces)          # one component, all triangles: order kept
    assert b.component_names == ["skin"] and (b.component == 0).all()
    # and through the other tools' own readers
    if ext == "bdf":
        from pyNastran.bdf.bdf import read_bdf
        model = read_bdf(str(path), xref=False, validate=False, debug=None)
        xyz = np.array([model.nodes[i].xyz for i in range(1, cessna.n_points + 1)])
        conn = np.array([model.elements[i].node_ids for i in range(1, cessna.n_faces + 1)]) - 1
        assert np.abs(xyz - cessna.points).max() <= tol
        assert np.array_equal(conn, cessna.faces[:, :3])
        assert model.elements[1].comment.split()[-1] == "skin"
    elif ext == "msh":
        gmsh = pytest.importorskip("gmsh")
        own = not gmsh.isInitialized()
        if own:
            gmsh.initialize(readConfigFiles=False, interruptible=False)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.open(str(path))
            assert [gmsh.model.getPhysicalName(d, t) for d, t in gmsh.model.getPhysicalGroups(2)] == ["skin"]
            tags, coords, _ = gmsh.model.mesh.getNodes()
            assert np.array_equal(np.asarray(coords).reshape(-1, 3)[np.argsort(tags)], cessna.points)
            _, etags, enodes = gmsh.model.mesh.getElements(2)
            order = np.argsort(etags[0])
            conn = np.asarray(enodes[0], np.int64).reshape(-1, 3)[order] - 1
            assert np.array_equal(conn, cessna.faces[:, :3])
            gmsh.model.remove()
        finally:
            if own:
                gmsh.finalize()
    else:
        import meshio
        r = meshio.abaqus.read(str(path)) if ext == "inp" else meshio.read(str(path))
        assert np.abs(r.points - cessna.points).max() <= tol
        assert len(r.cells) == 1 and r.cells[0].type == "triangle"
        assert np.array_equal(r.cells[0].data, cessna.faces[:, :3])


@pytest.mark.parametrize("ext", FORMATS)
def test_writes_are_deterministic(tmp_path, ext):
    m = mixed_mesh()
    a = write_mesh(m, tmp_path / f"a.{ext}").read_bytes()
    b = write_mesh(m, tmp_path / f"b.{ext}").read_bytes()
    assert a == b


# ------------------------------------------------------------------ Nastran
def test_bdf_reads_in_pynastran_with_properties_and_pytacs_names(tmp_path):
    from pyNastran.bdf.bdf import read_bdf

    m = mixed_mesh()
    path = write_mesh(m, tmp_path / "m.bdf", thickness={"skin": 0.004, "spar_front": 0.0015},
                      material={"E": 70e9, "nu": 0.3, "rho": 2700.0})
    model = read_bdf(str(path), xref=False, validate=False, debug=None)
    o = export_order(m)
    eids = sorted(model.elements)
    assert eids == list(range(1, m.n_faces + 1))
    for k, eid in enumerate(eids):
        e = model.elements[eid]
        f = m.faces[o[k]]
        want = (f[f >= 0] + 1).tolist()
        assert e.node_ids == want
        assert e.type == ("CQUAD4" if len(want) == 4 else "CTRIA3")
        assert e.pid == m.component[o[k]] + 1
    xyz = np.array([model.nodes[i].xyz for i in sorted(model.nodes)])
    assert sorted(model.nodes) == list(range(1, m.n_points + 1))
    assert np.abs(xyz - m.points).max() <= _coord_tol("bdf", m.points)
    assert sorted(model.properties) == [1, 2, 3]
    t = {pid: model.properties[pid].t for pid in model.properties}
    assert t == {1: 0.004, 2: DEFAULT_THICKNESS, 3: 0.0015}
    assert all(model.properties[p].mid1 == 1 for p in t)
    mat = model.materials[1]
    assert (mat.e, mat.nu, mat.rho) == (70e9, 0.3, 2700.0)
    # pyTACS (pyMeshLoader): the element comment holding 'Shell element data for family'
    # names the component by its last word
    found = {}
    for eid in eids:
        c = model.elements[eid].comment
        if "Shell element data for family" in c:
            found[model.elements[eid].pid] = c.split()[-1]
    assert found == {c + 1: bdf_family_name(n, c) for c, n in enumerate(NAMES)}
    assert found[2] == "rib_1"
    lines = path.read_text().splitlines()
    assert "$ Shell element data for family skin" in lines


def test_bdf_pynastran_fallback_reads_same_mesh(tmp_path, monkeypatch):
    m = mixed_mesh()
    path = write_mesh(m, tmp_path / "m.bdf")
    fast = load_mesh(path)
    monkeypatch.setattr(load_readers, "_read_own_bdf", lambda p: None)
    slow = load_mesh(path)
    assert np.array_equal(fast.points, slow.points)
    assert np.array_equal(fast.faces, slow.faces)
    assert np.array_equal(fast.component, slow.component)
    assert fast.component_names == slow.component_names == NAMES


def test_bdf_fast_reader_rejects_edited_file(tmp_path):
    m = mixed_mesh()
    path = write_mesh(m, tmp_path / "m.bdf")
    text = path.read_text().replace("$ Shell element data for family rib_1\n",
                                    "$ Shell element data for family rib_1\nCBAR    99       1       1       2\n")
    path.write_text(text)
    assert load_readers._read_own_bdf(path) is None


# ------------------------------------------------------------------ CalculiX
def test_inp_structure_and_calculix_limits(tmp_path):
    m = mixed_mesh()
    m.component_names = ["skin", "rib 1", "9 spar" + "x" * 100]
    blocks = inp_mesh_lines(m, {"skin": 0.004}, {"name": "Al 2024", "E": 73.1e9})
    path = write_mesh(m, tmp_path / "m.inp", thickness={"skin": 0.004}, material={"name": "Al 2024", "E": 73.1e9})
    text = path.read_text()
    assert "".join(blocks) == text
    assert all(b.endswith("\n") for b in blocks)
    elsets = inp_elset_names(m)
    assert elsets[:2] == ["skin", "rib_1"]
    assert elsets[2].startswith("C_9_spar") and len(elsets[2]) == 80
    for c, n in enumerate(m.component_names):
        assert f"** family {c} {n}\n" in text
        assert f"*SHELL SECTION, ELSET={elsets[c]}, MATERIAL=Al_2024\n" in text
    assert "*SHELL SECTION, ELSET=skin, MATERIAL=Al_2024\n0.004\n" in text
    assert "*ELASTIC\n73100000000.0, 0.33\n*DENSITY\n2810.0\n" in text
    assert "*ELEMENT, TYPE=S4, ELSET=skin\n" in text and "*ELEMENT, TYPE=S3, ELSET=skin\n" in text
    # every real field fits CalculiX's 20-character read, every line its 132 characters
    node_block = text.split("*NODE, NSET=NALL\n")[1].split("*ELEMENT")[0]
    fields = [f.strip() for line in node_block.splitlines() for f in line.split(",")[1:]]
    assert len(fields) == 3 * m.n_points and max(len(f) for f in fields) <= 20
    assert max(len(line) for line in text.splitlines()) <= 132
    b = load_mesh(path)
    assert b.component_names == m.component_names


def test_inp_reads_with_meshio_abaqus(tmp_path):
    import meshio

    m = mixed_mesh()
    path = write_mesh(m, tmp_path / "m.inp")
    r = meshio.abaqus.read(str(path))
    assert np.abs(r.points - m.points).max() <= _coord_tol("inp", m.points)
    o = export_order(m)
    faces = np.vstack([np.c_[cb.data, np.full(len(cb.data), -1)] if cb.type == "triangle" else cb.data
                       for cb in r.cells])
    assert np.array_equal(faces, m.faces[o])
    assert {k.lower() for k in r.cell_sets} >= {"skin", "rib_1", "spar_front"}


# ------------------------------------------------------------------ VTU
def test_vtu_reads_in_meshio_and_pyvista(tmp_path):
    import meshio
    import pyvista as pv

    m = mixed_mesh()
    q = np.linspace(0.1, 0.8, m.n_faces)
    path = write_mesh(m, tmp_path / "m.vtu", quality={"scaled_jacobian": q})
    r = meshio.read(str(path))
    assert {n: int(v[0]) for n, v in r.field_data.items()} == {n: i for i, n in enumerate(NAMES)}
    o = export_order(m)
    comp = np.concatenate(r.cell_data["component"])
    assert np.array_equal(comp[:m.n_faces], m.component[o])
    assert np.array_equal(comp[m.n_faces:], m.feature_edge_ids)
    qq = np.concatenate(r.cell_data["scaled_jacobian"])
    assert np.array_equal(qq[:m.n_faces], q[o]) and np.isnan(qq[m.n_faces:]).all()
    g = pv.read(str(path))
    assert list(g.field_data.keys()) == NAMES
    assert g.n_cells == m.n_faces + len(m.feature_edges)
    assert np.array_equal(np.asarray(g.points), m.points)


# ------------------------------------------------------------------ Gmsh
def test_msh_opens_in_gmsh_with_named_physical_groups(tmp_path):
    gmsh = pytest.importorskip("gmsh")
    m = mixed_mesh()
    path = write_mesh(m, tmp_path / "m.msh")
    own = not gmsh.isInitialized()
    if own:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.open(str(path))
        groups = gmsh.model.getPhysicalGroups(2)
        assert [t for _, t in groups] == [1, 2, 3]
        assert [gmsh.model.getPhysicalName(2, t) for _, t in groups] == NAMES
        tags, coords, _ = gmsh.model.mesh.getNodes()
        xyz = np.asarray(coords).reshape(-1, 3)[np.argsort(tags)]
        assert np.array_equal(xyz, m.points)
        o = export_order(m)
        for dim, ptag in groups:
            got = []
            for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, ptag):
                types, etags, enodes = gmsh.model.mesh.getElements(2, int(ent))
                for t, nodes in zip(types, enodes):
                    nn = 3 if t == 2 else 4
                    got += [tuple(r) for r in (np.asarray(nodes, np.int64).reshape(-1, nn) - 1).tolist()]
            want = [tuple(int(v) for v in f if v >= 0) for f in m.faces[o][m.component[o] == ptag - 1]]
            assert sorted(got) == sorted(want)
        gmsh.model.remove()
    finally:
        if own:
            gmsh.finalize()


# ------------------------------------------------------------------ parameters
def test_thickness_forms_and_errors():
    m = mixed_mesh()
    assert np.array_equal(resolve_thickness(m), np.full(3, DEFAULT_THICKNESS))
    assert np.array_equal(resolve_thickness(m, 0.01), np.full(3, 0.01))
    assert np.array_equal(resolve_thickness(m, {"rib 1": 0.003}), [DEFAULT_THICKNESS, 0.003, DEFAULT_THICKNESS])
    assert np.array_equal(resolve_thickness(m, [1, 2, 3]), [1.0, 2.0, 3.0])
    with pytest.raises(OutputError, match="unknown component"):
        resolve_thickness(m, {"wing": 0.01})
    with pytest.raises(OutputError, match="positive"):
        resolve_thickness(m, [0.01, -1, 0.01])
    with pytest.raises(OutputError, match="one value per component"):
        resolve_thickness(m, [0.01, 0.02])


def test_material_errors(tmp_path):
    m = mixed_mesh()
    with pytest.raises(OutputError, match="unknown material key"):
        write_mesh(m, tmp_path / "m.bdf", material={"young": 1.0})
    with pytest.raises(OutputError, match="nu"):
        write_mesh(m, tmp_path / "m.inp", material={"nu": 0.7})
    assert not list(tmp_path.iterdir())
    assert DEFAULT_MATERIAL["E"] == 71.7e9 and DEFAULT_MATERIAL["rho"] == 2810.0


# ------------------------------------------------------------------ errors and atomicity
def test_unknown_extension_lists_supported(tmp_path):
    with pytest.raises(OutputError, match=r"\.bdf.*\.inp.*\.vtu.*\.msh"):
        write_mesh(mixed_mesh(), tmp_path / "m.stl")
    assert not list(tmp_path.iterdir())


def test_missing_folder(tmp_path):
    with pytest.raises(OutputError, match="does not exist"):
        write_mesh(mixed_mesh(), tmp_path / "nope" / "m.vtu")


def test_folder_is_a_file(tmp_path):
    f = tmp_path / "file.txt"
    f.write_text("x")
    with pytest.raises(OutputError, match="not a folder"):
        write_mesh(mixed_mesh(), f / "m.vtu")


def test_read_only_folder(tmp_path):
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        target = ro / "m.bdf"
    else:   # root ignores permission bits: /sys refuses new files even for root
        if not Path("/sys").is_dir():
            pytest.skip("no read-only folder available as root")
        target = Path("/sys/shellmesh_test.bdf")
    try:
        with pytest.raises(OutputError, match="not writable"):
            write_mesh(mixed_mesh(), target)
        assert not target.exists()
    finally:
        if os.geteuid() != 0:
            (tmp_path / "ro").chmod(0o755)


@pytest.mark.parametrize("ext", FORMATS)
def test_failed_write_leaves_no_partial_file_and_keeps_old_one(tmp_path, monkeypatch, ext):
    m = mixed_mesh()
    target = tmp_path / f"m.{ext}"
    target.write_text("previous content")
    real_format_rows = export_mod._format_rows

    def boom(*a, **k):
        yield from real_format_rows(*a, **k)
        raise KeyboardInterrupt("interrupted mid-write")

    monkeypatch.setattr(export_mod, "_format_rows", boom)
    if ext == "vtu":
        import meshio

        def bad_write(path, *a, **k):
            Path(path).write_text("partial")
            raise OSError(28, "No space left on device")
        monkeypatch.setattr(meshio, "write", bad_write)
    with pytest.raises((KeyboardInterrupt, OutputError)):
        write_mesh(m, target)
    assert target.read_text() == "previous content"
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]


def test_nan_points_refused(tmp_path):
    m = mixed_mesh()
    m.points[3, 1] = np.nan
    with pytest.raises(OutputError, match="NaN"):
        write_mesh(m, tmp_path / "m.vtu")
    assert not list(tmp_path.iterdir())


def test_output_file_mode_follows_umask(tmp_path):
    path = write_mesh(mixed_mesh(), tmp_path / "m.msh")
    old = os.umask(0)
    os.umask(old)
    assert (path.stat().st_mode & 0o777) == (0o666 & ~old)


def test_written_names_table_is_json_exact(tmp_path):
    m = mixed_mesh()
    m.component_names = ["a\\b", "c\td", "pyNastran"]
    path = write_mesh(m, tmp_path / "m.bdf")
    assert "pyNastran:" not in path.read_text().split("\n", 1)[1]
    assert load_mesh(path).component_names == ["a\\b", "c\td", "pyNastran"]
    assert json.loads('"py\\u004eastran"') == "pyNastran"


@pytest.mark.slow
def test_round_trip_one_million_quads(tmp_path):
    """1M quads, 5 components: every format round-trips exactly (to its precision); the
    vectorised writers/readers keep each format to seconds (see docs/file_formats.md)."""
    n = 1000
    xs, ys = np.meshgrid(np.linspace(0, 30, n + 1), np.linspace(-3, 3, n + 1))
    pts = np.c_[xs.ravel(), ys.ravel(), np.sin(xs.ravel())]
    i, j = (a.ravel() for a in np.meshgrid(np.arange(n), np.arange(n)))
    faces = np.c_[j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i]
    m = ShellMesh(pts, faces, (i // 100) % 5, ["skin", "rib_1", "rib 2", "spar", "x"])
    o = export_order(m)
    for ext in FORMATS:
        b = load_mesh(write_mesh(m, tmp_path / f"big.{ext}"))
        assert np.abs(b.points - m.points).max() <= _coord_tol(ext, m.points)
        assert np.array_equal(b.faces, m.faces[o]) and np.array_equal(b.component, m.component[o])
        assert b.component_names == m.component_names
