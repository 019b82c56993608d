"""The quad stage's finishing policy: after the subdivision, the final smoothing (and where the
warp p99 acceptance is missed a second pass with the quad planarity term), skin nodes left off
the surface settled, poor elements repaired, warped quads flattened, and the report's figures
(:func:`quad_mesh`)."""
from __future__ import annotations

import dataclasses
import logging

import numpy as np

from ..core.supports import SURFACE, Supports
from ..core.topology import face_rings
from ..mesh import ShellMesh, norm_rows, vertex_faces
from ..options import QuadOptions, SmoothOptions
from ..quality import scaled_jacobian, warp
from ..smooth import local_edge_size, mesh_figures, smooth, smooth_report, untangle
from .planar import planarize
from .subdivide import settle_off_surface, subdivide_to_quads

__all__ = ["POOR_JACOBIAN", "OFF_SURFACE_TOL", "FINAL_MIN_JACOBIAN", "quad_mesh", "finish_quads", "finish_region"]

log = logging.getLogger("shellmesh_mdao")

#: Elements at or below this scaled Jacobian are reported (count, ids) and logged as a warning.
POOR_JACOBIAN = 0.2

#: Skin nodes farther than this fraction of the model's bounding-box diagonal from the input
#: surface are reported (report key ``off_surface``) and logged as a warning.
OFF_SURFACE_TOL = 1e-6

#: No step of the final smoothing passes may bring an element to or below this scaled Jacobian
#: (nor lower one already below it): :func:`~shellmesh_mdao.smooth.smooth`'s ``min_jacobian``.
FINAL_MIN_JACOBIAN = 0.3


def _warp_p99(mesh: ShellMesh, w: np.ndarray | None = None) -> float:
    """99th percentile of the quads' warp (degrees; 0 without quads), the acceptance's measure;
    ``w``: the warp of every face, if already measured."""
    if not mesh.n_quads:
        return 0.0
    return float(np.percentile(warp(mesh.points, mesh.faces)[~mesh.is_tri] if w is None else w[~mesh.is_tri], 99))


