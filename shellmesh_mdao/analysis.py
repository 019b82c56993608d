"""Linear static analysis of a :class:`~shellmesh_mdao.mesh.ShellMesh` with CalculiX (``ccx``).

The core is plain functions; the OpenMDAO components
(:mod:`shellmesh_mdao.components.mass_comp`, :mod:`shellmesh_mdao.components.calculix_comp`)
are thin wrappers around them.

:func:`write_deck`       complete CalculiX input deck: the mesh as shells (one ELSET and one
                         ``*SHELL SECTION`` per component family, written by
                         :func:`~shellmesh_mdao.export.inp_mesh_lines`), material, clamped nodes,
                         one static step with the load case, ``*NODE PRINT`` U and ``*EL PRINT`` S,
                         optionally a ``*BUCKLE`` step.
:func:`run_ccx`          runs ``ccx`` on a deck in its folder; :class:`SolverError` if it is
                         missing or fails (with the tail of its output).
:func:`read_dat`         parses the ``.dat`` file: nodal displacements and integration-point stresses.
:func:`analyse_shell`    all of it in a temporary folder, reduced to the outputs an optimiser
                         wants: mass, maximum von Mises stress and a KS aggregate of it per
                         family outside a band at the clamp (:func:`clamp_band_faces`), tip
                         deflection (mean over :func:`select_tip_nodes`), buckling factors.

Element choice (see ``docs/analysis.md``): ``element="linear"`` writes quads as ``S4`` and
triangles as ``S3``; ``element="quadratic"`` adds a straight midside node on every edge and
writes ``S8R``/``S6``. CalculiX expands every shell into a layer of solid elements
(S4 -> C3D8I, incompatible modes, accurate in bending; S4R -> C3D8R, too stiff for thin
shells; S3 -> C3D6, too stiff in bending; S8R -> C3D20R, S6 -> C3D15, both accurate).

Sign convention checked against ccx 2.20: a positive ``*DLOAD ... P`` on a shell pushes along
the element normal (right-hand rule of its node order), so :func:`write_deck` signs the
pressure of each face by its normal and the documented load (``pressure`` along ``+up``) does
not depend on face orientation.
"""
from __future__ import annotations

import fnmatch
import glob
import os
import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import ShellMeshError, SolverError
from .families import LOWER_SKIN_PATTERN, ROOT_RIB_PATTERN
from .export import export_order, inp_elset_names, inp_mesh_lines, resolve_material, resolve_thickness, \
    write_text_atomic
from .mesh import ShellMesh

__all__ = [
    "ANALYSIS_MATERIAL", "ELEMENT_TYPES", "CCX_INSTALL_HINT", "LOWER_SKIN_PATTERN", "DatResults", "ShellAnalysis",
    "find_ccx", "n_families", "family_areas", "family_areas_at", "shell_mass", "family_ids", "clamped_nodes",
    "layout_up", "resolve_up",
    "select_tip_nodes", "clamp_band_faces", "CLAMP_BAND_FRACTION", "BUCKLE_LOAD_SCALE", "BUCKLE_ACCURACY", "von_mises",
    "ks_aggregate", "write_deck", "run_ccx", "read_dat", "analyse_shell",
]

#: Material of the analysis: generic aluminium, SI units (Pa, kg/m^3).  Any key may be
#: overridden with ``material={...}`` (keys of :func:`~shellmesh_mdao.export.resolve_material`).
ANALYSIS_MATERIAL = {"name": "ALUMINIUM", "E": 70.0e9, "nu": 0.33, "rho": 2700.0, "ys": None}

#: ``element`` option -> (quad type, triangle type) written to the deck.
ELEMENT_TYPES = {"linear": ("S4", "S3"), "quadratic": ("S8R", "S6")}

#: How to get CalculiX; part of every "ccx not found" message.
CCX_INSTALL_HINT = ("install CalculiX with `apt-get install calculix-ccx` (Debian/Ubuntu; the binary is `ccx`), "
                    "or `conda install -c conda-forge calculix`, or pass the path of the executable "
                    "(ccx=... / environment variable SHELLMESH_CCX)")

#: The buckling step carries the static load times this scale, and the factors read are
#: multiplied by it: CalculiX 2.20's *BUCKLE misses or misplaces factors below about 1 (its
#: eigenvalue shift), so the step's load is kept far below the buckling load. A raw factor
#: below 2 (a load above 500 times the buckling load) is refused.
BUCKLE_LOAD_SCALE = 1.0e-3
#: Relative accuracy asked of ccx's buckling eigenvalue iteration (its default is 0.01).
BUCKLE_ACCURACY = 1.0e-6

#: Default width of the band at the clamp left out of the stress outputs, as a fraction of the
#: reach (the largest distance of a node from the clamp; about the span of a clamped wing).
CLAMP_BAND_FRACTION = 0.05

_NSET_CLAMP = "SM_CLAMPED"
_ELSET_PPOS = "SM_PRESSURE_POS"
_ELSET_PNEG = "SM_PRESSURE_NEG"


# --------------------------------------------------------------------------- small helpers
def n_families(mesh: ShellMesh) -> int:
    """Number of component families: ``len(mesh.component_names)`` (at least the largest id + 1).
    The ``thickness`` vectors of this module have this length, in ``mesh.component_names`` order."""
    m = int(mesh.component.max()) + 1 if mesh.n_faces else 0
    return max(len(mesh.component_names), m)


def family_areas(mesh: ShellMesh) -> np.ndarray:
    """(n_families,) total face area of each component family (0 for a family without faces)."""
    return np.bincount(mesh.component, weights=mesh.face_areas(), minlength=n_families(mesh)).astype(np.float64)


