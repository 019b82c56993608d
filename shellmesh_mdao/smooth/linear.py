"""Linear solves of the smoothing QP: the reduced system by a sparse L D L^T factorisation
(:class:`LDL`, qdldl) or Jacobi-preconditioned conjugate gradients (:class:`LinearSolver`), and
the KKT system of eq. 8 assembled literally (:func:`solve_kkt`, a reference for small meshes)."""
from __future__ import annotations

import numpy as np
import qdldl
from scipy import sparse
from scipy.sparse import linalg as spla

__all__ = ["CG_RTOL", "LDL", "LinearSolver", "solve_kkt"]

#: relative residual at which the conjugate gradients stop. The solution is a trust-region step,
#: clipped to ``trust`` times the distance to the nearest vertex and then line-searched, so
#: solving it more finely buys nothing: on the target case's final smoothing (47k unknowns) 10-11
#: iterations instead of the 21-22 that 1e-6 took (36 at 1e-10), the step within about 1e-3 of the
#: exact one, and the corpus's quality figures the same to four decimals (docs/optimisation.md).
CG_RTOL = 1e-3


def solve_kkt(K3, rho_v, mesh_n, g, supports, T, owner):
    """Eq. 8 assembled literally: [[B, A^T], [A, 0]] [D; lam] = [-g; 0] with B = K x I3 +
    diag(rho) and one constraint row per normal direction of each vertex (3 for fixed).
    Used to check the null-space solve; returns D (n, 3)."""
    n = mesh_n
    # A = complement of T's columns in each vertex block
    dof = supports.dof()
    Td = T.toarray() if T.shape[0] <= 3000 else None
    if Td is None:
        raise ValueError("solver='kkt' is a reference implementation for small meshes (n <= 1000)")
    rows_A = []
    for v in range(n):                       # reference path only (small meshes)
        cols = np.flatnonzero(owner == v)
        B = Td[3 * v:3 * v + 3, cols]
        Q, _ = np.linalg.qr(np.hstack([B, np.eye(3)]))
        N = Q[:, dof[v]:3] if dof[v] else np.eye(3)
        for j in range(N.shape[1]):
            r = np.zeros(3 * n)
            r[3 * v:3 * v + 3] = N[:, j]
            rows_A.append(r)
    A = sparse.csr_matrix(np.array(rows_A))
    rho3 = np.repeat(rho_v, 3)
    B = (K3 + sparse.diags(rho3)).tocsc()
    KKT = sparse.bmat([[B, A.T], [A, None]], format="csc")
    rhs = np.concatenate([-g, np.zeros(A.shape[0])])
    sol = spla.spsolve(KKT, rhs)
    return sol[:3 * n].reshape(n, 3)


class LDL:
    """Sparse LDL^T factorisations (qdldl: AMD ordering, no pivoting) of symmetric positive
    definite matrices that share one sparsity pattern: the ordering and the symbolic
    factorisation are made for the first matrix and kept while the pattern repeats, only
    the numeric factorisation is redone. Same matrix, same bits."""

    def __init__(self):
        self.pattern = None
        self.solver = None

    def factor(self, indptr, indices, data):
        """Factorise the matrix whose UPPER triangle is the CSC ``(data, indices, indptr)``."""
        n = len(indptr) - 1
        U = sparse.csc_matrix((data, indices, indptr), shape=(n, n))
        if (self.pattern is not None and np.array_equal(self.pattern[0], indptr)
                and np.array_equal(self.pattern[1], indices)):
            self.solver.update(U, upper=True)
        else:
            self.solver = qdldl.Solver(U, upper=True)
            self.pattern = (indptr.copy(), indices.copy())
        return self.solver


class LinearSolver:
    """Solver of the reduced system H u = b (H symmetric positive definite, symmetric bit for
    bit): a sparse LDL^T factorisation (qdldl, AMD ordering; made once, reused for every
    right-hand side; with ``ldl`` an :class:`LDL` kept across the matrices of one pattern,
    the ordering too) or Jacobi-preconditioned conjugate gradients on the same matrix."""

    def __init__(self, H, method: str, ldl: LDL | None = None):
        self.method = method
        if method == "lu":
            U = sparse.triu(H, format="csc")
            self.lu = (LDL() if ldl is None else ldl).factor(U.indptr, U.indices, U.data)
        else:
            self.H = H.tocsr()
            d = self.H.diagonal()
            self.dinv = np.divide(1.0, d, out=np.zeros_like(d), where=d > 0)

    def solve(self, b, rtol: float = CG_RTOL, maxiter: int = 5000):
        if self.method == "lu":
            return self.lu.solve(b)
        x = np.zeros_like(b)
        r = b.copy()
        nb = float(np.sqrt(np.einsum("i,i->", b, b)))
        if nb == 0:
            return x
        z = r * self.dinv
        p = z.copy()
        rz = float(np.einsum("i,i->", r, z))
        for _ in range(maxiter):
            Ap = self.H @ p
            a = rz / float(np.einsum("i,i->", p, Ap))
            x += a * p
            r -= a * Ap
            if np.sqrt(np.einsum("i,i->", r, r)) <= rtol * nb:
                break
            z = r * self.dinv
            rz2 = float(np.einsum("i,i->", r, z))
            p *= rz2 / rz
            p += z
            rz = rz2
        return x
