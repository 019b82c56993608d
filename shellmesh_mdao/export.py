"""Write a :class:`~shellmesh_mdao.mesh.ShellMesh` to FEA and visualisation formats.

:func:`write_mesh` picks the format from the file extension:

``.bdf`` / ``.nas``  Nastran bulk data (GRID*, CQUAD4/CTRIA3, one PSHELL per component, one MAT1),
                     readable by pyNastran, pyTACS and Nastran (``INCLUDE`` it after ``BEGIN BULK``).
``.inp``             CalculiX / Abaqus model part (*NODE, *ELEMENT with one ELSET per component,
                     *MATERIAL, *SHELL SECTION); no steps or loads.
``.vtu``             VTK XML unstructured grid (binary, zlib), cell data ``component``, per-element
                     quality arrays, feature edges as line cells, names as field data.
``.msh``             Gmsh MSH 4.1 (ASCII), one surface entity and one named physical group per component.

Every writer is atomic: the file is written to a hidden temporary file in the target
folder and moved into place with :func:`os.replace`, so a failed or interrupted write
never leaves a partial output file.

All formats write the faces in the same *export order* (:func:`export_order`): grouped by
component id, quads before triangles within a component, original order kept otherwise.
Element ``k`` of every file (1-based id ``k + 1``) is face ``export_order(mesh)[k]``; node
``i`` is written with 1-based id ``i + 1`` (all nodes, including unreferenced ones), so a
mesh already in export order reads back face for face and node for node.

See ``docs/file_formats.md`` for the details of each format.
"""
from __future__ import annotations

import json
import os
import re
import tempfile
from pathlib import Path
from typing import Callable
from xml.sax.saxutils import quoteattr

import numpy as np

from .errors import OutputError, ShellMeshError
from .core.formats import inp_elset_names, n_components, sanitise_name
from .families import padded_names, unnamed_name
from .mesh import ShellMesh

__all__ = [
    "write_mesh", "check_output_path", "write_text_atomic", "atomic_write", "export_order", "resolve_thickness", "resolve_material", "inp_mesh_lines",
    "inp_elset_names", "bdf_family_name", "DEFAULT_THICKNESS", "DEFAULT_MATERIAL", "OUTPUT_FORMATS",
]

#: Default shell thickness (model length units; 0.002 = 2 mm when the model is in metres).
DEFAULT_THICKNESS = 0.002

#: Default material: aluminium 7075-T6-like, SI units (Pa, kg/m^3).  ``ys`` is the tensile
#: yield stress, written as the MAT1 ST limit.
DEFAULT_MATERIAL = {"name": "AL7075", "E": 71.7e9, "nu": 0.33, "rho": 2810.0, "ys": 503.0e6}

#: Supported output extensions and what they write.
OUTPUT_FORMATS = {
    ".bdf": "Nastran bulk data",
    ".nas": "Nastran bulk data",
    ".inp": "CalculiX/Abaqus input (mesh, material, shell sections)",
    ".vtu": "VTK XML unstructured grid",
    ".msh": "Gmsh MSH 4.1",
}

_BDF_FAMILY_COMMENT = "$ Shell element data for family {}"
_BDF_PSHELL_COMMENT = "shellmesh_mdao component {}: {}"  # name as a JSON string
_INP_FAMILY_COMMENT = "** family {} {}"


# --------------------------------------------------------------------------- helpers
def export_order(mesh: ShellMesh) -> np.ndarray:
    """Permutation of the faces used by every writer: stable sort by (component id, triangle
    after quad).  ``faces_in_file = mesh.faces[export_order(mesh)]``."""
    return np.lexsort((mesh.is_tri.astype(np.int8), mesh.component)).astype(np.int64)


