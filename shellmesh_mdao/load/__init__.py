"""Read surface triangulations and meshes into :class:`~shellmesh_mdao.mesh.ShellMesh`.

:func:`load_surface` reads an input surface (STL/OBJ/PLY/OFF through trimesh, VTU/MSH
through meshio, VTK/VTP through pyvista, Nastran through pyNastran (our own files through a
vectorised reader), CalculiX/Abaqus INP with our own reader,
STEP/IGES through gmsh's OpenCASCADE tessellation), merges duplicate vertices, drops
collapsed and duplicated faces, and returns the mesh with a :class:`SurfaceReport` that
counts what it did and what is wrong (open edges, non-manifold edges, several bodies,
inconsistent orientation, a half model's symmetry plane, suspicious units) without repairing it.

:func:`repair_surface` (``load_surface(..., repair=True)``; the pipeline's load stage) makes a
surface as CAD exports really come ready for meshing or refuses it with a
:class:`MeshValidationError` naming the defect, where it is and the fix: faces oriented
consistently and outward per body, intersecting bodies joined by a boolean union
(manifold3d), a half model's symmetry-plane boundary accepted and reported (the clamped
edge), an open blunt trailing edge closed by a strip of triangles (reported), the input's
groups read as the skin, non-manifold edges and other open boundaries refused, a warning for
unlikely units.
The policy per defect is tabulated in ``docs/troubleshooting.md``.

:func:`load_mesh` reads one of our own output files (.vtu, .msh, .bdf/.nas, .inp) back
exactly, with its components, node order and element order (see
:mod:`shellmesh_mdao.export`).

Modules: ``raw`` (the raw mesh a reader returns, the format tables, path checks),
``readers`` (the file readers), ``cad`` (STEP/IGES healed, sewn and tessellated through gmsh),
``clean`` (the cleaning every load does), ``report`` (:class:`SurfaceReport`), ``gaps`` (open
gaps closed by strips), ``repair`` (dirty inputs: the defects counted, handled or refused),
``api`` (:func:`load_surface`, :func:`repair_surface`, :func:`load_mesh`).
"""
from __future__ import annotations

from .api import load_mesh, load_surface, repair_surface
from .raw import MAX_COORDINATE, MESH_FORMATS, SURFACE_FORMATS
from .repair import UNITS_DIAGONAL_RANGE, symmetry_boundary_vertices
from .report import SurfaceReport

__all__ = ["load_surface", "repair_surface", "load_mesh", "SurfaceReport", "symmetry_boundary_vertices",
           "SURFACE_FORMATS", "MESH_FORMATS", "UNITS_DIAGONAL_RANGE", "MAX_COORDINATE"]
