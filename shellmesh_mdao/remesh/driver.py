"""The remesh driver: :func:`remesh_skin` (sweeps of split / collapse / flip / relax, the
finishing rounds, the deviation passes and splits) and :func:`remesh_statistics`."""
from __future__ import annotations

import time

import numpy as np

from ..errors import MeshValidationError, SizeError
from .kernels import edge_lengths, group_order
from ..mesh import ShellMesh, dot_norm_rows, dot_rows, dot_unit_rows, reduce_short
from ..core.locator import SurfaceLocator
from ..options import RemeshOptions
from .common import CORNER, REGULAR, SPLIT_RATIO, tri_angles
from .operations import (collapse_edges, collapse_round, degenerate_round, faces_facing_ok, flip_round, micro_round,
                         phase, split_round)
from .relax import relax_vertices
from .stars import contract_pinched_stars
from .surface import InputSurface
from .work import Context, WorkMesh

__all__ = ["remesh_skin", "remesh_statistics", "DEFAULT_MIN_EDGE_FRACTION"]

#: the curvature-adapted edge length never goes below this fraction of ``target_edge``.
DEFAULT_MIN_EDGE_FRACTION = 0.1

# einsum's dot, its norm and unit rows (mesh.dot_rows & co.: compiled for (k, 3) rows)
_dot, _norm, _unit = dot_rows, dot_norm_rows, dot_unit_rows


