"""Spars and webs too thin for the element size: where a spar (or edge web) of a wing is less
than :data:`~shellmesh_mdao.project.MIN_MEMBER_HEIGHT` element sizes tall (a spar near the leading
or trailing edge, a thin tip, a thin tail at a coarse size: a web of quads of the element size would
be slivers), a local element size of its height over :data:`THIN_HEIGHT`
(:func:`thin_member_field`, a :class:`~shellmesh_mdao.core.sizefield.SizeField` the remesh,
imprint and members stages follow), so its web is :data:`THIN_HEIGHT` local sizes tall there.

The field goes down to :data:`~shellmesh_mdao.layout.MIN_LOCAL_SIZE` element sizes, where a web is
still at least :data:`~shellmesh_mdao.project.MIN_MEMBER_HEIGHT` local sizes tall; a spar lower
than that is refused by :func:`~shellmesh_mdao.project.check_member_heights` (and, for wings
given by stations, by the layout stage). Spars at least
:data:`~shellmesh_mdao.project.MIN_MEMBER_HEIGHT` element sizes tall get no field, so their meshes do
not change; the size asked for is not continuous in the height there (it falls from the element
size to 0.6 of it): refining spars up to :data:`THIN_HEIGHT` element sizes too changed meshes that
met every guarantee, and on the default wing's shape at size 0.25 on a coarse (24 x 16) input it
left skin nodes off the tip cap (0.15 element sizes).
"""
from __future__ import annotations

import numpy as np

from ..core.locator import SurfaceLocator
from ..core.sizefield import SizeField
from .seeds import MIN_MEMBER_HEIGHT, seed_curve_length, spar_heights

__all__ = ["thin_member_field", "THIN_STEP", "THIN_HEIGHT"]

#: a spar too thin for the element size gets elements of its height over this fraction, so it is
#: this many local sizes tall: the remesh keeps the upper and lower skin apart only where they are
#: more than twice its chordal deviation apart (0.4 sizes, ``layout.EDGE_WEB_HEIGHT``); a web lower
#: than that lies between remeshed faces running from the upper to the lower skin, and its curves
#: break or leave their side when imprinted
THIN_HEIGHT = 0.5
#: spars are sampled every this many element sizes to measure their height
THIN_STEP = 0.1


def thin_member_field(locator: SurfaceLocator, layout, size: float, step: float = THIN_STEP) -> SizeField:
    """The local element sizes thin spars need: every spar (edge webs included; explicit
    members are not measured) is sampled every ``step`` element sizes strictly between its ends
    and its height measured there (the distance between its upper and lower skin hits along
    ``+-up``, as :func:`~shellmesh_mdao.project.check_member_heights`); where it is less than
    :data:`~shellmesh_mdao.project.MIN_MEMBER_HEIGHT` ``* size``, both hits get the size
    ``height / THIN_HEIGHT`` (at least
    :data:`~shellmesh_mdao.layout.MIN_LOCAL_SIZE` ``* size``). An empty field when every spar is tall enough. The field's ``reasons`` name each
    thin spar with its smallest height and the size asked for there."""
    from ..layout import MIN_LOCAL_SIZE, load_layout

    lay = load_layout(layout)
    spars = [m for m in lay.members() if m.kind == "spar"]
    if not spars:
        return SizeField()
    size = float(size)
    counts = [min(max(np.ceil(seed_curve_length(m) / (step * size)) + 1, 3), 20000) for m in spars]
    _, own, upper, lower, height = spar_heights(locator, spars, counts)      # ends excluded
    thin = np.flatnonzero((height < MIN_MEMBER_HEIGHT * size) & (height > 0))
    if not len(thin):
        return SizeField()
    local = np.maximum(height[thin] / THIN_HEIGHT, MIN_LOCAL_SIZE * size)
    pts = np.vstack([upper[thin], lower[thin]])
    sizes = np.concatenate([local, local])
    reasons = []
    for i in np.unique(own[thin]):
        sel = own[thin] == i
        j = int(np.argmin(height[thin][sel]))
        reasons.append({"why": "thin member", "members": [spars[i].name], "height": float(height[thin][sel][j]),
                        "size": float(local[sel][j])})
    return SizeField(pts, sizes, reasons=tuple(reasons))
