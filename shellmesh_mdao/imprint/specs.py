"""The curves to imprint: one :class:`ChainSpec` per member side (a rib's or spar's plane between
its bounding planes, an explicit member segment by segment), from the layout and the projected
seed points (:func:`chain_specs`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.polygon import frame_from_normal, interior_samples, point_in_polygon, to2d
from ..errors import ImprintError, LayoutError
from ..layout import explicit_plane
from ..mesh import norm_rows
from ..core.section import Plane

__all__ = ["ChainSpec", "chain_specs"]


@dataclass
class ChainSpec:
    """One curve to imprint: ``plane`` inside the half-spaces ``bounds`` (side >= 0 is
    inside), the connected piece through ``seed`` (a point on the input surface, in the
    plane, e.g. a ray-cast hit; ``seed_tri`` its input triangle). ``member`` names the
    member (its component name) and ``side`` the skin side ('upper', 'lower', 'loop')."""

    member: str
    side: str
    plane: Plane
    bounds: tuple
    seed: np.ndarray
    seed_tri: int = -1
    ends: tuple = ()   # crossing points (3,) that must be vertices of this chain


def chain_specs(layout, projected) -> list:
    """The curves to imprint for every member of a resolved layout.

    ``layout``: a :class:`~shellmesh_mdao.layout.Layout`; ``projected``: the result of
    :func:`~shellmesh_mdao.project.project_layout` (seed points hit on the skin by rays cast
    from inside the wing). A rib or spar gives an upper and a lower chain between its
    bounding planes; a full-chord rib (fewer than two spars) one closed loop. Explicit
    members give one chain per side, each the union of the sections of the planes spanned by
    a polyline segment and its projection direction (one :class:`ChainSpec` per segment,
    sides ``upper_<s>``/``lower_<s>``). Raises :class:`~shellmesh_mdao.errors.LayoutError` when
    an explicit member lies in the plane of another member and their areas overlap.
    """
    _check_coplanar_overlaps(layout.members(), projected)
    specs = []
    for m in layout.members():
        pm = projected[m.name]
        if m.kind == "explicit":
            specs += _explicit_chain_specs(m, pm)
            continue
        plane = Plane.make(m.plane_point, m.plane_normal)
        bounds = tuple(Plane.make(p, n) for p, n in m.bound_planes)
        mid = len(pm.seeds) // 2
        if m.kind == "rib" and not bounds:
            specs.append(ChainSpec(m.name, "loop", plane, (), pm.upper[mid], int(pm.upper_tri[mid])))
            continue
        specs.append(ChainSpec(m.name, "upper", plane, bounds, pm.upper[mid], int(pm.upper_tri[mid])))
        specs.append(ChainSpec(m.name, "lower", plane, bounds, pm.lower[mid], int(pm.lower_tri[mid])))
    return specs


def _check_coplanar_overlaps(members, projected, tol: float = 1e-9) -> None:
    """Two members in one plane whose areas overlap (at least one of them explicit) are a
    :class:`~shellmesh_mdao.errors.LayoutError` naming both, raised before the imprint would
    cut the same skin curve twice. A member's area is taken as the polygon of its projected
    upper points followed by its projected lower points (reversed); explicit members count
    when their layout is planar (:func:`~shellmesh_mdao.layout.explicit_plane`)."""
    polys = []
    for m in members:                                     # loop over members
        pm = projected[m.name]
        if m.kind == "explicit":
            pp, pn = explicit_plane(m)
        else:
            pp, pn = m.plane_point, m.plane_normal
        if pn is None:
            continue
        up, lo = np.asarray(pm.upper, float), np.asarray(pm.lower, float)
        if np.linalg.norm(up[0] - lo[-1]) + np.linalg.norm(up[-1] - lo[0]) < \
                np.linalg.norm(up[0] - lo[0]) + np.linalg.norm(up[-1] - lo[-1]):
            lo = lo[::-1]
        polys.append((m, np.asarray(pp, float), np.asarray(pn, float), np.vstack([up, lo[::-1]])))
    for i in range(len(polys)):                           # loop over member pairs (a few dozen members)
        mi, pi, ni, qi = polys[i]
        for j in range(i + 1, len(polys)):
            mj, pj, nj, qj = polys[j]
            if mi.kind != "explicit" and mj.kind != "explicit":
                continue
            scale = float(norm_rows(np.ptp(np.vstack([qi, qj]), axis=0)))
            if np.linalg.norm(np.cross(ni, nj)) > tol or abs((pj - pi) @ ni) > tol * scale:
                continue
            e1, e2, o = frame_from_normal(ni, pi)
            a2, b2 = to2d(qi, e1, e2, o), to2d(qj, e1, e2, o)
            eps = 1e-6 * scale
            sa = np.vstack([a2, 0.5 * (a2 + np.roll(a2, -1, 0)), interior_samples(a2)])
            sb = np.vstack([b2, 0.5 * (b2 + np.roll(b2, -1, 0)), interior_samples(b2)])
            if point_in_polygon(sb, a2, eps).any() or point_in_polygon(sa, b2, eps).any():
                raise LayoutError(f"members '{mi.name}' and '{mj.name}' lie in the same plane and overlap; remove "
                                  "one of them or move it so their areas do not overlap")


def _explicit_chain_specs(m, pm) -> list:
    """Explicit member: for each side, one chain piece per polyline segment: the plane through
    the segment's two projected points containing the projection direction (or, without a
    direction, the mean of the two points' projection offsets ``hit - seed``; a point that
    already lies on the skin uses the normal of the triangle it lies on), bounded by the
    planes through the segment ends normal to the segment."""
    out = []
    for side, seeds, hits, normals, direction in (
            ("upper", pm.seeds, pm.upper, pm.upper_normal, m.direction),
            ("lower", pm.lower_seeds if pm.lower_seeds is not None else pm.seeds, pm.lower, pm.lower_normal,
             m.lower_direction)):
        for s in range(len(hits) - 1):
            a, b = hits[s], hits[s + 1]
            ab = b - a
            if np.linalg.norm(ab) == 0:
                raise ImprintError(f"{m.name}: points {s} and {s + 1} of its {side} curve project onto the same "
                                   "skin point; space the points further apart")
            if direction is not None:
                dvec = np.asarray(direction, float)
            else:
                dvec = _closest_point_direction(m.name, side, s, seeds, hits, normals, float(np.linalg.norm(ab)))
            nrm = np.cross(ab, dvec)
            if np.linalg.norm(nrm) <= 1e-12 * np.linalg.norm(ab) * max(np.linalg.norm(dvec), 1e-300):
                raise ImprintError(f"{m.name}: segment {s} of its {side} curve is parallel to its projection "
                                   "direction; choose a direction across the curve")
            bounds = (Plane.make(a, ab), Plane.make(b, -ab))
            seed = 0.5 * (a + b)
            out.append(ChainSpec(m.name, f"{side}_{s}", Plane.make(a, nrm), bounds, seed, -1))
    return out


def _closest_point_direction(name, side, s, seeds, hits, normals, length) -> np.ndarray:
    """Projection direction of segment ``s`` of a polyline projected to the closest skin points:
    the mean of the unit offsets ``hit - seed`` of its two ends; an end that lies on the skin
    (offset below 1e-9 of the segment length) takes the normal of its skin triangle instead,
    turned to agree with the other end."""
    dirs = []
    for k in (s, s + 1):
        off = np.asarray(hits[k], float) - np.asarray(seeds[k], float)
        ln = float(np.linalg.norm(off))
        dirs.append(off / ln if ln > 1e-9 * length else None)
    for i in (0, 1):
        if dirs[i] is None and normals is not None and np.linalg.norm(normals[s + i]) > 0:
            nv = np.asarray(normals[s + i], float)
            ref = dirs[1 - i]
            dirs[i] = -nv if ref is not None and nv @ ref < 0 else nv
    if dirs[0] is None and dirs[1] is None:
        raise ImprintError(f"{name}: the ends of segment {s} of its {side} polyline lie on the skin and no "
                           "'direction' is given; give a projection direction")
    if dirs[0] is None or dirs[1] is None:
        return dirs[0] if dirs[1] is None else dirs[1]
    if dirs[0] @ dirs[1] < 0:                      # the ends lie on opposite sides of the skin
        dirs[1] = -dirs[1]
    return dirs[0] + dirs[1]
