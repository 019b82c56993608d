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
edge), non-manifold edges and other open boundaries refused, a warning for unlikely units.
The policy per defect is tabulated in ``docs/troubleshooting.md``.

:func:`load_mesh` reads one of our own output files (.vtu, .msh, .bdf/.nas, .inp) back
exactly, with its components, node order and element order (see
:mod:`shellmesh_mdao.export`).
"""
from __future__ import annotations

import contextlib
import json
import logging
import re
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from .errors import InputFileError, MeshValidationError, ShellMeshError
from .mesh import ShellMesh, merge_close_points

__all__ = ["load_surface", "repair_surface", "load_mesh", "SurfaceReport", "symmetry_boundary_vertices",
           "SURFACE_FORMATS", "MESH_FORMATS", "UNITS_DIAGONAL_RANGE"]

log = logging.getLogger("shellmesh_mdao")

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

_DEFAULT_NAME = "skin"
#: Coordinates beyond this magnitude are refused (corrupt file; a 1 km aircraft in micrometres is 1e9).
MAX_COORDINATE = 1e15


# =========================================================================== report
@dataclass
class SurfaceReport:
    """What :func:`load_surface` / :func:`repair_surface` found and did.

    The counts describe the returned mesh. ``repairs`` lists what :func:`repair_surface`
    changed (empty when only loaded); ``symmetry_plane`` (``normal`` pointing away from the
    surface, ``point``, ``offset`` = point . normal, ``axis`` 'x'/'y'/'z' or None) is set for a
    half model whose open boundary lies in one plane, ``symmetry_vertices`` are those
    boundary vertices (indices into the returned mesh: the clamped/symmetry boundary);
    ``warnings`` holds units warnings and accepted defects."""

    path: str
    format: str
    n_triangles: int
    n_quads: int
    n_vertices: int
    bbox_min: tuple
    bbox_max: tuple
    diagonal: float
    closed: bool
    n_open_boundary_edges: int
    n_nonmanifold_edges: int
    n_bodies: int
    n_inconsistent_orientation_edges: int
    n_merged_vertices: int
    n_removed_duplicate_faces: int
    n_removed_degenerate_faces: int
    n_zero_area_faces: int = 0
    n_components: int = 1
    component_names: list = field(default_factory=list)
    units: str = ""
    load_seconds: float = 0.0
    notes: list = field(default_factory=list)
    n_boundary_loops: int = 0
    symmetry_plane: dict | None = None
    symmetry_vertices: list = field(default_factory=list)
    repaired: bool = False
    repairs: list = field(default_factory=list)
    warnings: list = field(default_factory=list)

    def to_dict(self) -> dict:
        """Plain JSON-serialisable dict of every field."""
        d = asdict(self)
        d["bbox_min"] = [float(v) for v in self.bbox_min]
        d["bbox_max"] = [float(v) for v in self.bbox_max]
        return d

    @property
    def problems(self) -> list[str]:
        """One line per defect found (empty for a clean, closed, single-body surface)."""
        out = []
        if self.n_open_boundary_edges:
            sym = ""
            if self.symmetry_plane:
                sp = self.symmetry_plane
                sym = f"; all in the symmetry plane {_plane_text(sp['normal'], sp['point'], sp['axis'])} (half model)"
            out.append(f"{self.n_open_boundary_edges} open boundary edges in {self.n_boundary_loops} loop(s) "
                       f"(surface is not closed){sym}")
        if self.n_nonmanifold_edges:
            out.append(f"{self.n_nonmanifold_edges} non-manifold edges (more than two faces on an edge)")
        if self.n_bodies > 1:
            out.append(f"{self.n_bodies} separate bodies")
        if self.n_inconsistent_orientation_edges:
            out.append(f"{self.n_inconsistent_orientation_edges} edges where neighbouring faces have "
                       "opposite orientation")
        if self.n_zero_area_faces:
            out.append(f"{self.n_zero_area_faces} zero-area faces (distinct but collinear nodes)")
        return out

    def summary_lines(self) -> list[str]:
        """Human-readable summary, one line per fact."""
        lo = ", ".join(f"{v:.6g}" for v in self.bbox_min)
        hi = ", ".join(f"{v:.6g}" for v in self.bbox_max)
        lines = [
            f"{self.path} ({self.format}): {self.n_triangles} triangles, {self.n_quads} quads, "
            f"{self.n_vertices} vertices, read in {self.load_seconds:.2f} s",
            f"bounding box [{lo}] .. [{hi}], diagonal {self.diagonal:.6g}; units: {self.units}",
            f"{'closed' if self.closed else 'open'}, {self.n_bodies} bod{'y' if self.n_bodies == 1 else 'ies'}, "
            f"{self.n_components} component(s): {', '.join(self.component_names)}",
            f"cleaned: merged {self.n_merged_vertices} duplicate vertices, removed "
            f"{self.n_removed_duplicate_faces} duplicate and {self.n_removed_degenerate_faces} degenerate faces",
        ]
        probs = self.problems
        lines.append("problems: " + ("; ".join(probs) if probs else "none"))
        lines.extend(f"note: {n}" for n in self.notes)
        lines.extend(f"repaired: {r}" for r in self.repairs)
        lines.extend(f"warning: {w}" for w in self.warnings)
        return lines


# =========================================================================== path checks
def _check_path(path, supported, what: str) -> Path:
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


class _Raw:
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
        self.names = list(names) if names else [_DEFAULT_NAME]
        self.fixed = fixed
        self.fe = fe
        self.fe_ids = fe_ids
        self.notes = list(notes or [])
        self.fmt = fmt


def _validate_raw(raw: _Raw, p: Path) -> None:
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


def _read(p: Path, cad_mesh_size=None) -> _Raw:
    ext = p.suffix.lower()
    try:
        if ext in (".stl", ".obj", ".ply", ".off"):
            return _read_trimesh(p)
        if ext in (".vtk", ".vtp"):
            return _read_pyvista(p)
        if ext == ".vtu":
            try:
                return _read_meshio(p)
            except Exception as e:
                first = e                   # other VTU flavours (appended raw, compressed): VTK
            try:
                raw = _read_pyvista(p)
            except Exception:
                raw = None
            if raw is None or not len(raw.faces):
                raise first
            return raw
        if ext == ".msh":
            return _read_meshio(p)
        if ext in (".bdf", ".nas"):
            return _read_bdf(p)
        if ext == ".inp":
            return _read_inp(p)
        if ext in (".step", ".stp", ".iges", ".igs"):
            return _read_cad(p, cad_mesh_size)
    except (ShellMeshError, ImportError):
        raise       # a missing library is an installation problem, not a corrupt file
    except MemoryError:
        raise InputFileError(f"{p.name} is too large to read into memory; use a machine with more memory or "
                             "export a coarser triangulation") from None
    except (Exception, SystemExit) as e:  # library errors on garbage/truncated files
        msg = str(e).strip().splitlines()
        msg = f"{type(e).__name__}: {msg[0][:300]}" if msg else type(e).__name__
        raise InputFileError(f"cannot read {p.name} as {ext[1:].upper()} ({msg}); "
                             "the file is corrupt, truncated or not in that format — re-export it") from None
    raise InputFileError(f"cannot read {p.name}: unsupported extension {p.suffix!r}; convert it to "  # pragma: no cover
                         ".stl or .vtu")


# =========================================================================== readers
def _read_trimesh(p: Path) -> _Raw:
    import trimesh

    if p.suffix.lower() == ".stl":    # direct reader: trimesh.load adds seconds of copies per 1M faces
        from trimesh.exchange.stl import load_stl
        try:
            with open(p, "rb") as fh:
                d = load_stl(fh)
            v = np.asarray(d["vertices"], np.float64)
            f = np.asarray(d["faces"], np.int64)
            if len(f):
                return _Raw(v, f, fmt="STL")
        except Exception:
            pass
    m = trimesh.load(str(p), process=False, force="mesh")
    if p.suffix.lower() == ".stl" and (not isinstance(m, trimesh.Trimesh) or not len(m.faces)):
        _stl_diagnose(p)
    if not isinstance(m, trimesh.Trimesh):
        raise InputFileError(f"{p.name} holds no triangle mesh (trimesh returned {type(m).__name__}); "
                             "give a surface mesh file")
    return _Raw(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64), fmt=p.suffix[1:].upper())


def _stl_diagnose(p: Path) -> None:
    """Explain why an STL gave no triangles: a binary file whose size disagrees with its
    triangle count is truncated or corrupt."""
    size = p.stat().st_size
    with open(p, "rb") as fh:
        head = fh.read(84)
    if head[:5].lower() == b"solid" and b"facet" in p.read_bytes()[:4096].lower():
        raise InputFileError(f"{p.name}: ASCII STL with no readable facets (truncated or corrupt); re-export it")
    if len(head) < 84:
        raise InputFileError(f"{p.name}: {size} bytes is too short for an STL file (truncated); re-export it")
    n = int(np.frombuffer(head[80:84], dtype="<u4")[0])
    if size != 84 + 50 * n:
        raise InputFileError(f"{p.name}: binary STL header announces {n} triangles ({84 + 50 * n} bytes) but the "
                             f"file has {size} bytes: truncated or corrupt; re-export it")


def _blocks_to_faces(cells):
    """Concatenate triangle and quad blocks (file order) of a meshio mesh."""
    faces, comp_idx, skipped = [], [], {}
    for bi, cb in enumerate(cells):
        if cb.type == "triangle":
            faces.append(np.hstack([cb.data.astype(np.int64), np.full((len(cb.data), 1), -1, np.int64)]))
        elif cb.type == "quad":
            faces.append(cb.data.astype(np.int64))
        else:
            skipped[cb.type] = skipped.get(cb.type, 0) + len(cb.data)
            continue
        comp_idx.append(bi)
    return faces, comp_idx, skipped


def _read_meshio(p: Path) -> _Raw:
    import meshio

    # call the format's reader directly: meshio.read() prints and calls sys.exit on bad files
    reader = {".vtu": meshio.vtu.read, ".msh": meshio.gmsh.read}[p.suffix.lower()]
    m = reader(str(p))
    faces, blocks, skipped = _blocks_to_faces(m.cells)
    notes = [f"ignored {n} {t} cells" for t, n in sorted(skipped.items()) if t not in ("line", "vertex")]
    f = np.vstack(faces) if faces else np.zeros((0, 4), np.int64)
    fmt = {".vtu": "VTU", ".msh": "Gmsh MSH"}[p.suffix.lower()]
    cd = m.cell_data
    fd = {k: np.asarray(v).reshape(-1) for k, v in (m.field_data or {}).items()}
    fixed = fe = fe_ids = None
    if "component" in cd:
        comp = np.concatenate([np.asarray(cd["component"][b]).reshape(-1) for b in blocks]) if blocks \
            else np.zeros(0, np.int32)
        k = int(comp.max()) + 1 if len(comp) else 0
        table = {int(v[0]): str(n) for n, v in fd.items() if v.size == 1 and np.issubdtype(v.dtype, np.integer)}
        k = max([k] + [i + 1 for i in table])
        names = [table.get(i, f"component_{i}") for i in range(k)]
        if (comp < 0).any():
            raise InputFileError(f"{p.name}: negative 'component' cell data; re-export the file")
        lines = [i for i, cb in enumerate(m.cells) if cb.type == "line"]
        if lines:
            fe = np.vstack([m.cells[i].data for i in lines]).astype(np.int64)
            fe_ids = np.concatenate([np.asarray(cd["component"][i]).reshape(-1) for i in lines])
        if "fixed" in m.point_data:
            fixed = np.flatnonzero(np.asarray(m.point_data["fixed"]).reshape(-1))
    elif "gmsh:physical" in cd:
        tags = np.concatenate([np.asarray(cd["gmsh:physical"][b]).reshape(-1) for b in blocks]) if blocks \
            else np.zeros(0, np.int64)
        named = {int(v[0]): str(n) for n, v in fd.items() if v.size >= 2 and int(v[1]) == 2}
        all_tags = np.unique(np.concatenate([tags, np.array(sorted(named), dtype=np.int64)]))
        if len(all_tags) and all_tags.min() >= 1 and np.array_equal(all_tags, np.arange(1, len(all_tags) + 1)):
            comp = tags - 1      # our own files: physical tag = component id + 1
        else:
            comp = np.searchsorted(all_tags, tags)
        names = [named.get(int(t), f"physical_{int(t)}") for t in all_tags]
    else:
        comp = None
        names = None
        for key in ("CellEntityIds", "medit:ref", "cell_tags"):
            if key in cd and blocks:
                tags = np.concatenate([np.asarray(cd[key][b]).reshape(-1) for b in blocks])
                uniq, comp = np.unique(tags, return_inverse=True)
                names = [f"{key}_{int(t)}" for t in uniq]
                break
    return _Raw(m.points[:, :3] if m.points.shape[1] >= 3 else np.c_[m.points, np.zeros(len(m.points))],
                f, comp, names, fixed, fe, fe_ids, notes, fmt)


def _read_pyvista(p: Path) -> _Raw:
    """Legacy VTK (.vtk), VTK PolyData (.vtp) and VTU files through pyvista/VTK: triangles,
    quads and 3/4-node polygons; ``component`` cell data and integer field data names kept."""
    import pyvista as pv

    import logging

    quiet = pv.vtk_verbosity("off") if hasattr(pv, "vtk_verbosity") else contextlib.nullcontext()
    root = logging.getLogger()
    level = root.level
    root.setLevel(logging.CRITICAL)       # pyvista relays VTK errors to the root logger
    try:
        with quiet, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            g = pv.read(str(p))
    finally:
        root.setLevel(level)
    if isinstance(g, pv.MultiBlock):
        g = g.combine()
    if not isinstance(g, pv.UnstructuredGrid):
        g = g.cast_to_unstructured_grid()
    types = np.asarray(g.celltypes, np.int64)
    off = np.asarray(g.cell_offsets if hasattr(g, "cell_offsets") else g.offset, np.int64)
    conn = np.asarray(g.cell_connectivity, np.int64)
    size = np.diff(off)
    tri = (types == 5) | ((types == 7) & (size == 3))
    quad = (types == 9) | ((types == 7) & (size == 4))
    pixel = types == 8
    faces = np.full((len(types), 4), -1, np.int64)
    for mask, k, order in ((tri, 3, [0, 1, 2]), (quad, 4, [0, 1, 2, 3]), (pixel, 4, [0, 1, 3, 2])):
        if mask.any():
            faces[mask, :k] = conn[off[:-1][mask][:, None] + np.asarray(order)]
    keep = tri | quad | pixel
    other = ~keep & ~np.isin(types, [1, 2, 3, 4])          # vertices and lines are silently not faces
    notes = [f"ignored {int(other.sum())} cells that are not triangles or quads"] if other.any() else []
    comp = names = None
    if "component" in g.cell_data:
        c = np.asarray(g.cell_data["component"]).reshape(-1).astype(np.int64)[keep]
        if len(c) and c.min() >= 0:
            comp = c
            table = {}
            for n in g.field_data.keys():
                v = np.asarray(g.field_data[n]).reshape(-1)
                if v.size == 1 and np.issubdtype(v.dtype, np.integer):
                    table[int(v[0])] = str(n)
            k = max([int(c.max()) + 1 if len(c) else 0] + [i + 1 for i in table])
            names = [table.get(i, f"component_{i}") for i in range(k)]
    return _Raw(np.asarray(g.points, np.float64), faces[keep], comp, names, notes=notes,
                fmt=p.suffix[1:].upper())


_PSHELL_NAME = re.compile(r"shellmesh_mdao component (\d+): (\".*\")")
_FAMILY = re.compile(r"Shell element data for family\s+(\S+)")
_FEMAP = re.compile(r"Femap Property\s+\d+\s*:\s*(\S+)")


_OWN_BDF_HEAD = b"$ pyNastran: punch=True\n$ shellmesh_mdao "


def _fixed_field(buf: np.ndarray, starts: np.ndarray, a: int, b: int, dtype) -> np.ndarray:
    """Columns ``a:b`` of the lines starting at ``starts`` parsed as numbers (vectorised)."""
    cols = buf[starts[:, None] + np.arange(a, b)]
    return np.ascontiguousarray(cols).view(f"S{b - a}").ravel().astype(dtype)


def _read_own_bdf(p: Path) -> _Raw | None:
    """Vectorised reader for the exact layout :func:`shellmesh_mdao.export.write_mesh` writes
    (GRID* large field, small-field CQUAD4/CTRIA3, our PSHELL comments).  Returns ``None``
    when the file deviates from that layout (edited by hand, other writer): the caller then
    uses pyNastran."""
    with open(p, "rb") as fh:
        if fh.read(len(_OWN_BDF_HEAD)) != _OWN_BDF_HEAD:
            return None
    buf = np.fromfile(p, dtype=np.uint8)
    if not len(buf) or buf[-1] != 10:
        return None
    ends = np.flatnonzero(buf == 10)
    starts = np.concatenate([[0], ends[:-1] + 1])
    lens = ends - starts
    if (buf == 13).any():
        return None
    padded = np.concatenate([buf, np.zeros(8, np.uint8)])

    def prefix(word: bytes, length: int | None = None) -> np.ndarray:
        ok = lens >= len(word) if length is None else lens == length
        for k, ch in enumerate(word):
            ok &= padded[starts + k] == ch
        return ok

    grid = prefix(b"GRID*   ", 72)
    cont = prefix(b"*       ", 24)
    quad = prefix(b"CQUAD4  ", 56)
    tri = prefix(b"CTRIA3  ", 48)
    comment = prefix(b"$")
    small = prefix(b"PSHELL*") | prefix(b"MAT1*") | (prefix(b"*") & ~cont) | (lens == 0)
    gi = np.flatnonzero(grid)
    if not (grid | cont | quad | tri | comment | small).all() or not len(gi):
        return None
    if gi[-1] + 1 >= len(lens) or not cont[gi + 1].all():
        return None
    nid = _fixed_field(padded, starts[gi], 8, 24, np.int64)
    xyz = np.column_stack([_fixed_field(padded, starts[gi], 40, 56, np.float64),
                           _fixed_field(padded, starts[gi], 56, 72, np.float64),
                           _fixed_field(padded, starts[gi + 1], 8, 24, np.float64)])
    qi, ti = np.flatnonzero(quad), np.flatnonzero(tri)
    eid = np.concatenate([_fixed_field(padded, starts[qi], 8, 16, np.int64),
                          _fixed_field(padded, starts[ti], 8, 16, np.int64)])
    pid = np.concatenate([_fixed_field(padded, starts[qi], 16, 24, np.int64),
                          _fixed_field(padded, starts[ti], 16, 24, np.int64)])
    conn = np.zeros((len(eid), 4), np.int64)
    for j in range(4):
        conn[:len(qi), j] = _fixed_field(padded, starts[qi], 24 + 8 * j, 32 + 8 * j, np.int64)
    for j in range(3):
        conn[len(qi):, j] = _fixed_field(padded, starts[ti], 24 + 8 * j, 32 + 8 * j, np.int64)
    names = {}
    for ci in np.flatnonzero(comment):
        line = bytes(buf[starts[ci]:ends[ci]]).decode("ascii", "replace")
        m = _PSHELL_NAME.search(line)
        if m:
            names[int(m.group(1))] = json.loads(m.group(2))
    if not names or sorted(names) != list(range(len(names))):
        return None
    o = np.argsort(nid, kind="stable")
    nid, xyz = nid[o], xyz[o]
    eo = np.argsort(eid, kind="stable")
    conn, pid = conn[eo], pid[eo]
    if len(pid) and (pid.min() < 1 or pid.max() > len(names)):
        return None
    pos = np.minimum(np.searchsorted(nid, conn), len(nid) - 1)
    valid = conn != 0
    valid[:, :3] = True
    if (valid & (nid[pos] != conn)).any():
        raise InputFileError(f"{p.name}: elements reference GRID ids that are not defined (file truncated?); "
                             "re-export the file")
    faces = np.where(valid, pos, -1)
    return _Raw(xyz, faces, pid - 1, [names[i] for i in range(len(names))], fmt="Nastran")


def _read_bdf(p: Path) -> _Raw:
    fast = _read_own_bdf(p)
    if fast is not None:
        return fast
    from pyNastran.bdf.bdf import read_bdf
    from pyNastran.bdf.errors import MissingDeckSections
    try:
        from cpylog import SimpleLogger
        kw = {"log": SimpleLogger(level="error")}
    except ImportError:  # pragma: no cover - older pyNastran without cpylog
        kw = {"debug": None}
    try:
        model = read_bdf(str(p), validate=False, xref=False, punch=False, **kw)
    except MissingDeckSections:
        model = read_bdf(str(p), validate=False, xref=False, punch=True, **kw)
    nids = np.array(sorted(model.nodes), dtype=np.int64)
    if not len(nids):
        return _Raw(np.zeros((0, 3)), np.zeros((0, 4)), notes=["no GRID cards"], fmt="Nastran")
    if any(model.nodes[n].cp for n in model.nodes):
        model.cross_reference()
        xyz = np.array([model.nodes[n].get_position() for n in nids], dtype=np.float64)
    else:
        xyz = np.array([model.nodes[n].xyz for n in nids], dtype=np.float64)
    eids = sorted(model.elements)
    kinds = {"CTRIA3": 3, "CTRIAR": 3, "CQUAD4": 4, "CQUADR": 4}
    conn, pids, skipped, first_comment = [], [], {}, {}
    for eid in eids:
        e = model.elements[eid]
        nn = kinds.get(e.type)
        if nn is None:
            skipped[e.type] = skipped.get(e.type, 0) + 1
            continue
        ids = list(e.node_ids[:nn]) + [0] * (4 - nn)
        conn.append(ids)
        pids.append(e.pid)
        if e.pid not in first_comment and e.comment:
            first_comment[e.pid] = e.comment
    notes = [f"ignored {n} {t} elements" for t, n in sorted(skipped.items())]
    if not conn:
        return _Raw(xyz, np.zeros((0, 4)), notes=notes, fmt="Nastran")
    conn = np.array(conn, dtype=np.int64)
    pids = np.array(pids, dtype=np.int64)
    pos = np.searchsorted(nids, conn)
    pos = np.minimum(pos, len(nids) - 1)
    missing = (nids[pos] != conn) & (conn != 0)
    if missing.any():
        raise InputFileError(f"{p.name}: elements reference {int(missing.sum())} GRID ids that are not defined "
                             "(file truncated?); re-export the file")
    faces = np.where(conn != 0, pos, -1)
    faces[:, :3] = pos[:, :3]
    all_pids = np.unique(np.concatenate([pids, np.array(sorted(model.properties), dtype=np.int64)]))
    comp = np.searchsorted(all_pids, pids)
    names = []
    exact = {}
    for pid in all_pids:
        prop = model.properties.get(int(pid))
        c = prop.comment if prop is not None else ""
        m = _PSHELL_NAME.search(c or "")
        if m:
            exact[int(pid)] = json.loads(m.group(2))
    for pid in all_pids:
        pid = int(pid)
        if pid in exact:
            names.append(exact[pid])
            continue
        m = _FAMILY.search(first_comment.get(pid, ""))
        prop = model.properties.get(pid)
        mf = _FEMAP.search(prop.comment) if prop is not None and prop.comment else None
        names.append(m.group(1) if m else mf.group(1) if mf else f"pid_{pid}")
    return _Raw(xyz, faces, comp, names, notes=notes, fmt="Nastran")


_INP_TRI = {"S3", "S3R", "S3RS", "STRI3", "M3D3", "CPS3", "CPE3", "R3D3", "SFM3D3"}
_INP_QUAD = {"S4", "S4R", "S4RS", "S4R5", "M3D4", "M3D4R", "CPS4", "CPS4R", "CPE4", "CPE4R", "R3D4",
             "SFM3D4", "SFM3D4R"}
_INP_FAMILY = re.compile(r"^\*\*\s*family\s+(\d+)\s(.*)$")


def _inp_params(line: str) -> tuple[str, dict]:
    parts = [s.strip() for s in line[1:].split(",")]
    kw = parts[0].upper()
    params = {}
    for s in parts[1:]:
        if not s:
            continue
        k, _, v = s.partition("=")
        params[k.strip().upper()] = v.strip()
    return kw, params


def _numbers(text: str, dtype, where: str = "") -> np.ndarray:
    """Parse the comma/space separated numbers of a data block in C (np.fromstring); falls
    back to a strict Python parse, which raises on a bad token."""
    s = text.replace(",", " ")
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        try:
            arr = np.fromstring(s, dtype=np.float64, sep=" ")
        except (DeprecationWarning, ValueError):
            arr = np.array(s.split(), dtype=np.float64)   # raises ValueError naming the token
    if dtype is np.int64:
        if len(arr) and not np.array_equal(arr, np.round(arr)):
            raise InputFileError(f"{where}: non-integer value in an integer data block (node or element "
                                 "numbers); fix or re-export the file")
        return arr.astype(np.int64)
    return arr


def _inp_sections(text: str, family: dict):
    """Yield ``(keyword line, data text)`` for every keyword of an INP text; comment lines
    (``**``) are skipped (data after them continues the keyword before), and our
    ``** family <id> <name>`` comments are collected into ``family``.  The scan loops over
    keyword lines only; data is handed over as text slices."""
    starts = [0] if text.startswith("*") else []
    j = text.find("\n*")
    while j >= 0:
        starts.append(j + 1)
        j = text.find("\n*", j + 1)
    head, parts = None, []
    for i, s0 in enumerate(starts):
        e0 = text.find("\n", s0)
        e0 = len(text) if e0 < 0 else e0
        nxt = starts[i + 1] if i + 1 < len(starts) else len(text)
        line = text[s0:e0].rstrip("\r")
        data = text[e0 + 1:nxt] if e0 + 1 < nxt else ""
        if line.startswith("**"):
            m = _INP_FAMILY.match(line)
            if m:
                family[int(m.group(1))] = m.group(2)
            parts.append(data)
            continue
        if head is not None:
            yield head, "".join(parts)
        head, parts = line, [data]
    if head is not None:
        yield head, "".join(parts)


def _read_inp(p: Path) -> _Raw:
    text = p.read_text(encoding="utf-8", errors="replace")
    family: dict[int, str] = {}
    node_ids, node_xyz = [], []
    elems = []          # (ids, conn (n,4), elset or None)
    elsets = {}         # NAME(upper) -> list of arrays of ids
    elset_display = {}
    notes = []
    for head, data in _inp_sections(text, family):
        kw, prm = _inp_params(head)
        if kw == "NODE":
            a = _numbers(data, np.float64, f"{p.name} *NODE")
            if len(a) % 4:
                raise InputFileError(f"{p.name}: *NODE data must be 'id, x, y, z' lines (truncated or corrupt); "
                                     "fix or re-export the file")
            a = a.reshape(-1, 4)
            node_ids.append(a[:, 0].astype(np.int64))
            node_xyz.append(a[:, 1:])
        elif kw == "ELEMENT":
            et = prm.get("TYPE", "").upper()
            nn = 3 if et in _INP_TRI else 4 if et in _INP_QUAD else 0
            if not nn:
                notes.append(f"ignored *ELEMENT TYPE={et}")
                continue
            a = _numbers(data, np.int64, f"{p.name} *ELEMENT")
            if len(a) % (nn + 1):
                raise InputFileError(f"{p.name}: *ELEMENT, TYPE={et} data must be 'id' + {nn} node numbers "
                                     "(truncated or corrupt); fix or re-export the file")
            a = a.reshape(-1, nn + 1)
            conn = np.full((len(a), 4), -1, np.int64)
            conn[:, :nn] = a[:, 1:]
            name = prm.get("ELSET")
            if name:
                elset_display.setdefault(name.upper(), name)
            elems.append((a[:, 0], conn, name.upper() if name else None))
        elif kw == "ELSET" and "ELSET" in prm:
            name = prm["ELSET"]
            elset_display.setdefault(name.upper(), name)
            toks = data.replace(",", " ").split()
            ids = np.array([t for t in toks if re.fullmatch(r"[+-]?\d+", t)], dtype=np.int64)
            if "GENERATE" in prm and len(ids) >= 2:
                g = ids.reshape(-1, 3) if len(ids) % 3 == 0 else \
                    np.c_[ids[:len(ids) // 2 * 2].reshape(-1, 2), np.ones(len(ids) // 2, np.int64)]
                ids = np.concatenate([np.arange(a, b + 1, max(st, 1)) for a, b, st in g])
            elsets.setdefault(name.upper(), []).append(ids)
    if not node_ids:
        return _Raw(np.zeros((0, 3)), np.zeros((0, 4)), notes=notes + ["no *NODE data"], fmt="INP")
    nid = np.concatenate(node_ids)
    xyz = np.vstack(node_xyz)
    order = np.argsort(nid, kind="stable")
    nid, xyz = nid[order], xyz[order]
    if len(nid) > 1 and (np.diff(nid) == 0).any():
        k = int(nid[1:][np.diff(nid) == 0][0])
        raise InputFileError(f"{p.name}: duplicate node numbers in *NODE (node {k} is defined twice); renumber "
                             "the nodes or re-export the file")
    if not elems:
        return _Raw(xyz, np.zeros((0, 4)), notes=notes, fmt="INP")
    eid = np.concatenate([e[0] for e in elems])
    conn = np.vstack([e[1] for e in elems])
    valid = conn >= 0
    pos = np.searchsorted(nid, np.where(valid, conn, nid[0]))
    pos = np.minimum(pos, len(nid) - 1)
    if (valid & (nid[pos] != conn)).any():
        raise InputFileError(f"{p.name}: elements reference undefined node numbers (file truncated?); "
                             "re-export the file")
    faces = np.where(valid, pos, -1)
    # components: our family table first, then ELSET names in order of appearance
    names: list[str] = []
    key_to_id: dict[str, int] = {}
    if family:
        from .export import inp_elset_names
        k = max(family) + 1
        names = [family.get(i, f"component_{i}") for i in range(k)]
        fake = ShellMesh(np.zeros((0, 3)), np.zeros((0, 4)), component_names=names)
        key_to_id = {s.upper(): i for i, s in enumerate(inp_elset_names(fake))}
    comp = np.full(len(eid), -1, np.int64)
    ofs = 0
    for ids, c, name in elems:
        if name is not None:
            if name not in key_to_id:
                key_to_id[name] = len(names)
                names.append(elset_display[name])
            comp[ofs:ofs + len(ids)] = key_to_id[name]
        ofs += len(ids)
    if (comp < 0).any():   # elements without ELSET on *ELEMENT: first numeric *ELSET holding them
        for name, parts in elsets.items():
            ids = np.concatenate(parts) if parts else np.zeros(0, np.int64)
            hit = (comp < 0) & np.isin(eid, ids)
            if hit.any():
                if name not in key_to_id:
                    key_to_id[name] = len(names)
                    names.append(elset_display[name])
                comp[hit] = key_to_id[name]
        if (comp < 0).any():
            if _DEFAULT_NAME not in names:
                names.append(_DEFAULT_NAME)
            comp[comp < 0] = names.index(_DEFAULT_NAME)
    eorder = np.argsort(eid, kind="stable")
    return _Raw(xyz, faces[eorder], comp[eorder], names, notes=notes, fmt="INP")


def _read_cad(p: Path, size=None) -> _Raw:
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
        return _Raw(xyz, idx, notes=notes, fmt="STEP" if p.suffix.lower() in (".step", ".stp") else "IGES")
    finally:
        try:
            gmsh.model.setCurrent(model_name)
            gmsh.model.remove()
        except Exception:
            pass
        if own:
            gmsh.finalize()


# =========================================================================== cleaning
def _unique_rows(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique rows of a 2-D array by a stable lexsort (much faster than
    ``np.unique(axis=0)``).  Returns ``(first, inverse)``: the lowest original index of each
    unique row (groups in sorted row order) and the group of every row."""
    n = len(a)
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.lexsort(a.T[::-1])
    s = a[order]
    new = np.ones(n, bool)
    new[1:] = (s[1:] != s[:-1]).any(1)
    inv = np.empty(n, np.int64)
    inv[order] = np.cumsum(new) - 1
    return order[new], inv


