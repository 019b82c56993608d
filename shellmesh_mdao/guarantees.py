"""The guarantees of a final mesh, checked on a pipeline result.

Every run of :func:`~shellmesh_mdao.pipeline.run_pipeline` to its last stage must give a mesh
with the properties below. :func:`check_guarantees` checks them in this order on the
:class:`~shellmesh_mdao.pipeline.PipelineResult` and raises
:class:`~shellmesh_mdao.errors.GuaranteeError` (a ``MeshValidationError``) at the first one missed; its message names
the guarantee, the figure measured and the place (element, node or edge, with coordinates).
When all hold it returns the measured figures. The tests, the stress sweep
(:mod:`shellmesh_mdao.benchmarks.stress`) and the benchmark use it.

======================================  =====================================================
guarantee                               what holds
======================================  =====================================================
``final mesh``                          the result is the quad stage's (no ``until``)
``all quads``                           at least one element, and no triangle
``scaled Jacobian``                     every element's scaled Jacobian is above ``min_sj``
                                        (default 0.2; two member curves crossing at an angle
                                        ``a`` leave a corner of ``a``, so a layout with such
                                        crossings needs a lower bound)
``poor elements reported``              the report's ``poor_elements`` counts every element
                                        at or below :data:`~shellmesh_mdao.quad.finish.POOR_JACOBIAN`
                                        (0.2) and lists the first 100
``no duplicate points``                 no two nodes within 1e-9 of the diagonal
``no hanging nodes``                    no node lies inside another face's boundary edge
``no degenerate faces``                 no face with a repeated node or zero area
``no unreferenced points``              every node belongs to a face
``closed skin``                         (``input_closed``) the skin faces have no boundary
                                        edge: the skin is closed where the input was
``junctions are mesh edges``            every member feature edge (where a member meets the
                                        skin or another member) is an edge of the mesh
``junction valence``                    each of those edges has 2, 3 or 4 faces (3 where a
                                        member meets the skin, 4 where members cross); 1 is
                                        allowed too with ``free_edges``
``no free member edge``                 (unless ``free_edges``) the mesh has no boundary edge:
                                        every member boundary is a junction
``nodes on member planes``              every node of a planar member lies in its plane
                                        (within 1e-9 of the diagonal)
``planarize bound``                     planarize moved no skin node by more than
                                        ``planar_offset * size``
``off-surface nodes reported``          the report's ``off_surface`` counts the skin nodes off
                                        the input (farther than 1e-6 of the diagonal) and their
                                        largest distance; after planarize moved nodes on
                                        purpose, the count lies between the nodes left off
                                        before it and those plus the ones it moved, no node is
                                        farther than the larger of the two bounds, and fewer
                                        quads are warped than before it
``skin nodes on the surface``           at least 99.5 % of the skin nodes (less the share
                                        planarize moved) lie on the input surface, and none is
                                        farther than 5e-3 of the diagonal
``few fixed nodes``                     fewer than ``max_fixed`` of the nodes (default 5 %)
                                        have the FIXED support (they do not move in smoothing)
======================================  =====================================================

Skin nodes lie on the input up to two documented exceptions, which the last checks allow for:
the subdivision keeps a new node at its linear position where projecting it would fold a child
and its repair stalls (a crease much tighter than the element size; reported in
``off_surface``), and planarize moves free skin nodes around quads warped above 10 degrees, by
at most ``planar_offset * size``, on purpose (reported in ``planarize``).
"""
from __future__ import annotations

import numpy as np

from .errors import GuaranteeError
from .families import is_member
from .quad.finish import POOR_JACOBIAN
from .quality import element_quality
from .core.supports import FIXED, PLANE, SURFACE

__all__ = ["GUARANTEES", "MAX_FIXED", "MAX_FIXED_NON_PLANAR", "check_guarantees", "gate_flags", "member_faces"]

#: the guarantees :func:`check_guarantees` checks, in its order (the names its errors use)
GUARANTEES = ("final mesh", "all quads", "scaled Jacobian", "poor elements reported", "no duplicate points",
              "no hanging nodes", "no degenerate faces", "no unreferenced points", "closed skin",
              "junctions are mesh edges", "junction valence", "no free member edge", "nodes on member planes",
              "planarize bound", "off-surface nodes reported", "skin nodes on the surface", "few fixed nodes")

