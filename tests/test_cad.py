"""CAD input (STEP/IGES through gmsh/OpenCASCADE): healed and sewn, tessellated at a size derived
from the target element size, an open blunt trailing edge closed; the corpus CAD wing
(``ucrm_wing.igs``: unsewn B-spline patches, trailing edge open inboard, root on y = 0) loads to
a half model and goes through the remesh."""
import json

import numpy as np
import pytest

from shellmesh_mdao.errors import SizeError
from shellmesh_mdao.load import load_surface, repair_surface, symmetry_boundary_vertices
from shellmesh_mdao.load.cad import (DEFAULT_SIZE_FRACTION, FINEST_SIZE_FRACTION, MIN_SIZE_FRACTION,
                                     cad_element_size)

gmsh = pytest.importorskip("gmsh")

UCRM_SIZE = 12.85


class _Session:
    """gmsh initialised for the test's own models (finalised after) unless it already was."""

    def __enter__(self):
        self.own = not gmsh.isInitialized()
        if self.own:
            gmsh.initialize(readConfigFiles=False, interruptible=False)
        gmsh.option.setNumber("General.Terminal", 0)
        return gmsh

    def __exit__(self, *exc):
        if self.own:
            gmsh.finalize()


def _unsewn_box_step(path, gap=0.0):
    """A 1 x 2 x 3 box written as six separate faces (no shared edges; one face moved by ``gap``
    along x), as CAD exports surfaces that were never sewn."""
    with _Session():
        gmsh.model.add("unsewn")
        box = gmsh.model.occ.addBox(0, 0, 0, 1, 2, 3)
        gmsh.model.occ.synchronize()
        faces = gmsh.model.getBoundary([(3, box)], oriented=False)
        copies = [gmsh.model.occ.copy([f])[0] for f in faces]
        gmsh.model.occ.remove([(3, box)], recursive=True)
        if gap:
            gmsh.model.occ.translate([copies[0]], gap, 0, 0)
        gmsh.model.occ.synchronize()
        gmsh.write(str(path))
        gmsh.model.remove()
    return path


# ------------------------------------------------------------------ element size
def test_cad_element_size_follows_the_target_size_within_bounds():
    d = 1000.0
    assert cad_element_size(d) == d * DEFAULT_SIZE_FRACTION
    assert cad_element_size(d, size=7.5) == 7.5
    assert cad_element_size(d, size=1e6) == d * DEFAULT_SIZE_FRACTION          # never coarser than the default
    assert cad_element_size(d, size=1e-6) == d * FINEST_SIZE_FRACTION
    assert cad_element_size(d, size="abc") == cad_element_size(d, size=-1.0) == d * DEFAULT_SIZE_FRACTION
    assert cad_element_size(d, cad_mesh_size=3.0, size=7.5) == 3.0            # an explicit size wins
    for bad in (0.0, -1.0, float("nan"), "x", True):
        with pytest.raises(SizeError, match="cad_mesh_size .* must be a positive length"):
            cad_element_size(d, cad_mesh_size=bad)


# ------------------------------------------------------------------ healing and sewing
@pytest.mark.parametrize("gap", [0.0, 2e-5])
def test_unsewn_faces_are_sewn_into_one_closed_body(tmp_path, gap):
    path = _unsewn_box_step(tmp_path / "faces.step", gap)
    with _Session():                               # the faces really are separate in the file
        gmsh.model.add("check")
        gmsh.model.occ.importShapes(str(path))
        gmsh.model.occ.synchronize()
        assert len(gmsh.model.getEntities(2)) == 6 and len(gmsh.model.getEntities(1)) == 24
        gmsh.model.remove()
    mesh, rep = repair_surface(path, size=0.05)
    assert rep.closed and rep.n_bodies == 1 and rep.n_nonmanifold_edges == 0 and mesh.check().ok
    assert mesh.face_areas().sum() == pytest.approx(22.0, rel=1e-4)
    assert any("healed and sewn by OpenCASCADE" in n and "0 free curves" in n for n in rep.notes)
    assert any("element size 0.05," in n for n in rep.notes)
    assert mesh.edge_lengths().max() <= 0.05 * 1.5


def test_gmsh_failure_falls_back_to_the_opencascade_tessellation(tmp_path, monkeypatch):
    path = _unsewn_box_step(tmp_path / "faces.step")

    def fail(*a, **k):
        raise Exception("meshing failed on purpose")
    monkeypatch.setattr(gmsh.model.mesh, "generate", fail)
    mesh, rep = repair_surface(path, size=0.5)
    assert rep.closed and rep.n_bodies == 1
    assert mesh.face_areas().sum() == pytest.approx(22.0, rel=1e-9)         # flat faces: exact
    assert any("tessellated by OpenCASCADE (BRepMesh" in n and "meshing failed on purpose" in n for n in rep.notes)


