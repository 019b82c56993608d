"""HiGHS calls of the split and merge stages: an LP or MIP passed in one piece
(:func:`highs_solve`), and an LP whose rows fall apart into blocks solved as two halves side by
side (:func:`highs_solve_halves`)."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ..errors import SolverError
from .threads import Background

__all__ = ["HighsResult", "highs_solve", "highs_solve_halves", "LP_HALF_MIN"]


@dataclass
class HighsResult:
    """Outcome of :func:`highs_solve`: the primal solution ``x`` (None when HiGHS found none),
    HiGHS's model-status string, objective, achieved relative MIP gap (0 for an LP), wall time
    and the MIP's dual bound (the objective for an LP)."""

    x: np.ndarray | None
    status: str
    objective: float
    mip_gap: float
    seconds: float
    dual_bound: float = float("nan")


def _highs_core(highspy):
    """HiGHS's solver class without highspy's Python wrapper, whose constructor turns on its
    callbacks and with them prints HiGHS's banner to standard output before any option can
    be set (highspy 1.16); the wrapper where the core is not exposed. We use no callbacks."""
    try:
        from highspy._core import _Highs
    except ImportError:  # pragma: no cover - other highspy layouts
        return highspy.Highs
    return _Highs


def highs_solve(c, A: sparse.csr_matrix, row_lo, row_hi, ub, *, integer: bool, time_limit: float,
                 mip_gap: float | None = None, start: np.ndarray | None = None,
                 presolve: bool | None = None, basis: tuple | None = None) -> HighsResult:
    """Solve ``min c^T x, row_lo <= A x <= row_hi, 0 <= x <= ub`` with HiGHS.

    ``presolve``: HiGHS's presolve on or off; default (None) off for an LP and HiGHS's
    choice for a MIP.
    ``basis``: for an LP, ``(basic columns, basic rows)`` (two bool masks, as many basic as
    there are rows, the basis matrix nonsingular): the simplex starts from it, every other
    column at its lower bound and every other row at its lower side.

    The model is passed in one piece (row-wise CSR, numpy arrays).  Returns the primal
    solution (None when HiGHS found none), HiGHS's model-status string, objective,
    achieved relative MIP gap (0 for an LP) and wall time."""
    try:
        import highspy
    except ImportError as exc:  # pragma: no cover - highspy is a hard dependency
        raise SolverError("highspy (HiGHS) is not installed: run `pip install highspy`") from exc
    t0 = time.perf_counter()
    n = len(c)
    A = sparse.csr_matrix(A)
    A.sort_indices()
    h = _highs_core(highspy)()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("random_seed", 0)
    h.setOptionValue("presolve", ("choose" if integer else "off") if presolve is None else
                     ("on" if presolve else "off"))
    h.setOptionValue("time_limit", float(time_limit))
    if mip_gap is not None:
        h.setOptionValue("mip_rel_gap", float(mip_gap))
    # the arrays go to HiGHS as they are (passModel's array form: a HighsLp's fields are copied
    # element by element through Python, 20 ms for the split LP's 24k columns and 0.3M entries)
    f64 = [np.ascontiguousarray(v, dtype=np.float64) for v in (c, np.zeros(n), ub, row_lo, row_hi, A.data)]
    a_start, a_index = (np.ascontiguousarray(v, dtype=np.int32) for v in (A.indptr, A.indices))
    integrality = np.full(n, int(highspy.HighsVarType.kInteger) if integer else int(highspy.HighsVarType.kContinuous),
                          np.int32)
    st = h.passModel(int(n), int(A.shape[0]), int(A.nnz), int(highspy.MatrixFormat.kRowwise),
                     int(highspy.ObjSense.kMinimize), 0.0, *f64[:5], a_start, a_index, f64[5], integrality)
    if st == highspy.HighsStatus.kError:
        raise SolverError("HiGHS rejected the optimisation model (internal error); "
                          "report this with the input mesh")
    if integer and start is not None:
        # the start is the incumbent HiGHS's feasibility-jump heuristic would look for first;
        # skipping it halves the merge's solve (0.13 -> 0.06 s on the target case, the same
        # solution). HiGHS releases before the option ignore it (an error status, no change)
        h.setOptionValue("mip_heuristic_run_feasibility_jump", False)
        sol = highspy.HighsSolution()
        sol.col_value = np.asarray(start, dtype=np.float64)
        sol.value_valid = True
        h.setSolution(sol)
    if basis is not None and not integer:
        col_basic, row_basic = basis
        status_of = np.array([highspy.HighsBasisStatus.kLower, highspy.HighsBasisStatus.kBasic], dtype=object)
        b = highspy.HighsBasis()
        b.col_status = status_of[np.asarray(col_basic, bool).astype(np.intp)].tolist()
        b.row_status = status_of[np.asarray(row_basic, bool).astype(np.intp)].tolist()
        b.valid = True
        if h.setBasis(b) == highspy.HighsStatus.kError:
            raise SolverError("HiGHS rejected the starting basis (internal error); report this with the input mesh")
    h.run()
    ms = h.getModelStatus()
    status = h.modelStatusToString(ms)
    info = h.getInfo()
    has_x = info.primal_solution_status == 2    # kSolutionStatusFeasible
    x = np.asarray(h.getSolution().col_value, dtype=np.float64) if has_x else None
    obj = float(info.objective_function_value) if has_x else float("nan")
    gap = float(info.mip_gap) if integer else 0.0
    bound = float(info.mip_dual_bound) if integer else obj
    return HighsResult(x, status, obj, gap, time.perf_counter() - t0, bound)


