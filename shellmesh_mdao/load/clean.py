"""The cleaning every load does: duplicate vertices merged, collapsed and duplicated faces
removed, unused vertices dropped (:func:`clean_to_mesh`)."""
from __future__ import annotations

import numpy as np

from ..errors import InputFileError, MeshValidationError
from ..mesh import ShellMesh, merge_close_points
from .raw import RawMesh

__all__ = ["clean_to_mesh"]


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


def _clean(raw: RawMesh, merge_tol):
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


def clean_to_mesh(raw: RawMesh, name: str, merge_tol):
    """The cleaned :class:`ShellMesh` of a raw mesh (vertices closer than ``merge_tol`` times the
    diagonal merged), its counts (merged, duplicate, degenerate) and notes."""
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
