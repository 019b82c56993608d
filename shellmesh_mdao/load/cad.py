"""The load stage's CAD reader: STEP/IGES tessellated by gmsh's OpenCASCADE (extra ``cad``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputFileError
from .raw import RawMesh

__all__ = ["read_cad"]


def read_cad(p: Path, size=None) -> RawMesh:
    """STEP/IGES file ``p`` tessellated by gmsh at element size ``size`` (default diagonal / 50)."""
    try:
        import gmsh
    except Exception:
        raise InputFileError(f"reading {p.name} (STEP/IGES) needs gmsh: pip install shellmesh_mdao[cad]") from None
    own = not gmsh.isInitialized()
    if own:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    model_name = f"shellmesh_load_{id(p)}"
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(model_name)
        try:
            gmsh.model.occ.importShapes(str(p))
            gmsh.model.occ.synchronize()
        except Exception as e:
            raise InputFileError(f"cannot read {p.name}: OpenCASCADE import failed ({e}); "
                                 "check that it is a valid STEP/IGES file") from None
        if not gmsh.model.getEntities(2):
            raise InputFileError(f"{p.name} contains no surfaces (only curves/points); export surfaces or solids")
        x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(-1, -1)
        diag = float(np.linalg.norm([x1 - x0, y1 - y0, z1 - z0]))
        h = float(size) if size else diag / 50.0
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.option.setNumber("Mesh.MeshSizeMin", h / 20.0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 12)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.model.mesh.generate(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        tags = np.asarray(tags, np.int64)
        xyz = np.asarray(coords, np.float64).reshape(-1, 3)
        etypes, _, enodes = gmsh.model.mesh.getElements(2)
        tris = [np.asarray(n, np.int64).reshape(-1, 3) for t, n in zip(etypes, enodes) if t == 2]
        tri = np.vstack(tris) if tris else np.zeros((0, 3), np.int64)
        order = np.argsort(tags, kind="stable")
        idx = order[np.searchsorted(tags[order], tri)]
        notes = ["tessellated by gmsh/OpenCASCADE with element size "
                 f"{h:.4g}; OpenCASCADE converts STEP/IGES lengths to millimetres"]
        return RawMesh(xyz, idx, notes=notes, fmt="STEP" if p.suffix.lower() in (".step", ".stp") else "IGES")
    finally:
        try:
            gmsh.model.setCurrent(model_name)
            gmsh.model.remove()
        except Exception:
            pass
        if own:
            gmsh.finalize()