def family_areas_at(mesh: ShellMesh, x, weights=None):
    """Face area of each family of ``mesh`` with its nodes at ``x`` (flattened or (n, 3)), and with
    ``weights`` (one per family) the gradient (n, 3) of ``sum_f weights[family(f)] * area_f`` with
    respect to the node coordinates (a quad's area is half the norm of its diagonals' cross product,
    as :meth:`~shellmesh_mdao.mesh.ShellMesh.face_areas`; a triangle's half its edges')."""
    P = np.asarray(x)
    P = P.reshape(-1, 3) if np.iscomplexobj(P) else P.astype(np.float64).reshape(-1, 3)
    f = mesh.faces
    tri = f[:, 3] < 0
    i0, i1, i2 = f[:, 0], f[:, 1], f[:, 2]
    i3 = np.where(tri, f[:, 0], f[:, 3])
    # quads: d1 = p2 - p0, d2 = p3 - p1; triangles: d1 = p1 - p0, d2 = p2 - p0
    d1 = np.where(tri[:, None], P[i1] - P[i0], P[i2] - P[i0])
    d2 = np.where(tri[:, None], P[i2] - P[i0], P[i3] - P[i1])
    v = 0.5 * np.cross(d1, d2)
    area = np.sqrt((v * v).sum(1))          # complex-step safe
    nf = n_families(mesh)
    areas = np.zeros(nf, area.dtype)
    np.add.at(areas, mesh.component, area)
    if weights is None:
        return areas, None
    w = np.asarray(weights, np.float64)[mesh.component]
    nhat = np.divide(v, area[:, None], out=np.zeros_like(v), where=area[:, None] > 0) * w[:, None]
    g1 = 0.5 * np.cross(d2, nhat)            # d area / d d1
    g2 = 0.5 * np.cross(nhat, d1)            # d area / d d2
    grad = np.zeros_like(P)
    # quads: d1 = p2 - p0, d2 = p3 - p1; triangles: d1 = p1 - p0, d2 = p2 - p0
    a_idx = np.where(tri, i1, i2)
    b_idx = np.where(tri, i2, i3)
    c_idx = np.where(tri, i0, i1)
    for d in range(3):
        grad[:, d] += np.bincount(a_idx, weights=g1[:, d], minlength=len(P))
        grad[:, d] -= np.bincount(i0, weights=g1[:, d], minlength=len(P))
        grad[:, d] += np.bincount(b_idx, weights=g2[:, d], minlength=len(P))
        grad[:, d] -= np.bincount(c_idx, weights=g2[:, d], minlength=len(P))
    return areas, grad


def shell_mass(mesh: ShellMesh, thickness, density: float) -> float:
    """Mass of the shells: ``density * sum_f area_f * thickness[family(f)]``.

    ``thickness`` is anything :func:`~shellmesh_mdao.export.resolve_thickness` accepts (one value
    per family in ``mesh.component_names`` order, a dict name -> t, a number)."""
    t = resolve_thickness(mesh, thickness)
    return float(density) * float(family_areas(mesh) @ t)


def family_ids(mesh: ShellMesh, patterns) -> np.ndarray:
    """Sorted ids of the families whose name matches any of ``patterns`` (``fnmatch`` patterns
    such as ``"*/lower_skin/bay_*"``, or exact names; a single string is one pattern)."""
    if isinstance(patterns, str):
        patterns = [patterns]
    names = list(mesh.component_names)
    return np.array([i for i, n in enumerate(names) if any(fnmatch.fnmatchcase(n, p) for p in patterns)],
                    dtype=np.int64)


def _used_nodes(mesh: ShellMesh) -> np.ndarray:
    used = np.zeros(mesh.n_points, bool)
    used[mesh.faces[mesh.faces >= 0]] = True
    return used


def _load_layout(layout):
    if layout is None:
        return None
    from .layout import Layout, load_layout

    return layout if isinstance(layout, Layout) else load_layout(layout)


def layout_up(layout) -> np.ndarray:
    """Unit ``up`` of the first wing of a layout (path, dict or Layout): a corner-given wing's
    (its own, else the layout's), else a station-given wing's (its own, the layout's, or the one
    measured from the skin when the layout is resolved)."""
    lay = _load_layout(layout)
    if lay is None or not (lay.wings or lay.station_wings):
        raise SolverError("the analysis needs the 'up' direction (the load and the tip deflection act along it) "
                          "and the layout has no wing: give up=[0, 0, 1] (the chord-plane normal)")
    if lay.wings:
        return lay.wing_up(lay.wings[0])
    w = lay.station_wings[0]
    up = w.up if w.up is not None else lay.up if lay.up is not None else \
        (w.planform.up if w.resolved else None)
    if up is None:
        raise SolverError(f"wing '{w.name}' is given by its stations without 'up': give up=[0, 0, 1] (the chord-plane "
                          "normal) to the analysis, or 'up' to the wing in the layout")
    u = np.asarray(up, dtype=np.float64)
    return u / np.linalg.norm(u)


def _span_vector(lay) -> np.ndarray | None:
    """Root -> tip direction of a layout's first wing (None without wings)."""
    if lay is None:
        return None
    if lay.wings:
        return lay.wings[0].span_vector()
    if lay.station_wings:
        w = lay.station_wings[0]
        return np.asarray(w.axis, dtype=np.float64) * np.sign(w.tip - w.root)
    return None


def resolve_up(up=None, layout=None) -> np.ndarray:
    """Unit load direction: ``up`` if given, else the ``up`` of the layout's first wing."""
    if up is None:
        if layout is None:
            raise SolverError("the analysis needs the 'up' direction (the pressure and the tip deflection act "
                              "along it): give up=[0, 0, 1] (the chord-plane normal) or the layout")
        return layout_up(layout)
    u = np.asarray(up, dtype=np.float64).reshape(-1)
    if u.shape != (3,) or not np.isfinite(u).all() or np.linalg.norm(u) == 0:
        raise SolverError(f"up must be a non-zero vector [x, y, z], got {up!r}")
    return u / np.linalg.norm(u)


def _span_coordinate(mesh: ShellMesh, layout=None, axis=None) -> np.ndarray:
    """(n,) coordinate of every node along the span axis, growing from root to tip (the axis of
    :func:`clamped_nodes`' ``"root"`` rule)."""
    P, used = mesh.points, _used_nodes(mesh)
    if not used.any():
        raise SolverError("the mesh has no faces: nothing to clamp or analyse")
    sign = 1.0
    if axis is not None:
        if axis not in (0, 1, 2):
            raise SolverError(f"axis must be 0, 1 or 2 (x, y, z), got {axis!r}")
        ax = int(axis)
    elif _span_vector(_load_layout(layout)) is not None:
        s = _span_vector(_load_layout(layout))
        ax = int(np.argmax(np.abs(s)))
        sign = 1.0 if s[ax] >= 0 else -1.0
    else:
        ext = P[used].max(0) - P[used].min(0)
        ax = int(np.argmax(ext))
    return sign * P[:, ax]


def _family_nodes(mesh: ShellMesh, fam) -> np.ndarray:
    """Sorted used nodes of the faces of families ``fam`` and of their imprint chains (feature
    edges owned by them)."""
    sel = np.zeros(mesh.n_points, bool)
    f = mesh.faces[np.isin(mesh.component, fam)]
    sel[f[f >= 0]] = True
    sel[mesh.feature_edges[np.isin(mesh.feature_edge_ids, fam)].reshape(-1)] = True
    return np.flatnonzero(sel & _used_nodes(mesh)).astype(np.int64)