def resolve_thickness(mesh: ShellMesh, thickness=None) -> np.ndarray:
    """Thickness of each component, a (ncomp,) float array.

    ``thickness`` may be ``None`` (all :data:`DEFAULT_THICKNESS`), a number (all the same),
    a dict ``component name -> t`` (components not named get the default) or a sequence
    with one value per component id.  Raises :class:`OutputError` for unknown names,
    wrong lengths and non-positive or non-finite values."""
    k = n_components(mesh)
    names = list(mesh.component_names)
    if thickness is None:
        t = np.full(k, DEFAULT_THICKNESS)
    elif isinstance(thickness, dict):
        unknown = [n for n in thickness if n not in names]
        if unknown:
            raise OutputError(f"thickness given for unknown component(s) {unknown}; "
                              f"the mesh's components are {names}")
        t = np.array([thickness.get(n, DEFAULT_THICKNESS) for n in names[:k]]
                     + [DEFAULT_THICKNESS] * (k - len(names)), dtype=float)
    elif np.ndim(thickness) == 0:
        t = np.full(k, float(thickness))
    else:
        t = np.asarray(thickness, dtype=float).reshape(-1)
        if len(t) != k:
            raise OutputError(f"thickness array has {len(t)} values but the mesh has {k} components; "
                              "give one value per component id (or a dict name -> thickness)")
    bad = ~np.isfinite(t) | (t <= 0)
    if bad.any():
        raise OutputError(f"thickness must be positive and finite; got {t[bad].tolist()} for components "
                          f"{[names[i] if i < len(names) else i for i in np.flatnonzero(bad)]}")
    return t


def resolve_material(material: dict | None = None) -> dict:
    """The material written by every FEA format: :data:`DEFAULT_MATERIAL` updated with
    ``material`` (keys ``name``, ``E``, ``nu``, ``rho``, ``G`` (optional, else derived by the
    solver), ``ys`` (optional tensile yield stress))."""
    out = dict(DEFAULT_MATERIAL)
    if material:
        allowed = {"name", "E", "nu", "rho", "G", "ys"}
        unknown = sorted(set(material) - allowed)
        if unknown:
            raise OutputError(f"unknown material key(s) {unknown}; allowed keys are {sorted(allowed)}")
        out.update(material)
    for key in ("E", "rho"):
        v = float(out[key])
        if not np.isfinite(v) or v <= 0:
            raise OutputError(f"material {key} must be positive and finite, got {out[key]!r}")
    nu = float(out["nu"])
    if not (-1.0 < nu < 0.5):
        raise OutputError(f"material nu must lie in (-1, 0.5), got {out['nu']!r}")
    for key in ("G", "ys"):
        if out.get(key) is not None and (not np.isfinite(float(out[key])) or float(out[key]) <= 0):
            raise OutputError(f"material {key} must be positive and finite, got {out[key]!r}")
    out["name"] = str(out["name"])
    return out


def _fixed_decimals(points: np.ndarray, width: int) -> str:
    """printf format writing every coordinate in at most ``width`` characters with as many
    decimals as fit: fixed point sized for the largest magnitude, exponent form if huge."""
    maxabs = float(np.abs(points).max()) if points.size else 0.0
    digits = len(str(int(maxabs))) if maxabs >= 1 else 1
    dec = width - 2 - digits
    if dec >= 1 and round(maxabs, dec) >= 10.0 ** digits:
        dec -= 1
    if dec < 4:
        return f"%{width}.{width - 7}E"
    return f"%{width}.{dec}f"


def _format_rows(row_fmt: str, columns: list, chunk: int = 100_000):
    """Yield text for rows formatted with ``row_fmt`` (printf style); ``columns`` are arrays
    of equal length.  Formatting is done in C by one ``%`` per chunk of rows (integer
    columns travel as exact float64 when mixed with real columns: ids stay far below 2**53)."""
    n = len(columns[0]) if columns else 0
    ints = all(np.issubdtype(np.asarray(c).dtype, np.integer) for c in columns)
    dtype = np.int64 if ints else np.float64
    for s in range(0, n, chunk):
        e = min(n, s + chunk)
        block = np.column_stack([np.asarray(c[s:e], dtype=dtype) for c in columns])
        yield (row_fmt * (e - s)) % tuple(block.ravel().tolist())