def _clean(raw: _Raw, merge_tol):
    """Merge vertices, fix/remove collapsed faces, remove duplicates.  Returns the cleaned
    (points, faces, component) and counts."""
    pts = raw.points + 0.0          # -0.0 -> 0.0
    faces = raw.faces
    comp = raw.component
    n0 = len(pts)
    # exact duplicates first (cheap), keeping first-appearance order
    first, inv = _unique_rows(pts)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    upts = pts[np.sort(first)]
    o2n = rank[inv]
    diag = float(np.linalg.norm(upts.max(0) - upts.min(0))) if len(upts) else 0.0
    if merge_tol and diag > 0:
        upts, o2 = merge_close_points(upts, float(merge_tol) * diag)
        o2n = o2[o2n]
    n_merged = n0 - len(upts)
    f = np.where(faces >= 0, o2n[np.maximum(faces, 0)], -1)
    # collapsed faces
    quad = f[:, 3] >= 0
    eq_prev = f == np.roll(f, 1, axis=1)            # slot j equals slot j-1 (cyclic)
    s = np.sort(f, axis=1)
    distinct = 1 + (s[:, 1:] != s[:, :-1]).sum(1) - (~quad)   # tris: -1 counted once
    tri_bad = ~quad & (distinct < 3)
    quad_ok = quad & (distinct == 4)
    quad_to_tri = quad & (distinct == 3) & (eq_prev.sum(1) == 1)
    quad_bad = quad & ~quad_ok & ~quad_to_tri
    if quad_to_tri.any():
        rows = np.flatnonzero(quad_to_tri)
        keep = ~eq_prev[rows]
        f[rows, :3] = f[rows][keep].reshape(-1, 3)
        f[rows, 3] = -1
    good = ~(tri_bad | quad_bad)
    n_degenerate = int((~good).sum())
    f, comp = f[good], comp[good]
    # exact duplicates (same node set, any order/orientation): keep the first
    firstf, _ = _unique_rows(np.sort(f, axis=1))
    keepf = np.sort(firstf)
    n_dup = len(f) - len(keepf)
    f, comp = f[keepf], comp[keepf]
    return upts, f, comp, n_merged, n_degenerate, n_dup, int(quad_to_tri.sum())