def clamped_nodes(mesh: ShellMesh, rule="root", *, layout=None, axis=None, tol: float | None = None) -> np.ndarray:
    """Node indices (0-based, sorted) clamped by the analysis.

    ``rule``:

    * ``"root"`` (default): every node used by a face whose coordinate along the span axis is
      within ``tol`` of the root end. The span axis is ``axis`` (0, 1, 2 for x, y, z) if given;
      else, with a ``layout``, the coordinate axis closest to its first wing's span vector
      (mid-chord root -> tip), the root end being the end that vector points away from; else
      the longest bounding-box axis, root at its minimum. ``tol`` defaults to 1e-4 times the
      mesh's bounding-box diagonal (a station-given wing: its span axis, root station to tip
      station). For a wing whose root is a flat end cap (the NACA wings,
      a box beam) this is the cap and the skin's root section.
    * ``"root_rib"``: the nodes of every family named ``*/rib_0`` (the root rib of each wing)
      and of its imprint chains on the skin (feature edges owned by that family).
    * an array of node indices: used as given (checked for range).
    """
    used = _used_nodes(mesh)
    if not isinstance(rule, str):
        ids = np.unique(np.asarray(rule, dtype=np.int64).reshape(-1))
        if not len(ids):
            raise SolverError("the list of clamped nodes is empty: give at least the nodes of one root section")
        if ids.min() < 0 or ids.max() >= mesh.n_points:
            raise SolverError(f"clamped node ids must lie in [0, {mesh.n_points}) (0-based mesh node indices); "
                              f"got values from {int(ids.min())} to {int(ids.max())}")
        if not used[ids].all():
            raise SolverError(f"clamped nodes {ids[~used[ids]][:5].tolist()} are not used by any element: clamp "
                              "nodes of the mesh's faces")
        return ids
    if rule == "root":
        c = _span_coordinate(mesh, layout, axis)
        tol = 1e-4 * mesh.diagonal if tol is None else float(tol)
        root = c[used].min()
        return np.flatnonzero(used & (c <= root + tol)).astype(np.int64)
    if rule == "root_rib":
        fam = family_ids(mesh, ROOT_RIB_PATTERN)
        if not len(fam):
            raise SolverError("clamp='root_rib' needs a family named '<wing>/rib_0' (the root rib) in the mesh; "
                              f"the families are {list(mesh.component_names)}: use clamp='root' or give node ids")
        ids = _family_nodes(mesh, fam)
        if not len(ids):
            raise SolverError("the root rib '*/rib_0' has no nodes in the mesh (no faces, no imprint chain): run "
                              "the pipeline through the imprint stage or use clamp='root'")
        return ids
    raise SolverError(f"unknown clamp rule {rule!r}: use 'root', 'root_rib' or an array of node indices")


def select_tip_nodes(mesh: ShellMesh, rule="auto", *, layout=None, axis=None, tol: float | None = None) -> np.ndarray:
    """Node indices (0-based, sorted) whose mean displacement along ``up`` is the tip deflection.

    ``rule``:

    * ``"auto"`` (default; also None): ``"tip_rib"`` when the mesh has ribs, else ``"tip_section"``.
    * ``"tip_rib"``: the nodes of the tip rib (the rib of highest index ``<wing>/rib_<k>`` with faces
      or chains in the mesh, all its segments) of the first wing (the layout's first wing, else the first
      wing with ribs in ``mesh.component_names``) and of its imprint chains on the skin.
    * ``"tip_section"``: the nodes within ``tol`` (default 1e-4 of the bounding-box diagonal) of the
      tip end along the span axis (the axis of :func:`clamped_nodes`' ``"root"`` rule, ``axis`` and
      ``layout`` as there): a flat tip cap and the skin's tip section.
    * a family name or ``fnmatch`` pattern, or a list of them (e.g. ``"wing/rib_5"``): the nodes of
      those families' faces and imprint chains.
    * an array of node indices: used as given (checked for range and use).
    """
    from .families import parse_component

    used = _used_nodes(mesh)
    rule = "auto" if rule is None else rule
    if not isinstance(rule, str) and not (isinstance(rule, (list, tuple)) and rule and
                                          all(isinstance(r, str) for r in rule)):
        ids = np.unique(np.asarray(rule, dtype=np.int64).reshape(-1))
        if not len(ids) or ids.min() < 0 or ids.max() >= mesh.n_points or not used[ids].all():
            raise SolverError(f"tip_nodes must be a non-empty list of node indices in [0, {mesh.n_points}) used by "
                              "the mesh's faces, a family name/pattern, or 'auto', 'tip_rib', 'tip_section'")
        return ids
    ribs = {}                      # wing -> [(rib index, family id)] of the ribs with faces or chains
    present = np.zeros(max(n_families(mesh), len(mesh.component_names)), bool)
    fe = mesh.feature_edge_ids
    present[np.concatenate([mesh.component, fe[(fe >= 0) & (fe < len(present))]]).astype(np.int64)] = True
    for i, n in enumerate(mesh.component_names):
        if not present[i]:
            continue
        try:
            c = parse_component(n)
        except ShellMeshError:
            continue
        if c.kind == "rib" and c.wing is not None:
            ribs.setdefault(c.wing, []).append((c.index, i))
    if rule == "auto":
        rule = "tip_rib" if ribs else "tip_section"
    if rule == "tip_rib":
        lay = _load_layout(layout)
        first = [w.name for w in (lay.wings + lay.station_wings)] if lay is not None else []
        wing = next((w for w in first if w in ribs), next(iter(ribs), None))
        if wing is None:
            raise SolverError("tip_nodes='tip_rib' needs rib families '<wing>/rib_<k>' in the mesh; the families "
                              f"are {list(mesh.component_names)[:12]}: use tip_nodes='tip_section', a family name "
                              "or node ids")
        k = max(k for k, _ in ribs[wing])
        ids = _family_nodes(mesh, [i for kk, i in ribs[wing] if kk == k])
    elif rule == "tip_section":
        c = _span_coordinate(mesh, layout, axis)
        tol = 1e-4 * mesh.diagonal if tol is None else float(tol)
        ids = np.flatnonzero(used & (c >= c[used].max() - tol)).astype(np.int64)
    else:
        ids = _family_nodes(mesh, family_ids(mesh, rule))
    if not len(ids):
        raise SolverError(f"tip_nodes={rule!r} selects no node of the mesh (no family matches, or its family has "
                          f"no faces); the families are {list(mesh.component_names)[:12]}: give another family, "
                          "'tip_section' or node ids")
    return ids


