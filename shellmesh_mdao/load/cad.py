"""The load stage's CAD reader: STEP/IGES healed, sewn and tessellated by gmsh/OpenCASCADE (extra
``cad``).

Real CAD comes as separate patches whose shared edges are a little apart, with degenerate
edges and tiny faces. :func:`read_cad` heals the shapes with OpenCASCADE (``occ.healShapes``:
degenerated edges, small edges and faces fixed, faces sewn) at the smallest tolerance of
:data:`SEW_TOLERANCES` that sews the most (the one leaving the shortest free edges), so shared
patch edges become one edge and the tessellation has one vertex row along them. It then
tessellates the surfaces with gmsh (Frontal-Delaunay) at an element size derived from the
target size of the mesh to be made, refined where the curvature needs it, so the chordal
deviation stays a small fraction of the remesh's; surfaces gmsh cannot mesh fall back to
OpenCASCADE's own tessellation (BRepMesh, deflection bounded)."""
from __future__ import annotations

import contextlib
import math
import os
import sys
from pathlib import Path

import numpy as np

from ..errors import InputFileError, SizeError
from .raw import RawMesh

__all__ = ["read_cad", "cad_element_size", "SEW_TOLERANCES", "CURVATURE_ELEMENTS", "MIN_SIZE_FRACTION",
           "DEFAULT_SIZE_FRACTION"]

#: Sewing tolerances tried, as fractions of the bounding-box diagonal: the smallest that leaves
#: the shortest free (unshared) edges is kept.
SEW_TOLERANCES = (1e-7, 1e-6, 1e-5, 1e-4)
#: Elements per 2 pi of radius of curvature in the tessellation (chordal deviation about
#: 2 % of the radius where the curvature sets the size).
CURVATURE_ELEMENTS = 16
#: The smallest tessellation element, as a fraction of the element size (the deviation on
#: features sharper than that stays below about a third of it).
MIN_SIZE_FRACTION = 0.1
#: The element size without a target size, and the coarsest one, as a fraction of the diagonal.
DEFAULT_SIZE_FRACTION = 1.0 / 50.0
#: The finest element size derived from a target size, as a fraction of the diagonal.
FINEST_SIZE_FRACTION = 1.0 / 2000.0

_OPTIONS = ("General.Terminal", "Mesh.MeshSizeMax", "Mesh.MeshSizeMin", "Mesh.MeshSizeFromCurvature",
            "Mesh.MeshSizeExtendFromBoundary", "Mesh.Algorithm", "Mesh.StlLinearDeflection",
            "Mesh.StlLinearDeflectionRelative", "Mesh.StlAngularDeflection")


def cad_element_size(diagonal: float, cad_mesh_size=None, size=None) -> float:
    """The tessellation's element size: ``cad_mesh_size`` when given (a positive length, else a
    :class:`SizeError`); else the target element size ``size`` of the mesh to be made (the
    remesh then works at twice that and refines from it), kept between 1/2000 and 1/50 of the
    ``diagonal``; else diagonal / 50. A ``size`` that is not a usable number is ignored here
    (the pipeline refuses it with its own message)."""
    if cad_mesh_size is not None:
        try:
            h = float(cad_mesh_size)
        except (TypeError, ValueError):
            h = float("nan")
        if isinstance(cad_mesh_size, bool) or not math.isfinite(h) or h <= 0:
            raise SizeError(f"cad_mesh_size {cad_mesh_size!r} must be a positive length (the element size of the "
                            "STEP/IGES tessellation, in the model's units); give e.g. the target element size")
        return h
    coarse = DEFAULT_SIZE_FRACTION * diagonal
    try:
        s = float(size)
    except (TypeError, ValueError):
        return coarse
    if isinstance(size, bool) or not math.isfinite(s) or s <= 0:
        return coarse
    return float(min(max(s, FINEST_SIZE_FRACTION * diagonal), coarse))


