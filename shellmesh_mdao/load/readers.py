"""The load stage's file readers: :func:`read_file` picks the reader by extension (STL/OBJ/PLY/OFF
through trimesh, VTU/MSH through meshio, VTK/VTP through pyvista, Nastran through our vectorised
reader or pyNastran, INP through our own reader, STEP/IGES through :mod:`.cad`) and turns library
errors on bad files into :class:`~shellmesh_mdao.errors.InputFileError`."""
from __future__ import annotations

import contextlib
import json
import re
import warnings
from pathlib import Path

import numpy as np

from ..errors import InputFileError, ShellMeshError
from ..families import physical_group_name, unnamed_name
from ..mesh import ShellMesh
from .cad import read_cad
from .raw import DEFAULT_NAME, RawMesh

__all__ = ["read_file"]


def read_file(p: Path, cad_mesh_size=None, size=None) -> RawMesh:
    """The raw mesh of file ``p`` by the reader of its extension (``cad_mesh_size``: the element
    size of a STEP/IGES tessellation, else derived from ``size``, the target element size)."""
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
            return read_cad(p, cad_mesh_size, size)
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
def _read_trimesh(p: Path) -> RawMesh:
    import trimesh

    if p.suffix.lower() == ".stl":    # direct reader: trimesh.load adds seconds of copies per 1M faces
        from trimesh.exchange.stl import load_stl
        try:
            with open(p, "rb") as fh:
                d = load_stl(fh)
            v = np.asarray(d["vertices"], np.float64)
            f = np.asarray(d["faces"], np.int64)
            if len(f):
                return RawMesh(v, f, fmt="STL")
        except Exception:
            pass
    m = trimesh.load(str(p), process=False, force="mesh")
    if p.suffix.lower() == ".stl" and (not isinstance(m, trimesh.Trimesh) or not len(m.faces)):
        _stl_diagnose(p)
    if not isinstance(m, trimesh.Trimesh):
        raise InputFileError(f"{p.name} holds no triangle mesh (trimesh returned {type(m).__name__}); "
                             "give a surface mesh file")
    return RawMesh(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64), fmt=p.suffix[1:].upper())


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


def _read_meshio(p: Path) -> RawMesh:
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
        names = [table.get(i, unnamed_name(i)) for i in range(k)]
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
        names = [named.get(int(t), physical_group_name(int(t))) for t in all_tags]
    else:
        comp = None
        names = None
        for key in ("CellEntityIds", "medit:ref", "cell_tags"):
            if key in cd and blocks:
                tags = np.concatenate([np.asarray(cd[key][b]).reshape(-1) for b in blocks])
                uniq, comp = np.unique(tags, return_inverse=True)
                names = [f"{key}_{int(t)}" for t in uniq]
                break
    return RawMesh(m.points[:, :3] if m.points.shape[1] >= 3 else np.c_[m.points, np.zeros(len(m.points))],
                f, comp, names, fixed, fe, fe_ids, notes, fmt)


def _read_pyvista(p: Path) -> RawMesh:
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
            names = [table.get(i, unnamed_name(i)) for i in range(k)]
    return RawMesh(np.asarray(g.points, np.float64), faces[keep], comp, names, notes=notes,
                fmt=p.suffix[1:].upper())


_PSHELL_NAME = re.compile(r"shellmesh_mdao component (\d+): (\".*\")")
_FAMILY = re.compile(r"Shell element data for family\s+(\S+)")
_FEMAP = re.compile(r"Femap Property\s+\d+\s*:\s*(\S+)")


_OWN_BDF_HEAD = b"$ pyNastran: punch=True\n$ shellmesh_mdao "


def _fixed_field(buf: np.ndarray, starts: np.ndarray, a: int, b: int, dtype) -> np.ndarray:
    """Columns ``a:b`` of the lines starting at ``starts`` parsed as numbers (vectorised)."""
    cols = buf[starts[:, None] + np.arange(a, b)]
    return np.ascontiguousarray(cols).view(f"S{b - a}").ravel().astype(dtype)


def _read_own_bdf(p: Path) -> RawMesh | None:
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
    return RawMesh(xyz, faces, pid - 1, [names[i] for i in range(len(names))], fmt="Nastran")


def _read_bdf(p: Path) -> RawMesh:
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
        return RawMesh(np.zeros((0, 3)), np.zeros((0, 4)), notes=["no GRID cards"], fmt="Nastran")
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
        return RawMesh(xyz, np.zeros((0, 4)), notes=notes, fmt="Nastran")
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
    return RawMesh(xyz, faces, comp, names, notes=notes, fmt="Nastran")


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


def _read_inp(p: Path) -> RawMesh:
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
        return RawMesh(np.zeros((0, 3)), np.zeros((0, 4)), notes=notes + ["no *NODE data"], fmt="INP")
    nid = np.concatenate(node_ids)
    xyz = np.vstack(node_xyz)
    order = np.argsort(nid, kind="stable")
    nid, xyz = nid[order], xyz[order]
    if len(nid) > 1 and (np.diff(nid) == 0).any():
        k = int(nid[1:][np.diff(nid) == 0][0])
        raise InputFileError(f"{p.name}: duplicate node numbers in *NODE (node {k} is defined twice); renumber "
                             "the nodes or re-export the file")
    if not elems:
        return RawMesh(xyz, np.zeros((0, 4)), notes=notes, fmt="INP")
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
        from ..core.formats import inp_elset_names
        k = max(family) + 1
        names = [family.get(i, unnamed_name(i)) for i in range(k)]
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
            if DEFAULT_NAME not in names:
                names.append(DEFAULT_NAME)
            comp[comp < 0] = names.index(DEFAULT_NAME)
    eorder = np.argsort(eid, kind="stable")
    return RawMesh(xyz, faces[eorder], comp[eorder], names, notes=notes, fmt="INP")
