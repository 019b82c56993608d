"""Splitting optimisation (Li & Hwang, paper Sec. IV.C.1, eq. 1-3).

Every polygon of a mixed triangle/quad mesh gets eleven 0/1 decision variables,
one per splitting option (a triangle has seven real options; the last four are
padded with upper bound 0, as in the paper).  The linear programme

    minimise    c_s^T x_s
    subject to  sum_o x_s[f, o] = 1                       (one option per polygon)
                A_agree x_s = 0                           (eq. 3: all faces around an
                                                           edge agree on splitting it)
                0 <= x_s <= ub_s                          (ub_s = 0 for padded options and
                                                           for options that split a fixed edge)

is assembled with :mod:`scipy.sparse` and solved with HiGHS; when the LP optimum is
fractional it is re-solved as a MIP.  The option tables are reconstructed from the
paper's Fig. 4/5 text and its eq. 3 example (see :func:`split_options` and
``docs/optimisation.md``).

The energy of one polygon (eq. 2) is implemented in the *deviation* form

    e_s = c1 * sum_i (l_i / l_avg - 1)^2 + c2 * sum_i (theta_i / theta_ref - 1)^2

because eq. 2 read literally, ``c1 sum l_i/l_avg + c2 sum theta_i/theta_ref``, is the
same constant for every planar polygon (``n c1 + (n-2) 180/theta_ref c2``) and so
cannot rank the options; ``form="literal"`` and ``form="abs"`` are available for
comparison.  The weight of an option is the summed energy of the polygons it
creates (paper: "the sum of the energy of two new quads").
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from .core.highs import highs_solve
from .core.supports import Supports, edge_midpoint_projector, pipeline_supports, supports_hold
from .core.threads import Background
from .core.topology import fixed_edge_mask
from .errors import MeshValidationError, ProjectionError, SolverError
from .mesh import ShellMesh, norm_rows, reduce_short
from .options import SplitOptions

__all__ = ["SplitOptionTables", "SplitResult", "SplitLP", "split_options", "polygon_energy", "split_energy",
           "build_split_lp", "split_polygons", "split_mesh", "N_OPTIONS", "TRI", "QUAD"]

N_OPTIONS = 11
TRI, QUAD = 0, 1
#: local node numbering used by the option tables: corners 0..3, midpoint of side k
#: (side k joins corner k and the next corner) is node 4 + k, the face centre is node 8.
MID0, CENTRE = 4, 8

# --------------------------------------------------------------------------- tables
# children[kind, option, child] = 4 local node ids (-1 in slot 4 for a triangle child,
# all -1 for "no such child").  kind 0 = triangle, 1 = quad (the paper's [x_t, x_q]).
_CH = np.full((2, N_OPTIONS, 2, 4), -1, dtype=np.int64)
# ---- quad, sides 0:(0,1) 1:(1,2) 2:(2,3) 3:(3,0)
_CH[QUAD, 0] = [[0, 1, 5, 7], [7, 5, 2, 3]]          # mid(1-2) -- mid(3-0): two quads
_CH[QUAD, 1] = [[0, 4, 6, 3], [4, 1, 2, 6]]          # mid(0-1) -- mid(2-3): two quads
for _j in range(4):
    _e = (_j + 1) % 4                                # split side e from vertex e-1 ...
    _CH[QUAD, 2 + _j] = [[(_e - 1) % 4, _e, MID0 + _e, -1],
                         [(_e - 1) % 4, MID0 + _e, (_e + 1) % 4, (_e + 2) % 4]]
    #                                                  ... or from vertex e+2
    _CH[QUAD, 6 + _j] = [[MID0 + _e, (_e + 1) % 4, (_e + 2) % 4, -1],
                         [_e, MID0 + _e, (_e + 2) % 4, (_e + 3) % 4]]
_CH[QUAD, 10, 0] = [0, 1, 2, 3]                      # keep
# ---- triangle, sides 0:(0,1) 1:(1,2) 2:(2,0)
for _k in range(3):
    # option k: split side k by a line from the opposite vertex k+2: two triangles
    _CH[TRI, _k] = [[_k, MID0 + _k, (_k + 2) % 3, -1],
                    [MID0 + _k, (_k + 1) % 3, (_k + 2) % 3, -1]]
    # option 3+k: cut corner k (mid of side k-1 -- mid of side k): triangle + quad
    _CH[TRI, 3 + _k] = [[_k, MID0 + _k, MID0 + (_k + 2) % 3, -1],
                        [MID0 + _k, (_k + 1) % 3, (_k + 2) % 3, MID0 + (_k + 2) % 3]]
_CH[TRI, 6, 0] = [0, 1, 2, -1]                       # keep
_CH.setflags(write=False)

_SPLITS = np.zeros((2, N_OPTIONS, 4), dtype=bool)    # which sides an option splits
for _kind in (TRI, QUAD):
    for _o in range(N_OPTIONS):
        _nodes = _CH[_kind, _o]
        for _s in range(4):
            _SPLITS[_kind, _o, _s] = bool((_nodes == MID0 + _s).any())
_SPLITS.setflags(write=False)
_VALID = np.zeros((2, N_OPTIONS), dtype=bool)
_VALID[TRI, :7] = True
_VALID[QUAD, :] = True
_VALID.setflags(write=False)
_KEEP = np.array([6, 10])                            # the "do not split" option per kind
# options splitting each side: exactly three for every (kind, side) that exists
_SIDE_OPTS = np.zeros((2, 4, 3), dtype=np.int64)
for _kind in (TRI, QUAD):
    for _s in range(3 if _kind == TRI else 4):
        _SIDE_OPTS[_kind, _s] = np.flatnonzero(_SPLITS[_kind, :, _s])
_SIDE_OPTS.setflags(write=False)

_NAMES = {
    TRI: ["split side 0 from vertex 2", "split side 1 from vertex 0", "split side 2 from vertex 1",
          "cut corner 0 (sides 2,0)", "cut corner 1 (sides 0,1)", "cut corner 2 (sides 1,2)", "keep",
          "(padding)", "(padding)", "(padding)", "(padding)"],
    QUAD: ["mid-mid sides 1,3", "mid-mid sides 0,2",
           "vertex 0 -> mid side 1", "vertex 1 -> mid side 2", "vertex 2 -> mid side 3",
           "vertex 3 -> mid side 0",
           "vertex 3 -> mid side 1", "vertex 0 -> mid side 2", "vertex 1 -> mid side 3",
           "vertex 2 -> mid side 0", "keep"],
}


@dataclass(frozen=True)
class SplitOptionTables:
    """The splitting option tables (paper Fig. 4 and 5, reconstructed).

    ``children``  (2, 11, 2, 4) local node ids of the (at most two) polygons an option
                  creates; kind 0 = triangle, 1 = quad; local nodes 0..3 are the corners,
                  ``4 + k`` the midpoint of side k (corner k to the next corner), 8 the
                  centre (reserved, no option uses it); -1 pads triangles / missing children.
    ``splits``    (2, 11, 4) bool, side k is split by the option.
    ``valid``     (2, 11) bool, False for the four padded triangle options (upper bound 0).
    ``keep``      (2,) index of the "do not split" option (6 for triangles, 10 for quads).
    ``side_options`` (2, 4, 3) the three options that split each side.
    ``names``     short description of every option.
    """

    children: np.ndarray
    splits: np.ndarray
    valid: np.ndarray
    keep: np.ndarray
    side_options: np.ndarray
    names: dict


def split_options() -> SplitOptionTables:
    """Return the option tables: 11 quad options, 7 triangle options padded to 11.

    Quad (sides 0:(0,1), 1:(1,2), 2:(2,3), 3:(3,0)): option 0 joins the midpoints of
    sides 1 and 3, option 1 those of sides 0 and 2 (two quads each); options 2..5
    join vertex ``j`` to the midpoint of side ``j+1``; options 6..9 join vertex
    ``j+3`` to the midpoint of side ``j+1`` (a triangle and a quad each); option 10
    keeps the quad.  Triangle (sides 0:(0,1), 1:(1,2), 2:(2,0)): options 0..2 split
    side k from the opposite vertex (two triangles); options 3..5 cut corner k by
    joining the midpoints of its two sides (a triangle and a quad); option 6 keeps.
    This numbering reproduces the paper's eq. 3 example exactly: triangle side (2,0)
    is split by options 2, 3, 5 and quad side (1,2) by options 0, 2, 6.
    """
    return SplitOptionTables(_CH, _SPLITS, _VALID, _KEEP.copy(), _SIDE_OPTS, _NAMES)


# --------------------------------------------------------------------------- energy
_BIG = 1.0e3      # energy of a degenerate polygon (zero-length side)


def polygon_energy(corners, is_tri, c1: float = 1.0, c2: float = 1.0, form: str = "squared") -> np.ndarray:
    """Energy of eq. 2 for a batch of polygons.

    ``corners`` (k, 4, 3) coordinates (slot 4 ignored where ``is_tri``), ``is_tri`` (k,).
    ``form``: ``"squared"`` (default) ``c1 sum (l_i/l_avg - 1)^2 + c2 sum (theta_i/theta - 1)^2``,
    ``"abs"`` the same with absolute values, ``"literal"`` eq. 2 exactly as printed,
    ``c1 sum l_i/l_avg + c2 sum theta_i/theta`` (constant for planar polygons).
    ``theta`` is 60 degrees for triangles and 90 for quads; angles are 3-D corner angles.
    A polygon with a zero-length side gets a large energy (1e3).
    """
    P = np.asarray(corners, dtype=np.float64)
    tri = np.asarray(is_tri, dtype=bool)
    k = len(P)
    if k == 0:
        return np.zeros(0)
    valid = np.ones((k, 4), bool)
    valid[tri, 3] = False
    if tri.all() or not tri.any():
        # one kind (split_energy's batches): the same corners by plain column indices
        nxt = np.array([1, 2, 0, 0] if tri[0] else [1, 2, 3, 0])
        prv = np.array([2, 0, 1, 1] if tri[0] else [3, 0, 1, 2])
        rows = slice(None)
    else:
        nxt = np.where(tri[:, None], np.array([1, 2, 0, 0]), np.array([1, 2, 3, 0]))
        prv = np.where(tri[:, None], np.array([2, 0, 1, 1]), np.array([3, 0, 1, 2]))
        rows = np.arange(k)[:, None]
    d = P[rows, nxt] - P                             # side i: corner i -> next corner
    L = norm_rows(d, axis=2)
    n = np.where(tri, 3.0, 4.0)
    Lm = np.where(valid, L, 0.0)
    lavg = reduce_short(Lm, "sum") / n
    degenerate = reduce_short((L <= 0) & valid, "any") | ~(lavg > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = -d[rows, prv]                            # corner i -> previous corner
        cosang = reduce_short(u * d, "sum", axis=2) / (L[rows, prv] * L)
        ang = np.arccos(np.clip(cosang, -1.0, 1.0))
        ratio = L / lavg[:, None]
    ref = np.where(tri, np.pi / 3, np.pi / 2)[:, None]
    aratio = ang / ref
    if form == "squared":
        tl, ta = (ratio - 1.0) ** 2, (aratio - 1.0) ** 2
    elif form == "abs":
        tl, ta = np.abs(ratio - 1.0), np.abs(aratio - 1.0)
    elif form == "literal":
        tl, ta = ratio, aratio
    else:
        raise ValueError(f"unknown energy form {form!r}: use 'squared', 'abs' or 'literal'")
    e = c1 * reduce_short(np.where(valid, tl, 0.0), "sum") + c2 * reduce_short(np.where(valid, ta, 0.0), "sum")
    return np.where(degenerate | ~np.isfinite(e), _BIG, e)


def _local_coords(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m, 9, 3): corners, side midpoints, centre (triangle: slot 3 / side 3 repeat corner 0)."""
    tri = faces[:, 3] < 0
    f = np.where(faces >= 0, faces, faces[:, :1])
    C = points[f]
    nxt = np.where(tri[:, None], np.array([1, 2, 0, 0]), np.array([1, 2, 3, 0]))
    M = 0.5 * (C + C[np.arange(len(f))[:, None], nxt])
    cen = np.where(tri[:, None], reduce_short(C[:, :3], "mean"), reduce_short(C, "mean"))
    return np.concatenate([C, M, cen[:, None]], axis=1)


