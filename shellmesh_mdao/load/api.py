"""The load stage's entry points: :func:`load_surface`, :func:`repair_surface`, :func:`load_mesh`."""
from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from ..errors import InputFileError, MeshValidationError
from ..mesh import ShellMesh
from .clean import clean_to_mesh
from .raw import MESH_FORMATS, SURFACE_FORMATS, RawMesh, check_path, validate_raw
from .readers import read_file
from .repair import describe_surface, read_as_skin, repair_defects
from .report import SurfaceReport

__all__ = ["load_surface", "repair_surface", "load_mesh"]

log = logging.getLogger("shellmesh_mdao")


# =========================================================================== public API
def load_surface(path, merge_tol: float | None = 1e-9, *, cad_mesh_size: float | None = None,
                 repair: bool = False, allow_open: bool = False, union: bool = True, size=None,
                 close_gaps: bool = True, keep_groups: bool = False) -> tuple[ShellMesh, SurfaceReport]:
    """Read a surface triangulation (or mixed tri/quad surface) and report on it.

    Formats: STL/OBJ/PLY/OFF (trimesh, ``process=False``), VTU/MSH (meshio), VTK/VTP (pyvista),
    Nastran .bdf/.nas (pyNastran; GRID + CTRIA3/CQUAD4/CTRIAR/CQUADR), CalculiX/Abaqus .inp,
    STEP/STP/IGES/IGS (needs the ``cad`` extra: healed, sewn and tessellated by gmsh/OpenCASCADE,
    see :func:`~shellmesh_mdao.load.cad.read_cad`; element size ``cad_mesh_size``, else ``size``
    (the target element size of the mesh to be made, as the pipeline passes it), else
    diagonal / 50).

    Cleaning always done here, each counted in the report: vertices closer than ``merge_tol``
    times the bounding-box diagonal are merged (``None`` or ``0`` merges only exact
    duplicates); faces whose nodes collapse are removed (a quad with one repeated adjacent
    node becomes a triangle); faces repeating another face's node set are removed (first
    kept); unused vertices are dropped.

    With ``repair=False`` (the default; ``shellmesh info``) open boundaries, non-manifold
    edges, several bodies, inconsistent orientation and zero-area faces are counted, never
    repaired; a half model's symmetry plane is detected and reported; a units warning is
    added when the diagonal is outside :data:`UNITS_DIAGONAL_RANGE`. With ``repair=True``
    the surface is made ready for meshing or refused: see :func:`repair_surface` (also for
    ``allow_open``, ``union``, ``close_gaps`` and ``keep_groups``).

    Raises :class:`InputFileError` (missing file, folder, unknown extension, empty or
    unreadable file) or :class:`MeshValidationError` (NaN/inf coordinates; with ``repair``
    the defects :func:`repair_surface` refuses)."""
    t0 = time.perf_counter()
    p = check_path(path, SURFACE_FORMATS, "surface")
    raw = read_file(p, cad_mesh_size, size)
    validate_raw(raw, p)
    return _load_raw(raw, p.name, str(p), merge_tol, repair, (allow_open, union, close_gaps, keep_groups), t0)


def _load_raw(raw, name, path, merge_tol, repair, how, t0):
    mesh, counts, notes = clean_to_mesh(raw, name, merge_tol)
    if repair:
        allow_open, union, close_gaps, keep_groups = how
        mesh, repairs, warns, known = repair_defects(mesh, name, allow_open, union, close_gaps)
        if not keep_groups:
            mesh, line = read_as_skin(mesh)
            if line:
                repairs.append(line)
        report = describe_surface(mesh, raw.fmt, path, counts, notes, known)
        report.repaired = True
        report.repairs = repairs
        report.warnings = warns + report.warnings
    else:
        report = describe_surface(mesh, raw.fmt, path, counts, notes)
    for w in report.warnings:
        log.warning("warning: %s: %s", name, w)
    report.load_seconds = time.perf_counter() - t0
    return mesh, report