# ============================================================================ driver
def _work_from_surface(surf):
    nv = len(surf.P)
    ptr, order = group_order(surf.T.reshape(-1), nv)
    vtri = np.where(np.diff(ptr) > 0, order[np.minimum(ptr[:-1], len(order) - 1)] // 3, -1)
    vtri = np.where(surf.v_kind == REGULAR, vtri, -1)
    vin = np.where(surf.v_kind == CORNER, np.arange(nv), -1)
    W = WorkMesh(surf.P.copy(), surf.T.copy(), surf.tri_patch.copy(), surf.v_kind.copy(), surf.v_S.copy(),
              surf.v_chain.copy(), vin, vtri, surf.fe_in.copy(), surf.fe_in_chain.copy(), surf.h.copy())
    return W


def _iterate(W, ctx, iterations, timings, log):
    for it in range(iterations):
        t0 = time.perf_counter()
        ns = phase(split_round, W, ctx, 60)
        t1 = time.perf_counter()
        nc = phase(collapse_round, W, ctx, 200)
        t2 = time.perf_counter()
        nf = phase(flip_round, W, ctx, 10, "valence")
        t3 = time.perf_counter()
        relax_vertices(W, ctx)
        W.h = ctx.sizing(W)
        t4 = time.perf_counter()
        for k, dt in zip(("split", "collapse", "flip", "relax"), (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
            timings[k] = timings.get(k, 0.0) + dt
        if log:
            log(f"iteration {it}: {ns} splits, {nc} collapses, {nf} flips -> {len(W.F)} triangles")


def _open_low_valence_corners(W, ctx):
    """A corner (or line end) with only three neighbours but a full fan of angles around it
    (a trailing edge ending in a rounded tip) cannot lose the slivers around it by
    collapses: split the edge facing its widest angle so that it gets a fourth neighbour."""
    T = W.topo()
    F = W.F
    nptr, _ = T.vertex_neighbors()
    deg = np.diff(nptr)
    ang = np.radians(tri_angles(W.P, F))
    asum = np.zeros(W.n)
    for k in range(3):
        asum += np.bincount(F[:, k], weights=ang[:, k], minlength=W.n)
    low = (deg == 3) & (W.kind != REGULAR) & (asum > np.radians(200.0))
    if not low.any():
        return 0
    fi, ki = np.nonzero(low[F])
    # per low vertex: its face with the widest angle there
    o = np.lexsort((-ang[fi, ki], F[fi, ki]))
    first = np.ones(len(o), bool)
    first[1:] = F[fi, ki][o][1:] != F[fi, ki][o][:-1]
    fi, ki = fi[o][first], ki[o][first]
    e = T.lookup(F[fi, (ki + 1) % 3], F[fi, (ki + 2) % 3])
    isf, _ = W.feature_lookup(T)
    e = e[(e >= 0) & ~isf[np.maximum(e, 0)]]
    if not len(e):
        return 0
    return split_round(W, ctx, forced=e)


def _cleanup_round(W, ctx, bad_angle=20.0):
    """Collapse the shortest edge of every triangle whose smallest angle is below
    ``bad_angle`` when that strictly raises the smallest angle around it (looser length
    and normal limits than the sweeps: the aim is the worst triangles only)."""
    T = W.topo()
    F = W.F
    P = W.P
    A = tri_angles(P, F)
    bad = np.flatnonzero(reduce_short(A, "min") < bad_angle)
    if not len(bad):
        return 0
    # the shortest side is opposite the smallest angle
    k = np.argmin(A[bad], axis=1)
    e = T.lookup(F[bad, (k + 1) % 3], F[bad, (k + 2) % 3])
    e = np.unique(e[e >= 0])
    if not len(e):
        return 0
    L = edge_lengths(P, T.E[e])
    return collapse_edges(W, ctx, T, e, prio=-L, max_normal_turn=60.0, quality=True, max_len_ratio=2.0)


def _standing_faces(W, ctx):
    """Faces standing across the surface (see :func:`~.operations.faces_facing_ok`)."""
    return np.flatnonzero(~faces_facing_ok(W, ctx, W.F, W.face_normals()))


def _unstand_round(W, ctx):
    """Collapse an edge of every face standing across the surface (shortest first), with
    the topological, inversion and facing tests only."""
    bad = _standing_faces(W, ctx)
    if not len(bad):
        return 0
    T = W.topo()
    F = W.F
    e = np.unique(np.concatenate([T.lookup(F[bad, k], F[bad, (k + 1) % 3]) for k in range(3)]))
    e = e[e >= 0]
    L = edge_lengths(W.P, T.E[e])
    return collapse_edges(W, ctx, T, e, prio=-L, check_geometry=False)


def _contract_pinched(W, ctx, max_rounds=8):
    """:func:`~.stars.contract_pinched_stars` until it stalls (each round raises the smallest
    angle of every star it changes); the number of nodes removed."""
    total = 0
    for _ in range(max_rounds):
        k = contract_pinched_stars(W, ctx)
        total += k
        if not k:
            break
    return total


def _finish(W, ctx, rounds, timings, log):
    t0 = time.perf_counter()
    if _open_low_valence_corners(W, ctx):
        W.h = ctx.sizing(W)
    phase(micro_round, W, ctx, 20, 0.25)
    W.h = ctx.sizing(W)
    for _ in range(rounds):
        phase(flip_round, W, ctx, 10, "angle")
        phase(_cleanup_round, W, ctx, 5)
        relax_vertices(W, ctx)
        W.h = ctx.sizing(W)
    phase(flip_round, W, ctx, 10, "angle")
    phase(_cleanup_round, W, ctx, 5)
    phase(flip_round, W, ctx, 10, "angle")
    timings["finish"] = timings.get("finish", 0.0) + time.perf_counter() - t0


class _MidpointDistances:
    """Distance of edge midpoints to the input (``loc.closest``), remembered by the midpoint's
    exact coordinates: the remesh's last steps ask for every edge of a mesh of which only a
    few edges are new since the last time, and a midpoint's distance depends on its
    coordinates alone (a hint only shortens the search), so the answers are the same bits
    as asking for every edge again."""

    def __init__(self, loc):
        self.loc = loc
        self.keys = np.zeros(0, np.uint64)
        self.mid = np.zeros((0, 3))
        self.dist = np.zeros(0)

    @staticmethod
    def _keys(X):
        """One uint64 per row of (k, 3) float64 ``X``, equal for rows of equal bits (rows with
        equal keys are compared in full before a distance is reused)."""
        b = np.ascontiguousarray(X).view(np.uint64)
        return (b[:, 0] * np.uint64(0x9E3779B97F4A7C15)) ^ (b[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F)) ^ b[:, 2]

    def __call__(self, P, E, vtri):
        mid = 0.5 * (P[E[:, 0]] + P[E[:, 1]])
        keys = self._keys(mid)
        dist = np.empty(len(E))
        miss = np.ones(len(E), bool)
        if len(self.keys) and len(E):
            o = np.argsort(self.keys, kind="stable")
            pos = np.minimum(np.searchsorted(self.keys[o], keys), len(o) - 1)
            j = o[pos]
            hit = (self.keys[j] == keys) & (self.mid[j] == mid).all(1)
            dist[hit] = self.dist[j[hit]]
            miss = ~hit
        if miss.any():
            _, _, dist[miss] = self.loc.closest(mid[miss], hint=vtri[E[miss, 0]])
        self.keys, self.mid, self.dist = keys, mid, dist
        return dist


def _deviation(W, ctx, mids):
    """Distance from edge midpoints (and face centroids) to the input, with the input
    triangle each face centroid projects to (patch and normal compatible); the midpoints'
    distances from ``mids`` (a :class:`_MidpointDistances`)."""
    T = W.topo()
    E = T.E
    dm = mids(W.P, E, W.vtri)
    C = (W.P[W.F[:, 0]] + W.P[W.F[:, 1]] + W.P[W.F[:, 2]]) / 3
    fn = W.face_normals()
    cp, ctri, ok = ctx.project(C, fn, W.fpatch, hint=W.vtri[W.F[:, 0]])
    dc = _norm(cp - C)
    return dm, dc, ctri, ok


def remesh_skin(mesh: ShellMesh, target_edge: float, options: RemeshOptions = RemeshOptions(), *,
                locator: SurfaceLocator | None = None, feature_angle: float = 30.0, iterations: int = 8,
                min_edge: float | None = None, gradation: float = 0.5, corner_angle: float = 50.0,
                wedge_angle: float = 20.0, keep_component_borders: bool = True, deviation_passes: int = 2,
                deviation_splits: bool = True, finish_rounds: int = 4, max_flip_dihedral: float = 120.0,
                size_field=None, report: dict | None = None, log=None) -> ShellMesh:
    """Isotropic, curvature-adapted remesh of a triangulated skin to ``target_edge``.

    The input's resolution does not set the output's: the result has edges around
    ``target_edge`` on flat regions whatever the input tessellation (a 23.5k- and a 1.5M-
    triangle tessellation of the same aircraft give the same sizes), shorter ones only
    where the surface needs them (curvature, narrow regions between feature lines).

    Deviation guarantee: every vertex lies on the input surface (closest point, float64);
    every edge midpoint lies within ``max_deviation`` of the input unless the edge is
    shorter than ``2 * min_edge`` or splitting it would create a triangle with an angle
    below 20 degrees (``report['n_edges_over_deviation']`` counts those, and
    ``report['deviation_edge_midpoints']`` / ``['deviation_face_centroids']`` give the
    largest distances reached).

    Parameters
    ----------
    mesh : ShellMesh
        The input skin (triangles; quads are split). Must be edge-manifold; open
        boundaries are allowed and kept as feature lines.
    target_edge : float
        Edge length wanted on flat regions (about twice the final quad size ``H``).
    options : RemeshOptions
        The remesh stage's options (:class:`~shellmesh_mdao.options.RemeshOptions`):
        ``remesh_deviation``, the chordal deviation allowed as a fraction of ``target_edge``
        (``max_deviation = remesh_deviation * target_edge``: the chordal deviation allowed
        between the remesh and the input, an absolute length; edges shrink where the
        curvature needs it, down to ``min_edge``; feature lines closer to each other than
        ``2 * max_deviation`` (a wedge at a sharp trailing-edge tip, the two creases of a
        coarsely faceted leading edge, a sliver patch) are merged into one), and
        ``remesh_pass_fraction`` (see ``deviation_passes``); ``remesh`` is the stage's
        switch and is not read here.
    locator : SurfaceLocator, optional
        A locator already built on the triangles of ``mesh`` (saves rebuilding it).
    feature_angle : float
        Input edges whose two triangles' normals differ by more than this (degrees) are
        sharp feature lines: kept as chains of mesh edges.
    iterations : int
        Split/collapse/flip/relax sweeps (Botsch--Kobbelt) per pass.
    min_edge : float, optional
        Smallest curvature-adapted edge length, default
        ``DEFAULT_MIN_EDGE_FRACTION * target_edge``.
    gradation : float
        Largest rate of change of the edge length with distance (0.5: an edge at
        distance d from a small one is at most 0.5 d longer).
    corner_angle : float
        A feature line turning by more than this (degrees) at a vertex gets a corner
        there (a fixed vertex); feature-line ends and junctions are always corners.
    wedge_angle : float
        Two feature lines leaving a corner at less than this angle (degrees) are treated
        as one line where they are closer than ``2 * max_deviation``.
    keep_component_borders : bool
        Also keep borders between input components as feature lines.
    deviation_passes : int
        Extra passes that shrink the sizing where the measured deviation exceeds
        ``max_deviation`` and remesh again (each re-runs ``iterations // 2`` sweeps and the
        finishing rounds over the whole skin). A pass runs only while more than
        ``options.remesh_pass_fraction`` of the edges deviate (0: any edge); fewer are left to
        the deviation splits, which split them where they are.
    deviation_splits : bool
        Finally split the edges still deviating too much (see the guarantee above).
    finish_rounds : int
        Angle-improving flip, worst-triangle collapse and relaxation rounds at the end.
    max_flip_dihedral : float
        Largest dihedral (degrees) across which an edge may be flipped during remeshing
        (every flip must also keep the new edge within ``max_deviation`` and not turn a
        triangle against the input normal).
    size_field : SizeField, optional
        Local edge lengths asked for below ``target_edge`` (a
        :class:`~shellmesh_mdao.core.sizefield.SizeField` in the units of ``target_edge``: two
        members closer than the element size): the sizing is the smaller of the curvature
        sizing and the field, evaluated where each vertex is (not smeared over the input
        triangles), never below ``min_edge``.
    report : dict, optional
        Filled with figures: counts, edge-length percentiles relative to the target,
        angles, deviation, timings.
    log : callable, optional
        Called with progress lines.

    Returns
    -------
    ShellMesh
        Triangles, every vertex on the input surface; ``feature_edges`` the sharp lines
        (ids -1); ``fixed_vertices`` their corners (line ends and junctions, sharp turns);
        ``component`` taken from the input triangle each face centroid projects to
        (restricted to the centroid's own feature-bounded patch).

    Raises
    ------
    SizeError
        Non-positive/non-finite sizes, a size larger than the model or one that would
        give more than 5e7 triangles.
    MeshValidationError
        Empty, non-finite or non-manifold input.
    """
    t_start = time.perf_counter()
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("remesh_skin needs a ShellMesh: load the surface with the loader first")
    if mesh.n_faces == 0:
        raise MeshValidationError("the skin has no faces: load a non-empty surface")
    try:
        target = float(target_edge)
    except (TypeError, ValueError):
        raise SizeError(f"target edge length {target_edge!r} is not a number: give a positive size") from None
    if not np.isfinite(target) or target <= 0:
        raise SizeError(f"target edge length {target_edge!r} must be positive and finite: give a positive size")
    if not np.isfinite(mesh.points).all():
        raise MeshValidationError("the skin has NaN/inf coordinates: repair the input surface")
    diag = mesh.diagonal
    if target > diag:
        raise SizeError(f"target edge length {target:g} exceeds the model size (bounding-box diagonal "
                        f"{diag:g}): give a size in the units of the surface file, smaller than the model")
    area = float(mesh.face_areas().sum())
    est = area / (0.433 * target ** 2)
    if est > 5e7:
        raise SizeError(f"target edge length {target:g} would give about {est:.3g} triangles on a skin of "
                        f"area {area:.4g}: give a larger size (in the units of the surface file)")
    delta = options.remesh_deviation * target
    if not np.isfinite(delta) or delta <= 0:
        raise SizeError(f"max_deviation {delta!r} must be positive: give a positive length")
    h_min = DEFAULT_MIN_EDGE_FRACTION * target if min_edge is None else float(min_edge)
    if not np.isfinite(h_min) or h_min <= 0 or h_min > target:
        raise SizeError(f"min_edge {min_edge!r} must be positive and at most target_edge")
    timings = {}
    t0 = time.perf_counter()
    surf = InputSurface(mesh, target, delta, feature_angle, corner_angle, wedge_angle, keep_component_borders,
                    locator)
    surf.set_sizing(h_min, gradation, None if size_field is None or size_field.empty else size_field)
    timings["prepare"] = time.perf_counter() - t0
    ctx = Context(surf, max_flip_dihedral=max_flip_dihedral, delta=delta)
    W = _work_from_surface(surf)
    W.h = ctx.sizing(W)
    t0 = time.perf_counter()
    nm = phase(micro_round, W, ctx, 50, 0.25)
    timings["micro"] = time.perf_counter() - t0
    if log:
        log(f"{nm} tiny input edges collapsed")
    _iterate(W, ctx, iterations, timings, log)
    _finish(W, ctx, finish_rounds, timings, log)
    passes = 0
    mids = _MidpointDistances(surf.loc)
    for _ in range(deviation_passes):
        dm, dc, _, _ = _deviation(W, ctx, mids)
        T = W.topo()
        E = T.E
        L = edge_lengths(W.P, E)
        over = (dm > delta) & (L > SPLIT_RATIO * h_min)
        if not over.any() or over.sum() <= options.remesh_pass_fraction * len(over):
            break
        passes += 1
        # shrink the field at the input triangles under the offending edges
        mid = 0.5 * (W.P[E[over, 0]] + W.P[E[over, 1]])
        _, tri, _ = surf.loc.closest(mid)
        lnew = L[over] * np.sqrt(delta / dm[over]) * 0.8
        verts = np.concatenate([surf.T[tri].reshape(-1), surf.T[W.vtri[E[over]].reshape(-1)[
            W.vtri[E[over]].reshape(-1) >= 0]].reshape(-1)])
        hn = np.concatenate([np.repeat(lnew, 3), np.repeat(np.repeat(lnew, 2)[W.vtri[E[over]].reshape(-1) >= 0], 3)])
        surf.shrink_sizing(verts, hn, gradation)
        W.h = ctx.sizing(W)
        if log:
            log(f"deviation pass {passes}: {int(over.sum())} edges deviate more than {delta:g}")
        _iterate(W, ctx, max(2, iterations // 2), timings, log)
        _finish(W, ctx, finish_rounds, timings, log)
    # ---------------------------------------------------------------- deviation splits
    # last resort for the guarantee: split (at the projected midpoint) every edge whose
    # midpoint is still farther than max_deviation from the input, down to 2 * min_edge
    t0 = time.perf_counter()
    n_dev_splits = 0
    for _ in range(12 if deviation_splits else 0):
        T = W.topo()
        E = T.E
        L = edge_lengths(W.P, E)
        dm = mids(W.P, E, W.vtri)
        over = np.flatnonzero((dm > delta) & (L > 2.0 * h_min))
        if not len(over):
            break
        k = split_round(W, ctx, forced=over, min_angle_guard=20.0, deviation=dm)
        n_dev_splits += k
        W.h = ctx.sizing(W)
        phase(flip_round, W, ctx, 5, "angle")
        phase(_cleanup_round, W, ctx, 3)
        if not k:
            break
    timings["deviation_splits"] = time.perf_counter() - t0
    # safety net: faces standing across the surface (through a thin tip) are collapsed away
    if len(_standing_faces(W, ctx)):
        phase(_unstand_round, W, ctx, 10)
        phase(flip_round, W, ctx, 5, "angle")
        # the collapses above check no angles: clean up the slivers they left (below 10 degrees only:
        # a clean-up at the finishing rounds' 20 degrees reshaped whole tip caps and left skin nodes
        # off the surface on straight_wing stress seed 58)
        phase(_cleanup_round, W, ctx, 3, 10.0)
        phase(flip_round, W, ctx, 5, "angle")
    # last: the stars of corners and chain nodes with three or four neighbours that keep a sliver no
    # edge operation removes (a sharp trailing edge ending in a tip thinner than max_deviation; once
    # here, after every global round, so that only those stars change)
    n_pinched = _contract_pinched(W, ctx)
    if n_pinched:
        phase(flip_round, W, ctx, 5, "angle")
    # faces of three nodes in a line, where nodes met on a crest of the input tighter than the edges
    n_degenerate = 0
    for _ in range(10):
        k = degenerate_round(W, ctx)
        n_degenerate += k
        if not k:
            break
    # ---------------------------------------------------------------- output
    dm, dc, ctri, ok = _deviation(W, ctx, mids)
    comp = surf.tri_comp[ctri]
    fdeg = np.bincount(W.fe.reshape(-1), minlength=W.n) if len(W.fe) else np.zeros(W.n, np.int64)
    corners = np.flatnonzero((W.kind == CORNER) | ((fdeg > 0) & (fdeg != 2)))
    out = ShellMesh(W.P, W.F, comp, surf.component_names, corners, W.fe, np.full(len(W.fe), -1, np.int32))
    timings["total"] = time.perf_counter() - t_start
    if report is not None:
        report.update(_stats(out, target, delta, dm, dc))
        # edge length against the local size asked for (curvature / feature-size adapted)
        E = out.edges()
        L = out.edge_lengths()
        he = 0.5 * (W.h[E[:, 0]] + W.h[E[:, 1]])
        pct = [1, 5, 25, 50, 75, 95, 99]
        report["edge_to_local_size_percentiles"] = {p: float(np.percentile(L / he, p)) for p in pct}
        flat = he >= 0.95 * target
        report["fraction_edges_unrefined"] = float(flat.mean())
        if flat.any():
            report["edge_length_percentiles_unrefined"] = {p: float(np.percentile(L[flat], p) / target)
                                                          for p in pct}
        report.update(dict(timings=timings, deviation_passes=passes, n_deviation_splits=n_dev_splits,
                           n_pinched_contracted=int(n_pinched), n_degenerate_flipped=int(n_degenerate),
                           n_standing_faces=int(len(_standing_faces(W, ctx))),
                           n_input_triangles=len(surf.T),
                           n_feature_chains=int(surf.n_chains), n_corners=int((W.kind == CORNER).sum()),
                           max_deviation=delta, min_edge=h_min, target_edge=target,
                           sizing=surf.sizing_summary()))
    return out


def _stats(out, target, delta, dm, dc):
    L = out.edge_lengths()
    A = tri_angles(out.points, out.faces[:, :3])
    amin = A.min(1)
    pct = [0, 1, 5, 25, 50, 75, 95, 99, 100]
    return dict(n_triangles=int(out.n_faces), n_vertices=int(out.n_points),
                edge_length_percentiles={p: float(np.percentile(L, p) / target) for p in pct},
                min_angle=float(amin.min()), angle_percentiles={p: float(np.percentile(amin, p)) for p in (1, 5, 50)},
                n_min_angle_below_10=int((amin < 10).sum()), n_min_angle_below_20=int((amin < 20).sum()),
                max_angle=float(A.max()),
                deviation_edge_midpoints=float(dm.max()) if len(dm) else 0.0,
                deviation_face_centroids=float(dc.max()) if len(dc) else 0.0,
                n_edges_over_deviation=int((dm > delta).sum()))


def remesh_statistics(result: ShellMesh, source: ShellMesh, target_edge: float,
                      locator: SurfaceLocator | None = None) -> dict:
    """Figures of a remesh against its input: edge-length percentiles (relative to
    ``target_edge``), angles, and the distance from the result's vertices, edge midpoints
    and face centroids to the input surface (output -> input) and from the input
    vertices to the result (input -> output)."""
    loc = locator if locator is not None else SurfaceLocator.from_mesh(source)
    tris, _ = result.triangles()
    E = result.edges()
    mid = 0.5 * (result.points[E[:, 0]] + result.points[E[:, 1]])
    _, _, dv = loc.closest(result.points)
    _, _, dm = loc.closest(mid)
    _, _, dc = loc.closest(result.face_centroids())
    _, _, di = SurfaceLocator(result.points, tris).closest(source.points)
    s = _stats(result, float(target_edge), np.inf, dm, dc)
    s.update(deviation_vertices=float(dv.max()), deviation_input_to_output=float(di.max()),
             diagonal=float(source.diagonal))
    return s
