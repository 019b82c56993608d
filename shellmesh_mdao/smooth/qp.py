"""The smoothing QP (paper eq. 6-8): trust-region steps of :func:`smooth` along the node
supports, each solved in the supports' tangent spaces, clipped, projected back and
line-searched so that no element folds."""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from ..core.supports import Supports, support_normals
from ..core.threads import Background
from ..core.topology import faces_of
from ..errors import MeshValidationError
from .kernels import ReducedHessian, nearest_other_distance, pair_difference
from ..mesh import ShellMesh, dot_norm_rows, dot_unit_rows, edge_topology, vertex_faces
from ..options import SmoothOptions
from .elements import element_min_sj, face_normals, facing, mesh_figures
from .energy import (OrthoTerm, WarpTerm, energy_pairs, local_edge_size, tangent_frames,
                     vertex_normals_and_curvature)
from .linear import LDL, LinearSolver, solve_kkt

__all__ = ["AUTO_LU_MAX_UNKNOWNS", "SmoothResult", "smooth", "smooth_report", "smooth_mesh"]

#: ``solver="auto"`` factorises with sparse LU up to this many unknowns and uses
#: Jacobi-preconditioned CG above. 0: CG always. At :data:`.linear.CG_RTOL` 1e-3 the smoothing before
#: subdivision takes 188 ms with CG against 215 ms with the factorisation on the target case
#: (5.7k nodes), 41 against 42 ms on a 715-node wing; a factorisation's fill-in grows fast on
#: surface meshes (splu: 0.25 s at 20k unknowns, 2.7 s at 51k).
AUTO_LU_MAX_UNKNOWNS = 0

#: the line search's facing guard: no step may leave a face turned further than this from the
#: support normal (input facet, member plane) at every one of its corners, unless it was already
#: and the step turns it no further
STAND_ANGLE = 60.0
COS_STAND = float(np.cos(np.radians(STAND_ANGLE)))

# einsum's norm and unit rows (mesh.dot_norm_rows & co.: compiled for (k, 3) rows)
_norm, _unit = dot_norm_rows, dot_unit_rows


@dataclass
class SmoothResult:
    """Outcome of :func:`smooth`.

    ``iterations``        trust-region steps taken; ``seconds`` wall time;
    ``factorisations``    sparse LU factorisations done (one per ``refresh`` steps);
    ``max_move``          largest single vertex move of the whole run (length units);
    ``moves``             largest move of each step;
    ``n_step_halvings``   vertex-step halvings done by the fold / jump line search;
    ``n_rejected``        vertex steps finally set to zero by the line search;
    ``n_fold_hits``, ``n_jump_hits``, ``n_stand_hits``: line-search hits by cause (a vertex of an
                          element that would fold; a projection that jumped or found no
                          compatible triangle; an element the step would turn across its
                          supports, :data:`STAND_ANGLE`);
    ``quality_before``, ``quality_after``: :func:`mesh_figures` of input and output.
    """

    iterations: int
    seconds: float
    max_move: float
    n_step_halvings: int
    n_rejected: int = 0
    factorisations: int = 0
    n_fold_hits: int = 0
    n_jump_hits: int = 0
    n_stand_hits: int = 0
    moves: list = field(default_factory=list)
    quality_before: dict = field(default_factory=dict)
    quality_after: dict = field(default_factory=dict)


def smooth_report(res) -> dict:
    """The pipeline report's figures of a :class:`SmoothResult` ``res`` (stage keys ``smooth`` and
    ``final_smooth``)."""
    return {"iterations": int(res.iterations), "seconds": round(res.seconds, 4), "max_move": float(res.max_move),
            "n_rejected": int(res.n_rejected), "quality_before": res.quality_before,
            "quality_after": res.quality_after}


