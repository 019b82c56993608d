"""What the members stage needs per member beyond its chains: :class:`MemberInfo` (plane, running
direction, owning wing) from the layout, and the least-squares plane of a member's points."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import LayoutError
from ..core.section import Plane
from ..layout import Layout, explicit_plane, load_layout

__all__ = ["MemberInfo", "member_infos", "fit_plane"]


@dataclass
class MemberInfo:
    """What :func:`build_members` needs per member beyond its chains.

    ``name``          the member's name (``<wing>/rib_<k>``, ``<wing>/spar_<j>`` or an explicit
                      member's name); its chains (``ChainResult.member``) carry the same name.
    ``kind``          ``'rib'``, ``'spar'`` or ``'explicit'``.
    ``plane_point``, ``plane_normal``  the member plane; both None for a non-planar member
                      (meshed through a Coons patch of its four sides).
    ``up``            the wing's up vector (informative).
    ``direction``     the member's running direction (rib: front to rear, spar: root to tip;
                      ``end - start`` of its defining curve in the layout): orients the chains
                      and numbers the pieces ``seg_<j>`` along it. None: the upper chain's order.
    ``wing``, ``index`` owning wing and rib/spar number (None and position for explicit members).
    """

    name: str
    kind: str = "explicit"
    plane_point: np.ndarray | None = None
    plane_normal: np.ndarray | None = None
    up: np.ndarray | None = None
    direction: np.ndarray | None = None
    wing: str | None = None
    index: int = 0

    def __post_init__(self):
        for k in ("plane_point", "plane_normal", "up", "direction"):
            v = getattr(self, k)
            if v is not None:
                v = np.asarray(v, dtype=np.float64).reshape(3)
                if not np.isfinite(v).all():
                    raise LayoutError(f"member '{self.name}': {k} {v.tolist()} is not finite; give a finite vector")
                setattr(self, k, v)
        if (self.plane_point is None) != (self.plane_normal is None):
            raise LayoutError(f"member '{self.name}': give both plane_point and plane_normal (or neither for a "
                              "non-planar member)")
        if self.plane_normal is not None:
            n = float(np.linalg.norm(self.plane_normal))
            if n == 0:
                raise LayoutError(f"member '{self.name}': plane_normal is the zero vector; give the plane's normal")
            self.plane_normal = self.plane_normal / n

    @property
    def is_planar(self) -> bool:
        return self.plane_normal is not None

    @property
    def plane(self) -> Plane | None:
        return Plane(self.plane_point, self.plane_normal) if self.is_planar else None

    @classmethod
    def from_spec(cls, spec) -> "MemberInfo":
        """From a :class:`~shellmesh_mdao.layout.MemberSpec` (or anything with its attributes).
        An explicit member runs along its ``upper`` polyline; it gets the plane its layout spans
        when its polylines and projection directions lie in one plane (:func:`explicit_plane`),
        else none here (:func:`build_members` fits one to its imprinted chains when they are
        coplanar, as for closest-point projection, or meshes it panel by panel)."""
        kind = getattr(spec, "kind", "explicit")
        pp, pn = getattr(spec, "plane_point", None), getattr(spec, "plane_normal", None)
        direction = None
        start, end = getattr(spec, "start", None), getattr(spec, "end", None)
        if start is not None and end is not None:
            direction = np.asarray(end, float) - np.asarray(start, float)
        if kind == "explicit" and getattr(spec, "upper", None) is not None:
            up_pts = np.asarray(spec.upper, float).reshape(-1, 3)
            direction = up_pts[-1] - up_pts[0]
            if pn is None:
                pp, pn = explicit_plane(spec)
        return cls(name=spec.name, kind=kind, plane_point=pp, plane_normal=pn, up=getattr(spec, "up", None),
                   direction=direction, wing=getattr(spec, "wing", None), index=int(getattr(spec, "index", 0) or 0))


def fit_plane(pts: np.ndarray, tol: float):
    """Least-squares plane of ``pts``: ``(point, normal)``, or ``(None, None)`` when they are
    not coplanar within ``tol`` times their extent (or are collinear)."""
    c = pts.mean(0)
    ext = float(np.linalg.norm(pts.max(0) - pts.min(0)))
    if ext == 0 or len(pts) < 3:
        return None, None
    _, s, vt = np.linalg.svd(pts - c)
    if s[1] <= 1e-9 * s[0]:
        return None, None
    n = vt[2]
    if np.abs((pts - c) @ n).max() > tol * ext:
        return None, None
    return c, n


def member_infos(layout) -> list:
    """:class:`MemberInfo` of every member of a layout (a :class:`~shellmesh_mdao.layout.Layout`,
    dict or path), in :meth:`~shellmesh_mdao.layout.Layout.members` order."""
    lay = layout if isinstance(layout, Layout) else load_layout(layout)
    return [MemberInfo.from_spec(s) for s in lay.members()]
