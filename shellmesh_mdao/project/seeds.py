"""The projection of a layout's members onto the skin (:func:`project_layout`,
:func:`project_wing_stations`, :func:`project_polyline`: seed points hit on the skin by rays
along the wing's up direction, or closest points), the result per member
(:class:`ProjectedMember`) and the spar-height check (:func:`check_member_heights`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ProjectionError
from ..mesh import norm_rows
from ..core.locator import SurfaceLocator

__all__ = ["project_wing_stations", "project_polyline", "project_layout", "ProjectedMember", "MIN_MEMBER_HEIGHT",
           "check_member_heights", "spar_heights", "seed_curve_length"]


# ----------------------------------------------------------------------------- projection
def _fmt_points(p, idx, limit=4) -> str:
    sel = np.asarray(idx)[:limit]
    s = ", ".join("[" + ", ".join(f"{v:.6g}" for v in p[i]) + "]" for i in sel)
    more = f" (and {len(idx) - limit} more)" if len(idx) > limit else ""
    return s + more


def _up_of(wing) -> np.ndarray:
    up = getattr(wing, "up", wing)
    if up is None:
        raise ProjectionError("no 'up' direction given for the wing: resolve the layout first "
                              "(Layout.members() gives every member its wing's up)")
    u = np.asarray(up, dtype=np.float64).reshape(3)
    n = np.linalg.norm(u)
    if not np.isfinite(n) or n == 0:
        raise ProjectionError(f"'up' {u.tolist()} is zero or not finite: give the chord-plane normal")
    return u / n


def project_wing_stations(locator: SurfaceLocator, wing, points, name: str = "member"):
    """Project points of a wing's chord plane onto its upper and lower skin.

    Each point casts one ray along ``+up`` and one along ``-up`` and keeps the first hit,
    so the wing's own skin is found even where a fuselage or tail lies further along the
    same line. ``wing`` is anything with an ``up`` attribute (a :class:`MemberSpec`, a
    :class:`~shellmesh_mdao.layout.WingLayout` with its own up) or the up vector itself.

    Returns ``(upper_hits, lower_hits)``, each a tuple ``(points (k,3), tri (k,))``.
    Raises :class:`ProjectionError` naming ``name`` and the points whose ray misses."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    up = _up_of(wing)
    k = len(pts)
    o = np.vstack([pts, pts])
    d = np.vstack([np.broadcast_to(up, (k, 3)), np.broadcast_to(-up, (k, 3))])
    hp, ti, _ = locator.raycast(o, d)
    miss = ti < 0
    if miss.any():
        mu = np.flatnonzero(miss[:k])
        ml = np.flatnonzero(miss[k:])
        parts = []
        if len(mu):
            parts.append(f"upward (+up) from {_fmt_points(pts, mu)}")
        if len(ml):
            parts.append(f"downward (-up) from {_fmt_points(pts, ml)}")
        raise ProjectionError(
            f"member '{name}': rays miss the skin {'; '.join(parts)}: the member's chord-plane points must lie "
            "inside the wing; check the wing corners (root_le/root_te/tip_le/tip_te), 'up', the stations and "
            "the chord fractions")
    return (hp[:k], ti[:k]), (hp[k:], ti[k:])


