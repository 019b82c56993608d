"""Quality figures of a mesh and the issue's acceptance targets, for the benchmark.

:func:`mesh_figures` measures a :class:`~shellmesh_mdao.mesh.ShellMesh` with
:mod:`shellmesh_mdao.quality` (element counts, scaled Jacobian, corner angles, warp, edge
lengths); members are the ribs and spars, ``<wing>/rib_<k>``, ``<wing>/spar_<j>`` and their
``/seg_<i>`` pieces (:func:`member_face_mask`), the rest is skin. :data:`TARGETS` are the
issue's acceptance targets and :func:`target_checks` gives pass/fail per figure.
"""
from __future__ import annotations

import numpy as np

from ..families import is_rib_or_spar

__all__ = ["TARGETS", "member_face_mask", "mesh_figures", "target_checks"]

#: Acceptance targets: key -> (label, kind, bound). kind "min": value >= bound; "max": value <=
#: bound; "range": lo <= value <= hi.
TARGETS = {
    "quad_percent": ("% quads", "min", 100.0),
    "n_sj_le_0.2": ("elements SJ ≤ 0.2", "max", 0),
    "mean_sj_skin": ("mean SJ skin", "min", 0.95),
    "mean_sj_members": ("mean SJ members", "min", 0.90),
    "angles_ok_percent": ("% quads, angles in [45, 135]", "min", 97.0),
    "warp_p99": ("warp p99 (deg)", "max", 10.0),
    "median_edge_ratio": ("median edge / size", "range", (0.7, 1.3)),
}


def member_face_mask(component: np.ndarray, component_names) -> np.ndarray:
    """(m,) bool: True for the faces of a member (a rib or spar component or one of its pieces,
    :func:`~shellmesh_mdao.families.is_rib_or_spar`), False for skin."""
    is_member = np.array([is_rib_or_spar(n) for n in component_names], bool)
    if not len(is_member):
        return np.zeros(len(component), bool)
    return is_member[np.asarray(component)]


def mesh_figures(mesh, size: float, members: np.ndarray | None = None) -> dict:
    """Quality figures of a :class:`~shellmesh_mdao.mesh.ShellMesh` built for target quad
    edge ``size``: element counts, ``quad_percent``, ``n_folded`` (scaled Jacobian <= 0),
    ``n_sj_le_0.2``, scaled Jacobian ``sj_min`` / ``sj_p1`` / ``sj_mean``, ``mean_sj_skin`` and
    ``mean_sj_members`` (None without members), corner angles ``min_angle`` / ``max_angle``
    (extremes over all elements) and ``angles_ok_percent`` (quads with every corner in
    [45, 135] deg), ``warp_p99`` / ``warp_max`` (quads, degrees), ``aspect_p99``,
    ``median_edge`` and ``median_edge_ratio`` (median unique-edge length / ``size``),
    ``valid`` (``mesh.check().ok``) and ``problems`` (its lines). ``members``: (m,) bool member-face mask (default from
    the component names, :func:`member_face_mask`)."""
    from ..quality import QUAD_ANGLE_RANGE, element_quality

    m = mesh.n_faces
    if members is None:
        members = member_face_mask(mesh.component, mesh.component_names)
    q = element_quality(mesh.points, mesh.faces)
    sj = q["scaled_jacobian"]
    quad = mesh.is_quad
    lo, hi = QUAD_ANGLE_RANGE
    ok = quad & (q["min_angle"] >= lo) & (q["max_angle"] <= hi)
    nq = int(quad.sum())
    med = float(np.median(mesh.edge_lengths())) if m else float("nan")
    problems = mesh.check().problems()

    def mean(sel):
        return float(sj[sel].mean()) if sel.any() else None

    return {
        "n_elements": int(m), "n_quads": nq, "n_tris": int(m - nq),
        "n_skin": int((~members).sum()), "n_members": int(members.sum()), "n_points": int(mesh.n_points),
        "quad_percent": 100.0 * nq / m if m else 0.0,
        "n_folded": int((sj <= 0).sum()),
        "n_sj_le_0.2": int((sj <= 0.2).sum()),
        "sj_min": float(sj.min()) if m else None,
        "sj_p1": float(np.percentile(sj, 1)) if m else None,
        "sj_mean": float(sj.mean()) if m else None,
        "mean_sj_skin": mean(~members),
        "mean_sj_members": mean(members),
        "min_angle": float(q["min_angle"].min()) if m else None,
        "max_angle": float(q["max_angle"].max()) if m else None,
        "angles_ok_percent": 100.0 * ok.sum() / nq if nq else None,
        "warp_p99": float(np.percentile(q["warp"][quad], 99)) if nq else None,
        "warp_max": float(q["warp"][quad].max()) if nq else None,
        "aspect_p99": float(np.percentile(q["aspect"], 99)) if m else None,
        "median_edge": med,
        "median_edge_ratio": med / float(size),
        "valid": not problems,
        "problems": problems,
    }


def target_checks(fig: dict) -> dict:
    """Pass/fail of every target in :data:`TARGETS` for figures ``fig`` of :func:`mesh_figures`:
    ``{key: True/False}``, or None where the figure does not exist (no members)."""
    out = {}
    for key, (_, kind, bound) in TARGETS.items():
        v = fig.get(key)
        if v is None:
            out[key] = None
        elif kind == "min":
            out[key] = bool(v >= bound)
        elif kind == "max":
            out[key] = bool(v <= bound)
        else:
            out[key] = bool(bound[0] <= v <= bound[1])
    return out