def _real20(x) -> str:
    """Shortest exact text of a real if it fits CalculiX's 20-character field, else 14 digits."""
    r = repr(float(x))
    return r if len(r) <= 20 else f"{float(x):.13e}"


def bdf_family_name(name: str, cid: int) -> str:
    """Component name as written in the ``$ Shell element data for family`` comment: pyTACS
    takes the comment's last word, so whitespace becomes ``_``."""
    s = re.sub(r"\s+", "_", name.strip()).encode("ascii", "replace").decode().replace("?", "_")
    s = re.sub("(?i)pynastran", "py_nastran", s)
    return s or unnamed_name(cid)


def _json_name(name: str) -> str:
    """Exact, ASCII, one-line encoding of a name for a Nastran comment.  pyNastran treats
    comments containing the word 'pyNastran' specially (and can fail on them), so its 'N'
    is written as a JSON unicode escape; ``json.loads`` restores the name exactly."""
    s = json.dumps(str(name), ensure_ascii=True)
    return re.sub("(?i)(py)(n)(astran)", lambda m: m[1] + "\\u%04x" % ord(m[2]) + m[3], s)


def _one_line(s: str) -> str:
    return re.sub(r"[\r\n]+", " ", s)


# --------------------------------------------------------------------------- atomic write
def _umask() -> int:
    old = os.umask(0o022)
    os.umask(old)
    return old


def _check_folder(path: Path) -> None:
    folder = path.parent
    if not folder.exists():
        raise OutputError(f"cannot write {path}: folder {folder} does not exist; create it first "
                          f"(mkdir -p {folder}) or choose another output path")
    if not folder.is_dir():
        raise OutputError(f"cannot write {path}: {folder} is a file, not a folder; choose an output "
                          "path inside an existing folder")
    if path.is_dir():
        raise OutputError(f"cannot write {path}: it is an existing folder; give a file name ending in "
                          f"one of {sorted(OUTPUT_FORMATS)}")


def _temp_in(path: Path) -> str:
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.close(fd)
    except OSError as e:
        raise OutputError(f"cannot write {path}: folder {path.parent} is not writable ({e.strerror}); "
                          "choose a writable folder or fix its permissions") from None
    return tmp_name


def check_output_path(path, formats=None) -> Path:
    """Fail early, before any work, when ``path`` cannot be written: missing or read-only
    folder, a folder given as the file, or (with ``formats``, default the mesh formats) an
    unsupported extension. Probes writability with a temporary file it removes."""
    path = Path(path)
    formats = OUTPUT_FORMATS if formats is None else formats
    if formats and path.suffix.lower() not in formats:
        raise OutputError(f"cannot write {path.name}: unknown output extension {path.suffix or '(none)'!r}; "
                          f"use one of {', '.join(sorted(formats))}")
    _check_folder(path)
    os.unlink(_temp_in(path))
    return path


def write_text_atomic(path, text: str) -> Path:
    """Write a text file (a report) atomically: temporary file in the same folder, then rename."""
    path = Path(path)
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def atomic_write(path, write: Callable[[Path], None]) -> Path:
    """Write ``path`` atomically: ``write(tmp)`` fills a temporary file in the same folder,
    which then replaces ``path`` (permissions as a new file would get). A failure removes the
    temporary file and leaves ``path`` as it was; an :class:`OSError` becomes an
    :class:`~shellmesh_mdao.errors.OutputError` naming the file. Returns ``path``."""
    path = Path(path)
    _check_folder(path)
    tmp_name = _temp_in(path)
    tmp = Path(tmp_name)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except ShellMeshError:
        tmp.unlink(missing_ok=True)
        raise
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"cannot write {path}: {e.strerror or e} (disk full or folder not writable?); "
                          "free space or choose another folder") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