def quad_mesh(mesh: ShellMesh, supports: Supports, size: float, options: QuadOptions = QuadOptions(),
              smooth_options: SmoothOptions = SmoothOptions()) -> tuple[ShellMesh, Supports, dict]:
    """The pipeline's quad stage: one subdivision to all quads (quad -> 4, triangle -> 3) over skin
    and members, new nodes projected onto their supports, then a final smoothing pass; elements
    still at or below
    :data:`POOR_JACOBIAN` are repaired locally (:func:`~shellmesh_mdao.smooth.untangle` on the two
    rings around them; report key ``poor_repair``), and what remains is reported and logged. Last,
    the free skin nodes around the quads still warped above ``warp_goal`` move along their normals,
    off the input by at most ``planar_offset`` times the size (:func:`~shellmesh_mdao.quad.planarize`;
    report key ``planarize``). Where the warp p99 is above ``warp_goal`` after the final smoothing
    and that last move alone does not bring it to the goal, a second smoothing pass with the quad
    planarity term runs, around the quads that move left above the goal (``final_warp_weight``;
    report key ``final_smooth.warp_term``), from the move's mesh with the nodes it may move put back
    where they were before the move; only those nodes are moved off the facets again after it
    (:func:`finish_region`), and the result is kept only if its warp p99 is below the move alone's
    (``warp_term.kept``: ``"pass"`` or ``"planarize_alone"``).

    ``size``: the target quad size; ``options``: the stage's
    :class:`~shellmesh_mdao.options.QuadOptions` (the names above are its options), and the
    smooth stage's ``smooth_energy`` and ``warp_from`` from ``smooth_options``
    (:class:`~shellmesh_mdao.options.SmoothOptions`); no step of either pass brings an element to
    or below :data:`FINAL_MIN_JACOBIAN`. Returns ``(mesh, supports, report)``, ``report`` the
    pipeline report's entries ``final_smooth`` (with ``final_iterations``), ``poor_repair``
    (where elements were repaired), ``off_surface``, ``planarize`` and ``poor_elements``; the
    warnings are logged (logger ``shellmesh_mdao``)."""
    o, so = options, smooth_options
    q, sup = subdivide_to_quads(mesh, supports, guard_jacobian=o.guard_jacobian)
    warp_term = None
    done = None
    if o.final_iterations:
        # both passes aim each edge at the local size of the subdivided mesh at its ends (at most
        # size): the grading of the remesh and the smooth stage stays
        hs = local_edge_size(q, size)
        # the first pass's figures after it are taken only if no second pass follows
        q, res = smooth(q, sup, iterations=o.final_iterations, energy=so.smooth_energy, target_edge=size,
                        edge_size=hs, ortho_weight=o.final_ortho_weight, refresh=o.final_refresh, warp_weight=0.0,
                        min_jacobian=FINAL_MIN_JACOBIAN, figures="before")
        # the planarity term trades scaled Jacobian for flatness: a second pass with it, only
        # where the warp p99 acceptance is missed and the planarize move alone cannot meet it
        wq = warp(q.points, q.faces)
        p99 = _warp_p99(q, wq)
        warp_term = {"warp_p99_before": p99, "warp_goal": o.warp_goal, "applied": False}
        second_pass = o.final_warp_weight > 0 and (o.warp_goal <= 0 or p99 > o.warp_goal)
        trial = None
        if second_pass and o.planar_offset > 0 and o.warp_goal > 0:
            # first the cheap way: the planarize move (and the settle and repair before it) on
            # this pass's mesh; kept if it meets the goal, else the second pass runs on this
            # pass's mesh, around the quads that move left above the goal
            trial = finish_quads(q, sup, size, options=o)
            alone = trial["planar"]["warp_p99_after"]
            warp_term["planarize_alone_p99"] = alone
            if alone <= o.warp_goal:
                done, second_pass = trial, False
        if second_pass:
            # only around the quads still warped (two rings): the rest of the mesh keeps the first
            # pass. With the planarize trial: the quads it left above the goal (it flattens the
            # others without the pass); without it, every quad in the planarity term
            vptr, vface = vertex_faces(q.faces, q.n_points)
            if trial is not None:
                tm = trial["mesh"]
                seeds = warp(tm.points, tm.faces) > o.warp_goal
            else:
                seeds = wq > so.warp_from
            warp_term["seed_quads"] = int(seeds.sum())
            warped = np.unique(q.faces[seeds])
            region = face_rings(q.faces, vptr, vface, warped[warped >= 0], 2)
            movable = np.unique(q.faces[region])
            movable = movable[movable >= 0]
            first = (q, res)
            if trial is not None:
                # the pass starts from the trial's mesh (settled, repaired, moved off the facets),
                # the region's nodes back where they were before the move: outside the region the
                # trial's result stands, and only the region is settled and moved again after it
                start = tm.points.copy()
                start[movable] = trial["before_planar"].points[movable]
                q = q.with_points(start)
            # every quad above warp_from in the term (warp_spread 180: none left out)
            q, res2 = smooth(q, sup, iterations=o.final_warp_iterations, energy=so.smooth_energy,
                             target_edge=size, edge_size=hs, ortho_weight=o.final_ortho_weight,
                             warp_weight=o.final_warp_weight, warp_from=so.warp_from, warp_spread=180.0,
                             min_jacobian=FINAL_MIN_JACOBIAN, vertices=movable, figures="after")
            res = dataclasses.replace(
                res2, quality_before=res.quality_before, moves=res.moves + res2.moves,
                max_move=max(res.max_move, res2.max_move),
                **{f: getattr(res, f) + getattr(res2, f) for f in (
                    "iterations", "seconds", "factorisations", "n_step_halvings", "n_rejected", "n_fold_hits",
                    "n_jump_hits")})
            warp_term.update(applied=True, warp_p99_after=_warp_p99(q), vertices=int(len(movable)))
            if trial is not None:
                # the pass and the move after it must beat the move alone, else the move alone
                # on the first pass's mesh is kept (its scaled Jacobians are the better ones)
                done = finish_region(q, sup, size, movable, trial, options=o)
                if done["planar"]["warp_p99_after"] >= trial["planar"]["warp_p99_after"]:
                    done, (q, res) = trial, first
                    res = dataclasses.replace(res, quality_after=mesh_figures(q, sup, size))
                    warp_term["kept"] = "planarize_alone"
                else:
                    warp_term["kept"] = "pass"
        else:
            res = dataclasses.replace(res, quality_after=mesh_figures(q, sup, size))
    if done is None:
        done = finish_quads(q, sup, size, options=o)
    q, sj, poor = done["mesh"], done["sj"], done["poor"]
    off_surface, warning = _off_surface(done, sup, size)
    if warning:
        log.warning(warning)
    report: dict = {}
    if o.final_iterations:
        report["final_smooth"] = smooth_report(res)
        report["final_smooth"]["warp_term"] = warp_term
    if done["repair"] is not None:
        report["poor_repair"] = done["repair"]
    report["off_surface"] = off_surface
    report["planarize"] = done["planar"]
    report["poor_elements"] = {"threshold": POOR_JACOBIAN, "count": int(len(poor)),
                               "folded": int((sj <= 0).sum()), "elements": poor[:100].tolist(),
                               "min_scaled_jacobian": float(sj.min()) if len(sj) else None}
    if len(poor):
        where = sorted({q.component_names[c] for c in q.component[poor]})
        log.warning("%d element(s) with scaled Jacobian <= %.1f (min %.3f) in %s: they come from sliver triangles "
                    "of the imprint that no stage could remove; see the report's 'poor_elements' (0-based ids)",
                    len(poor), POOR_JACOBIAN, float(sj.min()), ", ".join(where[:5]))
    return q, sup, report