#: relative tolerances (of the bounding-box diagonal): a node on a member plane, on the skin
PLANE_TOL, SURFACE_TOL = 1e-9, 1e-6
#: largest distance (of the diagonal) of a skin node from the input surface
MAX_SKIN_DISTANCE = 5e-3
#: smallest share of the skin nodes on the input surface (less the share planarize moved)
ON_SURFACE_SHARE = 0.995


def member_faces(mesh, infos) -> np.ndarray:
    """(m,) bool per face of ``mesh``: True for member faces (components named after a member
    of ``infos``, the pipeline's member list, or one of its ``/seg_<j>`` pieces)."""
    members = {m.name for m in infos}
    names = np.array([is_member(c, members) for c in mesh.component_names], bool)
    return names[mesh.component]


def _xyz(p) -> str:
    return "[" + ", ".join(f"{float(v):.6g}" for v in p) + "]"


def _element(mesh, i) -> str:
    i = int(i)
    corners = mesh.faces[i][mesh.faces[i] >= 0]
    return (f"element {i} ({mesh.component_names[mesh.component[i]]!r}, centre "
            f"{_xyz(mesh.points[corners].mean(axis=0))})")


def _node(mesh, v) -> str:
    return f"node {int(v)} at {_xyz(mesh.points[int(v)])}"


def _edge(mesh, a, b) -> str:
    return f"edge {int(a)}-{int(b)} (midpoint {_xyz(0.5 * (mesh.points[int(a)] + mesh.points[int(b)]))})"


def _missed(name: str, figure: str, place: str = "") -> None:
    raise GuaranteeError(f"mesh guarantee {name!r} missed: {figure}" + (f", at {place}" if place else ""))


#: the largest share of FIXED nodes; with non-planar explicit members, whose nodes do not move
MAX_FIXED, MAX_FIXED_NON_PLANAR = 0.05, 0.15


def gate_flags(result) -> dict:
    """The flags of :func:`check_guarantees` that follow from the run itself: ``input_closed``
    (the load report says the input skin was closed), ``free_edges`` (an open input, a half
    model, or explicit members, whose straight end lines may be attached to nothing) and
    ``max_fixed`` (:data:`MAX_FIXED_NON_PLANAR` with non-planar explicit members, else
    :data:`MAX_FIXED`)."""
    closed = bool(result.report.get("surface", {}).get("closed", True))
    lay = getattr(result, "layout", None)
    specs = lay.members() if hasattr(lay, "members") else []
    explicit = any(m.kind == "explicit" for m in specs)
    non_planar = any(m.kind == "explicit" and not m.is_planar for m in specs)
    return {"input_closed": closed, "free_edges": (not closed) or explicit,
            "max_fixed": MAX_FIXED_NON_PLANAR if non_planar else MAX_FIXED}


