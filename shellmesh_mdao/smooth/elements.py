"""Element measures of the smoothing, the untangling and the quad stage: unit normals, the
smallest corner scaled Jacobian, the oriented quality the untangling raises, faces draped over a
crease, tangent bases, and the acceptance figures of a mesh (:func:`mesh_figures`)."""
from __future__ import annotations

import math

import numpy as np

from ..core.supports import PLANE, Supports
from .kernels import element_normals, face_quality, min_corner_sj
from ..mesh import ShellMesh, cross_rows, dot_unit_rows, norm_rows

__all__ = ["face_normals", "facing", "element_min_sj", "oriented_quality", "draped_vertices", "tangent_basis",
           "mesh_figures"]

_TRI_SJ = 2.0 / math.sqrt(3.0)

# einsum's unit rows (mesh.dot_unit_rows: compiled for (k, 3) rows)
_unit = dot_unit_rows


def tangent_basis(n: np.ndarray):
    """Deterministic orthonormal tangent basis (t1, t2) of unit normals n (Duff et al. 2017)."""
    s = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (s + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t1 = np.stack([1.0 + s * n[:, 0] ** 2 * a, s * b, -s * n[:, 0]], 1)
    t2 = np.stack([b, s + n[:, 1] ** 2 * a, -n[:, 1]], 1)
    return t1, t2


# ============================================================================ element checks
def face_normals(P, faces, is_tri):
    """Unit normals of the elements (:func:`_corner_normals` of their corners, in one compiled
    pass: :func:`~shellmesh_mdao.smooth.kernels.element_normals`)."""
    return element_normals(P, faces, is_tri)


def _corner_normals(c, is_tri):
    """Unit normals of elements given by their corners ``c`` (m, 4, 3) (a triangle's fourth
    corner is not read)."""
    v = cross_rows(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1])
    if is_tri.any():
        ct = c[is_tri]
        v[is_tri] = cross_rows(ct[:, 1] - ct[:, 0], ct[:, 2] - ct[:, 0])
    return _unit(v)


def facing(faces, nface, nsup):
    """Per element: the largest dot product of its unit normal ``nface`` (m, 3) with the support
    normals ``nsup`` (n, 3) of its corners (zero rows: no support normal, not counted); +inf for
    an element none of whose corners has one."""
    fv = np.where(faces >= 0, faces, faces[:, :1])
    ns = nsup[fv]                                                   # (m, 4, 3)
    has = np.einsum("mij,mij->mi", ns, ns) > 0.5
    d = np.where(has, np.einsum("mij,mj->mi", ns, nface), -np.inf).max(1)
    return np.where(has.any(1), d, np.inf)


def element_min_sj(P, faces, is_tri, nref=None):
    """Per element: min over corners of the scaled Jacobian against the element's own normal
    and (if given) against ``nref``; triangles scaled by 2/sqrt(3) (1 = equilateral). A
    compiled loop (:func:`~shellmesh_mdao.smooth.kernels.min_corner_sj`), the same bits as
    :func:`_corner_min_sj` on the corners and their :func:`_corner_normals`."""
    return min_corner_sj(P, faces, is_tri, nref, _TRI_SJ)


def _corner_min_sj(c, is_tri, nown, nref=None):
    """:func:`element_min_sj` of elements given by their corners ``c`` (m, 4, 3) and unit
    normals ``nown``."""
    out = np.full(len(c), np.inf)
    for mask, k, scale in ((~is_tri, 4, 1.0), (is_tri, 3, _TRI_SJ)):
        if not mask.any():
            continue
        C = c[mask][:, :k]
        E = np.roll(C, -1, axis=1) - C                          # e_next at corner i
        Ep = np.roll(E, 1, axis=1)                              # -e_prev
        cr = cross_rows(Ep, E)
        L = norm_rows(E, axis=2)
        den = L * np.roll(L, 1, axis=1)
        for nn in (nown[mask], None if nref is None else nref[mask]):
            if nn is None:
                continue
            s = np.einsum("ikj,ij->ik", cr, nn)
            sj = np.divide(s, den, out=np.zeros_like(s), where=den > 0).min(1) * scale
            out[mask] = np.minimum(out[mask], sj)
    return out


def oriented_quality(C, is_tri, nref):
    """Per element with corner positions ``C`` (k, 4, 3): the scaled Jacobian (own normal,
    :func:`element_min_sj`), replaced by ``dot - 1`` (in [-2, -1]) where the element's own
    normal points against its reference normal ``nref`` (k, 3) (a flipped element). A compiled
    loop (:func:`~shellmesh_mdao.smooth.kernels.face_quality`), the same bits as
    ``np.where(d > 0, sj, d - 1)`` with ``nown = _corner_normals(C, is_tri)``,
    ``sj = _corner_min_sj(C, is_tri, nown)`` and ``d = dot_rows(nown, nref)``."""
    return face_quality(C, is_tri, nref, _TRI_SJ)


def draped_vertices(faces, nrm, spread):
    """(n,) bool: the vertices of the faces (quads and triangles) whose corners' support
    normals ``nrm`` (n, 3) are more than ``spread`` degrees apart; corners without a support
    normal (zero: fixed, on a curve) do not count."""
    fv = np.where(faces >= 0, faces, faces[:, :1])                 # a triangle repeats a corner
    f = nrm[fv]                                                     # (m, 4, 3)
    on = np.einsum("mij,mij->mi", f, f) > 0.5
    c = np.einsum("mij,mkj->mik", f, f)
    cmin = np.where(on[:, :, None] & on[:, None, :], c, 1.0).min((1, 2))
    out = np.zeros(len(nrm), bool)
    out[fv[cmin < np.cos(np.radians(spread))].ravel()] = True
    return out


def mesh_figures(mesh: ShellMesh, supports: Supports | None = None, size: float | None = None) -> dict:
    """The figures of the all-quad acceptance list for a mesh: ``quad_fraction``,
    ``min_sj``, ``mean_sj``, ``n_sj_le_0.2``, ``angles_ok`` (fraction of quads with every
    corner angle in [45, 135] degrees), ``warp_p99`` (degrees), ``median_edge`` (and
    ``median_edge_ratio`` = median / ``size`` when given), plus ``mean_sj_skin`` and
    ``mean_sj_members`` when ``supports`` tells which components are planar members."""
    from ..quality import element_quality
    if not mesh.n_faces:
        return {}
    q = element_quality(mesh.points, mesh.faces, ("min_angle", "max_angle", "warp", "scaled_jacobian"))
    sj = q["scaled_jacobian"]
    quad = mesh.is_quad
    ok = quad & (q["min_angle"] >= 45.0) & (q["max_angle"] <= 135.0)
    med = float(np.median(mesh.edge_lengths()))
    out = {"n_faces": int(mesh.n_faces), "quad_fraction": float(quad.mean()), "min_sj": float(sj.min()),
           "mean_sj": float(sj.mean()), "n_sj_le_0.2": int((sj <= 0.2).sum()),
           "angles_ok": float(ok.sum() / max(quad.sum(), 1)),
           "warp_p99": float(np.percentile(q["warp"][quad], 99)) if quad.any() else 0.0,
           "median_edge": med}
    if size:
        out["median_edge_ratio"] = med / float(size)
    if supports is not None and len(supports.comp_kind):
        member = supports.comp_kind[mesh.component] == PLANE
        if (~member).any():
            out["mean_sj_skin"] = float(sj[~member].mean())
        if member.any():
            out["mean_sj_members"] = float(sj[member].mean())
    return out