def _repair_poor(q: ShellMesh, sup, sj):
    """Elements at or below :data:`POOR_JACOBIAN` (scaled Jacobians ``sj`` of ``q``) repaired by
    :func:`~shellmesh_mdao.smooth.untangle` on the two rings around them, kept if no worse.
    Returns ``(q, sj, poor, repair)`` (``repair`` the report's figures, None without poor elements)."""
    poor = np.flatnonzero(sj <= POOR_JACOBIAN)
    if not len(poor):
        return q, sj, poor, None
    # last resort: move the vertices within two rings of the poor elements along their supports
    # (smooth.untangle: no element at or below the goal gets worse, none above falls to it)
    vptr, vface = vertex_faces(q.faces, q.n_points)
    region = face_rings(q.faces, vptr, vface, np.unique(q.faces[poor][q.faces[poor] >= 0]), 2)
    q2, info = untangle(q, sup, goal=POOR_JACOBIAN + 0.1, faces=region)
    sj2 = scaled_jacobian(q2.points, q2.faces)
    repair = {"elements_before": int(len(poor)), "elements_after": int((sj2 <= POOR_JACOBIAN).sum()),
              "min_before": float(sj.min()), "min_after": float(sj2.min()), "moves": int(info["moves"])}
    n2 = int((sj2 <= POOR_JACOBIAN).sum())
    if n2 <= len(poor) and (n2 < len(poor) or sj2.min() > sj.min()):
        q, sj = q2, sj2
        poor = np.flatnonzero(sj <= POOR_JACOBIAN)
    return q, sj, poor, repair


def _planarize(q: ShellMesh, sup, sj, poor, size: float, options: QuadOptions, vertices=None):
    """The quad stage's :func:`~shellmesh_mdao.quad.planarize` move on ``q`` (scaled Jacobians
    ``sj``, poor elements ``poor``), by at most ``options.planar_offset`` times ``size``, on the
    quads warped above ``options.warp_goal``, moving only ``vertices`` if given. Returns ``(q,
    planar, sj, poor)``, ``planar`` the report's figures (with the offset over the size and its
    bound)."""
    q, planar = planarize(q, sup, max_offset=options.planar_offset * size, warp_above=options.warp_goal,
                          guard_jacobian=POOR_JACOBIAN + 0.1, vertices=vertices)
    planar.update(max_offset_over_size=planar["max_offset"] / size, bound_over_size=options.planar_offset)
    if planar["applied"]:
        sj = scaled_jacobian(q.points, q.faces)
        poor = np.flatnonzero(sj <= POOR_JACOBIAN)
    return q, planar, sj, poor


def finish_region(q: ShellMesh, sup, size: float, movable, trial: dict,
                  options: QuadOptions = QuadOptions()) -> dict:
    """:func:`finish_quads` after the second pass, which started from the planarize trial's
    mesh and moved only the nodes ``movable``: the elements at or below :data:`POOR_JACOBIAN`
    repaired, then :func:`~shellmesh_mdao.quad.planarize` moving only ``movable`` (outside the
    region the trial's move stands; the smoothing put the region's nodes on their supports, and
    the trial settled the rest). ``before_planar``: the nodes that kept the trial's positions at
    the trial's positions before its move. The same keys as :func:`finish_quads`; ``planar``'s
    ``moved`` and ``max_offset`` count the trial's moves that stand as well, its
    ``quads_above_before`` and ``warp_p99_before`` are measured on ``before_planar``, and ``repair`` is
    the trial's where the region needed none. ``options``: the quad stage's
    :class:`~shellmesh_mdao.options.QuadOptions` (``planar_offset``, ``warp_goal``)."""
    q, sj, poor, repair = _repair_poor(q, sup, scaled_jacobian(q.points, q.faces))
    held = np.ones(q.n_points, bool)
    held[movable] = False
    held &= (q.points == trial["mesh"].points).all(1)
    bp = q.points.copy()
    bp[held] = trial["before_planar"].points[held]
    before_planar = q.with_points(bp)
    q, planar, sj, poor = _planarize(q, sup, sj, poor, size, options, vertices=movable)
    # the report counts every node off the facets in the result: the region's moves and the
    # trial's that stand outside it ("nodes": the region's candidates and those)
    step = norm_rows(q.points - bp, axis=1)
    kept_out = int((step[held] > 0).sum())
    # and its "before" figures are those of the mesh before every move it counts (the trial's moves
    # that stand flattened quads outside the region: measured after them, a region whose quads no
    # move can flatten would report the trial's moves as flattening nothing)
    wb = warp(bp, q.faces)
    planar.update(applied=bool(planar["applied"] or kept_out), nodes=int(planar["nodes"]) + kept_out,
                  moved=int((step > 0).sum()), max_offset=float(step.max(initial=0.0)),
                  quads_above_before=int((~q.is_tri & (wb > options.warp_goal)).sum()),
                  warp_p99_before=_warp_p99(q, wb))
    planar.update(max_offset_over_size=planar["max_offset"] / size)
    # the trial's repair stands too (the pass started from its mesh)
    return {"mesh": q, "sj": sj, "poor": poor, "repair": trial["repair"] if repair is None else repair,
            "settled": trial["settled"], "before_planar": before_planar, "planar": planar}