#: fewest columns the smaller half of an LP needs before :func:`highs_solve_halves` solves it in
#: a thread of its own (a thread and its HiGHS scheduler cost about 0.2 ms: a 2-column LP 0.53 ms
#: in a new thread against 0.31 ms in the caller's; the row-column components about 5 ms at 24k
#: columns)
LP_HALF_MIN = 2000


def _independent_halves(A: sparse.csr_matrix):
    """Two groups of the columns and rows of ``A`` that share no row: the connected components of
    its row-column graph, the largest first (ties: the lowest column), a component to the second
    group when more than half of all the columns come before its middle. Returns
    ``((cols0, rows0), (cols1, rows1))``, each sorted; rows without columns go to the first."""
    from scipy.sparse.csgraph import connected_components

    m, n = A.shape
    G = sparse.bmat([[None, A], [A.T, None]], format="csr")
    ncomp, lab = connected_components(G, directed=False)
    clab, rlab = lab[m:], lab[:m]
    size = np.bincount(clab, minlength=ncomp)
    first = np.full(ncomp, n, np.int64)
    u, at = np.unique(clab, return_index=True)
    first[u] = at
    order = np.lexsort((first, -size))
    mid = np.cumsum(size[order]) - 0.5 * size[order]
    second = np.zeros(ncomp, bool)
    second[order] = mid > 0.5 * n
    second[size == 0] = False
    return ((np.flatnonzero(~second[clab]), np.flatnonzero(~second[rlab])),
            (np.flatnonzero(second[clab]), np.flatnonzero(second[rlab])))


def highs_solve_halves(c, A: sparse.csr_matrix, row_lo, row_hi, ub, *, time_limit: float) -> HighsResult:
    """The LP of :func:`highs_solve` (``integer=False``), solved as two independent halves
    (:func:`_independent_halves`) side by side, one in a second thread (HiGHS releases the GIL),
    when the smaller half has at least :data:`LP_HALF_MIN` columns; else in one piece. An LP
    whose rows fall apart into blocks is its blocks' LPs side by side: the same optimal
    objective, though where the optimum is not unique another optimal vertex may come out.
    Status "Optimal" when both halves are optimal, else the first other status; the objective
    the sum; ``seconds`` the wall time of the whole."""
    t0 = time.perf_counter()
    A = sparse.csr_matrix(A)
    halves = _independent_halves(A) if A.shape[1] >= 2 * LP_HALF_MIN else None
    if halves is None or min(len(h[0]) for h in halves) < LP_HALF_MIN:
        return highs_solve(c, A, row_lo, row_hi, ub, integer=False, time_limit=time_limit)
    c, row_lo, row_hi, ub = (np.asarray(a, dtype=np.float64) for a in (c, row_lo, row_hi, ub))
    (c0, r0), (c1, r1) = halves
    other = Background(lambda: highs_solve(c[c1], A[r1][:, c1], row_lo[r1], row_hi[r1], ub[c1], integer=False,
                                             time_limit=time_limit))
    s0 = highs_solve(c[c0], A[r0][:, c0], row_lo[r0], row_hi[r0], ub[c0], integer=False, time_limit=time_limit)
    s1 = other.result()
    status = next((s.status for s in (s0, s1) if s.status != "Optimal"), "Optimal")
    if s0.x is None or s1.x is None:
        return HighsResult(None, status, float("nan"), 0.0, time.perf_counter() - t0)
    x = np.empty(len(c))
    x[c0] = s0.x
    x[c1] = s1.x
    obj = s0.objective + s1.objective
    return HighsResult(x, status, obj, 0.0, time.perf_counter() - t0, obj)
