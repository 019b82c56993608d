"""The merge stage: merging optimisation (Li & Hwang, paper Sec. IV.C.2, eq. 4-5).

One binary variable per candidate edge (an edge shared by exactly two triangles of
the same component, not fixed, whose merged quad passes the shape guards); at most
one merged edge per triangle (``A_m x_m <= 1``).  The weight of an edge is the
energy of the merged quad minus the energies of its two triangles (eq. 5 minus
eq. 2 twice); HiGHS minimises the summed weight as a MIP.

Energy of the merged quad (eq. 5, deviation form as in :mod:`.split`):

    e_m = c1 sum_i (l_i/l_avg - 1)^2 + c2 sum_i (theta_i/90deg - 1)^2 + c3 sum_i |e_i . n_q|

``e_i`` unit vector along side i, ``n_q`` unit normal from the cross product of the two
diagonals.  Eq. 5 prints ``sum e_i^T n_q`` without the absolute value; for a warped quad
those terms alternate in sign and nearly cancel, so the absolute value is used.

Guards (upper bound 0, i.e. the variable is not created): a corner scaled Jacobian
(measured against ``n_q``) at or below ``min_jacobian`` (so never a non-convex or
folded quad), a corner angle outside ``[min_angle, max_angle]``, or a dihedral angle
between the two triangles above ``max_dihedral``; also triangles traversing the shared
edge in the same direction (inconsistent orientation), since the quad could not be
oriented like both.  Edges with positive weight are left out as well (they are 0 in
every optimum).  Before the MIP, edges that belong to some optimal matching are fixed
by an exact reduction (:func:`~.triangles._safe_reduction`), which leaves HiGHS a much smaller
problem on real meshes.

With ``valence_weight`` > 0 (beyond the paper) the objective also counts, per interior
vertex, how far its valence in the merged mesh is from 4 (``lam |valence - 4|``, linear
with two slack columns per vertex): :func:`merge_triangles` explains the LP-then-MIP solve.

Modules: :mod:`.triangles` (candidates, energies, the MIP, the stage function :func:`merge_mesh`) and
:mod:`.kernels` (the exact reduction's compiled rounds).
"""
from .triangles import MergeResult, interior_vertices, merge_candidates, merge_mesh, merge_triangles, quad_energy

__all__ = ["MergeResult", "interior_vertices", "merge_candidates", "merge_triangles", "merge_mesh", "quad_energy"]