@contextlib.contextmanager
def _quiet_stdout():
    """OpenCASCADE's readers print to the process's standard output: send it to /dev/null."""
    try:
        sys.stdout.flush()
        fd = os.dup(1)
    except (OSError, ValueError, AttributeError):
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 1)
            try:
                yield
            finally:
                os.dup2(fd, 1)
    finally:
        os.close(fd)


def _import(gmsh, p: Path) -> None:
    try:
        with _quiet_stdout():
            gmsh.model.occ.importShapes(str(p))
        gmsh.model.occ.synchronize()
    except Exception as e:
        raise InputFileError(f"cannot read {p.name}: OpenCASCADE import failed ({e}); "
                             "check that it is a valid STEP/IGES file") from None


def _free_curves(gmsh) -> tuple[float, int, int]:
    """(length of the curves bounding one surface, their number, number of curves bounding three
    or more surfaces) of the current model."""
    length, n_free, n_nm = 0.0, 0, 0
    for _, c in gmsh.model.getEntities(1):
        up = len(gmsh.model.getAdjacencies(1, c)[0])
        if up == 1:
            n_free += 1
            length += gmsh.model.occ.getMass(1, c)
        elif up > 2:
            n_nm += 1
    return length, n_free, n_nm


def _heal_and_sew(gmsh, p: Path, diag: float, base: str, models: list) -> dict:
    """Heal and sew the shapes of ``p`` at each tolerance of :data:`SEW_TOLERANCES` (the first
    in the current model ``base``, already imported, the others in a fresh import of their
    own); the current model is left at the smallest tolerance that leaves the shortest free
    edges without making non-manifold edges."""
    best = None
    for k, frac in enumerate(SEW_TOLERANCES):
        name = base if k == 0 else f"{base}_sew{k}"
        if k:
            gmsh.model.add(name)
            models.append(name)
            _import(gmsh, p)
        tol = frac * diag
        try:
            gmsh.model.occ.healShapes([], tol, True, True, True, True, False)
            gmsh.model.occ.synchronize()
            length, n_free, n_nm = _free_curves(gmsh)
            ok = n_nm == 0 and bool(gmsh.model.getEntities(2))
        except Exception:
            ok = False
        if ok and (best is None or length < best["free_length"] * (1.0 - 1e-6)):
            if best is not None:
                gmsh.model.setCurrent(best["model"])
                gmsh.model.remove()
                models.remove(best["model"])
            best = {"model": name, "tolerance": tol, "free_length": length, "n_free": n_free}
        else:
            gmsh.model.setCurrent(name)
            gmsh.model.remove()
            models.remove(name)
        if best is not None and best["free_length"] == 0.0:
            break
    if best is None:            # healing failed at every tolerance: the shapes as imported
        name = f"{base}_raw"
        gmsh.model.add(name)
        models.append(name)
        _import(gmsh, p)
        length, n_free, _ = _free_curves(gmsh)
        return {"model": name, "tolerance": 0.0, "free_length": length, "n_free": n_free}
    gmsh.model.setCurrent(best["model"])
    return best


def _mesh_arrays(gmsh):
    """Nodes and triangles of the current model's mesh (all surfaces)."""
    tags, coords, _ = gmsh.model.mesh.getNodes()
    tags = np.asarray(tags, np.int64)
    xyz = np.asarray(coords, np.float64).reshape(-1, 3)
    etypes, _, enodes = gmsh.model.mesh.getElements(2)
    tris = [np.asarray(n, np.int64).reshape(-1, 3) for t, n in zip(etypes, enodes) if t == 2]
    tri = np.vstack(tris) if tris else np.zeros((0, 3), np.int64)
    order = np.argsort(tags, kind="stable")
    idx = order[np.searchsorted(tags[order], tri)] if len(tri) else tri
    return xyz, idx


def _unmeshed(gmsh) -> list:
    out = []
    for _, s in gmsh.model.getEntities(2):
        etypes, _, _ = gmsh.model.mesh.getElements(2, s)
        if not len(etypes):
            out.append(s)
    return out