def _orientation_conflicts(mesh: ShellMesh) -> int:
    t = mesh.topology()
    man = np.flatnonzero(t.valence == 2)
    if not len(man):
        return 0
    order = np.argsort(t.he_edge, kind="stable")
    first = np.searchsorted(t.he_edge[order], man)
    h0, h1 = order[first], order[first + 1]
    return int((t.he_from[h0] == t.he_from[h1]).sum())


def _units_note(fmt: str) -> str:
    if fmt in ("STEP", "IGES"):
        return "millimetres (OpenCASCADE default for STEP/IGES)"
    return "the file's own length units (the format records none)"


# =========================================================================== dirty inputs
#: A surface whose bounding-box diagonal is outside this range gets a units warning.
UNITS_DIAGONAL_RANGE = (1e-3, 1e5)
#: Open-boundary vertices within this fraction of the diagonal of one plane lie "in" it.
SYMMETRY_TOL = 1e-5
#: A face next to a symmetry-plane boundary must not lie in that plane: |n_face . n_plane|
#: at most this (the surface crosses the plane instead of ending in a hole of a flat face).
SYMMETRY_MAX_COS = 0.9

_AXES = "xyz"


def _face_bodies(topo, n_faces: int) -> np.ndarray:
    """Body (edge-connected piece) label of every face; labels numbered by lowest face."""
    if not n_faces:
        return np.zeros(0, np.int64)
    he = np.argsort(topo.he_edge, kind="stable")
    e = topo.he_edge[he]
    f = topo.he_face[he]
    same = e[1:] == e[:-1]
    a, b = f[:-1][same], f[1:][same]
    g = sparse.coo_matrix((np.ones(len(a)), (a, b)), shape=(n_faces, n_faces))
    _, lab = connected_components(g, directed=False)
    return _renumber_by_first(lab)