def smooth(mesh: ShellMesh, supports: Supports, *, iterations: int = SmoothOptions.smooth_iterations,
           energy: str = SmoothOptions.smooth_energy, target_edge: float | None = None, edge_size=None,
           diagonal_weight: float = 0.0,
           ortho_weight: float = 1.0, warp_weight: float = SmoothOptions.smooth_warp_weight,
           warp_from: float = SmoothOptions.warp_from, warp_spread: float = SmoothOptions.smooth_warp_spread,
           vertices=None, trust: float = 0.3, reg: float = 0.25, curvature_weight: float = 10.0, refresh: int = 4,
           min_jacobian: float = SmoothOptions.smooth_jacobian, max_halvings: int = 6, min_dot: float = 0.0,
           tol: float = 1e-4, solver: str = "auto", figures: str = "both") -> tuple[ShellMesh, SmoothResult]:
    """Move vertices along their supports to even out the mesh (paper eq. 6-8).

    The defaults of the keywords the smooth stage sets from its options are those options'
    (:class:`~shellmesh_mdao.options.SmoothOptions`): ``iterations`` ``smooth_iterations``,
    ``energy`` ``smooth_energy``, ``warp_weight`` ``smooth_warp_weight``, ``warp_from``
    ``warp_from``, ``warp_spread`` ``smooth_warp_spread``, ``min_jacobian``
    ``smooth_jacobian``; ``ortho_weight`` and ``refresh`` are the smooth stage's too.

    Parameters
    ----------
    mesh : the conforming mixed mesh (skin and members).
    supports : :class:`~shellmesh_mdao.core.supports.Supports` of its vertices
        (:func:`~shellmesh_mdao.core.supports.derive_supports`).
    iterations : maximum number of trust-region steps.
    energy : ``"length"``: the sum of edge LENGTHS, which the paper states as the
        goal, through its local quadratic model: pair weights ``1/L`` with ``L`` the length
        at the last refresh, so the gradient is the sum of unit edge vectors at each vertex
        (equilibrium: balanced edge directions, scale-free, keeps size gradation);
        ``"squared"`` (the default): eq. 6/7 as printed, sum of squared lengths (uniform
        Laplacian).
    target_edge : with ``energy="squared"`` and no ``edge_size``: each edge aims at this length
        and each quad diagonal at sqrt(2) times it (rest vectors along the current directions).
        With either energy it is the ``size`` of the reported ``median_edge_ratio``.
    edge_size : with ``energy="squared"``: (n,) local sizes, one per mesh vertex
        (:func:`~.energy.local_edge_size`); each edge aims at the mean of its two ends' sizes
        (each quad diagonal at sqrt(2) times that of its ends) instead of ``target_edge``.
    diagonal_weight : weight of the quad-diagonal pairs relative to the edges (0 = edges
        only, as in the paper).
    ortho_weight : weight of the quad-corner orthogonality term (beyond the paper; see
        :class:`OrthoTerm`): zero for right-angled corners of any aspect ratio.
    warp_weight : weight of the quad planarity term (beyond the paper; see :class:`WarpTerm`),
        which flattens the quads whose warp is above ``warp_from`` degrees (measured when the
        frames are rebuilt) by sliding their corners along their supports; 0 drops it. Not
        with ``solver="kkt"``.
    warp_from : warp (degrees) above which a quad is in the planarity term.
    warp_spread : a quad that shares a vertex with a face (itself included) whose corners'
        support normals (input facets, member planes) are more than this many degrees apart
        is left out of the planarity term: that face is draped over a crease or round much
        tighter than itself and cannot be flattened by sliding its corners, and pulling at it
        or beside it drags nodes across the crease. 180: none left out.
    vertices : ids of the vertices that may move (default None: all); the others hold
        still, as if FIXED, and only constrain the step (fold guard, energy). Only the faces at
        them take part (the same result as over the whole mesh with the others FIXED, bit for
        bit).
    trust : per-step move limit as a fraction of the distance to the nearest other vertex.
    reg : regulariser ``rho_i = reg * (mean diagonal of vertex i's energy block)
        * (1 + curvature_weight * kappa_i)`` with ``kappa_i = 1 - min_f n_i . n_f`` over the incident faces (0 on a
        flat patch, 1 across a right-angle crease).
    refresh : steps between rebuilding the tangent frames and weights and refactorising;
        in between the factorisation is reused and only the right-hand side is rebuilt.
    min_jacobian : an element whose scaled Jacobian (own normal, and normal before the
        step) would end at or below this value AND below its value before the step makes
        the line search halve the step of its vertices.
    max_halvings : halvings before a vertex's step is dropped for this iteration.
    min_dot : a skin vertex may only be projected onto input triangles whose normal has a
        dot product above this with the vertex normal.
    tol : stop when the largest move of a step is below ``tol`` times the median edge.
    solver : ``"lu"`` (sparse L D L^T of the reduced system by qdldl, reused for ``refresh`` steps),
        ``"cg"`` (Jacobi-preconditioned CG on the same matrix), ``"auto"`` (LU up to
        :data:`AUTO_LU_MAX_UNKNOWNS` unknowns, 0: none; CG above) or ``"kkt"`` (eq. 8 assembled
        literally; small meshes only, for checks).
    figures : which of ``quality_before`` / ``quality_after`` (:func:`mesh_figures`, about
        20-50 ms each on 25k quads) to fill: ``"both"`` (default), ``"before"``, ``"after"`` or
        ``"none"`` (the others stay empty dicts); for callers that chain passes.

    Returns ``(smoothed mesh, SmoothResult)``; topology, components, feature edges and fixed
    vertices are unchanged, only ``points`` move.
    """
    t0 = time.perf_counter()
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("smooth needs a ShellMesh; build one with ShellMesh(points, faces)")
    if not isinstance(supports, Supports) or supports.n != mesh.n_points:
        raise MeshValidationError("smooth needs Supports with one entry per mesh vertex: build them with "
                                  "derive_supports(mesh, ...) for this mesh")
    if figures not in ("both", "before", "after", "none"):
        raise ValueError(f"figures must be 'both', 'before', 'after' or 'none', got {figures!r}")
    if solver not in ("auto", "lu", "cg", "kkt"):
        raise ValueError(f"solver must be 'auto', 'lu', 'cg' or 'kkt', got {solver!r}")
    if not (np.isfinite(warp_weight) and warp_weight >= 0 and np.isfinite(warp_from) and warp_from >= 0
            and 0 < warp_spread <= 180):
        raise ValueError(f"need finite warp_weight >= 0, warp_from >= 0 and 0 < warp_spread <= 180, got "
                         f"{warp_weight}, {warp_from}, {warp_spread}")
    if warp_weight > 0 and solver == "kkt":
        raise ValueError("the planarity term (warp_weight > 0) needs solver 'auto', 'lu' or 'cg', not 'kkt'")
    if energy not in ("length", "squared"):
        raise ValueError(f"energy must be 'length' or 'squared', got {energy!r}")
    if not (trust > 0 and reg >= 0 and refresh >= 1 and iterations >= 0 and diagonal_weight >= 0):
        raise ValueError("need trust > 0, reg >= 0, refresh >= 1, iterations >= 0, diagonal_weight >= 0")
    if target_edge is not None and not (np.isfinite(target_edge) and target_edge > 0):
        from ..errors import SizeError
        raise SizeError(f"target_edge must be a positive length, got {target_edge}")
    if edge_size is not None:
        edge_size = np.asarray(edge_size, np.float64).reshape(-1)
        if len(edge_size) != mesh.n_points or not (np.isfinite(edge_size).all() and (edge_size > 0).all()):
            raise ValueError(f"edge_size must hold one positive length per mesh vertex ({mesh.n_points})")
    if vertices is not None:
        vertices = np.asarray(vertices, np.int64).reshape(-1)
        if len(vertices) and (vertices.min() < 0 or vertices.max() >= mesh.n_points):
            raise ValueError(f"vertices must be ids of mesh vertices (0 to {mesh.n_points - 1})")
        supports = supports.held(vertices)
    n = mesh.n_points
    P = mesh.points.copy()
    faces, is_tri = mesh.faces, mesh.is_tri
    before = mesh_figures(mesh, supports, target_edge) if figures in ("both", "before") else {}
    scale = float(np.median(mesh.edge_lengths())) if mesh.n_faces else 1.0
    dof = supports.dof()
    movable = np.flatnonzero(dof > 0)
    vptr, vface = vertex_faces(faces, n)
    E = mesh.edges()
    if vertices is not None:
        # only the faces at a movable vertex take part: the other faces' terms do not reach the
        # movable vertices' equations, and each of those equations sums the same terms in the
        # same order (pairs, quads and faces keep their order). A draped face (warp_spread) needs
        # two corners with a support normal, i.e. movable ones, so it is among these faces too.
        # The same bits as over the whole mesh, for the cost of the region
        act = faces_of(vptr, vface, movable, len(faces))
        faces, is_tri = faces[act], is_tri[act]
        vptr, vface = vertex_faces(faces, n)
        E = edge_topology(faces).edges
    pairs, pw0, pf = energy_pairs(E, faces, is_tri, diagonal_weight)
    i, j = pairs[:, 0], pairs[:, 1]
    # each pair's rest length (edges; the diagonals sqrt 2 times it): the mean of its ends' local
    # sizes, or target_edge
    rest = None
    if energy == "squared":
        if edge_size is not None:
            rest = 0.5 * (edge_size[i] + edge_size[j])
        elif target_edge is not None:
            rest = float(target_edge)
    has_quads = not is_tri.all()
    method = solver
    if solver == "auto":
        method = "lu" if int(dof.sum()) <= AUTO_LU_MAX_UNKNOWNS else "cg"
    moves, halvings, rejected, nfact, n_jump, n_fold, n_stand = [], 0, 0, 0, 0, 0, 0
    # each vertex's closest input triangle at its last projection: where the next query starts
    hint = np.full(n, -1, np.int64)
    lin = T = nrm = ortho = warpt = hess = None
    # each vertex's support normal (closest input facet, member plane; zero on curves and FIXED)
    # at its current position: the facing guard of the line search
    snrm = support_normals(supports, P, np.arange(n)) if len(movable) else np.zeros((n, 3))
    ldl = LDL()                     # the refreshed matrices share one pattern: one ordering
    it = 0
    for it in range(1, iterations + 1):
        if not len(movable):
            it = 0
            break
        # trust region: distance to the nearest other vertex, from a grid of cubes of >= 1.5 median
        # edges in a second thread while this one refreshes and solves (it depends on P alone;
        # the grid's cell sets the speed only: a KD-tree query's values)
        near = Background(nearest_other_distance, P, movable, 1.5 * scale)
        if (it - 1) % refresh == 0:
            vn, kap = vertex_normals_and_curvature(P, faces, is_tri, n)
            T, owner, nrm, tv = tangent_frames(mesh, P, supports, vn)
            pw = pw0.copy()
            if energy == "length":
                Lp = _norm(P[i] - P[j])
                pw = pw0 * np.divide(scale, Lp, out=np.zeros_like(Lp), where=Lp > 0)
            K = sparse.coo_matrix((np.concatenate([pw, pw, -pw, -pw]),
                                   (np.concatenate([i, j, i, j]), np.concatenate([i, j, j, i]))),
                                  shape=(n, n)).tocsr()
            diag_v = np.asarray(K.diagonal(), dtype=np.float64)
            col_start = np.searchsorted(owner, np.arange(n))
            ortho = None
            if ortho_weight > 0 and has_quads:
                ortho = OrthoTerm(P, faces, ~is_tri, scale)
                diag_v = diag_v + ortho_weight * ortho.block_trace(n)
            warpt = None
            if warp_weight > 0 and has_quads and method != "kkt":
                warpt = WarpTerm(P, faces, ~is_tri, scale, lambda v: support_normals(supports, P, v), warp_from,
                              warp_spread)
                if len(warpt):
                    diag_v = diag_v + warp_weight * warpt.block_trace(n)
                else:
                    warpt = None
            rho_v = reg * diag_v * (1.0 + curvature_weight * kap)
            if method == "kkt":            # full 3n matrix for the literal eq. 8
                K3 = sparse.kron(K, sparse.identity(3), format="csr")
                if ortho is not None:
                    K3 = K3 + ortho_weight * ortho.hessian(3 * np.arange(n), np.full(n, 3),
                                                           np.tile(np.eye(3), (n, 1)), 3 * n)
            else:
                if hess is None:           # the pattern: pairs, and whole quads where a quad term is used
                    quad_terms = has_quads and (ortho_weight > 0 or warp_weight > 0)
                    hess = ReducedHessian(i, j, faces[~is_tri] if quad_terms else np.zeros((0, 4), np.int64), dof,
                                          col_start)
                H = hess.matrix(hess.values(tv, pw, rho_v[owner], ortho=None if ortho is None else ortho.terms(),
                                            fo=ortho_weight,
                                            warp=None if warpt is None else warpt.terms(), fw=warp_weight))
                lin = LinearSolver(H, method, ldl)
            nfact += 1
        # gradient of the energy at D = 0 (homogeneous quadratic: K3 x, plus rest vectors)
        xc = P - P.mean(0)
        if method == "kkt":
            g = K3 @ xc.ravel()
        elif ortho is None:
            g = (K @ xc).ravel()
        else:
            g = (K @ xc).ravel() + ortho_weight * ortho.gradient(xc, n).ravel()
        if warpt is not None:
            g = g + warp_weight * warpt.gradient(xc, n).ravel()
        if rest is not None:
            rv = (rest * pf)[:, None] * _unit(P[i] - P[j])
            g = g - pair_difference(i, j, pw, rv, n).ravel()      # the rest vectors' pull, per vertex
        if method == "kkt":
            D = solve_kkt(K3, rho_v, n, g, supports, T, owner)
        else:
            D = (T @ lin.solve(-(T.T @ g))).reshape(n, 3)
        r = trust * near.result()
        Dm = D[movable]
        L = _norm(Dm)
        Dm *= np.minimum(1.0, np.divide(r, L, out=np.ones_like(L), where=L > 0))[:, None]
        D = np.zeros((n, 3))
        D[movable] = Dm
        # line search with per-vertex step factors
        todo = movable[_norm(D[movable]) > 0]
        fsel = faces_of(vptr, vface, todo, len(faces))
        nref = face_normals(P, faces[fsel], is_tri[fsel])
        sj_old = np.full(len(faces), np.inf)
        sj_old[fsel] = element_min_sj(P, faces[fsel], is_tri[fsel], nref)
        nref_all = np.zeros((len(faces), 3))
        nref_all[fsel] = nref
        face_old = np.full(len(faces), np.inf)
        face_old[fsel] = facing(faces[fsel], nref, snrm)
        sn_new = snrm.copy()
        alpha = np.zeros(n)
        alpha[todo] = 1.0
        X = P.copy()
        rounds = 0
        while len(todo):
            badv = np.zeros(0, np.int64)
            live = todo[alpha[todo] > 0]
            X[todo] = P[todo]
            if len(live):
                step = alpha[live, None] * D[live]
                x, ok, tri = supports.project_kind(P[live] + step, supports.kind[live], supports.ref[live],
                                                   nrm[live], min_dot, hint=hint[live], return_tri=True)
                hint[live] = tri
                jump = _norm(x - (P[live] + step)) > _norm(step) + 1e-12 * scale
                X[live] = x
                badv = live[~ok | jump]
                n_jump += len(badv)
                sn_new[live] = support_normals(supports, X, live)
            sn_new[todo[alpha[todo] == 0]] = snrm[todo[alpha[todo] == 0]]
            fs = faces_of(vptr, vface, todo, len(faces))
            sj_new = element_min_sj(X, faces[fs], is_tri[fs], nref_all[fs])
            badf = fs[(~np.isfinite(sj_new) | (sj_new <= min_jacobian)) & (sj_new < sj_old[fs] - 1e-12)]
            # no step may turn a face across its support (further than STAND_ANGLE from the
            # support normal at every corner), nor further across where it stood so before
            f_new = facing(faces[fs], face_normals(X, faces[fs], is_tri[fs]), sn_new)
            stand = fs[(f_new <= COS_STAND) & (f_new < face_old[fs] - 1e-12)]
            n_stand += len(stand)
            badf = np.union1d(badf, stand)
            fv = faces[badf]
            fv = fv[fv >= 0]
            hit = np.zeros(n, bool)
            hit[fv[alpha[fv] > 0]] = True
            n_fold += int(hit.sum())
            hit[badv] = True
            badv = np.flatnonzero(hit)
            if not len(badv):
                break
            rounds += 1
            if rounds <= max_halvings:
                alpha[badv] *= 0.5
                halvings += len(badv)
            else:
                alpha[badv] = 0.0
                rejected += len(badv)
            todo = badv
        move = float(_norm(X - P).max()) if n else 0.0
        moves.append(move)
        P = X
        snrm = sn_new
        if move < tol * scale:
            break
    out = mesh.with_points(P)
    res = SmoothResult(iterations=it, seconds=time.perf_counter() - t0, max_move=max(moves, default=0.0),
                       n_step_halvings=halvings, n_rejected=rejected, factorisations=nfact, moves=moves,
                       n_fold_hits=n_fold, n_jump_hits=n_jump, n_stand_hits=n_stand, quality_before=before,
                       quality_after=mesh_figures(out, supports, target_edge) if figures in ("both", "after") else {})
    return out, res