def _tessellate(gmsh, h: float) -> str:
    """Mesh the current model's surfaces: gmsh at element size ``h`` (down to
    :data:`MIN_SIZE_FRACTION` of it by the curvature), else OpenCASCADE's BRepMesh with a chordal
    deflection of ``h`` / 25. Returns the note saying which."""
    gmsh.option.setNumber("Mesh.MeshSizeMax", h)
    gmsh.option.setNumber("Mesh.MeshSizeMin", MIN_SIZE_FRACTION * h)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", CURVATURE_ELEMENTS)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.Algorithm", 6)
    n_surf = len(gmsh.model.getEntities(2))
    try:
        gmsh.model.mesh.generate(2)
        failed = _unmeshed(gmsh)
        why = f"{len(failed)} of {n_surf} surfaces"
    except Exception as e:
        failed = [s for _, s in gmsh.model.getEntities(2)]
        why = f"gmsh failed ({str(e).strip().splitlines()[0][:200] if str(e).strip() else type(e).__name__})"
    if not failed:
        return (f"tessellated by gmsh: element size {h:.4g}, down to {MIN_SIZE_FRACTION * h:.3g} where the "
                f"curvature needs it ({CURVATURE_ELEMENTS} elements per 2 pi radius)")
    gmsh.model.mesh.clear()
    gmsh.option.setNumber("Mesh.StlLinearDeflection", h / 25.0)
    gmsh.option.setNumber("Mesh.StlLinearDeflectionRelative", 0)
    gmsh.option.setNumber("Mesh.StlAngularDeflection", 0.2)
    gmsh.model.mesh.importStl()
    gmsh.model.mesh.removeDuplicateNodes()
    return (f"tessellated by OpenCASCADE (BRepMesh, chordal deflection {h / 25.0:.3g}, 0.2 rad) because gmsh "
            f"could not mesh {why}")


def read_cad(p: Path, cad_mesh_size=None, size=None) -> RawMesh:
    """STEP/IGES file ``p`` healed, sewn and tessellated (see the module text). The element size
    is :func:`cad_element_size` (``cad_mesh_size``, else from the target size ``size``, else
    diagonal / 50). The notes say the sewing tolerance, the free edges left and the
    tessellation. gmsh options changed here are restored and the models made here removed, so
    a caller's gmsh session is left as it was."""
    try:
        import gmsh
    except Exception:
        raise InputFileError(f"reading {p.name} (STEP/IGES) needs gmsh: pip install shellmesh_mdao[cad]") from None
    own = not gmsh.isInitialized()
    if own:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    saved = {o: gmsh.option.getNumber(o) for o in _OPTIONS}
    try:
        previous = gmsh.model.getCurrent()
    except Exception:
        previous = None
    base = f"shellmesh_load_{id(p)}"
    models = [base]
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(base)
        _import(gmsh, p)
        if not gmsh.model.getEntities(2):
            raise InputFileError(f"{p.name} contains no surfaces (only curves/points); export surfaces or solids")
        x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(-1, -1)
        diag = float(np.linalg.norm([x1 - x0, y1 - y0, z1 - z0]))
        h = cad_element_size(diag, cad_mesh_size, size)
        sew = _heal_and_sew(gmsh, p, diag, base, models)
        n_surf = len(gmsh.model.getEntities(2))
        how = _tessellate(gmsh, h)
        xyz, idx = _mesh_arrays(gmsh)
        notes = [f"{n_surf} CAD surfaces healed and sewn by OpenCASCADE (tolerance {sew['tolerance']:.3g}); "
                 f"{sew['n_free']} free curves ({sew['free_length']:.4g} long) bound the surface",
                 how, "OpenCASCADE converts STEP/IGES lengths to millimetres"]
        return RawMesh(xyz, idx, notes=notes, fmt="STEP" if p.suffix.lower() in (".step", ".stp") else "IGES")
    finally:
        for m in models:
            try:
                gmsh.model.setCurrent(m)
                gmsh.model.remove()
            except Exception:
                pass
        if own:
            gmsh.finalize()
        else:
            for o, v in saved.items():
                gmsh.option.setNumber(o, v)
            if previous:
                try:
                    gmsh.model.setCurrent(previous)
                except Exception:
                    pass
