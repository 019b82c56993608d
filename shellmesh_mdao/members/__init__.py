"""Members: triangle meshes of the internal members that share the imprint chains' nodes.

Stage order: load -> layout -> project -> imprint -> **members** -> split -> merge -> smooth -> quad -> export.

Every internal member is a four-sided surface (the paper, Sec. IV.A): its upper and lower
sides are its imprint chains on the upper and lower skin, its two other sides are junction
lines with the members it ends on (a rib's lines with the front and rear spar) or straight
end lines where nothing closes it. The member mesh uses the chain vertices themselves (the
same point indices as the skin), so skin and member conform by construction.

Junctions between members (found as the skin vertices two members' chains share):

* a **junction line** joins the upper and lower crossing vertex of two members (both are
  skin vertices on both chains). For planar members it is the straight segment on the
  intersection line of the two planes (parallel to the wing's ``up`` in a wing box). It is
  discretised once and the same nodes are used by both members;
* **T-junction**: the line is at the end of one member's chains (a rib ends on a spar) and
  inside the other (the spar). The rib closes on it; the spar keeps it as interior edges
  and stays one component;
* **X-junction**: the line is inside both members (a rib crosses a middle spar). Both
  members are split into pieces along it, named ``<member>/seg_<j>`` with ``j`` counted
  along the member's direction (ribs front to rear, spars root to tip: a middle spar's
  ``seg_k`` is the bay between rib ``k`` and rib ``k + 1`` when it starts at rib 0). A
  member with at least one X-junction is split along all its interior junction lines;
* **L-junction**: the line ends both members (the wing-box corner rib 0 x spar 0).

Before meshing, chains are completed (edges a later cut split get their vertices back),
crossing vertices are put exactly on both planes, very uneven chain spacing is evened out
by sliding chain vertices along their exact curves, and chain edges much longer than the
member is tall are split (with the two skin triangles on them). Each planar member is then
one constrained Delaunay triangulation of its plane's 2D frame (``triangle``, no Steiner
point on any chain or junction segment), refined to a size graded from the boundary spacing
to ``size``, smoothed and pruned for its smallest angle. A kinked explicit member (one chain
piece per polyline segment on both sides, not coplanar) is split into panels by the straight
lines joining its upper and lower kinks, each meshed in its own plane; any other non-planar
member is meshed in the parameter square of a Coons patch of B-spline fits of its four sides.

Modules (each imports only the public names of the others):

* :mod:`.info`      :class:`MemberInfo` per member from the layout;
* :mod:`.junctions` a member's chains gathered from the imprint, and the junctions between members;
* :mod:`.spacing`   chain spacing evened out, thin chain edges split;
* :mod:`.meshing`   planar Delaunay, kinked panels and Coons patches (:func:`triangulate_planar`);
* :mod:`.build`     the stage's entry :func:`build_members`, the checks between members and
  :func:`member_statistics`.

See ``docs/members.md`` for the method, the numbering of the new nodes and the error
messages."""
from __future__ import annotations

from ..layout import explicit_plane      # (the layout's function; members.explicit_plane as before)
from ..imprint import MIN_LOOP_CORNER
from .build import build_members, member_statistics
from .info import MemberInfo, member_infos
from .meshing import DEFAULT_MIN_ANGLE, NARROW_STRIP, STRIP_MIN_ANGLE, coons_patch, triangulate_planar

__all__ = ["MemberInfo", "member_infos", "build_members", "member_statistics", "triangulate_planar",
           "coons_patch", "explicit_plane", "DEFAULT_MIN_ANGLE", "MIN_LOOP_CORNER", "NARROW_STRIP",
           "STRIP_MIN_ANGLE"]