def check_guarantees(result, input_closed: bool | None = None, min_sj: float = 0.2,
                     free_edges: bool | None = None, max_fixed: float | None = None) -> dict:
    """Check the guarantees of the final mesh of ``result`` (a
    :class:`~shellmesh_mdao.pipeline.PipelineResult` of a run to the quad stage), in the order
    of the module's table (:data:`GUARANTEES`).

    ``input_closed``, ``free_edges``, ``max_fixed``: None (default) takes them from the run
    (:func:`gate_flags`), as the pipeline's own gate does.
    ``input_closed``: the input skin was closed, so the output skin must be. ``min_sj``: every
    element's scaled Jacobian is above it (0.2 for layouts whose member curves cross at
    reasonable angles; two curves crossing at an angle ``a`` leave a corner of ``a``).
    ``free_edges``: members may have free edges (an explicit member's straight end line inside
    the wing, attached to nothing). ``max_fixed``: the largest share of FIXED nodes.

    Raises :class:`~shellmesh_mdao.errors.GuaranteeError` naming the first guarantee
    missed, the figure and the place. Returns the measured figures: ``n_elements``,
    ``n_points``, ``min_scaled_jacobian``, ``n_poor`` (elements at or below 0.2),
    ``junction_valence`` ({faces per junction edge: how many edges}), ``skin_boundary_edges``,
    ``boundary_edges``, ``max_plane_distance``, ``max_skin_distance``, ``skin_nodes_off``
    (farther than 1e-6 of the diagonal), ``skin_on_surface_share``, ``planarize_moved``,
    ``n_fixed``, ``fixed_share`` and ``quality`` (the arrays of
    :func:`~shellmesh_mdao.quality.element_quality`)."""
    flags = gate_flags(result)
    input_closed = flags["input_closed"] if input_closed is None else input_closed
    free_edges = flags["free_edges"] if free_edges is None else free_edges
    max_fixed = flags["max_fixed"] if max_fixed is None else max_fixed
    q = result.mesh
    if result.stage != "quad":
        _missed("final mesh", f"the result stops at stage {result.stage!r}; the guarantees are those of the "
                              "quad stage's mesh (run_pipeline without until)")
    if q.n_faces == 0:
        _missed("all quads", "the mesh has no element")
    if q.n_tris:
        _missed("all quads", f"{q.n_tris} triangles among {q.n_faces} elements", _element(q, np.argmax(q.is_tri)))
    eq = element_quality(q.points, q.faces)
    sj = eq["scaled_jacobian"]
    if not sj.min() > min_sj:
        worst = int(np.argmax(np.isnan(sj))) if np.isnan(sj).any() else int(np.argmin(sj))
        _missed("scaled Jacobian", f"{int((sj <= min_sj).sum())} elements with scaled Jacobian <= {min_sj:g}, "
                                   f"the lowest {sj[worst]:.3f}", _element(q, worst))
    poor = np.flatnonzero(sj <= POOR_JACOBIAN)
    rep = result.report["poor_elements"]
    if rep["count"] != len(poor) or rep["elements"] != poor[:100].tolist():
        _missed("poor elements reported", f"the report counts {rep['count']} elements at or below "
                                          f"{POOR_JACOBIAN:g}, the mesh has {len(poor)}: {poor[:5].tolist()}, ...; "
                                          f"the report lists {rep['elements'][:5]}, ...")
    chk = q.check()
    if len(chk.duplicate_points):
        a, b = chk.duplicate_points[0]
        _missed("no duplicate points", f"{len(chk.duplicate_points)} pairs of nodes within 1e-9 of the diagonal",
                f"nodes {int(a)} and {int(b)} at {_xyz(q.points[a])}")
    if len(chk.hanging_nodes):
        a, b, c = chk.hanging_nodes[0]
        _missed("no hanging nodes", f"{len(chk.hanging_nodes)} hanging nodes",
                f"{_node(q, c)}, inside {_edge(q, a, b)}")
    if len(chk.degenerate_faces):
        _missed("no degenerate faces", f"{len(chk.degenerate_faces)} faces with a repeated node or zero area",
                _element(q, chk.degenerate_faces[0]))
    if len(chk.unreferenced_points):
        _missed("no unreferenced points", f"{len(chk.unreferenced_points)} nodes in no face",
                _node(q, chk.unreferenced_points[0]))
    skin = q.submesh(~member_faces(q, result.state.infos))
    skin_open = skin.boundary_edges()
    if input_closed and len(skin_open):
        _missed("closed skin", f"{len(skin_open)} boundary edges of the skin faces (the input was closed)",
                _edge(q, *skin_open[0]))
    # junctions: every member boundary edge is shared with the skin or another member
    topo = q.topology()
    fe = q.feature_edges[q.feature_edge_ids >= 0]
    eid = topo.edge_ids(fe)
    if (eid < 0).any():
        _missed("junctions are mesh edges", f"{int((eid < 0).sum())} member feature edges are not edges of the "
                                            "mesh", _edge(q, *fe[np.argmax(eid < 0)]))
    val = topo.valence[eid]
    allowed = (1, 2, 3, 4) if free_edges else (2, 3, 4)
    bad = ~np.isin(val, allowed)
    if bad.any():
        k = int(np.argmax(bad))
        _missed("junction valence", f"{int(bad.sum())} junction edges with a number of faces outside "
                                    f"{list(allowed)}; this one has {int(val[k])}", _edge(q, *fe[k]))
    open_edges = q.boundary_edges()
    if not free_edges and len(open_edges):
        _missed("no free member edge", f"{len(open_edges)} boundary edges (each member boundary must be a "
                                       "junction)", _edge(q, *open_edges[0]))
    # every node on its support
    sup = result.state.supports
    diag = q.diagonal
    tol = SURFACE_TOL * diag
    d = sup.distance(q.points)
    on_plane = np.flatnonzero(sup.kind == PLANE)
    dp = d[on_plane]
    if not dp.max(initial=0) <= PLANE_TOL * diag:
        k = int(np.argmax(dp))
        _missed("nodes on member planes", f"{int((dp > PLANE_TOL * diag).sum())} member nodes off their plane, "
                                          f"up to {dp[k]:.3g} ({dp[k] / diag:.2g} of the diagonal)",
                _node(q, on_plane[k]))
    # skin nodes lie on the input; the subdivision's fold guard keeps new nodes at their linear
    # position where projecting them folds a child, and its settle step projects them and repairs
    # the elements around; where that repair stalls (a crease much tighter than the element
    # size) a few may stay at their linear position; planarize then moves free skin nodes around
    # quads warped above 10 degrees off the input on purpose, by at most planar_offset * size,
    # and reports how many
    on_skin = np.flatnonzero(sup.kind == SURFACE)
    ds = d[on_skin]
    off, planar = result.report["off_surface"], result.report["planarize"]
    bound = result.state.options.quad.planar_offset * result.state.size
    moved = planar["moved"] if planar else 0
    if planar is not None and not planar["max_offset"] <= bound * (1 + 1e-12):
        _missed("planarize bound", f"planarize moved a node by {planar['max_offset']:.3g}, above planar_offset "
                                   f"* size = {bound:.3g}")
    n_off = int((ds > tol).sum())
    far = _node(q, on_skin[np.argmax(ds)]) if len(ds) else ""
    if not moved:
        if off["count"] != n_off:
            _missed("off-surface nodes reported", f"the report counts {off['count']} skin nodes off the input, "
                                                  f"the mesh has {n_off}", far if n_off else "")
        if not np.isclose(off["max_distance"], ds.max(initial=0.0), rtol=1e-9, atol=1e-12):
            _missed("off-surface nodes reported", f"the report's largest distance from the input is "
                                                  f"{off['max_distance']:.6g}, the mesh's {ds.max(initial=0.0):.6g}",
                    far)
    else:
        # the nodes off by more than tol: those left off before planarize plus those it moved
        if not off["count"] <= n_off <= off["count"] + moved:
            _missed("off-surface nodes reported", f"{n_off} skin nodes off the input, not between the "
                                                  f"{off['count']} reported and those plus the {moved} planarize moved",
                    far)
        if not ds.max(initial=0.0) <= max(off["max_distance"], bound) + tol:
            _missed("off-surface nodes reported", f"a skin node {ds.max():.3g} off the input, above the reported "
                                                  f"{off['max_distance']:.3g} and planarize's bound {bound:.3g}", far)
        if not planar["quads_above_after"] < planar["quads_above_before"]:
            _missed("off-surface nodes reported", f"planarize moved {moved} nodes but left "
                                                  f"{planar['quads_above_after']} quads warped above its goal "
                                                  f"({planar['quads_above_before']} before)")
    share = float((ds <= tol).mean()) if len(ds) else float("nan")
    if not len(ds):
        _missed("skin nodes on the surface", "the mesh has no skin node")
    if not share >= ON_SURFACE_SHARE - moved / max(len(ds), 1):
        _missed("skin nodes on the surface", f"{100 * share:.2f} % of the skin nodes on the input surface, below "
                                             f"{100 * (ON_SURFACE_SHARE - moved / len(ds)):.2f} %", far)
    if not ds.max() <= MAX_SKIN_DISTANCE * diag:
        _missed("skin nodes on the surface", f"a skin node {ds.max():.3g} off the input ({ds.max() / diag:.2g} of "
                                             f"the diagonal, above {MAX_SKIN_DISTANCE:g})", far)
    n_fixed = int((sup.kind == FIXED).sum())
    if not n_fixed < max_fixed * q.n_points:
        _missed("few fixed nodes", f"{n_fixed} of {q.n_points} nodes fixed ({100 * n_fixed / q.n_points:.1f} %, "
                                   f"not below {100 * max_fixed:g} %)")
    vals, counts = np.unique(val, return_counts=True)
    return {"n_elements": int(q.n_faces), "n_points": int(q.n_points), "min_scaled_jacobian": float(sj.min()),
            "n_poor": int(len(poor)), "junction_valence": {int(v): int(c) for v, c in zip(vals, counts)},
            "skin_boundary_edges": int(len(skin_open)), "boundary_edges": int(len(open_edges)),
            "max_plane_distance": float(dp.max(initial=0.0)), "max_skin_distance": float(ds.max()),
            "skin_nodes_off": n_off, "skin_on_surface_share": share, "planarize_moved": int(moved),
            "n_fixed": n_fixed, "fixed_share": n_fixed / q.n_points, "quality": eq}