def split_energy(points, faces, *, c1: float = 1.0, c2: float = 1.0, form: str = "squared") -> np.ndarray:
    """(m, 11) weight of every option of every face: the summed eq.-2 energy of the
    polygons the option creates (new nodes at straight edge midpoints).  Padded
    triangle options get 0 (their upper bound is 0 in the LP)."""
    points = np.asarray(points, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    m = len(faces)
    W = np.zeros((m, N_OPTIONS))
    if m == 0:
        return W
    X = _local_coords(points, faces)
    kind = np.where(faces[:, 3] < 0, TRI, QUAD)
    for kd in (TRI, QUAD):
        sel = np.flatnonzero(kind == kd)
        if not len(sel):
            continue
        Xs = X[sel]
        for o in np.flatnonzero(_VALID[kd]):
            for ch in range(2):
                idx = _CH[kd, o, ch]
                if idx[0] < 0:
                    continue
                P = Xs[:, np.where(idx >= 0, idx, idx[0])]
                W[sel, o] += polygon_energy(P, np.full(len(sel), idx[3] < 0), c1, c2, form)
    return W


# --------------------------------------------------------------------------- split
@dataclass
class SplitResult:
    """Outcome of :func:`split_polygons`.

    ``status``         HiGHS model status of the final solve ("Optimal", "Time limit reached", ...).
    ``objective``      c_s^T x_s at the chosen solution (summed option energies).
    ``is_integral``    the LP optimum was already 0/1.
    ``used_mip``       the problem was re-solved with integrality (fractional LP).
    ``option_counts``  (2, 11) how many triangles (row 0) / quads (row 1) took each option.
    ``seconds``        wall time of the whole call.
    ``choice``         (m,) option chosen by each input face.
    ``new_nodes``      (k,) indices of the inserted midpoint nodes (appended after the input nodes).
    ``parent_edges``   (k, 2) node pair of the edge each new node splits.
    ``parent_face``    (m', ) input face of every output face.
    ``lp_seconds``, ``mip_seconds`` solver wall times.
    """

    status: str
    objective: float
    is_integral: bool
    used_mip: bool
    option_counts: np.ndarray
    seconds: float
    choice: np.ndarray = field(repr=False, default=None)
    new_nodes: np.ndarray = field(repr=False, default=None)
    parent_edges: np.ndarray = field(repr=False, default=None)
    parent_face: np.ndarray = field(repr=False, default=None)
    lp_seconds: float = 0.0
    mip_seconds: float = 0.0

    @property
    def n_split_edges(self) -> int:
        return 0 if self.new_nodes is None else len(self.new_nodes)


@dataclass
class SplitLP:
    """The splitting LP of eq. 1 in the paper's layout: variable ``11 * face + option``.

    ``c`` (11m,) option weights; ``A`` CSR with the m "one option" rows first, then one
    agreement row (eq. 3) per pair of consecutive faces around every edge (faces sorted
    by index; an edge with k faces gives k-1 rows, +1 on the options of the first face
    that split the edge, -1 on those of the second); ``rhs`` the equality right-hand side;
    ``ub`` (11m,) 0/1 upper bounds; ``energy`` (m, 11); ``kind`` (m,) 0 triangle / 1 quad;
    ``n_choice_rows`` = m.
    """

    c: np.ndarray
    A: sparse.csr_matrix
    rhs: np.ndarray
    ub: np.ndarray
    energy: np.ndarray
    kind: np.ndarray
    n_choice_rows: int


def build_split_lp(mesh: ShellMesh, *, c1: float = 1.0, c2: float = 1.0, fixed_edges=None,
                   split_fixed: bool = False, form: str = "squared", reduce: bool = True) -> SplitLP:
    """Assemble eq. 1-3 (vectorised, scipy.sparse CSR).

    Upper bounds are 0 for the padded triangle options, for options that split a fixed
    edge (unless ``split_fixed``) and for faces using one edge on two sides (kept as they
    are).  With ``reduce`` the dominated one of each pair of quad options that split the
    same single side (2+j versus 6+j; the costlier, the later on a tie) is also bounded to
    0, which cannot change the optimum."""
    m = mesh.n_faces
    faces = mesh.faces
    kind = np.where(faces[:, 3] < 0, TRI, QUAD)
    topo = mesh.topology()
    fixed = fixed_edge_mask(topo, mesh.feature_edges if fixed_edges is None else fixed_edges)
    W = split_energy(mesh.points, faces, c1=c1, c2=c2, form=form)
    ub = _VALID[kind].copy()
    fe = topo.face_edges
    if not split_fixed and fixed.any():
        side_fixed = (fe >= 0) & fixed[np.maximum(fe, 0)]
        ub &= ~(_SPLITS[kind] & side_fixed[:, None, :]).any(2)
    nsides = np.where(kind == TRI, 3, 4)
    dup_side = np.zeros(m, bool)
    for a in range(4):
        for b in range(a + 1, 4):
            dup_side |= (fe[:, a] == fe[:, b]) & (fe[:, a] >= 0) & (b < nsides)
    if dup_side.any():
        ub[dup_side] = False
        ub[dup_side, _KEEP[kind[dup_side]]] = True
    q = kind == QUAD
    if reduce and q.any():
        first_better = W[:, 2:6] <= W[:, 6:10]
        ub[:, 6:10] &= ~(q[:, None] & first_better)
        ub[:, 2:6] &= ~(q[:, None] & ~first_better)
    # ---- rows: one option per face
    nvar = N_OPTIONS * m
    r1_ptr = np.arange(m + 1, dtype=np.int64) * N_OPTIONS
    r1_idx = np.arange(nvar, dtype=np.int64)
    # ---- rows: agreement on every edge with >= 2 faces (eq. 3), chained f0=f1, f1=f2, ...
    order = np.lexsort((topo.he_face, topo.he_edge))
    he_e = topo.he_edge[order]
    pair = np.flatnonzero(he_e[1:] == he_e[:-1])
    if not split_fixed:
        pair = pair[~fixed[he_e[pair]]]
    ha, hb = order[pair], order[pair + 1]
    fa, fb = topo.he_face[ha], topo.he_face[hb]
    oa = _SIDE_OPTS[kind[fa], topo.he_side[ha]]          # (p, 3)
    ob = _SIDE_OPTS[kind[fb], topo.he_side[hb]]
    nag = len(pair)
    r2_idx = np.concatenate([N_OPTIONS * fa[:, None] + oa, N_OPTIONS * fb[:, None] + ob], axis=1)
    r2_val = np.concatenate([np.ones((nag, 3)), -np.ones((nag, 3))], axis=1)
    A = sparse.csr_matrix(
        (np.concatenate([np.ones(nvar), r2_val.ravel()]),
         np.concatenate([r1_idx, r2_idx.ravel()]),
         np.concatenate([r1_ptr, nvar + 6 * np.arange(1, nag + 1, dtype=np.int64)])),
        shape=(m + nag, nvar))
    A.sum_duplicates()
    rhs = np.concatenate([np.ones(m), np.zeros(nag)])
    return SplitLP(W.ravel(), A, rhs, ub.ravel().astype(np.float64), W, kind, m)


def split_polygons(mesh: ShellMesh, *, c1: float = 1.0, c2: float = 1.0, fixed_edges=None,
                   split_fixed: bool = False, time_limit: float = SplitOptions.split_time_limit, project=None,
                   form: str = "squared", integrality_tol: float = 1e-6) -> tuple[ShellMesh, SplitResult]:
    """Split triangles and quads where that lowers the eq.-2 energy (paper eq. 1-3).

    Parameters
    ----------
    mesh : the whole conforming mesh (skin and members together; non-manifold edges allowed).
    c1, c2 : weights of the edge-length and angle terms of eq. 2.
    fixed_edges : (k, 2) node pairs never split; default ``mesh.feature_edges``.  Pairs that
        are not mesh edges are ignored.
    split_fixed : going beyond the paper, allow fixed edges to be split, but only by all of
        their incident faces together (the agreement rows tie every face around an edge,
        so a member junction stays conforming); a split feature edge is replaced by its two
        halves with the same owner id and its midpoint becomes a fixed vertex.
    time_limit : seconds for each HiGHS solve (LP, then MIP if the LP optimum is fractional);
        default the solver option ``split_time_limit``.
    project : optional ``project(points (k,3), parent_edges (k,2)) -> (k,3)`` moving the new
        midpoints (e.g. back onto the input surface).
    form : energy form, see :func:`polygon_energy`.
    integrality_tol : an LP solution farther than this from 0/1 counts as fractional.

    Returns the split mesh (input nodes keep their indices; new nodes are appended in order
    of their edge's sorted node pair; the children of a face replace it in place, in
    option-table order) and a :class:`SplitResult`.  If HiGHS finds no solution within the
    time limit, every polygon is kept and ``status`` says so. (The LP starts from keeping every
    polygon, so at its time limit it has a feasible vertex; that vertex is used if it is no
    worse than keeping every polygon, else every polygon is kept.)
    """
    t0 = time.perf_counter()
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("split_polygons needs a ShellMesh; build one with ShellMesh(points, faces)")
    m = mesh.n_faces
    lp = build_split_lp(mesh, c1=c1, c2=c2, fixed_edges=fixed_edges, split_fixed=split_fixed, form=form)
    kind, c, nvar = lp.kind, lp.c, N_OPTIONS * m
    act = np.flatnonzero(lp.ub > 0)       # columns bounded to 0 are left out of the model
    A_act = lp.A[:, act]
    keep_x = np.zeros((m, N_OPTIONS))
    keep_x[np.arange(m), _KEEP[kind]] = 1.0
    keep_x = keep_x.ravel()
    used_mip, integral = False, True
    lp_s = mip_s = 0.0
    status = "Optimal"
    x = keep_x
    if m:
        # the simplex starts from the basis of keeping every polygon (its keep option basic in
        # its row, every agreement row's slack basic): a feasible vertex a few dozen pivots from
        # the optimum on the corpus, where from HiGHS's own start it took one per polygon
        # (12,178 on the target case; its LP 0.14 -> 0.07 s, the same solution)
        row_basic = np.arange(lp.A.shape[0]) >= lp.n_choice_rows
        sol = highs_solve(c[act], A_act, lp.rhs, lp.rhs, lp.ub[act], integer=False, time_limit=time_limit,
                           basis=(keep_x[act] > 0, row_basic))
        lp_s, status = sol.seconds, sol.status
        if sol.x is None:
            status += " (no LP solution: kept all polygons)"
            integral = False
        elif status != "Optimal" and float(c[act] @ sol.x) > float(c @ keep_x):
            # stopped short (time limit) at a vertex worse than keeping every polygon
            status += " (LP stopped above keeping all polygons: kept all polygons)"
            integral = False
        else:
            x = np.zeros(nvar)
            x[act] = sol.x
            integral = bool(np.abs(sol.x - np.round(sol.x)).max(initial=0.0) <= integrality_tol)
            if not integral:
                used_mip = True
                sol = highs_solve(c[act], A_act, lp.rhs, lp.rhs, lp.ub[act], integer=True,
                                   time_limit=time_limit, start=keep_x[act])
                mip_s, status = sol.seconds, sol.status
                if sol.x is None:
                    x = keep_x
                    status += " (no MIP solution: kept all polygons)"
                else:
                    x = np.zeros(nvar)
                    x[act] = sol.x
    X = np.round(x.reshape(m, N_OPTIONS))
    choice = np.argmax(X, axis=1) if m else np.zeros(0, dtype=np.int64)
    bad_rows = (X.sum(1) != 1) | (X[np.arange(m), choice] * lp.ub.reshape(m, N_OPTIONS)[np.arange(m), choice] != 1)
    if bad_rows.any():
        raise SolverError(f"HiGHS returned an invalid splitting choice for {int(bad_rows.sum())} polygons "
                          f"(status {status}); report this with the input mesh")
    topo = mesh.topology()
    out, info = _apply_split(mesh, topo, kind, choice, project)
    counts = np.zeros((2, N_OPTIONS), dtype=np.int64)
    np.add.at(counts, (kind, choice), 1)
    res = SplitResult(status=status, objective=float(c @ X.ravel()), is_integral=integral,
                      used_mip=used_mip, option_counts=counts, seconds=time.perf_counter() - t0,
                      choice=choice, lp_seconds=lp_s, mip_seconds=mip_s, **info)
    return out, res


def split_mesh(mesh: ShellMesh, locator, infos,
               options: SplitOptions = SplitOptions()) -> tuple[ShellMesh, Supports, dict]:
    """The pipeline's split stage: :func:`split_polygons` on the whole mesh (chains, junctions
    and feature lines are never split), its new midpoints put onto the node supports
    (:func:`~shellmesh_mdao.core.supports.edge_midpoint_projector`), and the supports of the
    result (:func:`~shellmesh_mdao.core.supports.pipeline_supports`: input skin ``locator``,
    member planes of ``infos``, feature curves). ``options``: the stage's
    :class:`~shellmesh_mdao.options.SplitOptions` (``split_time_limit``: HiGHS's, per solve).

    Returns ``(mesh, supports, report)``, ``report`` the pipeline report's ``split`` entry."""
    before = mesh

    def supports_and_projector():
        s = pipeline_supports(before, locator, infos)
        return s, edge_midpoint_projector(before, s)

    # made in a second thread while split_polygons builds and solves its LP (HiGHS releases the
    # GIL): the same values as made before it (the target case's split stage 0.154 -> 0.139 s,
    # docs/benchmarks.md, fifteenth pass)
    made = Background(supports_and_projector)
    mesh, res = split_polygons(before, time_limit=options.split_time_limit,
                               project=lambda points, parent_edges: made.result()[1](points, parent_edges))
    sup = made.result()[0]
    # where no edge was split (the target case) the mesh is the same and so are its supports
    if not (supports_hold(before, mesh) and np.array_equal(mesh.faces, before.faces)
            and np.array_equal(mesh.component, before.component)):
        sup = pipeline_supports(mesh, locator, infos)
    report = {"status": res.status, "objective": float(res.objective), "used_mip": bool(res.used_mip),
              "n_split_edges": int(res.n_split_edges), "seconds": round(res.seconds, 4)}
    return mesh, sup, report


def _apply_split(mesh: ShellMesh, topo, kind, choice, project):
    """Build the split mesh from the chosen options (vectorised)."""
    faces = mesh.faces
    m = len(faces)
    fe = topo.face_edges
    side_split = _SPLITS[kind, choice] & (fe >= 0)                     # (m, 4)
    esplit = np.zeros(len(topo.edges), bool)
    esplit[fe[side_split]] = True
    he_ok = side_split[topo.he_face, topo.he_side] == esplit[topo.he_edge]
    if not he_ok.all():
        raise SolverError("splitting solution violates edge agreement (eq. 3) on "
                          f"{int((~he_ok).sum())} half-edges; report this with the input mesh")
    split_ids = np.flatnonzero(esplit)
    n0 = mesh.n_points
    new_id = np.full(len(topo.edges), -1, dtype=np.int64)
    new_id[split_ids] = n0 + np.arange(len(split_ids))
    parent_edges = topo.edges[split_ids]
    mid = 0.5 * (mesh.points[parent_edges[:, 0]] + mesh.points[parent_edges[:, 1]])
    if project is not None and len(mid):
        moved = np.asarray(project(mid.copy(), parent_edges.copy()), dtype=np.float64)
        if moved.shape != mid.shape or not np.isfinite(moved).all():
            raise ProjectionError(
                f"the project callback returned {moved.shape} (finite: {bool(np.isfinite(moved).all())}) "
                f"for {mid.shape} midpoints; it must return one finite 3-D point per new node")
        mid = moved
    points = np.vstack([mesh.points, mid])
    L = np.full((m, 9), -1, dtype=np.int64)
    L[:, :4] = faces
    L[:, 4:8] = np.where(side_split, new_id[np.maximum(fe, 0)], -1)
    ch = _CH[kind, choice]                                              # (m, 2, 4)
    g = np.take_along_axis(L, np.maximum(ch, 0).reshape(m, 8), axis=1).reshape(m, 2, 4)
    g = np.where(ch >= 0, g, -1)
    present = ch[:, :, 0] >= 0
    new_faces = g[present]
    parent_face = np.repeat(np.arange(m), present.sum(1))
    if len(new_faces) and ((new_faces[:, :3] < 0).any()):
        raise SolverError("internal error building split faces (missing midpoint); report this")
    comp = mesh.component[parent_face]
    # ---- feature edges: replace split ones by their halves (same owner id)
    fedges, fids = mesh.feature_edges, mesh.feature_edge_ids
    fixed_v = mesh.fixed_vertices
    if len(fedges) and len(split_ids):
        eid = topo.edge_ids(fedges)
        hit = (eid >= 0) & esplit[np.maximum(eid, 0)]
        if hit.any():
            mids = new_id[eid[hit]]
            halves = np.vstack([np.stack([fedges[hit, 0], mids], 1), np.stack([mids, fedges[hit, 1]], 1)])
            fedges = np.vstack([fedges[~hit], halves])
            fids = np.concatenate([fids[~hit], fids[hit], fids[hit]])
            fixed_v = np.concatenate([fixed_v, mids])
    out = ShellMesh(points, new_faces, comp, list(mesh.component_names), fixed_v, fedges, fids)
    info = dict(new_nodes=n0 + np.arange(len(split_ids), dtype=np.int64), parent_edges=parent_edges,
                parent_face=parent_face)
    return out, info
