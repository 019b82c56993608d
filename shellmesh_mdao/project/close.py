"""Members closer than the element size: where two neighbouring ribs (or spars) of a wing come
closer than the element size on the skin, a local element size about their gap
(:func:`close_member_field`, a :class:`~shellmesh_mdao.core.sizefield.SizeField` the remesh,
imprint and members stages follow).

Members that coincide (closer than :data:`~shellmesh_mdao.layout.MIN_MEMBER_GAP` element sizes)
or cross are refused by the layout stage; everything from there up to one element size apart is
meshed, with elements about the gap between the two members, graded back to the element size.
"""
from __future__ import annotations

import re

import numpy as np
from scipy.spatial import cKDTree

from ..core.locator import SurfaceLocator
from ..core.sizefield import SizeField
from ..mesh import norm_rows
from .seeds import seed_curve_length

__all__ = ["close_member_field", "CLOSE_SIZE", "CLOSE_STEP"]

#: the local element size between two close members, as a fraction of their gap. The remesh
#: works at twice the element size: its triangles of 1.4 times the gap are about as tall as the gap
#: (1.21 times), so one row of well-shaped triangles fits between the two members, and the merge
#: and the subdivision make two rows of quads about 0.7 times the gap along the members and half
#: of it across. On the bundled wing (ribs 0.25-0.7 and spars 0.3-0.8 element sizes apart) the
#: quads between them have a median aspect ratio of 1.3-1.6 and at most 1.6-3.4; at 0.5 (square
#: quads of half the gap, 1.5 times as many elements) the median is 1.2 but the remesh's triangles
#: no longer fit the gap in one row and single quads reach 5-8; at 1.0 (one remesh edge of twice
#: the gap) the quads between are 2:1.
CLOSE_SIZE = 0.7
#: the members are sampled on the skin every this many element sizes to find their gaps
CLOSE_STEP = 0.05
_PART = re.compile(r"/part_\d+$")


def _samples(locator: SurfaceLocator, specs, step: float):
    """Points of every member's upper and lower curve on the skin (rays along +-up from its
    chord-plane curve, sampled every ``step``): ``(points (k, 3), member index (k,), side (k,),
    arc position along the member (k,))``; misses are dropped."""
    seeds, owner, arc = [], [], []
    for i, m in enumerate(specs):
        length = seed_curve_length(m)
        n = int(min(max(np.ceil(length / step) + 1, 2), 20000))
        pts = m.seed_points(n)
        seeds.append(pts)
        owner.append(np.full(n, i))
        arc.append(np.linspace(0.0, length, n))
    o = np.vstack(seeds)
    own = np.concatenate(owner)
    s = np.concatenate(arc)
    ups = np.stack([specs[i].up for i in own])
    hp, ti, _ = locator.raycast(np.vstack([o, o]), np.vstack([ups, -ups]))
    side = np.repeat([0, 1], len(o))
    keep = ti >= 0
    return hp[keep], np.tile(own, 2)[keep], side[keep], np.tile(s, 2)[keep]


def close_member_field(locator: SurfaceLocator, layout, size: float, step: float = CLOSE_STEP) -> SizeField:
    """The local element sizes two close members need: for every pair of ribs, or of spars
    (edge webs and kinked spars' pieces included, the pieces of one spar not paired), of one
    wing whose curves on the skin come closer than ``size`` (the same side: upper with upper,
    lower with lower), points along both curves where they do, each with the size
    :data:`CLOSE_SIZE` times the gap there (at least
    :data:`~shellmesh_mdao.layout.MIN_MEMBER_GAP` element sizes). Explicit members are not
    paired. An empty field when no members are close (the element size everywhere). The
    field's ``reasons`` name each pair with its smallest gap and size."""
    from ..layout import MIN_MEMBER_GAP, load_layout

    lay = load_layout(layout)
    specs = [m for m in lay.members() if m.kind in ("rib", "spar")]
    if len(specs) < 2:
        return SizeField()
    size = float(size)
    X, own, side, arc = _samples(locator, specs, step * size)
    if not len(X):
        return SizeField()
    group = np.unique([(m.wing, m.kind) for m in specs], axis=0, return_inverse=True)[1].reshape(-1)
    parent = np.unique([_PART.sub("", m.name) for m in specs], return_inverse=True)[1].reshape(-1)
    pairs = cKDTree(X).query_pairs(size, output_type="ndarray")
    if not len(pairs):
        return SizeField()
    i, j = pairs[:, 0], pairs[:, 1]
    mi, mj = own[i], own[j]
    ok = (side[i] == side[j]) & (group[mi] == group[mj]) & (parent[mi] != parent[mj])
    i, j, mi, mj = i[ok], j[ok], mi[ok], mj[ok]
    if not len(i):
        return SizeField()
    d = norm_rows(X[i] - X[j], axis=1)
    gap = np.full(len(X), np.inf)
    np.minimum.at(gap, i, d)
    np.minimum.at(gap, j, d)
    close = np.flatnonzero(gap < size)
    local = CLOSE_SIZE * np.maximum(gap[close], MIN_MEMBER_GAP * size)
    # thin each member side's points to about half their local size apart (the field between
    # them is then within an eighth of the grading's reach of the exact one)
    q = 0.5 * local.min()
    key = np.stack([own[close], side[close], np.floor(arc[close] / q).astype(np.int64)], 1)
    _, first = np.unique(key, axis=0, return_index=True)
    first = np.sort(first)
    pts, sizes = X[close][first], local[first]
    # why: every pair of members, its smallest gap and the size asked for
    lo = np.minimum(mi, mj)
    hi = np.maximum(mi, mj)
    pk, inv = np.unique(np.stack([lo, hi], 1), axis=0, return_inverse=True)
    pmin = np.full(len(pk), np.inf)
    np.minimum.at(pmin, inv.reshape(-1), d)
    reasons = tuple({"why": "close members", "members": [specs[a].name, specs[b].name], "gap": float(g),
                     "size": float(CLOSE_SIZE * max(g, MIN_MEMBER_GAP * size))}
                    for (a, b), g in zip(pk, pmin) if g < size)
    return SizeField(pts, sizes, reasons=reasons)