def _renumber_by_first(lab: np.ndarray) -> np.ndarray:
    """Relabel so that labels appear in increasing order of their first occurrence."""
    _, first, inv = np.unique(lab, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inv.reshape(-1)]


def _flip_faces(faces: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Reverse the orientation of ``faces[rows]`` keeping the first corner."""
    f = faces.copy()
    if not len(rows):
        return f
    quad = f[rows, 3] >= 0
    t, q = rows[~quad], rows[quad]
    f[t, 1], f[t, 2] = faces[t, 2], faces[t, 1]
    f[q, 1], f[q, 3] = faces[q, 3], faces[q, 1]
    return f


def _edge_where(points: np.ndarray, edges: np.ndarray, k: int = 3) -> str:
    """'at (x, y, z), (x, y, z) ...' for the midpoints of the first ``k`` edges."""
    mid = 0.5 * (points[edges[:k, 0]] + points[edges[:k, 1]])
    more = f" and {len(edges) - k} more" if len(edges) > k else ""
    return "at " + ", ".join("(" + ", ".join(f"{v:.6g}" for v in p) + ")" for p in mid) + more


def _orient_consistently(mesh: ShellMesh, body: np.ndarray, name: str) -> tuple[np.ndarray, int]:
    """Faces re-oriented so that every manifold edge is traversed once each way, per body
    (the orientation most of the body's faces have is kept; a tie keeps the lowest face's).
    Vectorised: the face graph is doubled (face f in state 0 and state 1) and an edge joins
    equal or opposite states by whether the two faces agree; a component holding both states
    of a face is a non-orientable body.
    Returns (faces, number of faces flipped)."""
    topo = mesh.topology()
    m = mesh.n_faces
    man = np.flatnonzero(topo.valence == 2)
    if not len(man):
        return mesh.faces.copy(), 0
    order = np.argsort(topo.he_edge, kind="stable")
    first = np.searchsorted(topo.he_edge[order], man)
    h0, h1 = order[first], order[first + 1]
    f0, f1 = topo.he_face[h0], topo.he_face[h1]
    flip = (topo.he_from[h0] == topo.he_from[h1]).astype(np.int64)   # same direction: must differ
    a = np.concatenate([f0, f0 + m])
    b = np.concatenate([f1 + flip * m, f1 + (1 - flip) * m])
    g = sparse.coo_matrix((np.ones(len(a)), (a, b)), shape=(2 * m, 2 * m))
    _, lab = connected_components(g, directed=False)
    bad = np.flatnonzero(lab[:m] == lab[m:])
    if len(bad):
        c = mesh.face_centroids()[bad[0]]
        raise MeshValidationError(
            f"{name}: a body of the surface is non-orientable (a Moebius-like band: its faces cannot all face "
            f"the same side; e.g. face {int(bad[0])} at ({', '.join(f'{v:.6g}' for v in c)})); re-export the "
            "surface as closed shells with consistent normals")
    # per body, the state holding most faces keeps its orientation (ties: the lowest face's)
    nb = int(body.max()) + 1
    root = np.full(nb, m, np.int64)
    np.minimum.at(root, body, np.arange(m))
    other = lab[:m] != lab[root[body]]
    n_other = np.bincount(body, weights=other, minlength=nb)
    n_all = np.bincount(body, minlength=nb)
    swap = n_other > n_all - n_other
    rows = np.flatnonzero(other != swap[body])
    return _flip_faces(mesh.faces, rows), len(rows)


def _signed_volumes(points, faces, body, n_body, apex) -> np.ndarray:
    """Signed volume of every body: cones from ``apex[body]`` over its faces (quads split)."""
    tri_a = faces[:, [0, 1, 2]]
    quad = np.flatnonzero(faces[:, 3] >= 0)
    t = np.vstack([tri_a, faces[quad][:, [0, 2, 3]]])
    tb = np.concatenate([body, body[quad]])
    ap = apex[tb]
    v = points[t] - ap[:, None, :]
    vol = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])) / 6.0
    return np.bincount(tb, weights=vol, minlength=n_body)


def _boundary_info(mesh: ShellMesh, tol_frac: float = SYMMETRY_TOL):
    """Classify the open boundary of a mesh.

    Returns ``(n_loops, plane, reason)``: ``plane`` is a dict (normal pointing away from the
    surface, a point, the axis name for a coordinate plane) when every open-boundary vertex
    lies in one plane, the whole surface lies on one side of it and no face next to the
    boundary lies in it (a half model cut at its symmetry plane); otherwise ``None`` and
    ``reason`` says why (``""`` for a closed surface)."""
    topo = mesh.topology()
    be = topo.edges[topo.valence == 1]
    if not len(be):
        return 0, None, ""
    bv, inv = np.unique(be, return_inverse=True)
    inv = inv.reshape(-1, 2)
    g = sparse.coo_matrix((np.ones(len(be)), (inv[:, 0], inv[:, 1])), shape=(len(bv), len(bv)))
    n_loops = int(connected_components(g, directed=False)[0])
    P = mesh.points[bv]
    diag = mesh.diagonal
    tol = tol_frac * diag
    lo, hi = P.min(0), P.max(0)
    spread = hi - lo
    ax = int(np.argmin(spread))
    if spread[ax] <= tol:
        normal = np.zeros(3)
        normal[ax] = 1.0
        point = 0.5 * (lo + hi)
        point[ax] = float(np.median(P[:, ax]))
        axis = _AXES[ax]
    else:
        c = P.mean(0)
        _, s, vt = np.linalg.svd(P - c, full_matrices=False)
        normal, point, axis = vt[2], c, None
        if len(s) < 3 or s[1] <= tol * np.sqrt(len(P)):
            return n_loops, None, "the open boundary edges lie along one line (a crack or an unzipped seam)"
        d = (P - c) @ normal
        if np.abs(d).max() > tol:
            k = int(np.argmax(np.abs(d)))
            return n_loops, None, (
                f"the {len(be)} open boundary edges ({n_loops} loop{'s' if n_loops > 1 else ''}) do not lie in "
                f"one plane (vertex at ({', '.join(f'{v:.6g}' for v in P[k])}) is {abs(d[k]):.3g} off their "
                "best-fit plane)")
    d_all = (mesh.points - point) @ normal
    if d_all.max() > tol and d_all.min() < -tol:
        return n_loops, None, (
            f"the open boundary lies in the plane {_plane_text(normal, point, axis)} but the surface lies on "
            "both sides of it, so it is not a half model cut at that plane")
    if d_all.max() > tol:
        normal = -normal
    fb = topo.edge_faces[topo.edge_faces_ptr[np.flatnonzero(topo.valence == 1)]]
    cos = np.abs(_unit_normals(mesh.points, mesh.faces[fb]) @ normal)
    if cos.max() > SYMMETRY_MAX_COS:
        k = int(fb[np.argmax(cos)])
        c = mesh.points[mesh.faces[k, :3]].mean(0)
        return n_loops, None, (
            f"the open boundary lies in the plane {_plane_text(normal, point, axis)} but faces next to it lie in "
            f"that plane too (face {k} at ({', '.join(f'{v:.6g}' for v in c)})): a hole in a flat face, not a "
            "half model cut at its symmetry plane")
    plane = {"normal": [float(v) + 0.0 for v in normal], "point": [float(v) for v in point],
             "offset": float(point @ normal), "axis": axis}
    return n_loops, plane, ""


def _unit_normals(points, faces) -> np.ndarray:
    """Unit normals of a few faces (quads: cross product of the diagonals)."""
    quad = faces[:, 3] >= 0
    a = points[faces[:, 0]]
    b = points[faces[:, 1]]
    c = points[faces[:, 2]]
    d = points[np.maximum(faces[:, 3], 0)]
    n = np.where(quad[:, None], np.cross(c - a, d - b), np.cross(b - a, c - a))
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


def _n_zero_area(mesh: ShellMesh) -> int:
    """Number of faces of exactly zero area (a quad: both halves)."""
    f = mesh.faces
    p = mesh.points
    z = ~(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]) != 0).any(1)
    quad = np.flatnonzero(z & (f[:, 3] >= 0))
    if len(quad):
        g = f[quad]
        z[quad] = ~(np.cross(p[g[:, 2]] - p[g[:, 0]], p[g[:, 3]] - p[g[:, 0]]) != 0).any(1)
    return int(z.sum())


def _any_positive_area(mesh: ShellMesh) -> bool:
    """Whether some face has a non-zero area (relative to the diagonal: no underflow); the
    first faces are tried first, so a valid surface costs next to nothing."""
    lo = mesh.points.min(0)
    scale = max(mesh.diagonal, 1e-300)
    for rows in (np.arange(min(mesh.n_faces, 4096)), np.arange(mesh.n_faces)):
        f = mesh.faces[rows]
        p = (mesh.points[f[:, :3]] - lo) / scale
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        if (np.abs(n).max(1) > 1e-24).any():
            return True
        quad = f[:, 3] >= 0
        if quad.any():
            q = (mesh.points[f[quad][:, [0, 2, 3]]] - lo) / scale
            if (np.abs(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])).max(1) > 1e-24).any():
                return True
    return False


def _plane_text(normal, point, axis) -> str:
    if axis is not None:
        return f"{axis} = {float(point[_AXES.index(axis)]):.6g}"
    n = np.asarray(normal)
    return f"({', '.join(f'{v:.4g}' for v in n)}) . x = {float(np.asarray(point) @ n):.6g}"


def symmetry_boundary_vertices(mesh: ShellMesh, plane: dict, tol: float = SYMMETRY_TOL) -> np.ndarray:
    """Sorted indices of the open-boundary vertices of ``mesh`` that lie in the symmetry
    ``plane`` (a :attr:`SurfaceReport.symmetry_plane` dict) within ``tol`` times the
    diagonal: the nodes to clamp (or give symmetry conditions) in an analysis of a half
    model, valid for any later mesh of the same surface (remeshed, imprinted, quads)."""
    if not plane:
        return np.zeros(0, np.int64)
    bv = np.unique(mesh.boundary_edges())
    if not len(bv):
        return bv.astype(np.int64)
    d = (mesh.points[bv] - np.asarray(plane["point"])) @ np.asarray(plane["normal"])
    return bv[np.abs(d) <= tol * max(mesh.diagonal, 1e-300)].astype(np.int64)


def _units_warnings(diag: float) -> list[str]:
    lo, hi = UNITS_DIAGONAL_RANGE
    if diag < lo:
        return [f"the surface is only {diag:.3g} units across (bounding-box diagonal): an aircraft in metres or "
                "millimetres is much larger; the file was probably written in kilometres or scaled by mistake. "
                "Rescale it so that one unit is a metre or a millimetre (the --size value is in the same units)"]
    if diag > hi:
        return [f"the surface is {diag:.3g} units across (bounding-box diagonal): that is {diag / 1000:.3g} m if "
                f"the units are millimetres and {diag / 1e6:.3g} m if they are micrometres; the file was "
                "probably written in micrometres (or millimetres of a very large aircraft) or scaled by mistake. "
                "Check the units and rescale if needed (the --size value is in the same units)"]
    return []


def _manifold(points, tris, name, what):
    import manifold3d as m3

    m = m3.Manifold(m3.Mesh64(np.ascontiguousarray(points, np.float64), np.ascontiguousarray(tris, np.uint64)))
    st = m.status()
    if st != m3.Error.NoError:
        raise MeshValidationError(
            f"{name}: cannot join {what} with manifold3d ({str(st).split('.')[-1]}): the body is not a closed, "
            "consistently oriented 2-manifold; export each body as a closed shell (or join the bodies in CAD)")
    return m.as_original()


def _body_triangles(faces, rows):
    f = faces[rows]
    quad = f[:, 3] >= 0
    tri = np.vstack([f[:, :3], f[quad][:, [0, 2, 3]]])
    src = np.concatenate([rows, rows[quad]])
    return tri, src


def _unite_bodies(mesh: ShellMesh, body: np.ndarray, plane, open_body: np.ndarray, name: str):
    """Boolean union (manifold3d) of every group of bodies whose volumes overlap. Open
    bodies of a half model are closed by their mirror image first and the union is cut back
    at the symmetry plane (its cap removed). Bodies that touch nothing keep their faces.
    Returns ``(mesh, groups)``: groups is a list of the united body lists."""
    import manifold3d as m3

    nb = int(body.max()) + 1
    if nb < 2:
        return mesh, []
    P, F = mesh.points, mesh.faces
    diag = mesh.diagonal
    corner_body = np.broadcast_to(body[:, None], F.shape)[F >= 0]
    order = np.argsort(corner_body, kind="stable")
    corner_pts = P[F[F >= 0]][order]
    starts = np.searchsorted(corner_body[order], np.arange(nb))
    lo = np.minimum.reduceat(corner_pts, starts, axis=0)
    hi = np.maximum.reduceat(corner_pts, starts, axis=0)
    if plane is not None:       # mirrored bodies: extend the boxes to their mirror images
        n, c = np.asarray(plane["normal"]), plane["offset"]
        box = np.stack([lo, hi], 1)                                        # (nb, 2, 3)
        corners = np.stack(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij"), -1).reshape(-1, 3)
        pts8 = box[:, corners, [0, 1, 2]]                                   # (nb, 8, 3)
        mir = pts8 - 2.0 * ((pts8 @ n) - c)[..., None] * n
        allp = np.concatenate([pts8, mir], 1)
        lo = np.where(open_body[:, None], allp.min(1), lo)
        hi = np.where(open_body[:, None], allp.max(1), hi)
    eps = 1e-9 * diag
    ov = ((lo[:, None, :] <= hi[None, :, :] + eps) & (lo[None, :, :] <= hi[:, None, :] + eps)).all(2)
    ia, ib = np.nonzero(np.triu(ov, 1))
    if not len(ia):
        return mesh, []
    mans: dict[int, object] = {}
    tri_src: dict[int, np.ndarray] = {}

    def manifold_of(b):
        if b in mans:
            return mans[b]
        rows = np.flatnonzero(body == b)
        tri, src = _body_triangles(F, rows)
        used, loc = np.unique(tri, return_inverse=True)
        loc = loc.reshape(-1, 3)
        V = P[used]
        if open_body[b]:
            if plane is None:
                raise MeshValidationError(
                    f"{name}: body {b} is open (not a closed shell) and overlaps another body, so they cannot be "
                    "joined; close it (or cut it exactly at the symmetry plane) in CAD")
            n, c = np.asarray(plane["normal"]), plane["offset"]
            d = V @ n - c
            on = np.zeros(len(used), bool)
            bnd = np.unique(mesh.boundary_edges())
            on[np.isin(used, bnd)] = True
            V = V.copy()
            V[on] -= d[on, None] * n                    # snap the cut onto the plane
            Vm = V - 2.0 * (V @ n - c)[:, None] * n
            idx = np.where(on, np.arange(len(V)), len(V) + np.cumsum(~on) - 1)
            V = np.vstack([V, Vm[~on]])
            loc = np.vstack([loc, idx[loc][:, ::-1]])
            src = np.concatenate([src, src])
        mans[b] = _manifold(V, loc, name, f"body {b}")
        tri_src[mans[b].original_id()] = src
        return mans[b]

    inter = []
    for a, b in zip(ia.tolist(), ib.tolist()):
        A, B = manifold_of(a), manifold_of(b)
        v = (A ^ B).volume()
        if v > 1e-12 * max(min(A.volume(), B.volume()), 0.0):
            inter.append((a, b))
    if not inter:
        return mesh, []
    ea = np.array(inter, np.int64)
    g = sparse.coo_matrix((np.ones(len(ea)), (ea[:, 0], ea[:, 1])), shape=(nb, nb))
    _, grp = connected_components(g, directed=False)
    sizes = np.bincount(grp)
    groups = [np.flatnonzero(grp == k).tolist() for k in np.unique(grp[sizes[grp] > 1])]
    groups.sort(key=lambda gl: gl[0])
    keep = ~np.isin(body, [b for gl in groups for b in gl])
    pieces = [mesh.submesh(keep).compact()[0]] if keep.any() else []
    for gl in groups:
        U = m3.Manifold.batch_boolean([manifold_of(b) for b in gl], m3.OpType.Add)
        if plane is not None:
            U = U.trim_by_plane([-v for v in plane["normal"]], -plane["offset"])
        out = U.to_mesh64()
        V = np.asarray(out.vert_properties, np.float64)[:, :3]
        T = np.asarray(out.tri_verts, np.int64).reshape(-1, 3)
        run = np.asarray(out.run_index, np.int64) // 3
        rid = np.asarray(out.run_original_id, np.int64)
        fid = np.asarray(out.face_id, np.int64)
        comp = np.full(len(T), -1, np.int64)
        for r in range(len(rid)):
            s = tri_src.get(int(rid[r]))
            if s is not None:                   # else the cap made by the cut: dropped
                comp[run[r]:run[r + 1]] = mesh.component[s[fid[run[r]:run[r + 1]]]]
        T, comp = T[comp >= 0], comp[comp >= 0]
        V, T, comp = _canonical(V, T, comp)
        pieces.append(ShellMesh(V, T, comp.astype(np.int32), list(mesh.component_names)).compact()[0])
    from .mesh import concatenate
    return concatenate(pieces, merge_tol=None), groups


def _canonical(V, T, comp):
    """Deterministic vertex and triangle order (manifold3d's output order is an
    implementation detail): vertices sorted by coordinates, triangles rotated to start at
    their lowest vertex and sorted."""
    vo = np.lexsort(V.T[::-1])
    rank = np.empty(len(V), np.int64)
    rank[vo] = np.arange(len(V))
    T = rank[T]
    k = np.argmin(T, axis=1)
    T = T[np.arange(len(T))[:, None], (k[:, None] + np.arange(3)) % 3]
    to = np.lexsort(T.T[::-1])
    return V[vo], T[to], comp[to]


def _describe(mesh: ShellMesh, fmt: str, path: str, counts: dict, notes: list, known: dict | None = None
              ) -> SurfaceReport:
    """The report of ``mesh``; ``known`` holds counts the caller already has (``n_bodies``,
    ``n_inconsistent``) so they are not computed again."""
    known = known or {}
    topo = mesh.topology()
    lo = mesh.points.min(0)
    hi = mesh.points.max(0)
    present = np.unique(mesh.component)
    n_loops, plane, _ = _boundary_info(mesh)
    report = SurfaceReport(
        path=path, format=fmt, n_triangles=mesh.n_tris, n_quads=mesh.n_quads,
        n_vertices=mesh.n_points, bbox_min=tuple(float(v) for v in lo), bbox_max=tuple(float(v) for v in hi),
        diagonal=mesh.diagonal, closed=mesh.is_closed(),
        n_open_boundary_edges=int((topo.valence == 1).sum()),
        n_nonmanifold_edges=int((topo.valence > 2).sum()), n_bodies=known["n_bodies"] if "n_bodies" in known else mesh.n_bodies(),
        n_inconsistent_orientation_edges=known["n_inconsistent"] if "n_inconsistent" in known
        else _orientation_conflicts(mesh),
        n_merged_vertices=int(counts.get("merged", 0)), n_removed_duplicate_faces=int(counts.get("dup", 0)),
        n_removed_degenerate_faces=int(counts.get("deg", 0)), n_zero_area_faces=_n_zero_area(mesh),
        n_components=len(present), component_names=[mesh.component_names[i] for i in present],
        units=_units_note(fmt), notes=list(notes), n_boundary_loops=n_loops, symmetry_plane=plane,
        symmetry_vertices=symmetry_boundary_vertices(mesh, plane).tolist() if plane else [],
        warnings=_units_warnings(mesh.diagonal))
    return report


def _clean_to_mesh(raw: _Raw, name: str, merge_tol):
    if merge_tol is not None and (isinstance(merge_tol, bool) or not isinstance(merge_tol, (int, float))
                                  or not np.isfinite(merge_tol) or merge_tol < 0):
        raise InputFileError(f"merge_tol must be a non-negative number (a fraction of the bounding-box diagonal, "
                             f"default 1e-9), got {merge_tol!r}")
    pts, faces, comp, n_merged, n_deg, n_dup, n_q2t = _clean(raw, merge_tol)
    if not len(faces):
        raise InputFileError(f"{name}: every face is degenerate (collapsed nodes); re-export the file")
    mesh = ShellMesh(pts, faces, comp, raw.names)
    mesh, _ = mesh.compact()
    if not mesh.diagonal > 1e-150:
        raise MeshValidationError(f"{name}: the surface has no size (bounding-box diagonal {mesh.diagonal:.3g}): "
                                  "its coordinates are corrupt or in absurd units; fix or re-export the file")
    n_unref = len(pts) - mesh.n_points
    notes = list(raw.notes)
    if n_q2t:
        notes.append(f"{n_q2t} quads with one repeated node turned into triangles")
    if n_unref:
        notes.append(f"dropped {n_unref} vertices used by no face")
    return mesh, {"merged": n_merged, "dup": n_dup, "deg": n_deg}, notes


def _repair(mesh: ShellMesh, name: str, allow_open: bool, union: bool):
    """Handle or refuse the defects :func:`_describe` found (see :func:`repair_surface`)."""
    repairs, warns = [], []
    topo = mesh.topology()
    nm = np.flatnonzero(topo.valence > 2)
    if len(nm):
        raise MeshValidationError(
            f"{name}: {len(nm)} non-manifold edges (shared by 3 or more faces) "
            f"{_edge_where(mesh.points, topo.edges[nm])}: internal walls, T-joints or overlapping copies. "
            "Export only the outer skin, as one closed shell per body (remove internal faces); intersecting "
            "closed bodies are then joined automatically")
    if not _any_positive_area(mesh):
        raise MeshValidationError(f"{name}: every face has zero area (all points of each face on a line); "
                                  "re-export the surface")
    body = _face_bodies(topo, mesh.n_faces)
    nb = int(body.max()) + 1
    faces, n_flip = _orient_consistently(mesh, body, name)
    if n_flip:
        repairs.append(f"re-oriented {n_flip} faces so that neighbouring faces agree "
                       f"({_orientation_conflicts(mesh)} edges were inconsistent)")
        mesh = ShellMesh(mesh.points, faces, mesh.component, list(mesh.component_names))
    n_loops, plane, reason = _boundary_info(mesh)
    topo = mesh.topology()
    be = topo.edges[topo.valence == 1]
    open_face = np.zeros(mesh.n_faces, bool)
    open_face[topo.edge_faces[topo.edge_faces_ptr[np.flatnonzero(topo.valence == 1)]]] = True
    open_body = np.zeros(nb, bool)
    open_body[body[open_face]] = True
    if len(be) and plane is None:
        if not allow_open:
            raise MeshValidationError(
                f"{name}: {len(be)} open boundary edges ({n_loops} loop{'s' if n_loops > 1 else ''}) "
                f"{_edge_where(mesh.points, be)}: {reason}. Close the surface in CAD (cap the open trailing edge, "
                "fill holes, stitch seams; unmerged vertices of a crack: re-export, or load with a larger "
                "merge_tol), or for a half model cut it exactly at the symmetry plane")
        warns.append(f"{len(be)} open boundary edges ({n_loops} loops) that are not a symmetry plane: "
                               f"{reason}; meshed as free edges")
    # outward: positive volume per body, cones from a point of its open boundary (on the
    # symmetry plane for a half model: the missing half adds nothing) or from its centroid
    P = mesh.points
    fv = mesh.faces
    corner_body = np.broadcast_to(body[:, None], fv.shape)[fv >= 0]
    cp = P[fv[fv >= 0]]
    cnt = np.bincount(corner_body, minlength=nb).astype(np.float64)
    apex = np.stack([np.bincount(corner_body, cp[:, k], nb) for k in range(3)], 1) / cnt[:, None]
    if len(be):
        bf = topo.edge_faces[topo.edge_faces_ptr[np.flatnonzero(topo.valence == 1)]]
        bb = body[bf]
        k = np.bincount(bb, minlength=nb).astype(np.float64)
        s = np.stack([np.bincount(bb, P[be[:, 0], j], nb) for j in range(3)], 1)
        has = k > 0
        apex[has] = s[has] / k[has, None]
    vol = _signed_volumes(P, mesh.faces, body, nb, apex)
    inward = np.flatnonzero(vol < 0)
    if len(inward):
        rows = np.flatnonzero(np.isin(body, inward))
        mesh = ShellMesh(P, _flip_faces(mesh.faces, rows), mesh.component, list(mesh.component_names))
        repairs.append(f"turned {len(inward)} inside-out bod{'y' if len(inward) == 1 else 'ies'} "
                       f"({len(rows)} faces) to face outward")
    if nb > 1 and union:
        mesh, groups = _unite_bodies(mesh, body, plane, open_body, name)
        for gl in groups:
            repairs.append(f"joined {len(gl)} intersecting bodies ({', '.join(map(str, gl))}) into one by a "
                           "boolean union (manifold3d)")
    if plane is not None:
        n_loops, _, _ = _boundary_info(mesh)
        nbe = len(mesh.boundary_edges())
        repairs.append(f"half model: {nbe} open boundary edges ({n_loops} loop{'s' if n_loops > 1 else ''}) "
                       f"lie in the symmetry plane {_plane_text(plane['normal'], plane['point'], plane['axis'])}; "
                       "they are a clamped (symmetry) boundary")
    # consistent by construction; the body count is unchanged unless bodies were joined
    known = {"n_inconsistent": 0}
    if not any(r.startswith("joined") for r in repairs):
        known["n_bodies"] = nb
    return mesh, repairs, warns, known


# =========================================================================== public API
def load_surface(path, merge_tol: float | None = 1e-9, *, cad_mesh_size: float | None = None,
                 repair: bool = False, allow_open: bool = False, union: bool = True
                 ) -> tuple[ShellMesh, SurfaceReport]:
    """Read a surface triangulation (or mixed tri/quad surface) and report on it.

    Formats: STL/OBJ/PLY/OFF (trimesh, ``process=False``), VTU/MSH (meshio), VTK/VTP (pyvista),
    Nastran .bdf/.nas (pyNastran; GRID + CTRIA3/CQUAD4/CTRIAR/CQUADR), CalculiX/Abaqus .inp,
    STEP/STP/IGES/IGS (gmsh's OpenCASCADE tessellation; needs the ``cad`` extra; element size
    ``cad_mesh_size``, default diagonal / 50).

    Cleaning always done here, each counted in the report: vertices closer than ``merge_tol``
    times the bounding-box diagonal are merged (``None`` or ``0`` merges only exact
    duplicates); faces whose nodes collapse are removed (a quad with one repeated adjacent
    node becomes a triangle); faces repeating another face's node set are removed (first
    kept); unused vertices are dropped.

    With ``repair=False`` (the default; ``shellmesh info``) open boundaries, non-manifold
    edges, several bodies, inconsistent orientation and zero-area faces are counted, never
    repaired; a half model's symmetry plane is detected and reported; a units warning is
    added when the diagonal is outside :data:`UNITS_DIAGONAL_RANGE`. With ``repair=True``
    the surface is made ready for meshing or refused: see :func:`repair_surface`.

    Raises :class:`InputFileError` (missing file, folder, unknown extension, empty or
    unreadable file) or :class:`MeshValidationError` (NaN/inf coordinates; with ``repair``
    the defects :func:`repair_surface` refuses)."""
    t0 = time.perf_counter()
    p = _check_path(path, SURFACE_FORMATS, "surface")
    raw = _read(p, cad_mesh_size)
    _validate_raw(raw, p)
    return _load_raw(raw, p.name, str(p), merge_tol, repair, allow_open, union, t0)


def _load_raw(raw, name, path, merge_tol, repair, allow_open, union, t0):
    mesh, counts, notes = _clean_to_mesh(raw, name, merge_tol)
    if repair:
        mesh, repairs, warns, known = _repair(mesh, name, allow_open, union)
        report = _describe(mesh, raw.fmt, path, counts, notes, known)
        report.repaired = True
        report.repairs = repairs
        report.warnings = warns + report.warnings
    else:
        report = _describe(mesh, raw.fmt, path, counts, notes)
    for w in report.warnings:
        log.warning("warning: %s: %s", name, w)
    report.load_seconds = time.perf_counter() - t0
    return mesh, report


def repair_surface(surface, merge_tol: float | None = 1e-9, *, allow_open: bool = False, union: bool = True,
                   cad_mesh_size: float | None = None) -> tuple[ShellMesh, SurfaceReport]:
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
    * open boundaries: when all open-boundary vertices lie in one plane, the surface lies on
      one side of it and crosses it (no face next to the boundary lies in it), the surface is
      a **half model**: accepted, and ``report.symmetry_plane`` (normal pointing away from
      the surface, a point, the axis of a coordinate plane) and ``report.symmetry_vertices``
      name the boundary to clamp (:func:`symmetry_boundary_vertices` finds it again in any
      later mesh). Other open boundaries (open trailing edges, holes, cracks) are refused,
      or with ``allow_open=True`` kept as free edges with a warning;
    * several bodies: bodies whose volumes overlap (a wing through a fuselage) are joined
      by a boolean union with manifold3d (for a half model each body is closed by its
      mirror image, united, and cut back at the symmetry plane); bodies that touch nothing
      are kept as they are. ``union=False`` keeps overlapping bodies unjoined;
    * units: a diagonal outside :data:`UNITS_DIAGONAL_RANGE` gives a warning
      (``report.warnings``, and logged) naming the likely unit mistake.

    Fixed vertices and feature edges of a :class:`ShellMesh` input are not kept."""
    t0 = time.perf_counter()
    if isinstance(surface, ShellMesh):
        raw = _Raw(surface.points, surface.faces, surface.component, surface.component_names, fmt="ShellMesh")
        if not len(raw.faces):
            raise MeshValidationError("the surface mesh has no faces; give a non-empty surface")
        bad = ~np.isfinite(raw.points).all(1)
        if bad.any():
            raise MeshValidationError(f"the surface mesh has {int(bad.sum())} of {len(raw.points)} vertices with "
                                      "NaN/inf coordinates; fix the mesh first (ShellMesh.check lists them)")
        return _load_raw(raw, "surface", "<mesh>", merge_tol, True, allow_open, union, t0)
    return load_surface(surface, merge_tol, cad_mesh_size=cad_mesh_size, repair=True, allow_open=allow_open,
                        union=union)


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
    p = _check_path(p, MESH_FORMATS, "mesh")
    raw = _read(p)
    _validate_raw(raw, p)
    try:
        return ShellMesh(raw.points, raw.faces, raw.component, raw.names, raw.fixed, raw.fe, raw.fe_ids)
    except MeshValidationError as e:
        raise InputFileError(f"{p.name}: {e}; re-export the file") from None
