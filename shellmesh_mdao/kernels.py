"""Compile every numba kernel of the package ahead of its first use.

The compiled kernels live beside the stage that uses them (``remesh/kernels.py``, ``imprint/kernels.py``,
``smooth/kernels.py``, ``merge/kernels.py``); the ones several stages share are in ``core/kernels.py`` and the
closest-point hierarchy of the input skin in ``core/bvh.py``. numba compiles each on its first call and caches the machine code next to its module
(``cache=True``): about 45 s once per install, 0.3 s to load afterwards. :func:`warm_up` calls every kernel
once on a tiny input, so that ``make install`` pays the compile and a benchmark loads them before its clock
starts. Each kernel returns the same arrays, bit for bit, as the numpy code it replaced (tests/test_kernels.py).
"""
from __future__ import annotations

import numpy as np

__all__ = ["warm_up"]


def warm_up() -> float:
    """Compile every kernel (or load it from numba's cache) on a tiny input; returns the
    seconds it took (about 45 s on a new install, 0.3 s once cached). Run by ``make install``
    and by the benchmark before its clock starts."""
    import time

    from .core.kernels import (arc_links, arc_order, chain_walk, closest_on_curves, cross_rows, dot_norm_rows,
                               dot_rows, dot_unit_rows, edge_lookup, edge_rows, edge_table, faces_at,
                               greedy_independent, in_range, norm_rows, segments_scan, stable_order,
                               stable_pair_order, vertex_faces)
    from .imprint.kernels import (centroid_d2, corner_cosines, segments_within, skin_flips, star_independent,
                                  star_moves)
    from .merge.kernels import safe_matching_rounds
    from .core.bvh import TriangleBVH, closest_on_triangles
    from .remesh.kernels import (collapse_apply, collapse_directions, collapse_select, common_neighbour_counts,
                                 corner_sin_cos, edge_lengths, edge_neighbours, facing_ok, flip_candidates,
                                 greedy_independent_rings, group_order, move_tests, rank_desc, triangle_normals)
    from .smooth.kernels import (ReducedHessian, corner_max_turn, corner_sums, element_normals, face_quality,
                                 min_corner_sj, nearest_other_distance, ortho_gradient, ortho_jacobian,
                                 pair_difference)

    t0 = time.perf_counter()
    greedy_independent(np.array([0, 1, 1]), np.array([0, 0, 1]), np.array([1, 2]), 2,
                       check=lambda w: np.ones(len(w), bool), max_sub=3)
    greedy_independent_rings(np.array([0, 1, 2]), np.array([1, 0]), np.array([0]), np.array([1]), np.array([1]))
    common_neighbour_counts(np.array([0, 1, 2]), np.array([1, 0]), np.array([0]), np.array([1]))
    ortho_jacobian(np.array([0]), np.array([1]), np.array([2]), np.array([[0.0, 0.0, 1.0]]), np.ones(1),
                   np.ones(1), np.ones(1), np.array([0, 2, 4]), np.array([2, 2, 0]), np.eye(3)[[0, 1, 0, 1]])
    ortho_gradient([0], [1], [2], np.array([[0.0, 0.0, 1.0]]), np.ones(1), np.ones(1), np.ones(1), np.eye(3), 3)
    chain_walk(np.array([[0, 1], [0, 2], [1, 2], [2, 3]]), 4)
    arc_links(np.array([0, 1, 3]), np.array([1, 2, 4]), 5, 0)
    arc_order(np.array([0, 1, 2]), np.array([1, 2, 0]), 3, 0)
    segments_scan(np.zeros((1, 3)), [0], [1], np.zeros((1, 3)), np.ones((1, 3)))
    segments_within(np.zeros((1, 3)), np.zeros((1, 3)), np.ones((1, 3)), 1.0)
    corner_sums(np.array([[0, 1, 2, -1]]), np.ones((1, 3)), 3)
    centroid_d2(np.eye(3), np.array([[0, 1, 2]]), np.zeros(3))
    corner_max_turn(np.array([[0, 1, 2, -1]]), np.eye(3), np.ones((1, 3)), 3)
    pair_difference(np.array([0]), np.array([1]), np.ones(1), np.ones((1, 3)), 2)
    rh = ReducedHessian(np.array([0, 1, 2, 3]), np.array([1, 2, 3, 0]), np.array([[0, 1, 2, 3]]),
                        np.array([2, 2, 1, 0]), np.array([0, 2, 4, 5]))
    rh.values(np.eye(3)[[0, 1, 0, 1, 2]], np.ones(4), np.ones(5),
              ortho=(np.tile([0.0, 0.0, 1.0], (4, 1)), np.ones(4), np.ones(4), np.ones(4)),
              warp=(np.array([0]), np.ones((1, 4, 3)), np.ones(1)))
    min_corner_sj(np.eye(3), np.array([[0, 1, 2, -1]]), np.array([True]), np.array([[0.0, 0.0, 1.0]]))
    min_corner_sj(np.eye(3), np.array([[0, 1, 2, -1]]), np.array([True]))
    face_quality(np.zeros((1, 4, 3)), np.array([True]), np.array([[0.0, 0.0, 1.0]]))
    stable_order(np.array([1, 0, 1]), 2)
    stable_pair_order(np.array([1, 0]), np.array([0, 1]), 2)
    rank_desc(np.array([1.0, 0.0]), np.array([3, 2], np.uint64))
    group_order(np.array([1, 0, 1]), 2)
    edge_neighbours(np.array([[0, 1]]), 2)
    vertex_faces(np.array([[0, 1, 2, -1]]), 3)
    vertex_faces(np.array([[0, 1, 2]]), 3)
    closest_on_triangles(np.ones((1, 3)), np.zeros((1, 3)), np.eye(3)[:1], np.eye(3)[1:2])
    TriangleBVH(np.eye(3), np.array([[0, 1, 2]])).closest(np.ones((1, 3)))
    nearest_other_distance(np.eye(3), np.array([0, 2]), 0.5)
    star_independent(np.array([0, 1]), np.array([0, 1, 2]), np.array([0, 0]), 1)
    in_range(np.zeros(1, np.int64), 1)
    safe_matching_rounds([0], [1], [-1.0], 2)
    closest_on_curves(np.zeros((1, 3)), [0], [0], [1], np.zeros((1, 3)), np.ones((1, 3)), [np.sqrt(3.0)])
    e = np.eye(3)
    cross_rows(e, e)
    norm_rows(e)
    dot_rows(e, e)
    dot_norm_rows(e)
    dot_unit_rows(e)
    edge_lengths(e, np.array([[0, 1]]))
    triangle_normals(e, np.array([[0, 1, 2]]))
    element_normals(np.vstack([e, [1.0, 1.0, 0.0]]), np.array([[0, 1, 2, -1], [0, 1, 3, 2]]), np.array([True, False]))
    faces_at(np.array([0, 1, 2, 2]), np.array([0, 0]), np.array([0, 2]), 1)
    corner_sin_cos(e[:1], e[1:2], e[2:])
    Q = np.zeros((2, 3, 3))
    corner_sin_cos(Q[:, 0], Q[:, 1], Q[:, 2])           # the strided corners of a (k, 3, 3) array
    corner_cosines(e[None])
    facing_ok(np.array([[0, 1, 2]]), np.zeros(3, np.int64), np.zeros(3, np.int64), e, e[:1], 0.5)
    for surf in (None, (TriangleBVH(e, np.array([[0, 1, 2]])), np.zeros(3))):
        collapse_select(np.array([0, 2, 4, 6]), np.array([1, 2, 0, 2, 0, 1]), np.array([0, 1, 2, 3]),
                        np.zeros(3, np.int64), np.array([[0, 1, 2]]), e, np.ones(3), np.array([0]), np.array([1]),
                        np.array([1]), np.array([[True, True]]), max_len_ratio=2.0, fn_old=e[2:], cos_turn=0.5,
                        kind=np.zeros(3, np.int64), vtri=np.zeros(3, np.int64), tri_n=e[:1], cos_facing=0.2,
                        surface=surf)
    Fq = np.array([[0, 1, 2], [1, 0, 3]])
    for dg in (None, np.full(4, 3.0)):
        flip_candidates(np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3]]), np.array([0, 3, 5, 5, 5]),
                        np.array([0, 2, 4, 1, 5]), np.array([3, -1, -1, -1, -1]), np.zeros(5, bool), Fq,
                        np.zeros(2, np.int64), np.vstack([e, [1.0, -1.0, 0.0]]), 0.5, np.zeros(4, np.int64),
                        np.zeros(4, np.int64), e, 0.2, dg, dg)
    _, h0, h1, cnt, E, _ = edge_table(Fq, 4)
    nptr4, nbr4 = edge_neighbours(E, 4)
    collapse_apply(Fq, np.zeros(2, np.int64), np.array([[0, 1], [1, 3]]), np.array([0, -1]), [3], [0], 4)
    for rf in (None, [3]):
        collapse_directions(E, [0, 1], h0, h1, cnt, Fq, nptr4, nbr4, np.zeros(4, np.int64), np.zeros(5, bool),
                            np.ones(4, bool), remove_first=rf)
    skin_flips(E, np.array([0, 3, 5, 5, 5]), h0, h1, cnt, np.zeros(5, bool), Fq, np.vstack([e, [1.0, -1.0, 0.0]]),
               0.5)
    move_tests(e, np.array([[0, 1, 2]]), e[2:], np.ones(1), np.array([True, False, False]), np.zeros(3, np.int64),
               np.zeros(3, np.int64), np.ones(3, bool), e, 0.5, 0.2)
    star_moves(np.array([0]), np.array([0]), Fq, np.vstack([e, [1.0, -1.0, 0.0]]), np.ones((4, 3)), np.ones((2, 3)))
    edge_lookup(np.array([[0, 1], [0, 2], [1, 2]]), np.array([0, 2, 3, 3]), np.array([0, 2]), np.array([1, 1]))
    edge_rows(np.array([[0, 1], [0, 2], [1, 2]]), 3)
    return time.perf_counter() - t0