def test_a_callers_gmsh_session_is_left_as_it_was(tmp_path):
    path = _unsewn_box_step(tmp_path / "faces.step")
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("mine")
        gmsh.model.occ.addSphere(0, 0, 0, 1)
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", 123.0)
        gmsh.option.setNumber("Mesh.Algorithm", 5)
        models = gmsh.model.list()
        mesh, rep = load_surface(path, size=0.5)
        assert rep.closed
        assert gmsh.model.getCurrent() == "mine" and gmsh.model.list() == models
        assert len(gmsh.model.getEntities(3)) == 1
        assert gmsh.option.getNumber("Mesh.MeshSizeMax") == 123.0 and gmsh.option.getNumber("Mesh.Algorithm") == 5
    finally:
        gmsh.finalize()


# ------------------------------------------------------------------ the corpus CAD wing
@pytest.fixture(scope="module")
def ucrm(geometry_dir):
    path = geometry_dir / "ucrm_wing.igs"
    mesh, rep = repair_surface(path, size=UCRM_SIZE)
    with _Session():                      # gmsh's own area of the CAD surfaces, as imported
        gmsh.model.add("area")
        gmsh.model.occ.importShapes(str(path))
        gmsh.model.occ.synchronize()
        area = sum(gmsh.model.occ.getMass(2, s) for _, s in gmsh.model.getEntities(2))
        gmsh.model.remove()
    return path, mesh, rep, area


def test_cad_wing_loads_to_a_half_model_with_its_open_trailing_edge_closed(ucrm):
    path, mesh, rep, cad_area = ucrm
    assert rep.format == "IGES" and rep.n_bodies == 1 and rep.n_nonmanifold_edges == 0 and mesh.check().ok
    # a half model: every open edge lies in the symmetry plane y = 0 (the root)
    sp = rep.symmetry_plane
    assert sp["axis"] == "y" and abs(sp["offset"]) < 1e-9
    bv = np.unique(mesh.boundary_edges())
    assert np.abs(mesh.points[bv, 1]).max() < 1e-9 and rep.n_boundary_loops == 1
    assert np.array_equal(symmetry_boundary_vertices(mesh, sp), bv)
    # the blunt trailing edge, open from the root to y = 77.6, closed by one strip
    (g,) = rep.closed_gaps
    assert g["start"][1] == pytest.approx(0.0, abs=1e-6) and g["end"][1] == pytest.approx(77.59, abs=0.05)
    assert 80.0 < g["length"] < 82.0 and 0.3 < g["width_min"] <= g["width_max"] < 0.5
    assert any(r.startswith("closed an open gap (an open blunt trailing edge) 80.9 long") for r in rep.repairs)
    # the surface is the CAD's: its area within 0.1 % of gmsh's area of the CAD surfaces (plus the strip)
    assert mesh.face_areas().sum() - g["area"] == pytest.approx(cad_area, rel=1e-3)
    lo, hi = np.array(rep.bbox_min), np.array(rep.bbox_max)
    assert np.allclose(lo[1], 0.0, atol=1e-6) and hi[1] == pytest.approx(749.95, abs=0.1)
    assert any("tessellated by gmsh: element size 12.85" in n for n in rep.notes)
    assert rep.component_names == ["skin"]
    json.dumps(rep.to_dict())


def test_cad_wing_without_repair_reports_the_sewn_surface(ucrm):
    path, mesh, rep, _ = ucrm
    m0, r0 = load_surface(path, size=UCRM_SIZE)
    # sewn: one body whose only open boundary is the root and the open trailing edge (one loop)
    assert r0.n_bodies == 1 and r0.n_boundary_loops == 1 and r0.n_nonmanifold_edges == 0
    assert r0.symmetry_plane is None and not r0.closed_gaps
    assert any("5 free curves" in n for n in r0.notes)
    assert mesh.n_faces - m0.n_faces == rep.closed_gaps[0]["n_triangles"]


def test_cad_wing_runs_through_the_remesh(ucrm, manifest):
    from shellmesh_mdao.layout import layout_from_manifest
    from shellmesh_mdao.pipeline import run_pipeline

    path = ucrm[0]
    lay = layout_from_manifest(manifest, "ucrm_wing", ribs=10, spars=[0.15, 0.65])
    res = run_pipeline(path, lay, UCRM_SIZE, until="remesh", progress=False)
    m = res.mesh
    assert m.n_faces > 1000 and len(m.nonmanifold_edges()) == 0
    bv = np.unique(m.boundary_edges())
    assert len(bv) and np.abs(m.points[bv, 1]).max() < 1e-9          # only the root is open
    assert res.report["surface"]["closed_gaps"] and res.report["surface"]["symmetry_plane"]["axis"] == "y"