def clamp_band_faces(mesh: ShellMesh, clamped, distance: float | None = None) -> tuple[np.ndarray, float]:
    """Faces near the clamp, left out of the stress outputs: ``(in_band (m,) bool, distance)``.

    A face is in the band when one of its nodes lies closer than ``distance`` (straight line) to
    a clamped node. ``distance`` defaults to :data:`CLAMP_BAND_FRACTION` (5 %) of the reach, the
    largest distance of a used node from the clamped nodes (about the span of a clamped wing);
    0 leaves every face in."""
    from scipy.spatial import cKDTree

    clamped = np.asarray(clamped, dtype=np.int64).reshape(-1)
    used = np.flatnonzero(_used_nodes(mesh))
    d = np.full(mesh.n_points, np.inf)
    d[used] = cKDTree(mesh.points[clamped]).query(mesh.points[used])[0]
    if distance is None:
        distance = CLAMP_BAND_FRACTION * float(d[used].max())
    distance = float(distance)
    if not np.isfinite(distance) or distance < 0:
        raise SolverError(f"clamp_band must be a distance >= 0 (mesh units; 0: no band), got {distance!r}")
    f = mesh.faces
    near = np.where(f >= 0, d[np.maximum(f, 0)], np.inf).min(1) < distance
    return near, distance


def von_mises(stress: np.ndarray) -> np.ndarray:
    """Von Mises stress of (k, 6) stress rows ``(sxx, syy, szz, sxy, sxz, syz)``."""
    s = np.asarray(stress, dtype=np.float64).reshape(-1, 6)
    d = (s[:, 0] - s[:, 1]) ** 2 + (s[:, 1] - s[:, 2]) ** 2 + (s[:, 2] - s[:, 0]) ** 2
    return np.sqrt(0.5 * d + 3.0 * (s[:, 3] ** 2 + s[:, 4] ** 2 + s[:, 5] ** 2))