def project_polyline(locator: SurfaceLocator, points, direction=None, name: str = "member"):
    """Project a polyline onto the skin: along ``direction`` (nearest hit at ``t > 0``,
    so a line that starts inside the body takes the first skin crossing along
    ``+direction``) or, with ``direction=None``, to the closest skin point.

    Returns ``(points (k,3), tri (k,))``; raises :class:`ProjectionError` naming ``name``
    and the points whose ray misses."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if direction is None:
        cp, tri, _ = locator.closest(pts)
        return cp, tri
    d = np.asarray(direction, dtype=np.float64)
    if d.ndim == 1:
        d = np.broadcast_to(d, pts.shape)
    hp, tri, _ = locator.raycast(pts, d)
    miss = np.flatnonzero(tri < 0)
    if len(miss):
        raise ProjectionError(
            f"member '{name}': projecting along {np.round(np.asarray(direction, float).reshape(-1, 3)[0], 6).tolist()} "
            f"misses the skin from {_fmt_points(pts, miss)}: move these points so that the direction points "
            "towards the skin, or omit 'direction' to project to the closest skin point")
    return hp, tri


@dataclass
class ProjectedMember:
    """Seeds of one member on the skin: ``seeds`` (k,3) its defining points (wing
    members: on the chord plane and the member plane; explicit members: the ``upper``
    polyline), ``upper``/``lower`` (k,3) their projections and ``upper_tri``/``lower_tri``
    (k,) the surface triangles hit (explicit members: ``lower_seeds`` holds the lower
    polyline, which may have a different length, and ``upper_normal``/``lower_normal`` the
    unit normals of the triangles hit, which give the projection direction of a point that
    already lies on the skin when no direction is given)."""

    name: str
    kind: str
    seeds: np.ndarray
    upper: np.ndarray
    lower: np.ndarray
    upper_tri: np.ndarray
    lower_tri: np.ndarray
    lower_seeds: np.ndarray | None = None
    upper_normal: np.ndarray | None = None
    lower_normal: np.ndarray | None = None


def _tri_normals(locator: SurfaceLocator, tri: np.ndarray) -> np.ndarray:
    """Unit normals of the locator's triangles ``tri`` (zero for a degenerate triangle)."""
    t = locator.triangles[np.asarray(tri, np.int64)]
    L = locator._local
    n = np.cross(L[t[:, 1]] - L[t[:, 0]], L[t[:, 2]] - L[t[:, 0]])
    ln = norm_rows(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


def _is_full_chord(m) -> bool:
    """A rib bounded by the leading and trailing edge (its wing has fewer than two spars)."""
    return m.kind == "rib" and not m.bound_planes


def _outline_ends(locator: SurfaceLocator, seeds, up_p, lo_p, up_t, lo_t) -> None:
    """Project the two end seeds of a full-chord rib in place.

    Those ends are the wing-box corners' leading- and trailing-edge points ``S(eta, 0)`` and
    ``S(eta, 1)``: they lie ON the skin's outline (the manifest's corners are edge points),
    where the ``+-up`` rays start on the surface and graze it, so they hit or miss by
    rounding. An end's projection is the closest skin point instead (the point where the
    upper and lower skins meet), for both sides. Only the middle seed of a full-chord rib
    picks its section loop (:func:`~shellmesh_mdao.imprint.chain_specs`); its interior seeds
    still have to hit the skin along ``+-up``, so a rib outside the wing is still refused."""
    ends = np.array([0, len(seeds) - 1])
    cp, tri, _ = locator.closest(seeds[ends])
    up_p[ends] = cp
    lo_p[ends] = cp
    up_t[ends] = tri
    lo_t[ends] = tri


def project_layout(locator: SurfaceLocator, layout, n_seeds: int = 5) -> dict:
    """Project every member of ``layout`` (a :class:`~shellmesh_mdao.layout.Layout`, a dict
    or a path) onto the skin: ``{member name: ProjectedMember}`` in :meth:`Layout.members`
    order. Wing members cast ``n_seeds`` points of their chord-plane curve along
    ``+/-up`` (a full-chord rib's two end points, which lie on the skin's leading and
    trailing edge, go to their closest skin point instead); explicit members project their
    upper and lower polylines."""
    from ..layout import load_layout
    lay = load_layout(layout)
    out = {}
    specs = lay.members()
    wing_specs = [m for m in specs if m.kind != "explicit"]
    if wing_specs:
        # one batched ray cast for all wing members (grouped by up only via broadcasting)
        seeds = [m.seed_points(n_seeds) for m in wing_specs]
        cnt = np.array([len(s) for s in seeds])
        o = np.vstack(seeds)
        ups = np.repeat(np.stack([m.up for m in wing_specs]), cnt, axis=0)
        hp, ti, _ = locator.raycast(np.vstack([o, o]), np.vstack([ups, -ups]))
        n = len(o)
        off = np.concatenate([[0], np.cumsum(cnt)])
        for i, m in enumerate(wing_specs):
            sl = slice(off[i], off[i + 1])
            up_p, lo_p = hp[:n][sl].copy(), hp[n:][sl].copy()
            up_t, lo_t = ti[:n][sl].copy(), ti[n:][sl].copy()
            if _is_full_chord(m):
                _outline_ends(locator, seeds[i], up_p, lo_p, up_t, lo_t)
            if (up_t < 0).any() or (lo_t < 0).any():
                project_wing_stations(locator, m, seeds[i], name=m.name)  # raises with the details
            out[m.name] = ProjectedMember(m.name, m.kind, seeds[i], up_p, lo_p, up_t, lo_t)
    for m in specs:
        if m.kind != "explicit":
            continue
        up_p, up_t = project_polyline(locator, m.upper, m.direction, name=m.name)
        lo_p, lo_t = project_polyline(locator, m.lower, m.lower_direction, name=m.name)
        out[m.name] = ProjectedMember(m.name, m.kind, m.upper.copy(), up_p, lo_p, up_t, lo_t,
                                      lower_seeds=m.lower.copy(), upper_normal=_tri_normals(locator, up_t),
                                      lower_normal=_tri_normals(locator, lo_t))
    return {m.name: out[m.name] for m in specs}


def seed_curve_length(m) -> float:
    """Length of the chord-plane curve of the wing member ``m`` (a
    :class:`~shellmesh_mdao.layout.MemberSpec`), measured on 65 of its seed points."""
    return float(norm_rows(np.diff(m.seed_points(65), axis=0), axis=1).sum())


def spar_heights(locator: SurfaceLocator, spars, counts):
    """The web heights of the wing members ``spars`` at ``counts[i]`` points of member ``i``
    strictly between its ends (of its chord-plane curve): the distance along its ``up`` between
    the upper and lower skin hits of rays cast along ``+-up`` (inf where a ray misses). Returns
    ``(points (k, 3), member index (k,), upper hits (k, 3), lower hits (k, 3), height (k,))``."""
    seeds = [m.seed_points(int(c) + 2)[1:-1] for m, c in zip(spars, counts)]
    own = np.repeat(np.arange(len(spars)), [len(s) for s in seeds])
    o = np.vstack(seeds)
    ups = np.stack([m.up for m in spars])[own]
    hp, ti, _ = locator.raycast(np.vstack([o, o]), np.vstack([ups, -ups]))
    k = len(o)
    ok = (ti[:k] >= 0) & (ti[k:] >= 0)
    height = np.where(ok, np.einsum("ij,ij->i", hp[:k] - hp[k:], ups), np.inf)
    return o, own, hp[:k], hp[k:], height


#: a spar web must be at least this many local element sizes tall everywhere along it (where it is
#: lower than that at the element size, the mesh refines around it: ``thin_member_field``)
MIN_MEMBER_HEIGHT = 0.3


def check_member_heights(locator: SurfaceLocator, layout, size: float, n: int = 21) -> dict:
    """Height of every spar web (distance between its upper and lower skin hits along
    ``+-up``, at ``n`` points strictly between the first and the last rib plane: at its ends
    a spar meets the outermost ribs, which may cut a rounded tip cap) against the element
    ``size``. Returns ``{spar name: (min height, point of the min)}``; raises
    :class:`LayoutError` when a spar is less than :data:`MIN_MEMBER_HEIGHT` times
    :data:`~shellmesh_mdao.layout.MIN_LOCAL_SIZE` element sizes tall somewhere (a spar at the
    very edge of a thin wing): a web lower than :data:`MIN_MEMBER_HEIGHT` element sizes is meshed
    with elements of twice its height (:func:`~shellmesh_mdao.project.thin_member_field`), and the
    mesh refines no further than :data:`~shellmesh_mdao.layout.MIN_LOCAL_SIZE` element sizes. Bounded ribs end on
    the spars, so their smallest heights are the spars'; full-chord ribs close at the edges
    by design and are not checked."""
    from ..errors import LayoutError
    from ..layout import load_layout
    lay = load_layout(layout)
    spars = [m for m in lay.members() if m.kind == "spar"]
    if not spars:
        return {}
    o, _, _, _, height = spar_heights(locator, spars, [n] * len(spars))          # ends excluded
    height = height.reshape(len(spars), n)
    out = {}
    for i, m in enumerate(spars):
        j = int(np.argmin(height[i]))
        out[m.name] = (float(height[i, j]), o[i * n + j].copy())
    from ..layout import MIN_LOCAL_SIZE
    for m in spars:
        h, p = out[m.name]
        if h < MIN_MEMBER_HEIGHT * MIN_LOCAL_SIZE * size:
            edge = "trailing" if m.parameter > 0.5 else "leading"
            ratio = np.floor(h / size * 1000.0) / 1000.0                # rounded down
            e = np.floor(np.log10(h / MIN_MEMBER_HEIGHT / MIN_LOCAL_SIZE)) - 3   # 4 significant digits, rounded down
            limit = np.floor(h / MIN_MEMBER_HEIGHT / MIN_LOCAL_SIZE / 10.0 ** e) * 10.0 ** e
            raise LayoutError(
                f"spar '{m.name}' (c={m.parameter:g}) is only {h:.4g} tall near {_fmt_points(p[None], [0])}, "
                f"{ratio:g} element sizes: a web of quads needs elements of at most {h / MIN_MEMBER_HEIGHT:.4g} there "
                f"(its height at least {MIN_MEMBER_HEIGHT:g} of them), below the smallest local size the mesh "
                f"refines to ({MIN_LOCAL_SIZE:g} element sizes, {MIN_LOCAL_SIZE * size:.4g}); move the spar away "
                f"from the {edge} edge (or the outermost rib inboard, if the point is at a thin tip) or use an "
                f"element size below {limit:.4g}")
    return out