def finish_quads(q: ShellMesh, sup, size: float, options: QuadOptions = QuadOptions()) -> dict:
    """The quad stage after its smoothing, on ``q``: skin nodes left off the surface settled,
    elements at or below :data:`POOR_JACOBIAN` repaired, then :func:`~shellmesh_mdao.quad.planarize`.
    Returns ``{"mesh", "sj", "poor", "repair", "settled", "before_planar", "planar"}``
    (``before_planar``: the mesh before planarize, whose nodes off the surface
    :func:`_off_surface` reports for the result the caller keeps); ``q`` and ``sup`` are not
    changed. ``options``: the quad stage's :class:`~shellmesh_mdao.options.QuadOptions`
    (``guard_jacobian``, ``planar_offset``, ``warp_goal``)."""
    # skin nodes the subdivision's fold guard left off the surface: once their neighbours have
    # been smoothed most of them can go onto it (the same settle, no element below the guard
    # made worse)
    q, settled = settle_off_surface(q, sup, tol=OFF_SURFACE_TOL, guard_jacobian=options.guard_jacobian)
    q, sj, poor, repair = _repair_poor(q, sup, scaled_jacobian(q.points, q.faces))
    before_planar = q
    # quads still warped above the goal straddle kinks of the faceted input that no move along it
    # can flatten: their free skin nodes leave the facets by at most planar_offset * size
    planar = None
    if options.planar_offset > 0:
        q, planar, sj, poor = _planarize(q, sup, sj, poor, size, options)
    return {"mesh": q, "sj": sj, "poor": poor, "repair": repair, "settled": settled, "before_planar": before_planar,
            "planar": planar}


def _off_surface(done: dict, sup, size: float) -> tuple[dict, str | None]:
    """The report's ``off_surface`` and its warning (None if no node is off) for the result of
    :func:`finish_quads` the quad stage keeps (measured only for that one: a planarize trial
    that is not kept needs neither)."""
    # skin nodes still off the input surface: the subdivision kept a new node at its linear position
    # where projecting it would fold a child, and neither its repair nor the one after the final
    # smoothing (settle_off_surface) could fix that (a parent face across a crease or a ridge much
    # tighter than the element size); measured before planarize, which moves nodes off on purpose
    q, settled = done["before_planar"], done["settled"]
    skin_nodes = np.flatnonzero(sup.kind == SURFACE)
    d = sup.distance(q.points, skin_nodes) if len(skin_nodes) else np.zeros(0)
    off = d > OFF_SURFACE_TOL * q.diagonal
    off_surface = {"count": int(off.sum()), "max_distance": float(d.max(initial=0.0)),
                   "before_settle": settled["before"], "settled": settled["before"] - settled["after"],
                   "max_distance_over_size": float(d.max(initial=0.0) / size),
                   "nodes": skin_nodes[off][:100].tolist()}
    warning = None
    if off.any():
        k = skin_nodes[off][np.argmax(d[off])]
        warning = (f"{int(off.sum())} skin node(s) off the input surface, up to {float(d[off].max()):.3g} "
                   f"({float(d[off].max() / size):.2f} element sizes) near "
                   f"{np.array2string(q.points[k], precision=4)}: a face spanned a crease or ridge much tighter "
                   "than the element size there; use a smaller --size or see the report's 'off_surface' (0-based ids)")
    return off_surface, warning