def ks_aggregate(values, groups, n_groups: int, rho: float = 50.0, ref=None) -> np.ndarray:
    """Kreisselmeier-Steinhauser aggregate of ``values`` per group (vectorised).

    ``ks_g = r_g * (m_g + ln(sum_{i in g} exp(rho * (v_i / r_g - m_g))) / rho)`` with
    ``m_g = max_i v_i / r_g``: a smooth upper bound of the group maximum,
    ``max_g <= ks_g <= max_g + r_g ln(n_g) / rho``. The reference ``r_g`` is ``ref`` when given
    (a number, e.g. the yield stress) and otherwise the group's own maximum (scale free).
    Empty groups, and groups whose values are all zero, give 0."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    g = np.asarray(groups, dtype=np.int64).reshape(-1)
    mx = np.full(n_groups, -np.inf)
    np.maximum.at(mx, g, v)
    if ref is None:
        r = np.where(np.isfinite(mx) & (mx > 0), mx, 1.0)
    else:
        r = np.full(n_groups, float(ref))
        if not np.isfinite(r).all() or (r <= 0).any():
            raise SolverError(f"ks_ref must be a positive stress, got {ref!r}")
    m = np.where(np.isfinite(mx), mx / r, 0.0)
    e = np.bincount(g, weights=np.exp(rho * (v / r[g] - m[g])), minlength=n_groups)
    ks = r * (m + np.log(np.where(e > 0, e, 1.0)) / rho)
    return np.where(np.isfinite(mx) & (mx > 0), ks, 0.0)


def _rows(fmt: str, columns, chunk: int = 100_000):
    """Text of rows formatted with ``fmt`` (printf) from equal-length columns, formatted in C
    one chunk at a time."""
    n = len(columns[0]) if len(columns) else 0
    for s in range(0, n, chunk):
        e = min(n, s + chunk)
        block = np.column_stack([np.asarray(c[s:e]) for c in columns]).astype(object)
        yield (fmt * (e - s)) % tuple(block.ravel().tolist())


def _id_lines(ids) -> str:
    """Ids (1-based ints) 8 per line, each line ending with a comma (CalculiX set data)."""
    ids = np.asarray(ids, dtype=np.int64).reshape(-1)
    full = len(ids) // 8 * 8
    out = "".join(_rows("%d, %d, %d, %d, %d, %d, %d, %d,\n", [ids[j:full:8] for j in range(8)])) if full else ""
    if full < len(ids):
        out += ", ".join(str(int(i)) for i in ids[full:]) + ",\n"
    return out


# --------------------------------------------------------------------------- ccx executable
def find_ccx(executable=None) -> str:
    """Path of the CalculiX solver: ``executable`` (a name on PATH or a path) if given, else
    the environment variable ``SHELLMESH_CCX``, else ``ccx`` on PATH, else the highest
    versioned ``ccx_<version>`` on PATH (some packages install ``ccx_2.20``). Raises
    :class:`SolverError` with the install command when none is found."""
    cand = executable if executable is not None else os.environ.get("SHELLMESH_CCX")
    if cand:
        p = shutil.which(str(cand))
        if p is None:
            raise SolverError(f"CalculiX executable {str(cand)!r} not found or not executable; {CCX_INSTALL_HINT}")
        return p
    p = shutil.which("ccx")
    if p:
        return p
    found = []
    for d in os.environ.get("PATH", "").split(os.pathsep):
        for f in glob.glob(os.path.join(d, "ccx_*")):
            m = re.fullmatch(r"ccx_(\d+(?:\.\d+)*)", os.path.basename(f))
            if m and os.access(f, os.X_OK) and os.path.isfile(f):
                found.append((tuple(int(x) for x in m[1].split(".")), f))
    if found:
        return sorted(found)[-1][1]
    raise SolverError(f"the CalculiX solver 'ccx' is not installed (not on PATH); {CCX_INSTALL_HINT}")


# --------------------------------------------------------------------------- deck
def _model_blocks(mesh: ShellMesh, t: np.ndarray, mat: dict, element: str) -> tuple[list, int]:
    """Model part of the deck (nodes, elements, material, sections) and the number of nodes."""
    qt, tt = ELEMENT_TYPES[element]
    if element == "linear":
        return inp_mesh_lines(mesh, t, mat, quad_type=qt, tri_type=tt), mesh.n_points
    # quadratic: straight midside node of edge e = node n + e, written after the corner nodes
    topo = mesh.topology()
    n = mesh.n_points
    mid = 0.5 * (mesh.points[topo.edges[:, 0]] + mesh.points[topo.edges[:, 1]])
    big = ShellMesh(np.vstack([mesh.points, mid]), mesh.faces, mesh.component, list(mesh.component_names))
    blocks = inp_mesh_lines(big, t, mat, quad_type=qt, tri_type=tt)
    # replace the element rows written by inp_mesh_lines (4/3 nodes) by 8/6-node rows, same numbering
    out, skipping, inserted = [], False, False
    for b in blocks:
        if b.startswith("*ELEMENT"):
            skipping = True
            if not inserted:
                out.extend(_quadratic_elements(mesh, topo.face_edges + n))
                inserted = True
            continue
        if skipping and not b.startswith("*"):
            continue
        skipping = False
        out.append(b)
    return out, big.n_points


def _quadratic_elements(mesh: ShellMesh, mids: np.ndarray) -> list:
    order = export_order(mesh)
    faces, mids, comp = mesh.faces[order] + 1, mids[order] + 1, mesh.component[order]
    elsets = inp_elset_names(mesh)
    k = len(elsets)
    starts = np.searchsorted(comp, np.arange(k + 1))
    eids = np.arange(1, len(faces) + 1)
    out = []
    for c in range(k):                      # loop over families (a handful), not elements
        s, e = starts[c], starts[c + 1]
        nq = int((faces[s:e, 3] > 0).sum())
        if nq:
            out.append(f"*ELEMENT, TYPE=S8R, ELSET={elsets[c]}\n")
            cols = [eids[s:s + nq]] + [faces[s:s + nq, j] for j in range(4)] + [mids[s:s + nq, j] for j in range(4)]
            out.extend(_rows("%d, %d, %d, %d, %d, %d, %d, %d, %d\n", cols))
        if nq < e - s:
            out.append(f"*ELEMENT, TYPE=S6, ELSET={elsets[c]}\n")
            cols = [eids[s + nq:e]] + [faces[s + nq:e, j] for j in range(3)] + [mids[s + nq:e, j] for j in range(3)]
            out.extend(_rows("%d, %d, %d, %d, %d, %d, %d\n", cols))
    return out


def _support_lines(mesh: ShellMesh, supports) -> list:
    """``*BOUNDARY`` lines of ``supports`` = ``[(node_ids, dofs), ...]`` (0-based ids, dofs 1-6)."""
    if not supports:
        return []
    out = ["*BOUNDARY\n"]
    used = _used_nodes(mesh)
    for item in supports:
        try:
            ids, dofs = item
            ids = np.unique(np.asarray(ids, dtype=np.int64).reshape(-1))
            dofs = sorted({int(d) for d in np.atleast_1d(dofs)})
        except (TypeError, ValueError):
            ids, dofs = np.zeros(0, np.int64), []
        if not len(ids) or not dofs or dofs[0] < 1 or dofs[-1] > 6 or ids.min() < 0 or ids.max() >= mesh.n_points \
                or not used[ids].all():
            raise SolverError(f"supports must be a list of (node_ids, dofs) pairs: 0-based ids of nodes used by the "
                              f"mesh's faces (in [0, {mesh.n_points})) and degrees of freedom 1-6 (1-3 translations, "
                              "4-6 rotations)")
        for d in dofs:
            out.extend(_rows(f"%d, {d}, {d}\n", [ids + 1]))
    return out


def _nodal_forces(mesh: ShellMesh, nodal_forces):
    if nodal_forces is None:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    try:
        ids, f = nodal_forces
    except (TypeError, ValueError):
        raise SolverError("nodal_forces must be a pair (node_ids (k,), forces (k, 3)) with 0-based mesh node "
                          "indices and force vectors") from None
    ids = np.asarray(ids, dtype=np.int64).reshape(-1)
    f = np.asarray(f, dtype=np.float64)
    if f.ndim == 1 and f.shape == (3,):
        f = np.broadcast_to(f, (len(ids), 3))
    if f.shape != (len(ids), 3):
        raise SolverError(f"nodal_forces: {len(ids)} node ids but forces of shape {f.shape}; give one (3,) "
                          "force vector per node")
    if len(ids) and (ids.min() < 0 or ids.max() >= mesh.n_points):
        raise SolverError(f"nodal_forces node ids must lie in [0, {mesh.n_points}) (0-based)")
    if not np.isfinite(f).all():
        raise SolverError("nodal_forces contain NaN/inf: give finite forces")
    if len(ids) and not _used_nodes(mesh)[ids].all():
        raise SolverError("nodal_forces act on nodes used by no element: load nodes of the mesh's faces")
    uid, inv = np.unique(ids, return_inverse=True)      # a node listed twice gets the sum of its forces
    tot = np.zeros((len(uid), 3))
    np.add.at(tot, inv.reshape(-1), f)
    return uid, tot


def write_deck(mesh: ShellMesh, path, *, thickness=None, material: dict | None = None, clamped,
               up=None, pressure: float = 0.0, pressure_families=LOWER_SKIN_PATTERN, nodal_forces=None,
               element: str = "linear", clamp_rotations: bool = True, supports=None, buckling: int = 0) -> dict:
    """Write a complete CalculiX input deck for a linear static analysis of ``mesh``.

    Parameters
    ----------
    thickness : one value per family (``mesh.component_names`` order), a dict name -> t, or a
        number (see :func:`~shellmesh_mdao.export.resolve_thickness`).
    material : overrides of :data:`ANALYSIS_MATERIAL` (keys ``E``, ``nu``, ``rho``, ``name``, ...).
    clamped : 0-based node indices with all translations (and, with ``clamp_rotations``, all
        rotations) fixed, or a rule of :func:`clamped_nodes` (applied without a layout).
    up : load direction; needed only when ``pressure`` is non-zero.
    pressure : uniform pressure (force per area) on the faces of ``pressure_families``
        (fnmatch patterns, default ``*/lower_skin/bay_*``), acting along ``+up`` whatever the
        face orientation (negative: along ``-up``).
    nodal_forces : ``(node_ids (k,), forces (k, 3))`` concentrated forces (0-based node indices;
        a (3,) force is applied to every listed node; repeated nodes get the sum).
    element : ``"linear"`` (S4 quads / S3 triangles) or ``"quadratic"`` (S8R / S6 with a
        straight midside node per edge).
    supports : more constraints, ``[(node_ids, dofs), ...]``: 0-based node ids and the degrees of
        freedom (1-3 translations, 4-6 rotations) fixed at 0 (e.g. a simple support: dof 3).
    buckling : with ``n > 0``, a second step (``*BUCKLE``) asks for the ``n`` lowest buckling
        factors of the same load case (:func:`read_dat` reads them).

    Element ``k`` of the deck (1-based id ``k + 1``) is face ``export_order(mesh)[k]``; node
    ``i`` has id ``i + 1``. The step prints ``U`` of every node and ``S`` (integration-point
    stresses) of every element to the ``.dat`` file. Returns a dict with ``element_of_face``
    (1-based element id of every face), ``n_pressure_faces``, ``load`` (total applied force
    vector) and ``n_nodes`` written. Atomic write (:func:`~shellmesh_mdao.export.write_text_atomic`).
    """
    if not isinstance(mesh, ShellMesh):
        raise SolverError(f"the analysis needs a ShellMesh, got {type(mesh).__name__}")
    if element not in ELEMENT_TYPES:
        raise SolverError(f"unknown element {element!r}: use one of {sorted(ELEMENT_TYPES)}")
    if not mesh.n_faces:
        raise SolverError("the mesh has no faces: nothing to analyse")
    if not np.isfinite(mesh.points).all():
        raise SolverError("the mesh has NaN/inf node coordinates: fix the mesh first (ShellMesh.check lists them)")
    t = resolve_thickness(mesh, thickness)
    mat = resolve_material({**ANALYSIS_MATERIAL, **(material or {})})
    clamped = clamped_nodes(mesh, clamped)
    blocks, n_written = _model_blocks(mesh, t, mat, element)
    order = export_order(mesh)
    eid = np.empty(mesh.n_faces, np.int64)
    eid[order] = np.arange(1, mesh.n_faces + 1)
    taken = {s.upper() for s in inp_elset_names(mesh)}
    clash = taken & {_NSET_CLAMP, _ELSET_PPOS, _ELSET_PNEG}
    if clash:
        raise SolverError(f"component name(s) {sorted(clash)} are reserved by the analysis deck: rename them")
    load = np.zeros(3)
    fix = clamped + 1
    if element == "quadratic":               # midside nodes of edges between two clamped nodes
        is_c = np.zeros(mesh.n_points, bool)
        is_c[clamped] = True
        e = mesh.topology().edges
        fix = np.concatenate([fix, mesh.n_points + 1 + np.flatnonzero(is_c[e].all(1))])
    tail = [f"*NSET, NSET={_NSET_CLAMP}\n", _id_lines(fix),
            f"*BOUNDARY\n{_NSET_CLAMP}, 1, {6 if clamp_rotations else 3}\n", *_support_lines(mesh, supports),
            "*STEP\n*STATIC\n"]
    loads = []                                # the step's loads: ("P", elset, p) and ("C", ids, dofs, forces)
    n_p = 0
    pressure = float(pressure)
    if not np.isfinite(pressure):
        raise SolverError(f"pressure must be finite, got {pressure!r}")
    if pressure != 0.0:
        u = resolve_up(up, None)
        fam = family_ids(mesh, pressure_families)
        faces = np.flatnonzero(np.isin(mesh.component, fam))
        if not len(faces):
            raise SolverError(f"no faces to carry the pressure: no family matches {pressure_families!r} (the "
                              f"families are {list(mesh.component_names)[:12]}...); run the pipeline with a layout "
                              "that has ribs, give pressure_families, or load the model with nodal_forces")
        av = mesh.face_area_vectors()[faces]
        sgn = av @ u
        pos, neg = faces[sgn >= 0], faces[sgn < 0]
        load += pressure * np.abs(sgn).sum() * u        # force along +up of each face: p * A * |n.up|
        n_p = len(faces)
        # a positive P on a ccx shell pushes along the element normal: P = +p where n.up >= 0
        for name, sel, val in ((_ELSET_PPOS, pos, pressure), (_ELSET_PNEG, neg, -pressure)):
            if len(sel):
                tail.insert(0, f"*ELSET, ELSET={name}\n" + _id_lines(np.sort(eid[sel])))
                loads.append(("P", name, val))
    ids, f = _nodal_forces(mesh, nodal_forces)
    if len(ids):
        load += f.sum(0)
        nz = np.nonzero(f)
        if len(nz[0]):
            loads.append(("C", ids[nz[0]] + 1, nz[1] + 1, f[nz]))

    def load_lines(scale):
        out = []
        for ld in loads:
            if ld[0] == "P":
                out.append(f"*DLOAD\n{ld[1]}, P, {ld[2] * scale!r}\n")
            else:
                out += ["*CLOAD\n", *_rows("%d, %d, %r\n", [ld[1], ld[2], ld[3] * scale])]
        return out

    tail += load_lines(1.0)
    tail.append("*NODE PRINT, NSET=NALL\nU\n*EL PRINT, ELSET=EALL\nS\n*END STEP\n")
    nb = int(buckling)
    if nb < 0:
        raise SolverError(f"buckling must be the number of buckling factors wanted (0: none), got {buckling!r}")
    if nb:       # loads of the static step again, scaled (a perturbation step drops them); no printout
        tail += [f"*STEP\n*BUCKLE\n{nb}, {BUCKLE_ACCURACY!r}\n", *load_lines(BUCKLE_LOAD_SCALE),
                 "*NODE PRINT, NSET=NALL, FREQUENCY=0\nU\n*EL PRINT, ELSET=EALL, FREQUENCY=0\nS\n*END STEP\n"]
    write_text_atomic(path, "".join(blocks) + "".join(tail))
    return {"element_of_face": eid, "n_pressure_faces": n_p, "load": load, "n_nodes": n_written}


# --------------------------------------------------------------------------- run
def _tail(text: str, n: int = 25) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    return "\n".join(lines[-n:])


def run_ccx(deck, *, executable=None, threads: int = 1, timeout: float | None = None) -> Path:
    """Run CalculiX on ``deck`` (a ``.inp`` file) in the deck's folder and return the path of
    its ``.dat`` result file. ``threads`` sets OMP_NUM_THREADS / CCX_NPROC_* (default 1: the
    machines are shared). The solver's console output is kept next to the deck as
    ``<job>.log``. Raises :class:`SolverError` when ccx is missing, times out, exits with an
    error, prints ``*ERROR`` or writes no results; the message ends with the tail of its output."""
    exe = find_ccx(executable)
    deck = Path(deck)
    if deck.suffix != ".inp" or not deck.is_file():
        raise SolverError(f"{deck} is not a CalculiX input deck (.inp file): write one with write_deck first")
    job = deck.stem
    nt = str(max(1, int(threads)))
    env = dict(os.environ, OMP_NUM_THREADS=nt, CCX_NPROC_EQUATION_SOLVER=nt, CCX_NPROC_STIFFNESS=nt,
               CCX_NPROC_RESULTS=nt)
    dat = deck.with_suffix(".dat")
    dat.unlink(missing_ok=True)
    try:
        proc = subprocess.run([exe, "-i", job], cwd=deck.parent, capture_output=True, text=True, env=env,
                              timeout=timeout, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired as e:
        out = (e.stdout or b"").decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or "")
        raise SolverError(f"ccx did not finish within {timeout} s on {deck.name}: raise the timeout or use a "
                          f"coarser mesh. Last output:\n{_tail(out)}") from None
    except OSError as e:
        raise SolverError(f"cannot run CalculiX {exe!r}: {e.strerror or e}; {CCX_INSTALL_HINT}") from None
    out = (proc.stdout or "") + (proc.stderr or "")
    try:
        deck.with_suffix(".log").write_text(out, encoding="utf-8")
    except OSError:
        pass
    if proc.returncode != 0 or "*ERROR" in out or not dat.is_file() or "Job finished" not in out:
        why = f"exit code {proc.returncode}" if proc.returncode != 0 else \
            ("it reported an error" if "*ERROR" in out else "it wrote no results")
        raise SolverError(f"CalculiX failed on {deck} ({why}); check the mesh (ShellMesh.check), the clamped "
                          f"nodes and the loads. Last lines of its output:\n{_tail(out)}")
    return dat


# --------------------------------------------------------------------------- parse
@dataclass
class DatResults:
    """Results of the last output time in a CalculiX ``.dat`` file.

    ``node_ids`` (p,) 1-based ids with ``displacement`` (p, 3); ``element_ids`` (r,) 1-based
    element id and ``integration_point`` (r,) of each stress row ``stress`` (r, 6)
    ``(sxx, syy, szz, sxy, sxz, syz)`` (global axes); ``buckling_factors`` (k,) of a ``*BUCKLE``
    step in mode order (empty without one)."""

    node_ids: np.ndarray
    displacement: np.ndarray
    element_ids: np.ndarray
    integration_point: np.ndarray
    stress: np.ndarray
    buckling_factors: np.ndarray = field(default_factory=lambda: np.zeros(0))


_BUCKLE_HEADER = "B U C K L I N G   F A C T O R   O U T P U T"
_BUCKLE_ROW = re.compile(r"^ *(\d+) +(\S+) *$", re.M)
_DAT_HEADER = re.compile(r"^ *(displacements|stresses) \(([^)]*)\) for set (\S+) and time +(\S+) *$", re.M)


def _numbers(block: str, ncol: int, where: str) -> np.ndarray:
    """(rows, ncol) float array of the first ``ncol`` numbers of each non-empty line (all lines
    have the same number of fields in a ccx table; converted by numpy in one go)."""
    first = block.lstrip().split("\n", 1)[0]
    if not first.strip():
        return np.zeros((0, ncol))
    ntok = len(first.split())
    toks = block.split()
    if ntok >= ncol and len(toks) % ntok == 0:
        arr = np.array(toks).reshape(-1, ntok)[:, :ncol]
    else:
        arr = np.array([ln.split()[:ncol] for ln in block.splitlines() if ln.strip()])
    try:
        return arr.astype(np.float64)
    except ValueError:
        # Fortran drops the 'E' of three-digit exponents: 1.234567-100
        fixed = np.char.replace(np.char.replace(arr, "-", "E-"), "+", "E+")
        fixed = np.char.replace(fixed, "EE", "E")
        fixed = np.where(np.char.startswith(fixed, "E-"), np.char.replace(fixed, "E-", "-", count=1), fixed)
        try:
            return fixed.astype(np.float64)
        except ValueError:
            raise SolverError(f"cannot read the {where} table of the CalculiX .dat file (unexpected number "
                              "format); please report this with the .dat file") from None


def read_dat(path) -> DatResults:
    """Parse the ``displacements`` (``*NODE PRINT ... U``) and ``stresses`` (``*EL PRINT ... S``)
    tables of a CalculiX ``.dat`` file (the last time written). Raises :class:`SolverError` when
    a table is missing."""
    text = Path(path).read_text(encoding="utf-8", errors="replace")
    k = text.find(_BUCKLE_HEADER)
    factors = np.zeros(0)
    if k >= 0:
        block = text[k + len(_BUCKLE_HEADER):].split("E I G E N", 1)[0]
        rows = _BUCKLE_ROW.findall(block)
        factors = _numbers("\n".join(v for _, v in rows), 1, "buckling factor").reshape(-1) if rows else factors
        text = text[:k]
    heads = list(_DAT_HEADER.finditer(text))
    last: dict = {}
    for i, h in enumerate(heads):
        end = heads[i + 1].start() if i + 1 < len(heads) else len(text)
        kind = h.group(1)
        if kind in last and last[kind][0] != h.group(4):
            last[kind] = (h.group(4), [])
        last.setdefault(kind, (h.group(4), []))[1].append(text[h.end():end])
    if "displacements" not in last or "stresses" not in last:
        raise SolverError(f"{path}: no displacement or stress table in the CalculiX results; the deck needs "
                          "*NODE PRINT (U) and *EL PRINT (S) requests (write it with write_deck)")
    u = _numbers("\n".join(last["displacements"][1]), 4, "displacement")
    s = _numbers("\n".join(last["stresses"][1]), 8, "stress")
    return DatResults(u[:, 0].astype(np.int64), u[:, 1:4], s[:, 0].astype(np.int64), s[:, 1].astype(np.int64),
                      s[:, 2:8], factors)


# --------------------------------------------------------------------------- all in one
@dataclass
class ShellAnalysis:
    """Outputs of :func:`analyse_shell`.

    ``displacement``    (n, 3) displacement of every mesh node (0 for unused nodes).
    ``von_mises``       (m,) largest integration-point von Mises stress of every face.
    ``mass``            density * sum(area * thickness).
    ``max_von_mises``   largest von Mises stress of the faces outside the clamp band.
    ``ks_von_mises``    (n_families,) KS aggregate of ``von_mises`` per family over its faces
                        outside the clamp band (0 if it has none).
    ``tip_deflection``  mean displacement along ``up`` of the ``tip_nodes`` (:func:`select_tip_nodes`).
    ``max_deflection``  displacement along ``up`` (signed) of the node of largest ``|u . up|``
                        of the whole model.
    ``in_clamp_band``   (m,) True for the faces left out of the stress outputs
                        (:func:`clamp_band_faces`, of width ``clamp_band``).
    ``peak_von_mises``  largest von Mises stress of all faces, the clamp band included.
    ``buckling_factors`` (k,) the ``buckling`` lowest buckling factors of the load case (load
                        multipliers, in ccx's order; empty without ``buckling``).
    ``ks_buckling``     KS aggregate (``ks_rho``) of ``1 / buckling_factors``: a smooth upper bound
                        of the load over the lowest buckling load (<= 1: no buckling); 0 without.
    ``up``, ``clamped`` and ``tip_nodes`` (node indices), ``load`` (total applied force),
    ``seconds`` (ccx run), ``workdir`` (the kept folder, or None).
    """

    displacement: np.ndarray
    von_mises: np.ndarray
    mass: float
    max_von_mises: float
    ks_von_mises: np.ndarray
    tip_deflection: float
    up: np.ndarray
    clamped: np.ndarray
    load: np.ndarray
    seconds: float
    element: str
    workdir: Path | None = None
    info: dict = field(default_factory=dict)
    max_deflection: float = 0.0
    tip_nodes: np.ndarray | None = None
    in_clamp_band: np.ndarray | None = None
    clamp_band: float = 0.0
    peak_von_mises: float = 0.0
    buckling_factors: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ks_buckling: float = 0.0


def analyse_shell(mesh: ShellMesh, thickness=None, *, material: dict | None = None, clamp="root", layout=None,
                  axis=None, clamp_tol: float | None = None, clamp_rotations: bool = True, up=None,
                  pressure: float = 0.0, pressure_families=LOWER_SKIN_PATTERN, nodal_forces=None,
                  tip_nodes="auto", element: str = "linear", ks_rho: float = 50.0, ks_ref=None,
                  clamp_band: float | None = None, buckling: int = 0, supports=None, executable=None, threads: int = 1,
                  timeout: float | None = None,
                  workdir=None) -> ShellAnalysis:
    """Linear static CalculiX analysis of ``mesh``: write the deck, run ccx, parse, reduce.

    ``clamp`` is a rule or node ids (:func:`clamped_nodes`, with ``layout``, ``axis`` and
    ``clamp_tol``); ``up`` defaults to the layout's first wing's ``up``; the load case is
    ``pressure`` on ``pressure_families`` (along ``+up``) plus ``nodal_forces`` (see
    :func:`write_deck`); at least one must be non-zero. ``tip_nodes`` (a rule of :func:`select_tip_nodes`,
    a family name/pattern or node ids) are the nodes whose mean ``u . up`` is the tip deflection.
    ``ks_rho``/``ks_ref`` parametrise :func:`ks_aggregate`; the faces within ``clamp_band`` of a
    clamped node (:func:`clamp_band_faces`; default 5 % of the reach) are left out of ``max_von_mises``
    and ``ks_von_mises``. ``buckling = n > 0`` adds a ``*BUCKLE`` step (the ``n`` lowest buckling
    factors of the same load case and their KS); ``supports`` are more constraints
    (:func:`write_deck`).
    ``workdir``: a folder (created if missing) where the deck and results are kept; by default
    a temporary folder that is removed. Raises :class:`SolverError` (ccx missing or failed,
    bad options) or :class:`~shellmesh_mdao.errors.OutputError` (bad thickness/material).
    """
    if not isinstance(mesh, ShellMesh):
        raise SolverError(f"the analysis needs a ShellMesh, got {type(mesh).__name__}")
    lay = _load_layout(layout)
    ids = clamped_nodes(mesh, clamp, layout=lay, axis=axis, tol=clamp_tol)
    u = resolve_up(up, lay)                      # the load and the tip deflection act along up
    fids, fvec = _nodal_forces(mesh, nodal_forces)
    if float(pressure) == 0.0 and (not len(fids) or not np.any(fvec)):
        raise SolverError("no load: give a non-zero pressure (on the lower-skin bays) or nodal_forces")
    mat = resolve_material({**ANALYSIS_MATERIAL, **(material or {})})
    t = resolve_thickness(mesh, thickness)
    find_ccx(executable)                       # fail before writing anything
    tip = select_tip_nodes(mesh, "auto" if tip_nodes is None else tip_nodes, layout=lay, axis=axis)
    band, band_width = clamp_band_faces(mesh, ids, clamp_band)
    keep = workdir is not None
    tmp = None
    if keep:
        folder = Path(workdir)
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise SolverError(f"cannot create the analysis folder {folder}: {e.strerror or e}; choose a writable "
                              "folder") from None
    else:
        tmp = tempfile.TemporaryDirectory(prefix="shellmesh_ccx_")
        folder = Path(tmp.name)
    try:
        deck = folder / "shell.inp"
        info = write_deck(mesh, deck, thickness=t, material=mat, clamped=ids, up=u, pressure=pressure,
                          pressure_families=pressure_families, nodal_forces=(fids, fvec), element=element,
                          clamp_rotations=clamp_rotations, supports=supports, buckling=buckling)
        t0 = time.perf_counter()
        dat = run_ccx(deck, executable=executable, threads=threads, timeout=timeout)
        seconds = time.perf_counter() - t0
        res = read_dat(dat)
    finally:
        if tmp is not None:
            tmp.cleanup()
    disp = np.zeros((mesh.n_points, 3))
    sel = (res.node_ids >= 1) & (res.node_ids <= mesh.n_points)
    disp[res.node_ids[sel] - 1] = res.displacement[sel]
    if not np.isfinite(disp).all() or not np.isfinite(res.stress).all():
        raise SolverError("CalculiX returned NaN/inf results: the model is probably not held (check the clamped "
                          "nodes) or has disconnected parts (ShellMesh.n_bodies)")
    order = export_order(mesh)
    if len(res.element_ids) and (res.element_ids.min() < 1 or res.element_ids.max() > mesh.n_faces):
        raise SolverError("the CalculiX stress table names elements that are not in the deck; please report this")
    vm_ip = von_mises(res.stress)
    vm = np.zeros(mesh.n_faces)
    np.maximum.at(vm, order[res.element_ids - 1], vm_ip)
    lam, ks_b = _buckling(res.buckling_factors, int(buckling), ks_rho)
    nf = n_families(mesh)
    out = ~band
    ks = ks_aggregate(vm[out], mesh.component[out], nf, rho=ks_rho, ref=ks_ref)
    d = disp @ u
    k = int(np.argmax(np.abs(d)))
    info.pop("element_of_face", None)
    return ShellAnalysis(
        displacement=disp, von_mises=vm, mass=float(mat["rho"]) * float(family_areas(mesh) @ t),
        max_von_mises=float(vm[out].max()) if out.any() else 0.0, ks_von_mises=ks,
        tip_deflection=float(d[tip].mean()), up=u, clamped=ids, load=info["load"], seconds=seconds, element=element,
        workdir=folder if keep else None, info=info, max_deflection=float(d[k]), tip_nodes=tip, in_clamp_band=band,
        clamp_band=band_width, peak_von_mises=float(vm.max()), buckling_factors=lam, ks_buckling=ks_b)


def _buckling(raw: np.ndarray, wanted: int, rho: float) -> tuple[np.ndarray, float]:
    """Buckling factors of the static load (the raw factors of the scaled buckling step times
    :data:`BUCKLE_LOAD_SCALE`) and the KS of their inverses (0 without a buckling step)."""
    if not wanted:
        return np.zeros(0), 0.0
    if len(raw) < wanted or not np.all(np.isfinite(raw)) or np.any(raw == 0):
        raise SolverError(f"CalculiX returned {len(raw)} usable buckling factors of the {wanted} asked for: ask "
                          "for fewer (buckling=...) or check the supports (a free body has zero factors)")
    if np.abs(raw).min() < 2.0:
        raise SolverError(f"the lowest buckling factor, {np.abs(raw).min() * BUCKLE_LOAD_SCALE:.3g}, is too small to "
                          "be computed reliably (the load is more than 500 times the buckling load): lower the "
                          "load or thicken the structure")
    factors = raw * BUCKLE_LOAD_SCALE
    return factors, float(ks_aggregate(1.0 / factors, np.zeros(len(factors), np.int64), 1, rho=rho)[0])