# --------------------------------------------------------------------------- public entry
def write_mesh(mesh: ShellMesh, path, *, thickness=None, material: dict | None = None,
               quality: dict | None = None) -> Path:
    """Write ``mesh`` to ``path``; the extension picks the format (see :data:`OUTPUT_FORMATS`).

    ``thickness`` (see :func:`resolve_thickness`) and ``material`` (see
    :func:`resolve_material`) go into the FEA formats (.bdf/.nas, .inp); ``quality`` is a dict
    ``name -> (n_faces,) array`` of per-element values written as VTU cell data.
    Component ids and names are carried in every format.  The write is atomic.
    Returns the written path.  Raises :class:`OutputError` for an unknown extension, a
    missing or read-only folder, or bad thickness/material/quality values."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in OUTPUT_FORMATS:
        raise OutputError(f"cannot write {path}: unknown extension {path.suffix!r}; supported: "
                          + ", ".join(f"{k} ({v})" for k, v in OUTPUT_FORMATS.items()))
    if not isinstance(mesh, ShellMesh):
        raise OutputError(f"write_mesh needs a ShellMesh, got {type(mesh).__name__}")
    if not np.isfinite(mesh.points).all():
        raise OutputError(f"cannot write {path}: {int((~np.isfinite(mesh.points).all(1)).sum())} nodes have "
                          "NaN/inf coordinates; fix the mesh first (ShellMesh.check lists them)")
    if ext in (".bdf", ".nas"):
        t, mat = resolve_thickness(mesh, thickness), resolve_material(material)
        return atomic_write(path, lambda p: _write_bdf(mesh, p, t, mat))
    if ext == ".inp":
        blocks = inp_mesh_lines(mesh, thickness, material)
        return atomic_write(path, lambda p: _write_blocks(p, blocks))
    if ext == ".vtu":
        q = _check_quality(mesh, quality)
        return atomic_write(path, lambda p: _write_vtu(mesh, p, q))
    return atomic_write(path, lambda p: _write_msh(mesh, p))


def _write_blocks(path: Path, blocks) -> None:
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        for b in blocks:
            fh.write(b)


def _check_quality(mesh: ShellMesh, quality) -> dict:
    out = {}
    for name, arr in (quality or {}).items():
        a = np.asarray(arr)
        if a.shape != (mesh.n_faces,):
            raise OutputError(f"quality array {name!r} has shape {a.shape}; it needs one value per face "
                              f"({mesh.n_faces},)")
        if name in ("component",):
            raise OutputError(f"quality array name {name!r} is reserved; rename it")
        out[str(name)] = a.astype(np.float64)
    return out


# --------------------------------------------------------------------------- Nastran
def _write_bdf(mesh: ShellMesh, path: Path, thickness: np.ndarray, mat: dict) -> None:
    from pyNastran.bdf.bdf import BDF

    from . import __version__

    order = export_order(mesh)
    faces = mesh.faces[order]
    comp = mesh.component[order]
    k = len(thickness)
    if mesh.n_points > 99_999_999 or mesh.n_faces > 99_999_999:
        raise OutputError("the mesh has more than 99,999,999 nodes or elements, which small-field "
                          "CQUAD4/CTRIA3 cards cannot number; write .vtu or .msh instead")
    names = padded_names(mesh.component_names, k)
    model = BDF(debug=None)
    mid = 1
    model.add_mat1(mid, float(mat["E"]), None if mat.get("G") is None else float(mat["G"]),
                   float(mat["nu"]), rho=float(mat["rho"]),
                   St=0.0 if mat.get("ys") is None else float(mat["ys"]),
                   comment=f" material {_json_name(mat['name'])}")
    head = [
        "$ pyNastran: punch=True\n",
        f"$ shellmesh_mdao {__version__} Nastran bulk data: {mesh.n_points} GRID, {mesh.n_faces} elements "
        f"({mesh.n_quads} CQUAD4, {mesh.n_tris} CTRIA3), {k} components\n",
        "$ bulk data only: INCLUDE this file after BEGIN BULK; pyTACS reads it directly\n",
        "$ PSHELL pid = component id + 1; MAT1 mid 1\n",
        model.materials[mid].write_card(size=16),
    ]
    for c in range(k):
        model.add_pshell(c + 1, mid1=mid, t=float(thickness[c]), mid2=mid, mid3=None,
                         comment=" " + _BDF_PSHELL_COMMENT.format(c, _json_name(names[c])))
        head.append(model.properties[c + 1].write_card(size=16))
    xyz_fmt = _fixed_decimals(mesh.points, 16)
    grid_fmt = f"GRID*   %16d{'':16s}{xyz_fmt}{xyz_fmt}\n*       {xyz_fmt}\n"
    ids = np.arange(1, mesh.n_points + 1)
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.writelines(head)
        for text in _format_rows(grid_fmt, [ids, mesh.points[:, 0], mesh.points[:, 1], mesh.points[:, 2]]):
            fh.write(text)
        eids = np.arange(1, len(faces) + 1)
        starts = np.searchsorted(comp, np.arange(k + 1))
        for c in range(k):
            s, e = starts[c], starts[c + 1]
            if s == e:
                continue
            fh.write(_BDF_FAMILY_COMMENT.format(bdf_family_name(names[c], c)) + "\n")
            f = faces[s:e]
            quad = f[:, 3] >= 0
            nq = int(quad.sum())       # quads come first within a component (export order)
            pid = np.full(e - s, c + 1)
            if nq:
                fh.writelines(_format_rows("CQUAD4  %8d%8d%8d%8d%8d%8d\n",
                                           [eids[s:s + nq], pid[:nq]] + [f[:nq, j] + 1 for j in range(4)]))
            if nq < e - s:
                fh.writelines(_format_rows("CTRIA3  %8d%8d%8d%8d%8d\n",
                                           [eids[s + nq:e], pid[nq:]] + [f[nq:, j] + 1 for j in range(3)]))


# --------------------------------------------------------------------------- CalculiX
def inp_mesh_lines(mesh: ShellMesh, thickness=None, material: dict | None = None, *,
                   quad_type: str = "S4", tri_type: str = "S3") -> list[str]:
    """Model part of a CalculiX/Abaqus input deck as a list of text blocks.

    Each entry is one or more complete lines ending in ``\\n``; ``"".join(blocks)`` is the
    text: header comments (``** family <id> <original name>`` per component), ``*NODE,
    NSET=NALL``, ``*ELEMENT, TYPE=S4|S3, ELSET=<name>`` per component (names from
    :func:`inp_elset_names`), ``*ELSET, ELSET=EALL``, ``*MATERIAL``/``*ELASTIC``/``*DENSITY``
    and one ``*SHELL SECTION`` per component.  Steps and loads are left to the caller.
    Node ``i`` gets number ``i + 1``; element ``k`` of :func:`export_order` number ``k + 1``.
    Coordinates are written in at most 20 characters (CalculiX reads reals as ``f20.0``)."""
    from . import __version__

    t = resolve_thickness(mesh, thickness)
    mat = resolve_material(material)
    k = len(t)
    elsets = inp_elset_names(mesh)
    names = padded_names(mesh.component_names, k)
    matname = sanitise_name(mat["name"], 80, set(), "MATERIAL")
    order = export_order(mesh)
    faces = mesh.faces[order]
    comp = mesh.component[order]
    blocks = [f"** shellmesh_mdao {__version__} CalculiX mesh: {mesh.n_points} nodes, {mesh.n_faces} elements "
              f"({mesh.n_quads} {quad_type}, {mesh.n_tris} {tri_type}), {k} components\n",
              "** component id -> original name (ELSET names are sanitised versions):\n"]
    blocks.append("".join(_INP_FAMILY_COMMENT.format(c, _one_line(names[c])) + "\n" for c in range(k)))
    blocks.append("*NODE, NSET=NALL\n")
    xyz = _fixed_decimals(mesh.points, 20).replace("%20", "%")
    blocks.extend(_format_rows(f"%d, {xyz}, {xyz}, {xyz}\n",
                               [np.arange(1, mesh.n_points + 1), mesh.points[:, 0], mesh.points[:, 1],
                                mesh.points[:, 2]]))
    eids = np.arange(1, len(faces) + 1)
    starts = np.searchsorted(comp, np.arange(k + 1))
    for c in range(k):
        s, e = starts[c], starts[c + 1]
        f = faces[s:e]
        nq = int((f[:, 3] >= 0).sum())
        if nq:
            blocks.append(f"*ELEMENT, TYPE={quad_type}, ELSET={elsets[c]}\n")
            blocks.extend(_format_rows("%d, %d, %d, %d, %d\n", [eids[s:s + nq]] + [f[:nq, j] + 1 for j in range(4)]))
        if nq < e - s:
            blocks.append(f"*ELEMENT, TYPE={tri_type}, ELSET={elsets[c]}\n")
            blocks.extend(_format_rows("%d, %d, %d, %d\n", [eids[s + nq:e]] + [f[nq:, j] + 1 for j in range(3)]))
    used = [elsets[c] for c in range(k) if starts[c + 1] > starts[c]]
    if used:
        blocks.append("*ELSET, ELSET=EALL\n" + "".join(
            ", ".join(used[i:i + 8]) + "\n" for i in range(0, len(used), 8)))
    blocks.append(f"*MATERIAL, NAME={matname}\n*ELASTIC\n{_real20(mat['E'])}, {_real20(mat['nu'])}\n"
                  f"*DENSITY\n{_real20(mat['rho'])}\n")
    for c in range(k):
        if starts[c + 1] > starts[c]:
            blocks.append(f"*SHELL SECTION, ELSET={elsets[c]}, MATERIAL={matname}\n{_real20(t[c])}\n")
    return blocks


# --------------------------------------------------------------------------- VTU
def _write_vtu(mesh: ShellMesh, path: Path, quality: dict) -> None:
    import meshio

    order = export_order(mesh)
    faces = mesh.faces[order]
    comp = mesh.component[order]
    tri = faces[:, 3] < 0
    # one block per (component, type) run in export order
    key = comp.astype(np.int64) * 2 + tri
    cut = np.flatnonzero(np.diff(key)) + 1
    bounds = np.concatenate([[0], cut, [len(faces)]]) if len(faces) else np.zeros(1, np.int64)
    cells, cdata = [], {"component": []}
    qdata = {n: [] for n in quality}
    for s, e in zip(bounds[:-1], bounds[1:]):
        if tri[s]:
            cells.append(("triangle", faces[s:e, :3]))
        else:
            cells.append(("quad", faces[s:e]))
        cdata["component"].append(comp[s:e].astype(np.int32))
        for n, a in quality.items():
            qdata[n].append(a[order[s:e]])
    if len(mesh.feature_edges):
        cells.append(("line", mesh.feature_edges))
        cdata["component"].append(mesh.feature_edge_ids.astype(np.int32))
        for n in quality:
            qdata[n].append(np.full(len(mesh.feature_edges), np.nan))
    cdata.update(qdata)
    fixed = np.zeros(mesh.n_points, np.uint8)
    fixed[mesh.fixed_vertices] = 1
    m = meshio.Mesh(mesh.points, cells, point_data={"fixed": fixed}, cell_data=cdata if cells else {})
    meshio.write(str(path), m, file_format="vtu")
    # meshio's VTU writer drops field data: add the component-name table ourselves
    k = n_components(mesh)
    names = padded_names(mesh.component_names, k)
    fd = "<FieldData>\n" + "".join(
        f'<DataArray type="Int32" Name={quoteattr(_one_line(n))} NumberOfTuples="1" format="ascii">{i}'
        f"</DataArray>\n" for i, n in enumerate(names)) + "</FieldData>\n"
    _insert_after_first(path, b"<UnstructuredGrid>\n", fd.encode("utf-8"))


def _insert_after_first(path: Path, marker: bytes, text: bytes) -> None:
    """Insert ``text`` after the first ``marker`` near the top of a file (streamed copy)."""
    with open(path, "rb") as fh:
        head = fh.read(4096)
        pos = head.find(marker)
        if pos < 0:
            raise OutputError(f"unexpected VTU layout written by meshio in {path}; please report this")
        tmp = path.with_name(path.name + ".fd")
        try:
            with open(tmp, "wb") as out:
                out.write(head[:pos + len(marker)])
                out.write(text)
                out.write(head[pos + len(marker):])
                while True:
                    b = fh.read(1 << 22)
                    if not b:
                        break
                    out.write(b)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
    os.replace(tmp, path)


# --------------------------------------------------------------------------- Gmsh
def _write_msh(mesh: ShellMesh, path: Path) -> None:
    """Gmsh MSH 4.1 ASCII: one discrete surface entity per component (tag = id + 1) carrying
    physical group id + 1 named after the component; nodes in one block on entity 1."""
    order = export_order(mesh)
    faces = mesh.faces[order]
    comp = mesh.component[order]
    k = max(n_components(mesh), 1)
    names = padded_names(mesh.component_names, k)
    starts = np.searchsorted(comp, np.arange(k + 1))
    pts = mesh.points
    lo = pts.min(0) if len(pts) else np.zeros(3)
    hi = pts.max(0) if len(pts) else np.zeros(3)
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n")
        fh.write(f"$PhysicalNames\n{k}\n")
        for c in range(k):
            fh.write(f'2 {c + 1} "{_one_line(names[c]).replace(chr(34), chr(39))}"\n')
        fh.write("$EndPhysicalNames\n")
        fh.write(f"$Entities\n0 0 {k} 0\n")
        for c in range(k):
            f = faces[starts[c]:starts[c + 1]]
            used = f[f >= 0]
            a, b = (pts[used].min(0), pts[used].max(0)) if len(used) else (lo, hi)
            fh.write(f"{c + 1} " + " ".join(f"{v:.16e}" for v in (*a, *b)) + f" 1 {c + 1} 0\n")
        fh.write("$EndEntities\n")
        n = mesh.n_points
        fh.write(f"$Nodes\n1 {n} {min(n, 1)} {n}\n2 1 0 {n}\n")
        ids = np.arange(1, n + 1)
        fh.writelines(_format_rows("%d\n", [ids]))
        fh.writelines(_format_rows("%.17g %.17g %.17g\n", [pts[:, 0], pts[:, 1], pts[:, 2]]))
        fh.write("$EndNodes\n")
        blocks = []
        for c in range(k):
            s, e = starts[c], starts[c + 1]
            nq = int((faces[s:e, 3] >= 0).sum())
            if nq:
                blocks.append((c, 3, s, s + nq))
            if nq < e - s:
                blocks.append((c, 2, s + nq, e))
        m = len(faces)
        fh.write(f"$Elements\n{len(blocks)} {m} {min(m, 1)} {m}\n")
        eids = np.arange(1, m + 1)
        for c, etype, s, e in blocks:
            fh.write(f"2 {c + 1} {etype} {e - s}\n")
            nn = 4 if etype == 3 else 3
            fh.writelines(_format_rows("%d" + " %d" * nn + "\n",
                                       [eids[s:e]] + [faces[s:e, j] + 1 for j in range(nn)]))
        fh.write("$EndElements\n")
