"""The load stage's raw mesh as a reader returns it (:class:`RawMesh`), the tables of the formats
it reads, and the checks of a path and of what was read."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputFileError, MeshValidationError
from ..families import SKIN

__all__ = ["SURFACE_FORMATS", "MESH_FORMATS", "DEFAULT_NAME", "MAX_COORDINATE", "RawMesh", "check_path", "validate_raw"]

#: Extensions :func:`load_surface` reads, and the library that reads them.
SURFACE_FORMATS = {
    ".stl": "trimesh", ".obj": "trimesh", ".ply": "trimesh", ".off": "trimesh",
    ".vtk": "pyvista/VTK", ".vtp": "pyvista/VTK", ".vtu": "meshio (pyvista/VTK if meshio fails)",
    ".msh": "meshio (Gmsh MSH 2.2/4.x)",
    ".bdf": "pyNastran", ".nas": "pyNastran", ".inp": "shellmesh_mdao INP reader",
    ".step": "gmsh/OpenCASCADE (extra 'cad')", ".stp": "gmsh/OpenCASCADE (extra 'cad')",
    ".iges": "gmsh/OpenCASCADE (extra 'cad')", ".igs": "gmsh/OpenCASCADE (extra 'cad')",
}
#: Extensions :func:`load_mesh` reads (our output formats).
MESH_FORMATS = (".vtu", ".msh", ".bdf", ".nas", ".inp")

#: The component name of a surface whose file names none.
DEFAULT_NAME = SKIN
#: Coordinates beyond this magnitude are refused (corrupt file; a 1 km aircraft in micrometres is 1e9).
MAX_COORDINATE = 1e15


# =========================================================================== path checks
def check_path(path, supported, what: str) -> Path:
    """``path`` as a :class:`~pathlib.Path`, or an :class:`InputFileError` saying why it cannot be
    read: missing, a folder, an extension not in ``supported``, empty."""
    p = Path(path)
    if not p.exists():
        raise InputFileError(f"{what} file {p} not found; check the path")
    if p.is_dir():
        raise InputFileError(f"{p} is a folder, not a {what} file; give the file itself")
    ext = p.suffix.lower()
    if ext not in supported:
        raise InputFileError(f"cannot read {p.name}: unknown extension {p.suffix!r}; supported: "
                             + ", ".join(supported))
    if p.stat().st_size == 0:
        raise InputFileError(f"{p} is empty (0 bytes); re-export the file")
    return p


class RawMesh:
    """Raw mesh as read: points, (m, 4) faces, component ids, names, extras."""

    def __init__(self, points, faces, component=None, names=None, fixed=None, fe=None, fe_ids=None,
                 notes=None, fmt=""):
        self.points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        f = np.asarray(faces, dtype=np.int64)
        if f.size == 0:
            f = np.zeros((0, 4), np.int64)
        if f.shape[1] == 3:
            f = np.hstack([f, np.full((len(f), 1), -1, np.int64)])
        self.faces = f
        self.component = (np.zeros(len(f), np.int32) if component is None
                          else np.asarray(component, dtype=np.int32))
        self.names = list(names) if names else [DEFAULT_NAME]
        self.fixed = fixed
        self.fe = fe
        self.fe_ids = fe_ids
        self.notes = list(notes or [])
        self.fmt = fmt


def validate_raw(raw: RawMesh, p: Path) -> None:
    """Refuse what a reader returned when it has no faces, NaN/inf or absurd coordinates, or faces
    referencing missing vertices."""
    if not len(raw.faces):
        raise InputFileError(f"{p.name} contains no triangles or quads"
                             + (f" ({'; '.join(raw.notes)})" if raw.notes else "")
                             + "; give a surface mesh file")
    bad = ~np.isfinite(raw.points).all(1)
    if bad.any():
        raise MeshValidationError(f"{p.name}: {int(bad.sum())} of {len(raw.points)} vertices have NaN/inf "
                                  "coordinates; fix or re-export the file")
    big = float(np.abs(raw.points).max()) if len(raw.points) else 0.0
    if big > MAX_COORDINATE:
        raise MeshValidationError(f"{p.name}: coordinates as large as {big:.3g} are not lengths in any unit (the "
                                  "file is corrupt or was scaled wrongly); fix or re-export the file")
    f = raw.faces
    if f[:, :3].min() < 0 or f.max() >= len(raw.points):
        raise InputFileError(f"{p.name}: faces reference vertices that do not exist (file truncated or "
                             "corrupt); re-export the file")