def smooth_mesh(mesh: ShellMesh, supports: Supports, target_edge: float,
                options: SmoothOptions = SmoothOptions()) -> tuple[ShellMesh, dict]:
    """The pipeline's smooth stage: :func:`smooth` on the whole merged mesh before subdivision,
    each edge aiming (``"squared"`` energy) at the local size of the merged mesh at its ends
    (:func:`~.energy.local_edge_size`: the mean length of the edges at a vertex, at most
    ``target_edge``, the remesh edge length), so that the grading the remesh made stays, with
    the stage's :class:`~shellmesh_mdao.options.SmoothOptions` (``smooth_iterations`` steps, no
    step bringing an element to or below ``smooth_jacobian``, energy ``smooth_energy``, the quad
    planarity term ``smooth_warp_weight`` above ``warp_from`` degrees, leaving out the quads by
    faces draped more than ``smooth_warp_spread``).

    Returns ``(mesh, report)``, ``report`` the pipeline report's ``smooth`` entry
    (:func:`smooth_report`)."""
    o = options
    # a triangle's scaled Jacobian bounds its three child quads' after subdivision: keep every
    # element above smooth_jacobian (0.4: triangle angles >= ~20 deg, children above ~0.3)
    # each edge aims at the local size, not at target_edge everywhere: pulling the small elements
    # of a graded region (a leading-edge nose) towards the flat-region length spread them over
    # the nose, and their children came out long, thin and warped
    out, res = smooth(mesh, supports, iterations=o.smooth_iterations, min_jacobian=o.smooth_jacobian,
                      energy=o.smooth_energy, target_edge=target_edge,
                      edge_size=local_edge_size(mesh, target_edge), warp_weight=o.smooth_warp_weight,
                      warp_from=o.warp_from, warp_spread=o.smooth_warp_spread)
    return out, smooth_report(res)
