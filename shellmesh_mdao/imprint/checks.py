"""Layouts the imprint cannot represent, refused before the skin is cut, every offender named at
once: full-chord ribs whose exact section has a corner sharper than a quad can fill
(:func:`check_loop_corners`), and member crossing points closer together than the skin can
hold apart (:func:`check_crossing_collisions`).

Both tests read the exact curves (plane sections of the input surface), not the skin being
cut, so their verdict does not depend on the element size: a layout refused here is refused at
every size, with a message that names the members, the places and the edit that fixes it.
"""
from __future__ import annotations

import numpy as np

from ..errors import ImprintError, LayoutError
from ..mesh import norm_rows

__all__ = ["MIN_LOOP_CORNER", "fmt_point", "loop_corner", "sharp_loop_message", "check_loop_corners",
           "check_crossing_collisions"]

#: a closed (full-chord) member's outline may not have a corner sharper than this: a quad in
#: a corner of angle a has a scaled Jacobian of at most sin(a), and the pipeline guarantees > 0.2
MIN_LOOP_CORNER = float(np.degrees(np.arcsin(0.2)))


def fmt_point(x) -> str:
    """A point for a message: ``[x, y, z]`` with 6 significant digits each."""
    return "[" + ", ".join(f"{float(c):.6g}" for c in x) + "]"


def loop_corner(points: np.ndarray, tol: float = 0.0):
    """The sharpest corner of the closed polyline ``points`` (implicitly closed): ``(angle in
    degrees, index)``. Points closer than ``tol`` to their predecessor are dropped first (an
    exact section passing through a vertex of the input repeats it)."""
    L = np.asarray(points, float)
    if tol > 0 and len(L) > 3:
        keep = norm_rows(L - np.roll(L, 1, axis=0), axis=1) > tol
        if keep.sum() >= 3:
            idx = np.flatnonzero(keep)
            L = L[idx]
        else:
            idx = np.arange(len(L))
    else:
        idx = np.arange(len(L))
    if len(L) < 3:
        return 180.0, 0
    u, v = np.roll(L, 1, axis=0) - L, np.roll(L, -1, axis=0) - L
    cosv = np.einsum("ij,ij->i", u, v) / np.maximum(norm_rows(u, axis=1) * norm_rows(v, axis=1), 1e-300)
    ang = np.degrees(np.arccos(np.clip(cosv, -1.0, 1.0)))
    k = int(np.argmin(ang))
    return float(ang[k]), int(idx[k])


def sharp_loop_message(items) -> str:
    """The refusal of full-chord members with corners sharper than :data:`MIN_LOOP_CORNER`:
    ``items`` is a list of ``(name, angle, point)``, every offender of the layout."""
    what = "; ".join(f"'{n}': a {a:.1f} deg corner at {fmt_point(p)} (scaled Jacobian at most "
                     f"sin({a:.1f} deg) = {np.sin(np.radians(a)):.3f})" for n, a, p in items)
    one = len(items) == 1
    return (f"full-chord member{'' if one else 's'} cut{'s' if one else ''} a sharp edge of the skin: {what}; "
            f"the upper and lower skin meet there at that angle, so any quad in {'that' if one else 'such a'} "
            f"corner is below the 0.2 scaled-Jacobian guarantee at any element size; end the "
            f"rib{'' if one else 's'} on spars (give the wing two or more spars: every rib then runs between "
            "them), move the rib so its plane does not cut that edge, or round that edge of the surface")


def check_loop_corners(chains, arcs, eps: float) -> None:
    """Refuse every closed chain (a full-chord rib: the whole section of its plane through the
    skin) whose exact curve has a corner sharper than :data:`MIN_LOOP_CORNER` -- its plane cuts
    a sharp leading or trailing edge, or runs on through another wing to that wing's sharp
    edge. One :class:`~shellmesh_mdao.errors.LayoutError` names every such member. ``eps``:
    the length below which consecutive section points count as one."""
    bad = []
    for spec, arc in zip(chains, arcs):               # one pass per chain (a few dozen)
        if not arc.closed or len(arc.points) < 3:
            continue
        a, k = loop_corner(arc.points, eps)
        if a < MIN_LOOP_CORNER:
            bad.append((spec.member, a, arc.points[k]))
    if bad:
        raise LayoutError(sharp_loop_message(bad))


def check_crossing_collisions(points: np.ndarray, owners: list, vertex_of: np.ndarray, size_hint: float) -> None:
    """Refuse crossing points (``points``, one per row, ``owners[i]`` the member names each
    belongs to) that fell on one skin vertex (``vertex_of[i]``): the members meeting there are
    closer together than the skin's edges, so their chains cannot keep them apart. One
    :class:`~shellmesh_mdao.errors.ImprintError` names every such group of members, where
    their points lie and how far apart they are. ``size_hint``: the local skin edge length
    (for the advice)."""
    vertex_of = np.asarray(vertex_of, np.int64)
    u, inv, cnt = np.unique(vertex_of, return_inverse=True, return_counts=True)
    groups = []
    for g in np.flatnonzero(cnt > 1).tolist():        # loop over the few collisions
        i = np.flatnonzero(inv.reshape(-1) == g)
        names = sorted({n for k in i.tolist() for n in owners[k]})
        X = points[i]
        gap = float(norm_rows(X[:, None, :] - X[None, :, :], axis=2).max())
        groups.append(f"{', '.join(repr(n) for n in names)} near {fmt_point(X.mean(0))} ({len(i)} crossing or end "
                      f"points {gap:.3g} apart)")
    if groups:
        raise ImprintError(f"member crossing points closer than the skin's edges ({size_hint:.3g} there) fell on "
                           f"one skin vertex at {len(groups)} place(s): {'; '.join(groups)}; move these members "
                           "apart in the layout (their ends or crossings at least one element size apart), or use "
                           "a smaller --size")