def repair_surface(surface, merge_tol: float | None = 1e-9, *, allow_open: bool = False, union: bool = True,
                   cad_mesh_size: float | None = None, size=None, close_gaps: bool = True,
                   keep_groups: bool = False) -> tuple[ShellMesh, SurfaceReport]:
    """Load (a path) or take (a :class:`ShellMesh`) a surface and make it ready for meshing,
    or refuse it with a :class:`MeshValidationError` naming the defect, where it is and the
    fix. What it does per defect (each change is a line of ``report.repairs``; the report's
    counts describe the returned mesh):

    * duplicated vertices: merged (``merge_tol`` times the diagonal); duplicated and
      degenerate faces: dropped (counted), as in :func:`load_surface`;
    * non-manifold edges (three or more faces on an edge): refused, naming where;
    * inconsistent orientation: faces re-oriented per body so that neighbours agree, then
      every body turned to face outward (positive enclosed volume); a non-orientable body
      is refused;
    * open boundaries: when all open-boundary vertices lie in one plane and the surface lies on
      one side of it and leaves it (faces lying in the plane next to the boundary only as thin
      strips, :data:`~.repair.SYMMETRY_MAX_FLAT`: a thin fin or trailing edge meeting the plane
      at a shallow angle), the surface is a **half model**: accepted, and
      ``report.symmetry_plane`` (normal pointing away from the surface, a point, the axis of a
      coordinate plane) and ``report.symmetry_vertices`` name the boundary to clamp
      (:func:`symmetry_boundary_vertices` finds it again in any later mesh);
    * open gaps: an open blunt trailing edge (two long, nearly parallel open boundary curves
      a small distance apart, joined at their ends or ending on the symmetry plane) is closed
      by a strip of triangles when that leaves the surface closed or a half model
      (``report.closed_gaps`` and a line of ``report.repairs`` say where, how long and how
      wide; :mod:`~shellmesh_mdao.load.gaps` has the criteria); ``close_gaps=False``
      refuses it instead. Other open boundaries (holes, cracks, open tips) are refused, or
      with ``allow_open=True`` kept as free edges with a warning;
    * several bodies: bodies whose volumes overlap (a wing through a fuselage) are joined
      by a boolean union with manifold3d (for a half model each body is closed by its
      mirror image, united, and cut back at the symmetry plane); bodies that touch nothing
      are kept as they are. ``union=False`` keeps overlapping bodies unjoined;
    * units: a diagonal outside :data:`UNITS_DIAGONAL_RANGE` gives a warning
      (``report.warnings``, and logged) naming the likely unit mistake;
    * groups: every group (component) of the input is read as the one component ``skin``
      (the surface is the skin; members come from the layout), with a line of
      ``report.repairs`` naming the groups; ``keep_groups=True`` keeps them.

    ``size`` (the target element size, as the pipeline passes it) sets the tessellation of a
    STEP/IGES file (:func:`~shellmesh_mdao.load.cad.read_cad`) unless ``cad_mesh_size`` is
    given. Fixed vertices and feature edges of a :class:`ShellMesh` input are not kept."""
    t0 = time.perf_counter()
    if isinstance(surface, ShellMesh):
        raw = RawMesh(surface.points, surface.faces, surface.component, surface.component_names, fmt="ShellMesh")
        if not len(raw.faces):
            raise MeshValidationError("the surface mesh has no faces; give a non-empty surface")
        bad = ~np.isfinite(raw.points).all(1)
        if bad.any():
            raise MeshValidationError(f"the surface mesh has {int(bad.sum())} of {len(raw.points)} vertices with "
                                      "NaN/inf coordinates; fix the mesh first (ShellMesh.check lists them)")
        return _load_raw(raw, "surface", "<mesh>", merge_tol, True, (allow_open, union, close_gaps, keep_groups),
                         t0)
    return load_surface(surface, merge_tol, cad_mesh_size=cad_mesh_size, repair=True, allow_open=allow_open,
                        union=union, size=size, close_gaps=close_gaps, keep_groups=keep_groups)


def load_mesh(path) -> ShellMesh:
    """Read one of our output files (.vtu, .msh, .bdf/.nas, .inp) back exactly: node order,
    element order (the writers' export order), component ids and names; from .vtu also the
    feature edges (line cells) and fixed vertices.  Nothing is merged or removed.

    Raises :class:`InputFileError` for a missing/unreadable/empty file or another extension
    (use :func:`load_surface` for input surfaces), :class:`MeshValidationError` for NaN/inf."""
    p = Path(path)
    if p.exists() and not p.is_dir() and p.suffix.lower() in SURFACE_FORMATS \
            and p.suffix.lower() not in MESH_FORMATS:
        raise InputFileError(f"cannot read {p.name} as a mesh: load_mesh reads our output formats "
                             f"({', '.join(MESH_FORMATS)}); use load_surface for {p.suffix} input surfaces")
    p = check_path(p, MESH_FORMATS, "mesh")
    raw = read_file(p)
    validate_raw(raw, p)
    try:
        return ShellMesh(raw.points, raw.faces, raw.component, raw.names, raw.fixed, raw.fe, raw.fe_ids)
    except MeshValidationError as e:
        raise InputFileError(f"{p.name}: {e}; re-export the file") from None
