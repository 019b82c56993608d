"""Smoothing optimisation (Li & Hwang, paper Sec. IV.C.3, eq. 6-8) along explicit vertex supports
(:mod:`shellmesh_mdao.core.supports`: every node is FIXED, slides on a CURVE, moves in a PLANE or on
the input SURFACE).

:func:`smooth` solves, per trust-region step, the paper's eq. 7

    min_D  E(x + D) + 1/2 sum_i rho_i |d_i|^2     s.t.   d_i in the tangent space of vertex i

with a quadratic energy E over the mesh edges (and optionally the quad diagonals).
``energy="length"`` is the quadratic model of the objective the paper states in
words, the sum of edge LENGTHS (pair weights 1/L frozen at the last refresh, so the
gradient is the sum of unit edge vectors); ``energy="squared"`` is eq. 6/7 as printed (sum
of squared lengths), optionally with rest lengths: ``target_edge``, or per vertex ``edge_size``
(the default, as the pipeline's option ``smooth_energy``; the pipeline's passes aim each edge at
the local size at its ends, :func:`local_edge_size`, so the remesh's grading stays). Beyond the paper,
``ortho_weight`` adds a quad-corner orthogonality term (zero for right angles at any
aspect ratio). The tangent constraint ``N D = 0`` is eliminated exactly with an
orthonormal tangent basis ``T`` (``D = T u``, null-space method): the same minimiser as the
KKT system eq. 8 (``solver="kkt"`` assembles eq. 8 literally; a test checks they agree),
with a symmetric positive definite matrix ``T^T A T + diag(rho)`` of half the size. That
matrix depends only on the mesh, the weights and the tangent frames, so it is built (and,
with ``solver="lu"``, factorised as L D L^T by ``qdldl``) once and reused for
``refresh`` steps, during which only the right-hand side changes; the default solves it by
Jacobi-preconditioned CG to :data:`CG_RTOL` (the regulariser keeps it well conditioned; at that
tolerance cheaper than the factorisation at every mesh size, see :data:`AUTO_LU_MAX_UNKNOWNS`).

Each step is clipped per vertex to ``trust`` times the distance to the nearest other
vertex (the paper's ``m D <= r``), the moved vertices are projected onto their supports,
and a vectorised line search halves the step of every vertex of an element that would
fold (scaled Jacobian, measured against the element's own normal and against its normal
before the step, at or below ``min_jacobian`` and lower than before) and of every vertex
whose projection jumps (landing farther from the tangent-plane point than the move, or
finding no input triangle facing the vertex's way nearby, e.g. only the opposite skin of
a thin trailing edge), and of every element the step would turn across its supports (further
than :data:`~.qp.STAND_ANGLE` from the support normal at every corner, and further than
before: a face dragged across a leading-edge nose tighter than itself).

Modules: :mod:`.qp` (the trust-region steps of :func:`smooth`; :func:`smooth_mesh`, the
pipeline's smooth stage), :mod:`.energy` (the energies and
their Hessian), :mod:`.linear` (the linear solves), :mod:`.untangling` (:func:`untangle`) and
:mod:`.elements` (element measures and :func:`mesh_figures`).
"""
from .energy import local_edge_size
from .elements import draped_vertices, element_min_sj, face_normals, mesh_figures, oriented_quality, tangent_basis
from .linear import CG_RTOL, LDL, LinearSolver
from .qp import AUTO_LU_MAX_UNKNOWNS, SmoothResult, smooth, smooth_mesh, smooth_report
from .untangling import untangle

__all__ = ["smooth", "smooth_mesh", "local_edge_size", "SmoothResult", "smooth_report", "untangle", "mesh_figures",
           "AUTO_LU_MAX_UNKNOWNS", "CG_RTOL", "LDL", "LinearSolver", "face_normals", "element_min_sj", "oriented_quality", "draped_vertices",
           "tangent_basis"]
