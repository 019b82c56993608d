"""Imprint: make each member's curve on the skin a chain of skin mesh edges.

Stage order: load -> layout -> project -> **imprint** -> members -> split -> merge -> smooth -> quad -> export.

For every planar member (rib, spar, and each segment of an explicit member) the exact
curve ``plane ∩ input surface`` between the member's bounds is traced on the INPUT
triangulation (:mod:`~shellmesh_mdao.core.section`): a plane meets each input triangle in an exact segment,
so the curve is exact. The working skin (the remeshed triangulation, whose vertices lie
on the input surface) is then cut by the same plane inside the same bounds:

1. the crossing points where two members meet on the skin (a rib's side line meets a
   spar's) are inserted first, as single vertices both chains will share;
2. skin vertices within ``snap`` times the local edge length of the plane are snapped
   onto the curve (no sliver triangles), the remaining crossed edges are split at the
   plane and the crossed triangles re-triangulated (best diagonal); a cut that misses one
   of its crossing vertices (a larger snap can reach a vertex across a thin section beside
   a crossing) is redone at ``SNAP_FALLBACK``;
3. every new or snapped chain vertex is moved to its closest point on the exact input
   curve, so it lies on the input surface AND on the member plane;
4. the chain edges become ``feature_edges`` tagged with the member's component id, their
   vertices ``fixed_vertices``; later stages never split, merge or move them off the chain.

All per-face work is vectorised; Python loops run over members and crossing points only.

Modules (each imports only the public names of the others; nothing here imports a later stage; the exact plane
sections of the input triangulation, :class:`Plane` and :class:`SectionArc`, are the shared
:mod:`shellmesh_mdao.core.section`):

* :mod:`.specs`     the curves to imprint from the layout (:class:`ChainSpec`, :func:`chain_specs`);
* :mod:`.cut`       cutting the skin along the member planes (:func:`imprint_chains`, :class:`ChainResult`);
* :mod:`.crossings` where chains must share vertices (member crossings, sharp input edges);
* :mod:`.checks`    layouts the cut cannot represent, refused from the exact curves before cutting;
* :mod:`.refine`    chain refinement toward the exact curve and coarsening toward the skin's spacing;
* :mod:`.improve`   flips and smoothing of the imprinted skin (:func:`improve_skin`);
* :mod:`.repair`    local repair of the few triangles left below the angle bound (:class:`SkinPatch`);
* :mod:`.bridges`   skin edges between two vertices of one member's chains (:func:`split_member_bridges`);
* :mod:`.families`  the bay families of the skin (:func:`skin_families`);
* :mod:`.stage`     the stage's cut and chain finishing in order (:func:`imprint_mesh`);
* :mod:`.common`    small helpers the modules share (triangle angles, index ranges, edge keys, the standing
                    rule of the moves of skin vertices).
"""
from __future__ import annotations

from ..core.polyline import closest_on_polyline
from .bridges import split_member_bridges
from .checks import MIN_LOOP_CORNER, check_crossing_collisions, fmt_point, check_loop_corners, loop_corner, sharp_loop_message
from .crossings import kept_sharp_segments
from .cut import SNAP_FALLBACK, ChainResult, chain_report, cut_chain, imprint_chains, insert_point
from .families import skin_families
from .improve import improve_skin
from .refine import chain_depths, coarsen_chains, refine_chains
from ..core.section import Plane, PlaneSection, SectionArc, plane_section, section_arc
from .specs import ChainSpec, chain_specs
from .stage import imprint_mesh

__all__ = ["ChainSpec", "ChainResult", "SNAP_FALLBACK", "chain_specs", "imprint_chains", "insert_point", "cut_chain",
           "closest_on_polyline", "kept_sharp_segments", "chain_depths", "refine_chains", "coarsen_chains",
           "improve_skin", "split_member_bridges", "skin_families", "chain_report", "imprint_mesh",
           "Plane", "PlaneSection", "SectionArc", "plane_section", "section_arc",
           "MIN_LOOP_CORNER", "fmt_point", "loop_corner", "sharp_loop_message", "check_loop_corners",
           "check_crossing_collisions"]
