"""The compiled kernels give the same sets and counts as the whole-array numpy code they replace."""
import numpy as np
import pytest

from scipy import sparse

from shellmesh_mdao.core.kernels import greedy_independent, stable_order, stable_pair_order
from shellmesh_mdao.core.kernels import closest_on_curves
from shellmesh_mdao.smooth.kernels import ReducedHessian, min_corner_sj, ortho_gradient, ortho_jacobian
from shellmesh_mdao.remesh.kernels import common_neighbour_counts, greedy_independent_rings
from shellmesh_mdao.mesh import cross_rows


def _batch_reference(owner, res, rank, nres, alive, check, max_sub):
    """The sub-rounds on whole arrays (the remesh's selection before the kernel)."""
    ncand = len(rank)
    alive = alive.copy()
    sel = np.zeros(ncand, bool)
    taken = np.zeros(nres, bool)
    o, r = owner, res
    for _ in range(max_sub):
        m = alive[o]
        o, r = o[m], r[m]
        if not len(o):
            break
        best = np.zeros(nres, np.int64)
        np.maximum.at(best, r, rank[o])
        lose = np.zeros(ncand, bool)
        lose[o[best[r] != rank[o]]] = True
        win = np.flatnonzero(alive & ~lose)
        if not len(win):
            break
        good = check(win)
        alive[win[~good]] = False
        win = win[good]
        if len(win):
            sel[win] = True
            wmask = np.zeros(ncand, bool)
            wmask[win] = True
            taken[r[wmask[o]]] = True
            alive[win] = False
            alive[o[taken[r]]] = False
        if not alive.any():
            break
    return sel


def _random_case(rng, ncand, nres, per):
    owner = np.repeat(np.arange(ncand), rng.integers(1, per + 1, ncand))
    res = rng.integers(0, nres, len(owner))
    rank = rng.permutation(ncand) + 1
    return owner, res, rank


@pytest.mark.parametrize("seed", range(12))
def test_greedy_independent_matches_the_batch_sub_rounds(seed):
    rng = np.random.default_rng(seed)
    ncand, nres = int(rng.integers(1, 3000)), int(rng.integers(1, 2000))
    owner, res, rank = _random_case(rng, ncand, nres, int(rng.integers(1, 20)))
    alive = rng.random(ncand) < 0.9
    bad = rng.random(ncand) < 0.3            # winners the check turns down

    def check(win):
        return ~bad[win]

    for max_sub in (1, 2, 3, 16):
        ref = _batch_reference(owner, res, rank, nres, alive, check, max_sub)
        got = greedy_independent(owner, res, rank, nres, alive=alive, check=check, max_sub=max_sub)
        assert np.array_equal(got, ref), (seed, max_sub)
    # ranks need not be 1..ncand: only their order counts
    got = greedy_independent(owner, res, 7 * rank + 3, nres, alive=alive, check=check, max_sub=16)
    assert np.array_equal(got, _batch_reference(owner, res, rank, nres, alive, check, 16))
    # without a check: every winner is kept, no two kept candidates share a resource
    got = greedy_independent(owner, res, rank, nres, max_sub=64)
    assert np.array_equal(got, _batch_reference(owner, res, rank, nres, np.ones(ncand, bool),
                                                lambda w: np.ones(len(w), bool), 64))
    used = res[got[owner]]
    pairs = np.unique(np.stack([owner[got[owner]], used], 1), axis=0)
    assert len(np.unique(pairs[:, 1])) == len(pairs[:, 1])


def test_greedy_independent_hands_the_check_each_sub_round_in_order():
    # a chain of candidates sharing resources: 0-1 share r0, 1-2 share r1, ...; ranks rise along
    # the chain, so the sub-rounds go from the top down, two candidates apart
    n = 7
    owner = np.repeat(np.arange(n), 2)
    res = np.stack([np.arange(n) - 1, np.arange(n)], 1).reshape(-1)
    keep = res >= 0
    owner, res = owner[keep], res[keep]
    rank = np.arange(n) + 1
    seen = []

    def check(win):
        seen.append(win.tolist())
        return win != 6                  # the top one is turned down: the next one wins instead

    sel = greedy_independent(owner, res, rank, n, check=check, max_sub=16)
    assert seen == [[6], [5], [3], [1]]
    assert np.flatnonzero(sel).tolist() == [1, 3, 5]


def _random_graph(rng, n, per=3):
    """Edges (unique, sorted pairs) and CSR neighbour lists of a random graph on n vertices."""
    e = np.unique(np.sort(rng.integers(0, n, (per * n, 2)), 1), axis=0)
    e = e[e[:, 0] != e[:, 1]]
    src = np.concatenate([e[:, 0], e[:, 1]])
    dst = np.concatenate([e[:, 1], e[:, 0]])
    o = np.argsort(src, kind="stable")
    nptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(src, minlength=n), out=nptr[1:])
    return e, nptr, dst[o]


@pytest.mark.parametrize("seed", range(6))
def test_greedy_independent_rings_matches_listed_entries(seed):
    # the collapses' lock regions: an edge (u, v) uses the 1-rings of both ends
    rng = np.random.default_rng(50 + seed)
    n = int(rng.integers(3, 1500))
    e, nptr, nbr = _random_graph(rng, n)
    u, v = e[:, 0], e[:, 1]
    cnt_u, cnt_v = np.diff(nptr)[u], np.diff(nptr)[v]
    owner = np.concatenate([np.repeat(np.arange(len(e)), cnt_u), np.repeat(np.arange(len(e)), cnt_v)])
    res = np.concatenate([np.concatenate([nbr[nptr[a]:nptr[a + 1]] for a in u] + [np.zeros(0, np.int64)]),
                          np.concatenate([nbr[nptr[b]:nptr[b + 1]] for b in v] + [np.zeros(0, np.int64)])])
    rank = rng.permutation(len(e)) + 1
    alive = rng.random(len(e)) < 0.8
    bad = rng.random(len(e)) < 0.25

    def check(win):
        return ~bad[win]

    ref = _batch_reference(owner, res, rank, n, alive, check, 16)
    got = greedy_independent_rings(nptr, nbr, u, v, rank, alive=alive, check=check, max_sub=16)
    assert np.array_equal(got, ref)
    assert got.sum() > 0


@pytest.mark.parametrize("seed", range(6))
def test_common_neighbour_counts_match_a_sort(seed):
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(2, 400))
    e, nptr, nbr = _random_graph(rng, n, per=5)
    u, v = e[:, 0], e[:, 1]
    ref = np.array([len(set(nbr[nptr[a]:nptr[a + 1]]) & set(nbr[nptr[b]:nptr[b + 1]])) for a, b in zip(u, v)],
                   dtype=np.int64)
    assert np.array_equal(common_neighbour_counts(nptr, nbr, u, v), ref)


def _ortho_reference(a, b, c, n, su, sv, sw, col_start, ncol, tv):
    """The whole-array assembly the kernel replaced: COO entries per role and tangent column,
    summed into CSR by scipy."""
    m, k = len(a), len(tv)
    rows, cols, vals = [], [], []
    rr = 3 * np.arange(m)
    for role, v in enumerate((a, b, c)):
        for jc in range(3):
            sel = np.flatnonzero(ncol[v] > jc)
            if not len(sel):
                continue
            col = col_start[v[sel]] + jc
            t, s_u, s_v = tv[col], su[sel, None], sv[sel, None]
            nx = cross_rows(n[sel], t)
            vec = s_u * t if role == 0 else (-s_u * t + s_v * nx if role == 1 else -s_v * nx)
            rows.append((rr[sel][:, None] + np.arange(3)).ravel())
            cols.append(np.repeat(col, 3))
            vals.append((vec * sw[sel, None]).ravel())
    return sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * m, k))


@pytest.mark.parametrize("seed", range(6))
def test_ortho_jacobian_matches_the_scipy_assembly(seed):
    rng = np.random.default_rng(200 + seed)
    nv = int(rng.integers(4, 300))
    ncol = rng.integers(0, 4, nv)                    # fixed, curve, plane/surface, free vertices
    ncol[rng.permutation(nv)[:3]] = 3
    col_start = np.concatenate([[0], np.cumsum(ncol)[:-1]])
    k = int(ncol.sum())
    if seed % 2:                                      # columns not in vertex order
        perm = rng.permutation(nv)
        start = np.concatenate([[0], np.cumsum(ncol[perm])[:-1]])
        col_start = np.empty(nv, np.int64)
        col_start[perm] = start
    m = int(rng.integers(1, 500))
    abc = np.array([rng.choice(nv, 3, replace=False) for _ in range(m)])
    a, b, c = abc.T
    n = rng.normal(size=(m, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    su, sv, sw = rng.uniform(0.1, 3.0, (3, m))
    su[::7] = 0.0                                     # a corner with a zero-length arm
    tv = rng.normal(size=(k, 3))
    data, indices, indptr = ortho_jacobian(a, b, c, n, su, sv, sw, col_start, ncol, tv)
    ref = _ortho_reference(a, b, c, n, su, sv, sw, col_start, ncol, tv)
    assert ref.has_sorted_indices
    assert np.array_equal(indptr, ref.indptr)
    assert np.array_equal(indices, ref.indices)
    assert np.array_equal(data, ref.data)            # the same bits, so the same Hessian and solve


@pytest.mark.parametrize("seed", range(4))
def test_ortho_gradient_matches_bincounts_and_the_jacobian(seed):
    rng = np.random.default_rng(250 + seed)
    nv = int(rng.integers(3, 200))
    m = int(rng.integers(1, 400))
    a, b, c = np.array([rng.choice(nv, 3, replace=False) for _ in range(m)]).T
    n = rng.normal(size=(m, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    su, sv, w = rng.uniform(0.1, 3.0, (3, m))
    x = rng.normal(size=(nv, 3)) * 10.0 ** rng.uniform(-3, 3)
    got = ortho_gradient(a, b, c, n, su, sv, w, x, nv)
    # the numpy version it replaced: residuals, then one bincount per role and axis
    r = su[:, None] * (x[a] - x[b]) - sv[:, None] * cross_rows(n, x[c] - x[b])
    wr = w[:, None] * r
    nwr = cross_rows(n, wr)
    ref = np.zeros((nv, 3))
    for v, gv in ((a, su[:, None] * wr), (b, -su[:, None] * wr - sv[:, None] * nwr), (c, sv[:, None] * nwr)):
        for d in range(3):
            ref[:, d] += np.bincount(v, weights=gv[:, d], minlength=nv)
    assert np.array_equal(got, ref)
    # r is linear in x: the gradient is J^T J x with J = sqrt(w) dr/dx (ortho_jacobian, full 3D columns)
    J = sparse.csr_matrix(ortho_jacobian(a, b, c, n, su, sv, np.sqrt(w), 3 * np.arange(nv), np.full(nv, 3),
                                         np.tile(np.eye(3), (nv, 1))), shape=(3 * m, 3 * nv))
    assert np.allclose(got.ravel(), J.T @ (J @ x.ravel()), rtol=1e-9, atol=1e-9 * np.abs(ref).max())


@pytest.mark.parametrize("seed", range(6))
def test_reduced_hessian_matches_the_scipy_products(seed):
    """The smoothing's Hessian assembled by ReducedHessian equals T^T (K (x) I) T + fo J_o^T J_o
    + fw J_w^T J_w + diag(rho) built with scipy products (the assembly it replaced), is
    symmetric bit for bit, and its pattern holds every coupling of two vertices with columns."""
    rng = np.random.default_rng(900 + seed)
    nq = int(rng.integers(1, 150))
    nv = 4 * nq // 2 + 8
    quads = np.array([rng.choice(nv, 4, replace=False) for _ in range(nq)])
    pairs = np.unique(np.sort(np.vstack([quads[:, [0, 1]], quads[:, [1, 2]], quads[:, [2, 3]], quads[:, [3, 0]]]),
                              axis=1), axis=0)
    ncol = rng.integers(0, 3, nv)                     # fixed, curve, plane/surface vertices
    ncol[rng.permutation(nv)[:2]] = 3
    col_start = np.concatenate([[0], np.cumsum(ncol)[:-1]])
    k = int(ncol.sum())
    owner = np.repeat(np.arange(nv), ncol)
    tv = rng.normal(size=(k, 3))
    pw = rng.uniform(0.2, 2.0, len(pairs))
    rho = rng.uniform(0.0, 1.0, k)
    # orthogonality corners of every quad, planarity rows of some
    a = np.roll(quads, 1, axis=1).ravel()
    b = quads.ravel()
    c = np.roll(quads, -1, axis=1).ravel()
    n = rng.normal(size=(len(b), 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    su, sv, sw = rng.uniform(0.1, 3.0, (3, len(b)))
    wsel = rng.random(nq) < 0.5
    wq = quads[wsel]
    wm = rng.normal(size=(len(wq), 4, 3))
    wsw = rng.uniform(0.1, 2.0, len(wq))
    fo, fw = 0.7, 1.3
    hess = ReducedHessian(pairs[:, 0], pairs[:, 1], quads, ncol, col_start)
    H = hess.matrix(hess.values(tv, pw, rho, ortho=(n, su, sv, sw), fo=fo, warp=(np.flatnonzero(wsel), wm, wsw),
                                fw=fw))
    assert H.has_sorted_indices
    T = sparse.csr_matrix((tv.ravel(), ((3 * owner[:, None] + np.arange(3)).ravel(), np.repeat(np.arange(k), 3))),
                          shape=(3 * nv, k))
    i, j = pairs.T
    K = sparse.coo_matrix((np.concatenate([pw, pw, -pw, -pw]), (np.concatenate([i, j, i, j]),
                                                                np.concatenate([i, j, j, i]))), shape=(nv, nv))
    Jo = sparse.csr_matrix(ortho_jacobian(a, b, c, n, su, sv, sw, col_start, ncol, tv), shape=(3 * len(b), k))
    sig = np.array([1.0, -1.0, 1.0, -1.0])
    Jw = np.zeros((len(wq), k))
    for kk in range(4):
        for jc in range(3):
            sel = np.flatnonzero(ncol[wq[:, kk]] > jc)
            col = col_start[wq[sel, kk]] + jc
            Jw[sel, col] += sig[kk] * wsw[sel] * np.einsum("ij,ij->i", wm[sel, kk], tv[col])
    ref = (T.T @ sparse.kron(K, sparse.identity(3)) @ T + fo * (Jo.T @ Jo) + fw * sparse.csr_matrix(Jw.T @ Jw)
           + sparse.diags(rho)).toarray()
    got = H.toarray()
    assert np.allclose(got, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    assert np.array_equal(got, got.T)
    # two threads, each filling the rows of one vertex range: the same bits as one
    hess.MIN_THREADED = 0
    d1 = hess.values(tv, pw, rho, ortho=(n, su, sv, sw), fo=fo, warp=(np.flatnonzero(wsel), wm, wsw), fw=fw, threads=1)
    d2 = hess.values(tv, pw, rho, ortho=(n, su, sv, sw), fo=fo, warp=(np.flatnonzero(wsel), wm, wsw), fw=fw, threads=2)
    assert np.array_equal(d1, H.data) and np.array_equal(d2, H.data)
    # the pattern: every nonzero of the reference is in it, and only couplings of pairs and quads
    Hp = sparse.csr_matrix((np.ones(H.nnz), H.indices, H.indptr), shape=(k, k)).toarray() > 0
    assert (ref[~Hp] == 0).all()
    near = np.zeros((nv, nv), bool)
    near[np.arange(nv), np.arange(nv)] = True
    for q in quads:
        near[np.ix_(q, q)] = True
    assert np.array_equal(Hp, near[np.ix_(owner, owner)])
    # no quad terms: the pattern is the pairs' alone
    hp = ReducedHessian(pairs[:, 0], pairs[:, 1], np.zeros((0, 4), np.int64), ncol, col_start)
    Hp2 = hp.matrix(hp.values(tv, pw, rho)).toarray()
    ref2 = (T.T @ sparse.kron(K, sparse.identity(3)) @ T + sparse.diags(rho)).toarray()
    assert np.allclose(Hp2, ref2, rtol=1e-12, atol=1e-12 * np.abs(ref2).max())
    adj = np.eye(nv, dtype=bool)
    adj[i, j] = adj[j, i] = True
    assert np.array_equal(hp.matrix(np.ones(len(hp.indices))).toarray() > 0, adj[np.ix_(owner, owner)])


@pytest.mark.parametrize("seed", range(4))
def test_min_corner_sj_matches_the_numpy_corners(seed):
    from shellmesh_mdao.smooth.elements import _TRI_SJ, _corner_min_sj, _corner_normals
    rng = np.random.default_rng(400 + seed)
    nv, m = 60, 300
    P = rng.normal(size=(nv, 3)) * 10.0 ** rng.uniform(-3, 3)
    faces = np.array([rng.choice(nv, 4, replace=False) for _ in range(m)])
    is_tri = rng.random(m) < 0.4
    faces[is_tri, 3] = -1
    faces[::17, 1] = faces[::17, 0]                     # a zero-length edge: its corners score 0
    nref = rng.normal(size=(m, 3))
    c = P[np.where(faces >= 0, faces, faces[:, :1])]
    for nr in (None, nref):
        ref = _corner_min_sj(c, is_tri, _corner_normals(c, is_tri), nr)
        assert np.array_equal(min_corner_sj(P, faces, is_tri, nr, _TRI_SJ), ref)


def _face_quality_numpy(C, is_tri, nref):
    """smooth.oriented_quality as it was before the compiled loop (the reference)."""
    from shellmesh_mdao.mesh import dot_rows
    from shellmesh_mdao.smooth.elements import _corner_min_sj, _corner_normals
    with np.errstate(all="ignore"):
        nown = _corner_normals(C, is_tri)
        sj = _corner_min_sj(C, is_tri, nown)
        d = dot_rows(nown, nref)
        return np.where(d > 0, sj, d - 1.0)


@pytest.mark.parametrize("seed", range(4))
def test_face_quality_matches_the_numpy_version(seed):
    """kernels.face_quality (smooth.oriented_quality, the untangling's measure) against the whole-
    array numpy formulas, bit for bit: random quads and triangles over six decades of scale, a
    zero-length edge, a degenerate element (zero normal: quality -1), flipped references,
    a reference normal with a NaN and one with a signed zero, corners with inf."""
    from shellmesh_mdao.smooth.kernels import face_quality
    from shellmesh_mdao.smooth.elements import _TRI_SJ, oriented_quality
    rng = np.random.default_rng(700 + seed)
    m = 400
    C = rng.normal(size=(m, 4, 3)) * 10.0 ** rng.uniform(-3, 3)
    is_tri = rng.random(m) < 0.4
    C[is_tri, 3] = rng.normal(size=(int(is_tri.sum()), 3))          # not read
    C[::13, 1] = C[::13, 0]                                          # a zero-length edge
    C[5] = C[5, 0]                                                   # every corner in one point
    C[7, 2, 1] = np.inf
    nref = rng.normal(size=(m, 3))
    nref /= np.linalg.norm(nref, axis=1)[:, None]                    # unit, as the callers give
    nref[::3] *= -1.0
    nref[11] = [np.nan, 0.0, 1.0]
    nref[12] = [-0.0, -0.0, -0.0]
    for tri_rows in (is_tri, np.zeros(m, bool), np.ones(m, bool)):
        ref = _face_quality_numpy(C, tri_rows, nref)
        got = face_quality(C, tri_rows, nref, _TRI_SJ)
        assert np.array_equal(got, ref, equal_nan=True)
        assert np.array_equal(oriented_quality(C, tri_rows, nref), ref, equal_nan=True)
    assert ref[5] == -1.0 and np.isnan(ref[11])
    assert ((ref >= -2) | np.isnan(ref)).all() and (ref[np.isfinite(ref)] <= 1.0 + 1e-12).all()
    with pytest.raises(ValueError, match="corners"):
        face_quality(C[:, :3], is_tri, nref)
    with pytest.raises(ValueError, match="one entry per element"):
        face_quality(C, is_tri[:-1], nref)


def test_min_corner_sj_known_values():
    P = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, np.sqrt(3) / 2, 0], [0.3, 0.3, 0]])
    faces = np.array([[0, 1, 2, 3], [0, 1, 4, -1], [0, 1, 5, 3]])    # square, equilateral, dart
    got = min_corner_sj(P, faces, np.array([False, True, False]))
    assert np.allclose(got[:2], 1.0)
    assert got[2] < 0                                    # the dart's reflex corner
    up = np.tile([0.0, 0.0, 1.0], (3, 1))
    assert np.allclose(min_corner_sj(P, faces[:2], np.array([False, True]), -up[:2]), -1.0)   # against a flipped reference
    # a triangle-only (m, 3) array is the same as its -1 padded (m, 4) form
    tri3 = np.array([[0, 1, 4], [0, 2, 3]])
    pad = np.column_stack([tri3, [-1, -1]])
    yes = np.array([True, True])
    assert np.array_equal(min_corner_sj(P, tri3, yes), min_corner_sj(P, pad, yes))
    # corner ids out of range are refused (a quad's fourth included, a triangle's padding not)
    for bad, tri in (([0, 1, 6, -1], True), ([0, 1, 2, -1], False), ([0, 1, 2, 6], False)):
        with pytest.raises(ValueError, match="faces holds indices outside"):
            min_corner_sj(P, np.array([bad]), np.array([tri]))


def test_ortho_jacobian_of_a_right_angle_is_zero():
    # unit square corner b=(0,0,0), a=(0,1,0) before it, c=(1,0,0) after it, normal +z:
    # r = (a-b)/|a-b| - n x (c-b)/|c-b| = (0,1,0) - (0,1,0) = 0 at this position, and J x = r
    P = np.array([[0.0, 1, 0], [0, 0, 0], [1, 0, 0]])
    col_start, ncol = np.array([0, 3, 6]), np.array([3, 3, 3])
    data, indices, indptr = ortho_jacobian([0], [1], [2], [[0.0, 0, 1]], [1.0], [1.0], [1.0], col_start, ncol,
                                           np.tile(np.eye(3), (3, 1)))
    J = sparse.csr_matrix((data, indices, indptr), shape=(3, 9))
    assert np.allclose(J @ P.ravel(), 0.0)
    # c moved to (1, 0.5, 0): n x c = (-0.5, 1, 0), so r = (0.5, 0, 0)
    assert np.allclose(J @ np.array([[0.0, 1, 0], [0, 0, 0], [1, 0.5, 0]]).ravel(), [0.5, 0, 0])


@pytest.mark.parametrize("seed", range(8))
def test_closest_on_curves_matches_the_numpy_pick(seed):
    # every segment of each query's curve as candidates of core.supports._pick_nearest: the same
    # points, distances (bits, signs of zero) and segments, at scales from 1e-3 to 1e3,
    # with queries on vertices (two segments tie) and a zero-length segment (NaN, never picked)
    from shellmesh_mdao.core.supports import _pick_nearest
    rng = np.random.default_rng(300 + seed)
    nc = int(rng.integers(1, 6))
    lens = rng.integers(1, 40, nc)
    start = np.concatenate([[0], np.cumsum(lens)[:-1]])
    stop = start + lens
    scale = 10.0 ** rng.uniform(-3, 3)
    pts = [np.cumsum(rng.normal(size=(n + 1, 3)) * scale, 0) + rng.normal(size=3) * scale for n in lens]
    a = np.concatenate([p[:-1] for p in pts])
    ab = np.concatenate([p[1:] for p in pts]) - a
    if seed % 2:
        ab[start[-1]] = 0.0
    L = np.sqrt(np.einsum("ij,ij->i", ab, ab))
    k = 300
    cid = rng.integers(0, nc, k)
    q = a[rng.integers(0, len(a), k)] + rng.normal(size=(k, 3)) * scale * 10.0 ** rng.uniform(-6, 1, (k, 1))
    q[:20] = a[np.minimum(start[cid[:20]] + 1, stop[cid[:20]] - 1)]
    qi = np.repeat(np.arange(k), lens[cid])
    si = np.concatenate([np.arange(start[c], stop[c]) for c in cid])
    with np.errstate(invalid="ignore", divide="ignore"):
        X, D, _ = _pick_nearest(q, qi, si, a, ab, L)
        x, d, seg = closest_on_curves(q, cid, start, stop, a, ab, L)
    assert np.array_equal(x, X) and np.array_equal(d, D)
    assert np.array_equal(np.signbit(x), np.signbit(X))
    assert ((seg >= start[cid]) & (seg < stop[cid])).all() and np.isfinite(d).all()


@pytest.mark.parametrize("seed", range(5))
def test_counting_sorts_give_numpy_stable_argsort(seed):
    rng = np.random.default_rng(500 + seed)
    n = int(rng.integers(1, 400))
    m = int(rng.integers(0, 4000))
    k, lo, hi = rng.integers(0, n, (3, m))
    assert np.array_equal(stable_order(k, n), np.argsort(k, kind="stable"))
    assert np.array_equal(stable_pair_order(lo, hi, n), np.argsort(lo * n + hi, kind="stable"))
    assert np.array_equal(stable_order([2, 0, 2, 1, 0], 3), [1, 4, 3, 0, 2])
    # grouping with row pointers, and vertex neighbours along edges: the numpy constructions
    # the remesh used before them
    from shellmesh_mdao.remesh.kernels import edge_neighbours, group_order
    ptr, order = group_order(k, n)
    assert np.array_equal(order, np.argsort(k, kind="stable"))
    assert np.array_equal(ptr, np.concatenate([[0], np.cumsum(np.bincount(k, minlength=n))]))
    E = np.stack([lo, hi], 1)
    src = np.concatenate([E[:, 0], E[:, 1]])
    dst = np.concatenate([E[:, 1], E[:, 0]])
    vptr, nbr = edge_neighbours(E, n)
    assert np.array_equal(nbr, dst[np.argsort(src, kind="stable")])
    assert np.array_equal(vptr, np.concatenate([[0], np.cumsum(np.bincount(src, minlength=n))]))
    # the edge table's row pointers against the numpy counts they replaced
    from shellmesh_mdao.core.kernels import edge_rows
    Es = E[np.lexsort((E[:, 1], E[:, 0]))]
    assert np.array_equal(edge_rows(Es, n), np.concatenate([[0], np.cumsum(np.bincount(Es[:, 0], minlength=n))]))
    with pytest.raises(ValueError, match="E holds indices outside"):
        edge_rows(np.array([[0, 1], [n, 0]]), n)



def _lexsort_ranks(prio, tie):
    """The ranks remesh.common.rank_candidates took from numpy before the radix sort."""
    order = np.lexsort((tie, -np.asarray(prio)))
    r = np.empty(len(prio), np.int64)
    r[order] = np.arange(len(prio), 0, -1)
    return r


@pytest.mark.parametrize("kind", range(5))
def test_rank_desc_gives_the_lexsort_ranks(kind):
    """Radix ranks against np.lexsort((tie, -prio)): normal floats, few distinct values (ties
    broken by the key), infinities and both zeros, subnormals, exponents across the whole
    range; the remesh's hashed ids and full 64-bit keys."""
    from shellmesh_mdao.remesh.kernels import rank_desc
    from shellmesh_mdao.remesh.common import _hash
    rng = np.random.default_rng(900 + kind)
    for _ in range(40):
        n = int(rng.integers(0, 3000))
        if kind == 0:
            prio = rng.normal(size=n)
        elif kind == 1:
            prio = np.round(rng.random(n), 1)
        elif kind == 2:
            prio = rng.choice([-np.inf, np.inf, 0.0, -0.0, 1.0, -1.0, 5e-324, -5e-324, 1e308], n)
        elif kind == 3:
            prio = -rng.random(n) * 1e-300
        else:
            prio = rng.integers(-3, 3, n).astype(float) * 2.0 ** rng.integers(-1074, 1000, n)
        if kind < 4:
            tie = _hash(rng.choice(10 * n + 10, n, replace=False))
        else:
            tie = np.unique(rng.integers(0, 2 ** 63, n, dtype=np.uint64) * np.uint64(2)
                            + rng.integers(0, 2, n, dtype=np.uint64))
            rng.shuffle(tie)
            prio = prio[:len(tie)]
        assert np.array_equal(rank_desc(prio, tie), _lexsort_ranks(prio, tie))
    with pytest.raises(ValueError, match="NaN"):
        rank_desc([1.0, np.nan], np.array([0, 1], np.uint64))
    with pytest.raises(ValueError, match="same length"):
        rank_desc([1.0, 2.0], np.array([0], np.uint64))

def _triangles_reference(p, a, b, c):
    """The whole-array version the kernel replaced (project.closest_point_on_triangles before it)."""
    p, a, b, c = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (p, a, b, c)))
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = np.einsum("ij,ij->i", ab, ap)
    d2 = np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3 = np.einsum("ij,ij->i", ab, bp)
    d4 = np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5 = np.einsum("ij,ij->i", ab, cp)
    d6 = np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2

    out = np.empty_like(p)
    done = np.zeros(len(p), dtype=bool)

    def put(mask, val):
        m = mask & ~done
        if m.any():
            out[m] = val[m] if val.ndim == 2 else val
        done[m] = True

    with np.errstate(divide="ignore", invalid="ignore"):
        put((d1 <= 0) & (d2 <= 0), a)                                      # vertex a
        put((d3 >= 0) & (d4 <= d3), b)                                     # vertex b
        put((d6 >= 0) & (d5 <= d6), c)                                     # vertex c
        v = d1 / (d1 - d3)
        put((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + v[:, None] * ab)        # edge ab
        w = d2 / (d2 - d6)
        put((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + w[:, None] * ac)        # edge ac
        w2 = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        put((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), b + w2[:, None] * (c - b))  # edge bc
        denom = va + vb + vc
        vv = vb / denom
        ww = vc / denom
        inside = a + vv[:, None] * ab + ww[:, None] * ac
        rest = ~done
        if rest.any():
            ok = rest & np.isfinite(inside).all(1)
            out[ok] = inside[ok]
            done[ok] = True
    if not done.all():  # fully degenerate (zero-area) triangles left: nearest of the 3 edges
        r = np.flatnonzero(~done)
        cands = [_segment_reference(p[r], a[r], b[r]), _segment_reference(p[r], b[r], c[r]),
                 _segment_reference(p[r], c[r], a[r])]
        d = np.stack([np.einsum("ij,ij->i", q - p[r], q - p[r]) for q in cands], 1)
        k = np.argmin(d, axis=1)
        out[r] = np.stack(cands, 1)[np.arange(len(r)), k]
    return out


def _segment_reference(p, a, b):
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.divide(np.einsum("ij,ij->i", p - a, ab), L2, out=np.zeros(len(p)), where=L2 > 0)
    return a + np.clip(t, 0.0, 1.0)[:, None] * ab


def test_closest_on_triangles_matches_the_numpy_regions():
    # every region of Ericson's test, points on vertices and edges, and zero-area triangles
    # (collinear, a repeated corner, all three corners equal): the same bits wherever the
    # numpy version gave a point; where it gave NaN (a zero-length edge, 0 / 0 in its region)
    # the kernel gives the closest point of the triangle's other edges
    from shellmesh_mdao.core.bvh import closest_on_triangles
    rng = np.random.default_rng(600)
    k = 20000
    a, b, c = rng.normal(size=(3, k, 3))
    p = rng.normal(size=(k, 3)) * 2
    b[::50] = a[::50]
    c[::50] = a[::50] + 1e-3
    c[1::50] = a[1::50] + 0.5 * (b[1::50] - a[1::50])
    a[2::50] = b[2::50] = c[2::50]
    p[3::50] = a[3::50]
    p[4::50] = 0.5 * (a[4::50] + b[4::50])
    with np.errstate(invalid="ignore", divide="ignore"):
        ref = _triangles_reference(p, a, b, c)
    got = closest_on_triangles(p, a, b, c)
    fin = np.isfinite(ref).all(1)
    assert (~fin).sum() > 0 and np.isfinite(got).all()
    assert np.array_equal(got[fin], ref[fin])
    assert np.array_equal(np.signbit(got[fin]), np.signbit(ref[fin]))
    # the former NaN rows: no farther than any corner nor the midpoint of any edge
    d = np.linalg.norm(got - p, axis=1)[~fin]
    for x in (a, b, c, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)):
        assert (d <= np.linalg.norm(x - p, axis=1)[~fin] + 1e-12).all()
    # a repeated corner (a = b): the closest point of segment a-c
    got = closest_on_triangles([[0.5, 2.0, 0.0]], [[0.0, 0, 0]], [[0.0, 0, 0]], [[1.0, 0, 0]])
    assert np.allclose(got, [[0.5, 0.0, 0.0]])
    # known answers: above the interior, beyond a vertex, beside an edge
    tri = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    q = np.array([[0.2, 0.2, 3.0], [-1.0, -1.0, 0.0], [0.5, -2.0, 1.0]])
    got = closest_on_triangles(q, tri[0], tri[1], tri[2])
    assert np.allclose(got, [[0.2, 0.2, 0.0], [0.0, 0.0, 0.0], [0.5, 0.0, 0.0]])


def test_kernels_refuse_indices_out_of_range():
    # the compiled loops do not check bounds: the wrappers must
    with pytest.raises(ValueError, match="res holds indices outside"):
        greedy_independent(np.array([0, 1]), np.array([0, 5]), np.array([1, 2]), 3)
    with pytest.raises(ValueError, match="owner holds indices outside"):
        greedy_independent(np.array([0, 2]), np.array([0, 1]), np.array([1, 2]), 3)
    with pytest.raises(ValueError, match="unique rank"):
        greedy_independent(np.array([0, 1]), np.array([0, 1]), np.array([4, 4]), 3)
    nptr, nbr = np.array([0, 1, 2]), np.array([1, 0])
    with pytest.raises(ValueError, match="v holds indices outside"):
        greedy_independent_rings(nptr, nbr, np.array([0]), np.array([2]), np.array([1]))
    with pytest.raises(ValueError, match="nbr holds indices outside"):
        common_neighbour_counts(nptr, np.array([1, 7]), np.array([0]), np.array([1]))
    with pytest.raises(ValueError, match="CSR row pointers"):
        common_neighbour_counts(np.array([0, 3, 2]), nbr, np.array([0]), np.array([1]))
    one = np.ones(1)
    with pytest.raises(ValueError, match="c holds indices outside"):
        ortho_jacobian([0], [1], [3], [[0.0, 0, 1]], one, one, one, [0, 1, 2], [1, 1, 1], np.eye(3))
    with pytest.raises(ValueError, match="rows of tv"):
        ortho_jacobian([0], [1], [2], [[0.0, 0, 1]], one, one, one, [0, 1, 2], [1, 1, 2], np.eye(3))
    with pytest.raises(ValueError, match="faces holds indices outside"):
        min_corner_sj(np.eye(3), np.array([[0, 1, 3, -1]]), np.array([True]))
    with pytest.raises(ValueError, match="an \\(m, 3\\) or \\(m, 4\\) array"):
        min_corner_sj(np.eye(3), np.array([0, 1, 2]), np.array([True]))
    with pytest.raises(ValueError, match="faces holds indices outside"):
        min_corner_sj(np.eye(3), np.array([[0, 1, 2, -1]]), np.array([False]))   # a quad needs its fourth node
    with pytest.raises(ValueError, match="keys holds indices outside"):
        stable_order([0, 3], 3)
    with pytest.raises(ValueError, match="lo holds indices outside"):
        stable_pair_order([-1], [0], 3)
    with pytest.raises(ValueError, match="cid holds indices outside"):
        closest_on_curves(np.zeros((1, 3)), [1], [0], [1], np.zeros((1, 3)), np.ones((1, 3)), [1.0])
    with pytest.raises(ValueError, match="segment range"):
        closest_on_curves(np.zeros((1, 3)), [0], [0], [2], np.zeros((1, 3)), np.ones((1, 3)), [1.0])


# ------------------------------------------------------------------ rows of three
def _rows(rng, k, special=True):
    """(k, 3) rows over twelve orders of magnitude, with zero rows, signed zeros, NaN and inf."""
    a = rng.normal(size=(k, 3)) * 10.0 ** rng.uniform(-6, 6, (k, 1))
    if special and k >= 8:
        a[0] = 0.0
        a[1] = [-0.0, 0.0, -0.0]
        a[2, 1] = np.nan
        a[3, 0] = np.inf
        a[4] = [1e-170, -1e-170, 1e-170]              # squares underflow
        a[5] = [1e160, 1e160, -1e160]                 # squares overflow
        a[6] = 0.0                                    # times a row of -1 below: three products of -0
        a[7] = -1.0
    return a


def _same(x, y):
    """Equal arrays, NaN where NaN, and the same sign of every zero."""
    x, y = np.asarray(x), np.asarray(y)
    assert x.shape == y.shape
    np.testing.assert_array_equal(x, y)
    assert np.array_equal(np.signbit(x), np.signbit(y))


@pytest.mark.parametrize("k", [0, 1, 7, 8, 9, 31, 1000, 4099])
def test_row_kernels_give_numpy_bits(k):
    from shellmesh_mdao.core import kernels as K
    from shellmesh_mdao.remesh.kernels import edge_lengths

    rng = np.random.default_rng(k)
    a, b = _rows(rng, k), _rows(rng, k)
    if k >= 8:
        b[6] = a[7]                                   # einsum's sum of -0 products is +0
    with np.errstate(all="ignore"):
        _same(K.dot_rows(a, b), np.einsum("ij,ij->i", a, b))
        _same(K.dot_rows(b, a), np.einsum("ij,ij->i", b, a))
        _same(K.dot_norm_rows(a), np.sqrt(np.einsum("ij,ij->i", a, a)))
        n = np.sqrt(np.einsum("ij,ij->i", a, a))[:, None]
        _same(K.dot_unit_rows(a), np.divide(a, n, out=np.zeros_like(a), where=n > 0))
        _same(K.norm_rows(a), np.linalg.norm(a, axis=1))
        _same(K.cross_rows(a, b), np.cross(a, b))
        # strided and non-float64 inputs: strided ones are copied, others are left to numpy
        w = np.hstack([a, b])
        _same(K.dot_rows(w[:, :3], w[:, 3:]), np.einsum("ij,ij->i", w[:, :3], w[:, 3:]))
        _same(K.cross_rows(a[::-1], b), np.cross(a[::-1], b))
        # edge lengths: the ends gathered and subtracted, then einsum's norm (E a strided view too)
        P = np.vstack([a, b])
        E = np.column_stack([rng.integers(0, max(len(P), 1), (k, 2)), np.zeros(k, np.int64)])[:, :2] \
            if len(P) else np.zeros((0, 2), np.int64)
        _same(edge_lengths(P, E), np.sqrt(np.einsum("ij,ij->i", P[E[:, 1]] - P[E[:, 0]], P[E[:, 1]] - P[E[:, 0]])))
    assert K.dot_rows(a[:20].clip(-1, 1).astype(np.float32), b[:20]) is None
    assert K.cross_rows(a[:, :2], b[:, :2]) is None
    assert K.norm_rows(a[None]) is None
    with pytest.raises(ValueError):
        edge_lengths(a, [[0, len(a)]])


@pytest.mark.parametrize("seed", range(3))
def test_mesh_helpers_keep_their_bits_through_the_kernels(seed):
    """mesh.cross_rows and mesh.norm_rows send (k, 3) rows to the kernels and anything else to
    numpy: both ways give np.cross's and np.linalg.norm's bits."""
    from shellmesh_mdao.mesh import norm_rows

    rng = np.random.default_rng(seed)
    a, b = _rows(rng, 500), _rows(rng, 500)
    with np.errstate(all="ignore"):
        _same(cross_rows(a, b), np.cross(a, b))
        _same(cross_rows(a.reshape(50, 10, 3), b.reshape(50, 10, 3)), np.cross(a.reshape(50, 10, 3), b.reshape(50, 10, 3)))
        _same(cross_rows(a, b[0]), np.cross(a, b[0]))                  # broadcast: numpy
        _same(norm_rows(a, axis=1), np.linalg.norm(a, axis=1))
        _same(norm_rows(a, axis=1, keepdims=True), np.linalg.norm(a, axis=1, keepdims=True))
        _same(norm_rows(a.reshape(50, 10, 3), axis=-1), np.linalg.norm(a.reshape(50, 10, 3), axis=-1))


def _old_tri_min_angle(A, B, C):
    def ang(u, v):
        return np.arctan2(np.sqrt(np.einsum("ij,ij->i", np.cross(u, v), np.cross(u, v))),
                          np.einsum("ij,ij->i", u, v))
    a0 = ang(B - A, C - A)
    a1 = ang(C - B, A - B)
    return np.degrees(np.minimum(np.minimum(a0, a1), np.pi - a0 - a1))


def _oldangles3(Pn):
    a, b, c = Pn[:, 0], Pn[:, 1], Pn[:, 2]

    def ang(u, v):
        cu = np.einsum("ij,ij->i", u, v) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1), 1e-300)
        return np.degrees(np.arccos(np.clip(cu, -1, 1)))
    return np.minimum(np.minimum(ang(b - a, c - a), ang(a - b, c - b)), ang(a - c, b - c))


@pytest.mark.parametrize("k", [1, 5, 8, 13, 64, 999, 5000])
def test_triangle_angle_kernels_give_the_numpy_angles(k):
    """The remesh's and the imprint's triangle angles, from the compiled arguments and numpy's
    arctan2 / arccos, equal the whole-numpy formulas they replaced (every array length,
    since numpy's vector loops treat the tail of an array apart)."""
    from shellmesh_mdao.imprint import kernels as K
    from shellmesh_mdao.imprint.common import angles3
    from shellmesh_mdao.remesh.common import tri_angles as _tri_angles, tri_min_angle as _tri_min_angle
    from shellmesh_mdao.remesh.common import tri_normals as _tri_normals

    rng = np.random.default_rng(100 + k)
    P = rng.normal(size=(3 * k, 3)) * 10.0 ** rng.uniform(-3, 3)
    F = rng.permutation(3 * k).reshape(k, 3)
    if k >= 5:
        P[F[0, 1]] = P[F[0, 0]]                          # a repeated corner
        P[F[1, 2]] = 0.5 * (P[F[1, 0]] + P[F[1, 1]])     # a flat triangle
    A, B, C = P[F[:, 0]], P[F[:, 1]], P[F[:, 2]]
    with np.errstate(all="ignore"):
        _same(_tri_min_angle(A, B, C), _old_tri_min_angle(A, B, C))
        u, v, w = B - A, C - A, np.cross(B - A, C - A)
        a0 = np.degrees(np.arctan2(np.sqrt(np.einsum("ij,ij->i", w, w)), np.einsum("ij,ij->i", u, v)))
        _same(_tri_angles(P, F)[:, 0], a0)
        _same(_tri_normals(P, F), np.cross(B - A, C - A))
        _same(angles3(P[F]), _oldangles3(P[F]))
    # known answers: a right isosceles triangle and an equilateral one
    R = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    np.testing.assert_allclose(_tri_angles(R, np.array([[0, 1, 2]]))[0], [90, 45, 45], atol=1e-12)
    Eq = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0]])
    np.testing.assert_allclose(angles3(Eq[None]), [60.0], atol=1e-12)
    np.testing.assert_allclose(K.corner_cosines(R[None])[0], [0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-15)


@pytest.mark.parametrize("seed", range(4))
def test_facing_ok_matches_the_einsum_test(seed):
    from shellmesh_mdao.remesh import kernels as K

    rng = np.random.default_rng(seed)
    n, m, k = 60, 40, 300
    kind = rng.integers(0, 3, n)
    vtri = rng.integers(-1, m, n)
    tri_n = rng.normal(size=(m, 3))
    tri_n /= np.linalg.norm(tri_n, axis=1)[:, None]
    tri_n[3] = np.nan                                     # a NaN normal: the face is not ok
    F = rng.integers(0, n, (k, 3))
    nrm = rng.normal(size=(k, 3))
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    c = np.cos(np.radians(80.0))
    reg = (kind[F] == 0) & (vtri[F] >= 0)
    d = np.einsum("kj,kij->ki", nrm, tri_n[np.maximum(vtri[F], 0)])
    want = ~reg.any(1) | (np.where(reg, d, -2.0).max(1) > c)
    got = K.facing_ok(F, kind, vtri, tri_n, nrm, c)
    assert got.dtype == bool and np.array_equal(got, want)
    assert not want.all() and want.any()
    # a face of only chain/corner vertices is always ok; one facing its surface is, one
    # standing across it is not
    one = np.array([[0, 1, 2]])
    z = np.array([[0.0, 0.0, 1.0]])
    assert K.facing_ok(one, [1, 2, 1], [0, 0, 0], z, -z, c)[0]
    assert K.facing_ok(one, [0, 0, 0], [0, 0, 0], z, z, c)[0]
    assert not K.facing_ok(one, [0, 0, 0], [0, 0, 0], z, np.array([[1.0, 0.0, 0.0]]), c)[0]
    with pytest.raises(ValueError):
        K.facing_ok(one, [0, 0, 0], [0, 0, 5], z, z, c)


def _old_collapse_geometric(a, b, okd, nptr, nbr, fptr, vf, F, P, h, max_len_ratio, fn_old, cos_turn, kind, vtri,
                            tri_n, cos_facing):
    """The numpy formulas of remesh.operations.collapse_edges' geometric tests (non-quality mode) before
    the kernel, on the pairs the length test allows."""
    from shellmesh_mdao.mesh import dot_norm_rows as _norm, dot_unit_rows as _unit
    from shellmesh_mdao.remesh.common import csr_entries as _expand, tri_min_angle as _tri_min_angle

    k = len(a)
    okd = okd.copy()
    ow, pos = _expand(nptr, a)
    xx = nbr[pos]
    m = xx != b[ow]
    ow, xx = ow[m], xx[m]
    r = _norm(P[xx] - P[b[ow]]) / (0.5 * (h[xx] + h[b[ow]]))
    rmax = np.zeros(k)
    np.maximum.at(rmax, ow, r)
    okd &= rmax <= max_len_ratio
    keep = np.flatnonzero(okd)
    out = np.full(k, np.inf)
    if not len(keep):
        return out
    a, b, rmax = a[keep], b[keep], rmax[keep]
    k2 = len(keep)
    ok2 = np.ones(k2, bool)
    ow, pos = _expand(fptr, a)
    ff = vf[pos]
    Fa = F[ff]
    Q0 = P[Fa]
    amin_old = np.full(k2, np.inf)
    np.minimum.at(amin_old, ow, _tri_min_angle(Q0[:, 0], Q0[:, 1], Q0[:, 2]))
    m = ~(Fa == b[ow][:, None]).any(1)
    ow, ff, Fa, Q = ow[m], ff[m], Fa[m], Q0[m]
    isa = Fa == a[ow][:, None]
    Q = np.where(isa[:, :, None], P[b[ow]][:, None, :], Q)
    nn = np.cross(Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0])
    area = _norm(nn)
    cosn = np.einsum("ij,ij->i", _unit(nn), fn_old[ff])
    cmin = np.full(k2, np.inf)
    np.minimum.at(cmin, ow, np.where(area > 1e-30 * h[b[ow]] ** 2, cosn, -2.0))
    ok2 &= cmin > cos_turn
    Fb = np.where(isa, b[ow][:, None], Fa)
    reg = (kind[Fb] == 0) & (vtri[Fb] >= 0)
    d = np.einsum("kj,kij->ki", _unit(nn), tri_n[np.maximum(vtri[Fb], 0)])
    facing = ~reg.any(1) | (np.where(reg, d, -2.0).max(1) > cos_facing)
    ok2 &= ~(np.bincount(ow, weights=~facing, minlength=k2) > 0)
    amin_new = np.full(k2, np.inf)
    np.minimum.at(amin_new, ow, _tri_min_angle(Q[:, 0], Q[:, 1], Q[:, 2]))
    ok2 &= amin_new >= np.minimum(5.0, 0.5 * amin_old)
    out[keep] = np.where(ok2, rmax, np.inf)
    return out


def _wavy_grid(rng, jitter, nx=14):
    """A wavy, jittered nx x nx grid of points, each cell cut into two triangles along a random
    diagonal: (points, triangles, the grid's point ids (nx, nx))."""
    g = np.stack(np.meshgrid(np.arange(nx), np.arange(nx), indexing="ij"), -1).reshape(-1, 2).astype(float)
    g += rng.uniform(-jitter, jitter, g.shape)
    P = np.column_stack([g, 0.8 * np.sin(g[:, 0] * 0.9) * np.cos(g[:, 1] * 0.7)])
    idx = np.arange(nx * nx).reshape(nx, nx)
    q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    flip = rng.random(len(q)) < 0.5
    F = np.concatenate([np.where(flip[:, None], q[:, [0, 1, 2]], q[:, [0, 1, 3]]),
                        np.where(flip[:, None], q[:, [0, 2, 3]], q[:, [1, 2, 3]])])
    return P, F, idx


def _grid_topology(F, n):
    """The remesh's edge table of triangles ``F`` on ``n`` points, its vertex neighbours and the
    faces around each vertex (CSR pairs)."""
    from shellmesh_mdao.remesh.common import EdgeTable
    T = EdgeTable(F, n)
    return T, T.vertex_neighbors(), T.vertex_faces(F)


@pytest.mark.parametrize("seed", range(4))
def test_collapse_select_matches_the_numpy_formulas(seed):
    """kernels.collapse_select takes the collapses (vertex removed, where it goes) that the
    remesh took before: greedy_independent_rings calling back into Python each sub-round with
    the numpy formulas of the tests (numpy's arctan2 for the angles), both directions of every
    winner, the smaller longest-new-edge ratio first. On a wavy, jittered grid with a NaN size,
    a node on top of its neighbour and faces standing across the input."""
    from shellmesh_mdao.remesh.kernels import collapse_select, greedy_independent_rings
    from shellmesh_mdao.mesh import dot_unit_rows as _unit
    from shellmesh_mdao.remesh.common import tri_normals as _tri_normals

    rng = np.random.default_rng(seed)
    P, F, idx = _wavy_grid(rng, 0.3)
    n = len(P)
    T, (nptr, nbr), (fptr, vf) = _grid_topology(F, n)
    h = rng.uniform(0.8, 1.6, n)
    h[3] = np.nan                                        # a NaN size fails its collapses
    fn_old = _unit(_tri_normals(P, F))
    kind = rng.integers(0, 3, n)
    tri_n = fn_old[rng.permutation(len(F))] * rng.choice([-1.0, 1.0], (len(F), 1))   # some faces stand across
    vtri = rng.integers(-1, len(F), n)
    u, v = T.E[:, 0], T.E[:, 1]
    dir_ok = rng.random((len(u), 2)) < 0.8
    rank = rng.permutation(len(u)) + 1
    # a node on top of its neighbour: collapses next to it make faces of zero area
    P[idx[5, 5]] = P[idx[5, 6]]
    cos_facing = np.cos(np.radians(80.0))
    taken = backward = refused = 0
    for turn, ratio in ((45.0, 4.0 / 3.0), (120.0, 2.5), (45.0, 2.5)):   # past 90 degrees only the area guard refuses
        cos_turn = np.cos(np.radians(turn))
        acc_a, acc_b, refusals = [], [], []

        def check(win):
            sc = _old_collapse_geometric(np.concatenate([u[win], v[win]]), np.concatenate([v[win], u[win]]),
                                         np.concatenate([dir_ok[win, 0], dir_ok[win, 1]]), nptr, nbr, fptr, vf, F,
                                         P, h, ratio, fn_old, cos_turn, kind, vtri, tri_n,
                                         cos_facing).reshape(2, -1).T
            good = np.isfinite(sc).any(1)
            refusals.append(good)
            d = np.argmin(sc[good], axis=1)
            acc_a.append(np.where(d == 0, u[win[good]], v[win[good]]))
            acc_b.append(np.where(d == 0, v[win[good]], u[win[good]]))
            return good
        greedy_independent_rings(nptr, nbr, u, v, rank, alive=dir_ok.any(1), check=check, max_sub=16)
        a, b = collapse_select(nptr, nbr, fptr, vf, F, P, h, u, v, rank, dir_ok, max_len_ratio=ratio,
                               fn_old=fn_old, cos_turn=cos_turn, kind=kind, vtri=vtri, tri_n=tri_n,
                               cos_facing=cos_facing, max_sub=16)
        np.testing.assert_array_equal(a, np.concatenate(acc_a))
        np.testing.assert_array_equal(b, np.concatenate(acc_b))
        taken += len(a)
        backward += int((a > b).sum())                  # edges are (lower, higher): v into u
        refused += sum(int((~g).sum()) for g in refusals)
    # collapses taken in both directions, and winners refused by the tests
    assert taken > 15 and backward > 5 and refused > 50
    with pytest.raises(ValueError):
        collapse_select(nptr, nbr, fptr, vf, F, P, h, u, np.full(len(u), n), rank, dir_ok, max_len_ratio=2.0,
                        fn_old=fn_old, cos_turn=0.5, kind=kind, vtri=vtri, tri_n=tri_n, cos_facing=cos_facing)


@pytest.mark.parametrize("seed", range(4))
def test_collapse_select_facing_only_matches_the_numpy_formulas(seed):
    """kernels.collapse_select with a surface (the remesh's micro collapses) takes the
    collapses the remesh took before: the call-back selection on the numpy formulas of the
    facing tests (no new face standing across the input, nor facing against the input triangle
    closest to its centroid, found by SurfaceLocator.closest), u into v first, else v into u.
    On a wavy, jittered grid whose input is a tilted, partly flipped copy of itself."""
    from shellmesh_mdao.remesh.kernels import collapse_select, facing_ok, greedy_independent_rings
    from shellmesh_mdao.mesh import cross_rows
    from shellmesh_mdao.core.locator import SurfaceLocator
    from shellmesh_mdao.mesh import dot_norm_rows as _norm, dot_unit_rows as _unit
    from shellmesh_mdao.remesh.common import csr_entries as _expand, tri_normals as _tri_normals

    rng = np.random.default_rng(seed)
    P, F, idx = _wavy_grid(rng, 0.35)
    n = len(P)
    T, (nptr, nbr), (fptr, vf) = _grid_topology(F, n)
    # the input: the grid raised and tilted, a third of its triangles turned over
    Pin = P + np.array([0.1, -0.2, 0.3]) + 0.15 * P[:, [1, 0, 2]] * [1.0, -1.0, 0.0]
    Fin = np.where((rng.random(len(F)) < 0.3)[:, None], F[:, [0, 2, 1]], F)
    loc = SurfaceLocator(Pin, Fin)
    tri_n = _unit(_tri_normals(Pin, Fin))
    kind = rng.integers(0, 3, n)
    vtri = rng.integers(-1, len(Fin), n)
    cos_facing = np.cos(np.radians(80.0))
    u, v = T.E[:, 0], T.E[:, 1]
    dir_ok = rng.random((len(u), 2)) < 0.8
    rank = rng.permutation(len(u)) + 1

    def facing(a, b, okd):
        k = len(a)
        out = np.full(k, np.inf)
        keep = np.flatnonzero(okd)
        a, b = a[keep], b[keep]
        ow, pos = _expand(fptr, a)
        Fa = F[vf[pos]]
        m = ~(Fa == b[ow][:, None]).any(1)
        ow, Fa = ow[m], Fa[m]
        Q = np.where((Fa == a[ow][:, None])[:, :, None], P[b[ow]][:, None, :], P[Fa])
        nn = _unit(cross_rows(Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]))
        Fb = np.where(Fa == a[ow][:, None], b[ow][:, None], Fa)
        badf = ~facing_ok(Fb, kind, vtri, tri_n, nn, cos_facing)
        chk = np.flatnonzero(~badf)
        if len(chk):
            _, ti, _ = loc.closest(Q[chk].mean(1))
            badf[chk] = np.einsum("ij,ij->i", nn[chk], tri_n[ti]) <= 0
        bad = np.bincount(ow, weights=badf, minlength=len(keep)) > 0
        out[keep] = np.where(~bad, _norm(P[a] - P[b]), np.inf)
        return out

    acc_a, acc_b, refusals = [], [], []

    def check(win):
        s0 = facing(u[win], v[win], dir_ok[win, 0])
        s1 = np.full(len(win), np.inf)
        redo = np.flatnonzero(~np.isfinite(s0))
        s1[redo] = facing(v[win[redo]], u[win[redo]], dir_ok[win[redo], 1])
        good = np.isfinite(s0) | np.isfinite(s1)
        refusals.append(good)
        acc_a.append(np.where(np.isfinite(s0), u[win], v[win])[good])
        acc_b.append(np.where(np.isfinite(s0), v[win], u[win])[good])
        return good
    greedy_independent_rings(nptr, nbr, u, v, rank, alive=dir_ok.any(1), check=check, max_sub=16)
    a, b = collapse_select(nptr, nbr, fptr, vf, F, P, np.ones(n), u, v, rank, dir_ok, kind=kind, vtri=vtri,
                           tri_n=tri_n, cos_facing=cos_facing, surface=loc.compiled_tree(), max_sub=16)
    np.testing.assert_array_equal(a, np.concatenate(acc_a))
    np.testing.assert_array_equal(b, np.concatenate(acc_b))
    # collapses taken in both directions, and winners refused by the tests
    assert len(a) > 8 and (a > b).sum() > 3 and sum(int((~g).sum()) for g in refusals) > 5


@pytest.mark.parametrize("seed", range(4))
def test_flip_candidates_match_the_numpy_formulas(seed):
    """kernels.flip_candidates gives the flips, valence gains, new normals and angle arguments
    of the remesh's numpy formulas it replaced (c-d not an edge yet, one patch, the valence
    gain, the dihedrals of the old and new pairs, facing), on a wavy, jittered grid with a
    tetrahedron beside it (whose flips would create existing edges), a node on top of its
    neighbour, feature edges, two patches and faces standing across."""
    from shellmesh_mdao.remesh.kernels import flip_candidates
    from shellmesh_mdao.mesh import dot_unit_rows as _unit
    from shellmesh_mdao.remesh.common import EdgeTable, min_angle_of as _min_angle_of

    rng = np.random.default_rng(seed)
    P, F, idx = _wavy_grid(rng, 0.3)
    t0 = len(P)
    P = np.vstack([P, [[20.0, 0, 0], [21.0, 0, 0], [20.0, 1.0, 0], [20.0, 0, 1.0]]])
    F = np.vstack([F, t0 + np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])])
    P[idx[5, 5]] = P[idx[5, 6]]
    n, m = len(P), len(F)
    T = EdgeTable(F, n)
    E = T.E
    isf = rng.random(len(E)) < 0.1
    fpatch = (rng.random(m) < 0.1).astype(np.int64)
    kind = rng.integers(0, 3, n)
    tri_n = _unit(np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]]))
    tri_n = tri_n[rng.permutation(m)] * rng.choice([-1.0, 1.0], (m, 1))
    vtri = rng.integers(-1, m, n)
    cosmax, cos_facing = np.cos(np.radians(30.0 + 40.0 * seed)), np.cos(np.radians(80.0))
    deg = np.diff(T.vertex_neighbors()[0]).astype(np.float64)
    tgt = rng.integers(4, 8, n).astype(np.float64)
    # the numpy formulas
    cand = np.flatnonzero((T.h1 >= 0) & ~isf)
    h0, h1 = T.h0[cand], T.h1[cand]
    f0, f1 = h0 // 3, h1 // 3
    a, b = F[f0, h0 % 3], F[f0, (h0 % 3 + 1) % 3]
    c, d = F[f0, (h0 % 3 + 2) % 3], F[f1, (h1 % 3 + 2) % 3]
    topo = (c != d) & (T.lookup(c, d) < 0) & (fpatch[f0] == fpatch[f1])
    Pa, Pb, Pc, Pd = P[a], P[b], P[c], P[d]
    with np.errstate(all="ignore"):
        n0 = _unit(np.cross(Pb - Pa, Pc - Pa))
        n1 = _unit(np.cross(Pa - Pb, Pd - Pb))
        geo = np.einsum("ij,ij->i", n0, n1) > cosmax
        w0 = _unit(np.cross(Pd - Pa, Pc - Pa))
        w1 = _unit(np.cross(Pb - Pd, Pc - Pd))
        for mm in (w0, w1):
            geo &= (np.einsum("ij,ij->i", mm, n0) > cosmax) & (np.einsum("ij,ij->i", mm, n1) > cosmax)
        for Fn, mm in ((np.stack([a, d, c], 1), w0), (np.stack([d, b, c], 1), w1)):
            reg = (kind[Fn] == 0) & (vtri[Fn] >= 0)
            dd = np.einsum("kj,kij->ki", mm, tri_n[np.maximum(vtri[Fn], 0)])
            geo &= ~reg.any(1) | (np.where(reg, dd, -2.0).max(1) > cos_facing)

    def en(vtx, k):
        return (deg[vtx] + k - tgt[vtx]) ** 2
    gain = en(a, 0) + en(b, 0) + en(c, 0) + en(d, 0) - (en(a, -1) + en(b, -1) + en(c, 1) + en(d, 1))
    assert (~(c != d) | ~(T.lookup(c, d) < 0)).any()     # the tetrahedron's flips are refused
    for valence in (False, True):
        ok = topo & geo & (gain > 0 if valence else True)
        got = flip_candidates(E, T.kptr(), T.h0, T.h1, isf, F, fpatch, P, cosmax, kind, vtri, tri_n, cos_facing,
                              deg if valence else None, tgt if valence else None)
        e, abcd, ff, gn, m0, m1, sc = got
        np.testing.assert_array_equal(e, cand[ok])
        np.testing.assert_array_equal(abcd, np.stack([a, b, c, d], 1)[ok])
        np.testing.assert_array_equal(ff, np.stack([f0, f1], 1)[ok])
        np.testing.assert_array_equal(gn, gain[ok] if valence else np.zeros(ok.sum()))
        _same(m0, w0[ok])
        _same(m1, w1[ok])
        for j, (A, B, C) in enumerate(((Pa, Pb, Pc), (Pb, Pa, Pd), (Pa, Pd, Pc), (Pd, Pb, Pc))):
            _same(_min_angle_of(sc[j]), _old_tri_min_angle(A[ok], B[ok], C[ok]))
        assert 10 < ok.sum() < 0.9 * len(cand)
    with pytest.raises(ValueError):
        flip_candidates(E, T.kptr(), T.h0, T.h1, isf, F, fpatch, P[:-1], cosmax, kind, vtri, tri_n, cos_facing)


@pytest.mark.parametrize("seed", range(4))
def test_skin_flips_match_the_numpy_formulas(seed):
    """kernels.skin_flips gives the imprint's flip candidates, orientation test and angle
    cosines of the numpy formulas it replaced (an edge table by a stable sort of the half-edge
    keys, locked edges, active vertices, dihedral, existing new edge, the new pair against the
    mean normal), on a wavy, jittered grid with a tetrahedron beside it (whose flips would
    create existing edges), a folded corner and a node on top of its neighbour."""
    from shellmesh_mdao.core.kernels import edge_table
    from shellmesh_mdao.imprint.kernels import corner_cosines, skin_flips
    from shellmesh_mdao.mesh import cross_rows, norm_rows

    rng = np.random.default_rng(seed)
    P, T, idx = _wavy_grid(rng, 0.3)
    P[idx[3, 3], 2] += 2.5                                 # a spike: steep dihedrals around it
    t0 = len(P)
    P = np.vstack([P, [[20.0, 0, 0], [21.0, 0, 0], [20.0, 1.0, 0], [20.0, 0, 1.0]]])
    T = np.vstack([T, t0 + np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])])
    P[idx[5, 5]] = P[idx[5, 6]]
    n = len(P)
    # the numpy formulas
    a, b = T, np.roll(T, -1, axis=1)
    lo, hi = np.minimum(a, b).ravel(), np.maximum(a, b).ravel()
    key = lo * n + hi
    order = np.argsort(key, kind="stable")
    ks = key[order]
    start = np.r_[True, ks[1:] != ks[:-1]]
    uk = ks[start]
    run = np.cumsum(start) - 1
    cnt = np.diff(np.append(np.flatnonzero(start), len(ks)))
    same = np.flatnonzero(ks[1:] == ks[:-1])
    same = same[cnt[run[same]] == 2]
    h0, h1 = order[same], order[same + 1]
    ek = key[h0]
    E0 = np.stack([lo, hi], 1)[order][start]
    locked_pairs = E0[rng.random(len(E0)) < 0.1][:, ::-1]
    free = ~np.isin(ek, locked_pairs.min(1) * n + locked_pairs.max(1))
    h0, h1 = h0[free], h1[free]
    f0, s0, f1, s1 = h0 // 3, h0 % 3, h1 // 3, h1 % 3
    p, qq, r, s_ = T[f0, s0], T[f0, (s0 + 1) % 3], T[f0, (s0 + 2) % 3], T[f1, (s1 + 2) % 3]
    active = rng.random(n) < 0.9
    cmax = np.cos(np.radians(35.0 + 10.0 * seed))
    ok = (T[f1, s1] == qq) & (T[f1, (s1 + 1) % 3] == p) & (r != s_) & active[p] & active[qq]
    p, qq, r, s_, f0, f1 = p[ok], qq[ok], r[ok], s_[ok], f0[ok], f1[ok]
    n0 = cross_rows(P[qq] - P[p], P[r] - P[p])
    n1 = cross_rows(P[p] - P[qq], P[s_] - P[qq])
    cosd = np.einsum("ij,ij->i", n0, n1) / np.maximum(norm_rows(n0, axis=1) * norm_rows(n1, axis=1), 1e-300)
    new_key = np.minimum(r, s_) * n + np.maximum(r, s_)
    pre = np.flatnonzero((cosd > cmax) & ~np.isin(new_key, uk))
    p, qq, r, s_, f0, f1, n0, n1 = (x[pre] for x in (p, qq, r, s_, f0, f1, n0, n1))
    t0_, t1_ = np.stack([r, s_, qq], 1), np.stack([s_, r, p], 1)
    nn0 = cross_rows(P[t0_[:, 1]] - P[t0_[:, 0]], P[t0_[:, 2]] - P[t0_[:, 0]])
    nn1 = cross_rows(P[t1_[:, 1]] - P[t1_[:, 0]], P[t1_[:, 2]] - P[t1_[:, 0]])
    navg = n0 / np.maximum(norm_rows(n0, axis=1, keepdims=True), 1e-300) + \
        n1 / np.maximum(norm_rows(n1, axis=1, keepdims=True), 1e-300)
    un = navg / np.maximum(norm_rows(navg, axis=1, keepdims=True), 1e-300)
    orient = (np.einsum("ij,ij->i", nn0, un) > cmax * norm_rows(nn0, axis=1)) & \
        (np.einsum("ij,ij->i", nn1, un) > cmax * norm_rows(nn1, axis=1))
    # the kernel
    _, H0, H1, CNT, E, _ = edge_table(T, n)
    kptr = np.concatenate([[0], np.cumsum(np.bincount(E[:, 0], minlength=n))])
    from shellmesh_mdao.core.kernels import edge_lookup
    locked = np.zeros(len(E), bool)
    locked[edge_lookup(E, kptr, locked_pairs[:, 0], locked_pairs[:, 1])] = True
    got_pqrs, got_ff, got_orient, got_cos = skin_flips(E, kptr, H0, H1, CNT, locked, T, P, cmax, active)
    np.testing.assert_array_equal(got_pqrs, np.stack([p, qq, r, s_], 1))
    np.testing.assert_array_equal(got_ff, np.stack([f0, f1], 1))
    np.testing.assert_array_equal(got_orient, orient)
    for j, tri in enumerate((T[f0], T[f1], t0_, t1_)):
        _same(got_cos[j], corner_cosines(P[tri]))
    # candidates and refusals of every kind occur
    assert 10 < len(pre) < ok.sum() and orient.any() and (~orient).any()
    assert np.isin(new_key, uk).any() and (cosd <= cmax).any()
    with pytest.raises(ValueError):
        skin_flips(E, kptr, H0, H1, CNT, locked[:-1], T, P, cmax)


@pytest.mark.parametrize("seed", range(4))
def test_star_moves_match_the_numpy_formulas(seed):
    """kernels.star_moves gives the imprint smoothing's corner cosines of every star triangle
    with its vertex moved and before, and its turn-over test, as the numpy formulas it replaced
    (gathers and np.where per corner, corner_cosines of the whole triangle set, np.einsum), on a
    wavy grid whose vertices move by up to two cells (some triangles turn over), one onto its
    neighbour."""
    from shellmesh_mdao.imprint.kernels import corner_cosines, star_moves
    from shellmesh_mdao.mesh import cross_rows, vertex_faces

    rng = np.random.default_rng(seed)
    P, T, idx = _wavy_grid(rng, 0.3)
    n = len(P)
    new = P + rng.uniform(-2.0, 2.0, P.shape) * (rng.random((n, 1)) < 0.5)
    new[idx[4, 4]] = P[idx[4, 5]]
    ptr, star = vertex_faces(T, n)
    cand = np.flatnonzero(rng.random(n) < 0.6)
    rows = np.repeat(cand, np.diff(ptr)[cand])
    tris = np.concatenate([star[ptr[v]:ptr[v + 1]] for v in cand])
    a, b, c = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
    nrm = cross_rows(b - a, c - a)
    Tm = T[tris]
    which = Tm == rows[:, None]
    pa = np.where(which[:, 0, None], new[rows], P[Tm[:, 0]])
    pb = np.where(which[:, 1, None], new[rows], P[Tm[:, 1]])
    pc = np.where(which[:, 2, None], new[rows], P[Tm[:, 2]])
    want_new = corner_cosines(np.stack([pa, pb, pc], 1))
    want_old = corner_cosines(P[T])[tris]
    want_flip = np.einsum("ij,ij->i", cross_rows(pb - pa, pc - pa), nrm[tris]) <= 0
    cos_new, cos_old, flip = star_moves(rows, tris, T, P, new, nrm)
    _same(cos_new, want_new)
    _same(cos_old, want_old)
    np.testing.assert_array_equal(flip, want_flip)
    assert 0 < flip.sum() < len(flip)
    with pytest.raises(ValueError):
        star_moves(rows, tris, T, P, new[:-1], nrm)


@pytest.mark.parametrize("seed", range(4))
def test_move_tests_match_the_numpy_formulas(seed):
    """kernels.move_tests gives the remesh relaxation's face tests (normal turn, lost area,
    facing against or standing across the input at regular corners) and angle arguments of the
    numpy formulas it replaced, on a wavy grid whose vertices move by up to two cells, one onto
    its neighbour, with NaN input normals and faces of the input turned over."""
    from shellmesh_mdao.remesh.kernels import move_tests
    from shellmesh_mdao.mesh import dot_norm_rows as _norm, dot_unit_rows as _unit
    from shellmesh_mdao.remesh.common import min_angle_of as _min_angle_of, tri_min_angle as _tri_min_angle
    from shellmesh_mdao.remesh.common import tri_normals as _tri_normals

    rng = np.random.default_rng(seed)
    P, F, idx = _wavy_grid(rng, 0.3)
    n, m = len(P), len(F)
    moved = rng.random(n) < 0.5
    cur = np.where(moved[:, None], P + rng.uniform(-2.0, 2.0, P.shape), P)
    cur[idx[4, 4]] = P[idx[4, 5]]
    moved[idx[4, 4]] = True
    An_old = _tri_normals(P, F)
    area_old = _norm(An_old)
    fn_old = np.divide(An_old, area_old[:, None], out=np.zeros_like(An_old), where=area_old[:, None] > 0)
    tri_n = _unit(An_old)[rng.permutation(m)] * rng.choice([-1.0, 1.0], (m, 1))
    tri_n[3] = np.nan
    newtri, vtri = rng.integers(-1, m, n), rng.integers(-1, m, n)
    reg = rng.random(n) < 0.7
    cosmax, cos_facing = np.cos(np.radians(60.0)), np.cos(np.radians(80.0))
    fi = np.flatnonzero(moved[F].any(1))
    Fi = F[fi]
    # the numpy formulas
    An = _tri_normals(cur, Fi)
    ar = _norm(An)
    nu = np.divide(An, ar[:, None], out=np.zeros_like(An), where=ar[:, None] > 0)
    want = (np.einsum("ij,ij->i", nu, fn_old[fi]) <= cosmax) | (ar <= 1e-3 * area_old[fi])
    dmax = np.full(len(Fi), -2.0)
    anyreg = np.zeros(len(Fi), bool)
    with np.errstate(invalid="ignore"):
        for k in range(3):
            vk = Fi[:, k]
            tk = np.where(moved[vk], newtri[vk], vtri[vk])
            rk = reg[vk] & (tk >= 0)
            d = np.einsum("ij,ij->i", nu, tri_n[np.maximum(tk, 0)])
            want |= rk & (d <= 0)
            dmax = np.where(rk, np.maximum(dmax, d), dmax)
            anyreg |= rk
        want |= anyreg & (dmax <= cos_facing)
    bad, sc = move_tests(cur, Fi, fn_old[fi], area_old[fi], moved, newtri, vtri, reg, tri_n, cosmax, cos_facing)
    np.testing.assert_array_equal(bad, want)
    _same(_min_angle_of(sc), _tri_min_angle(cur[Fi[:, 0]], cur[Fi[:, 1]], cur[Fi[:, 2]]))
    assert 0 < bad.sum() < len(bad)
    with pytest.raises(ValueError):
        move_tests(cur, Fi, fn_old[fi], area_old[fi], moved, newtri, vtri, reg, tri_n[:5], cosmax, cos_facing)


@pytest.mark.parametrize("seed", range(3))
def test_edge_table_matches_the_sorted_key_runs(seed):
    """kernels.edge_table gives remesh.common.EdgeTable's arrays of the whole-array construction: a stable
    sort of the half-edge keys and its runs (boundary, interior and, allowed, non-manifold edges)."""
    from shellmesh_mdao.core.kernels import edge_table

    rng = np.random.default_rng(seed)
    n = 60
    F = np.array([rng.choice(n, 3, replace=False) for _ in range(150)])
    F = np.vstack([F, F[:5, [1, 0, 2]], F[:2]])          # some edges of three and four half-edges
    m = len(F)
    a = F.reshape(-1)
    b = F[:, [1, 2, 0]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * n + hi
    order = np.argsort(key, kind="stable")
    ks = key[order]
    first = np.r_[True, ks[1:] != ks[:-1]]
    starts = np.flatnonzero(first)
    cnt = np.diff(np.append(starts, len(ks)))
    he_edge = np.empty(3 * m, np.int64)
    he_edge[order] = np.cumsum(first) - 1
    h0 = order[starts]
    h1 = np.where(cnt == 2, order[np.minimum(starts + 1, len(order) - 1)], -1)
    got = edge_table(F, n)
    want = (he_edge, h0, h1, cnt, np.stack([lo[h0], hi[h0]], 1), ks[starts])
    for g, w in zip(got, want):
        assert np.array_equal(g, w)
    assert {1, 2}.issubset(set(cnt.tolist())) and cnt.max() > 2
    with pytest.raises(ValueError):
        edge_table(F, 10)


@pytest.mark.parametrize("seed", range(3))
def test_edge_lookup_matches_the_sorted_keys(seed):
    """edge_lookup (a scan of the few edges of each lower end) gives the edge ids the sorted
    key search gave, -1 for absent pairs, in either order of the ends."""
    from shellmesh_mdao.core.kernels import edge_lookup, edge_table
    rng = np.random.default_rng(30 + seed)
    n = 200
    F = np.array([rng.choice(n, 3, replace=False) for _ in range(300)])
    E, keys = edge_table(F, n)[4], edge_table(F, n)[5]
    kptr = np.concatenate([[0], np.cumsum(np.bincount(E[:, 0], minlength=n))])
    u, v = rng.integers(0, n, 5000), rng.integers(0, n, 5000)
    u[:len(E)], v[:len(E)] = E[:, 1], E[:, 0]                           # every edge, reversed
    q = np.minimum(u, v) * n + np.maximum(u, v)
    pos = np.minimum(np.searchsorted(keys, q), len(keys) - 1)
    ref = np.where(keys[pos] == q, pos, -1)
    got = edge_lookup(E, kptr, u, v)
    assert np.array_equal(got, ref) and (got[:len(E)] == np.arange(len(E))).all() and (got == -1).any()


def test_pair_difference_gives_the_bincount_bits():
    """pair_difference sums each pair's vector onto its first vertex minus onto its second
    vertex, as numpy's bincounts did, bit for bit (repeated vertices, signed zeros)."""
    from shellmesh_mdao.smooth.kernels import pair_difference
    rng = np.random.default_rng(12)
    n, k = 50, 3000
    i, j = rng.integers(0, n, k), rng.integers(0, n, k)
    w = rng.uniform(0.1, 3.0, k)
    rv = rng.normal(size=(k, 3)) * 10.0 ** rng.uniform(-6, 6, (k, 3))
    rv[::13] = -0.0
    ref = np.zeros((n, 3))
    for d in range(3):
        ref[:, d] = np.bincount(i, weights=w * rv[:, d], minlength=n) - np.bincount(j, weights=w * rv[:, d], minlength=n)
    assert pair_difference(i, j, w, rv, n).tobytes() == ref.tobytes()


def test_corner_sums_and_max_turn_give_the_numpy_bits():
    """The smoothing's vertex normals and curvature: corner_sums is bincount of each face's
    vector over its valid corners, corner_max_turn is np.maximum.at of 1 - einsum's dot, bit
    for bit (triangles padded with -1, vertices without faces)."""
    from shellmesh_mdao.smooth.kernels import corner_max_turn, corner_sums
    rng = np.random.default_rng(21)
    n, m = 300, 500
    faces = np.array([rng.choice(n - 20, 4, replace=False) for _ in range(m)])
    faces[::3, 3] = -1
    av = rng.normal(size=(m, 3)) * 10.0 ** rng.uniform(-5, 5, (m, 1))
    valid = faces >= 0
    fi = np.broadcast_to(np.arange(m)[:, None], faces.shape)[valid]
    vi = faces[valid]
    ref = np.zeros((n, 3))
    for d in range(3):
        ref[:, d] = np.bincount(vi, weights=av[fi, d], minlength=n)
    assert corner_sums(faces, av, n).tobytes() == ref.tobytes()
    vn = rng.normal(size=(n, 3))
    fn = rng.normal(size=(m, 3))
    kap = np.zeros(n)
    np.maximum.at(kap, vi, 1.0 - np.einsum("ij,ij->i", vn[vi], fn[fi]))
    assert corner_max_turn(faces, vn, fn, n).tobytes() == kap.tobytes()


def test_centroid_d2_gives_the_numpy_bits():
    """The imprint's nearest-centroid scan: the squared centroid distances of numpy's formula."""
    from shellmesh_mdao.imprint.kernels import centroid_d2
    from shellmesh_mdao.mesh import reduce_short
    rng = np.random.default_rng(5)
    P = rng.normal(size=(400, 3)) * 10.0 ** rng.uniform(-4, 4, (400, 1))
    T = np.array([rng.choice(400, 3, replace=False) for _ in range(700)])
    x = rng.normal(size=3)
    cen = (P[T[:, 0]] + P[T[:, 1]] + P[T[:, 2]]) / 3
    assert centroid_d2(P, T, x).tobytes() == reduce_short((cen - x) ** 2, "sum").tobytes()


def test_index_checks_match_numpys_min_and_max():
    """The kernels' index check (a compiled pass for int64 arrays, numpy's min and max for the
    others) accepts exactly the arrays whose entries are all in [0, n), 2-D, non-contiguous
    and int32 ones included, and names the range it found."""
    from shellmesh_mdao.core.kernels import check_index as _check_index
    rng = np.random.default_rng(4)
    for _ in range(200):
        n = int(rng.integers(1, 50))
        a = rng.integers(-2, n + 2, size=int(rng.integers(1, 40)))
        for arr in (a, a.reshape(-1, 1), np.repeat(a, 2)[::2], a.astype(np.int32)):
            good = a.min() >= 0 and a.max() < n
            if good:
                _check_index("x", arr, n)
            else:
                with pytest.raises(ValueError, match=rf"x holds indices outside \[0, {n}\): {a.min()}\.\.{a.max()}"):
                    _check_index("x", arr, n)
    _check_index("x", np.zeros(0, np.int64), 0)


def _collapse_directions_numpy(E, cand, h0all, h1all, valence, F, nptr, nbr, kind, isf, chain_ok, remove_first):
    """remesh.operations.collapse_edges' numpy cheap tests before kernels.collapse_directions."""
    from shellmesh_mdao.remesh.kernels import common_neighbour_counts
    n = len(nptr) - 1
    deg = np.diff(nptr)
    h0, h1 = h0all[cand], h1all[cand]
    opp0 = F[h0 // 3, (h0 % 3 + 2) % 3]
    opp1 = np.where(h1 >= 0, F[np.maximum(h1, 0) // 3, (np.maximum(h1, 0) % 3 + 2) % 3], -1)
    u, v = E[cand, 0], E[cand, 1]
    ok = (deg[opp0] > 3) & ((opp1 < 0) | (deg[np.maximum(opp1, 0)] > 3))
    ok &= common_neighbour_counts(nptr, nbr, u, v) == valence[cand]
    boundary_v = np.zeros(n, bool)
    boundary_v[E[valence == 1].reshape(-1)] = True
    ok &= ~((valence[cand] == 2) & boundary_v[u] & boundary_v[v])
    dir_ok = np.zeros((len(cand), 2), bool)
    for dirn, a in ((0, u), (1, v)):
        ka = kind[a]
        dir_ok[:, dirn] = ok & ((ka == 0) | ((ka == 1) & isf[cand] & chain_ok[a]))
    if remove_first is not None and len(remove_first):
        rf = np.zeros(n, bool)
        rf[remove_first] = True
        for dirn, a in ((0, u), (1, v)):
            dir_ok[:, dirn] |= ok & rf[a] & (kind[a] == 2) & isf[cand]
        dir_ok[:, 0] &= ~(rf[v] & ~rf[u])
        dir_ok[:, 1] &= ~(rf[u] & ~rf[v])
    return ok, dir_ok


@pytest.mark.parametrize("seed", range(6))
def test_collapse_directions_give_the_numpy_masks(seed):
    """The remesh's cheap collapse tests in one compiled pass against the numpy tests they
    replaced, on Delaunay meshes with open boundaries, random vertex kinds, feature edges,
    chain counts and vertices to remove first."""
    from scipy.spatial import Delaunay

    from shellmesh_mdao.core.kernels import edge_table
    from shellmesh_mdao.remesh.kernels import collapse_directions, edge_neighbours
    rng = np.random.default_rng(70 + seed)
    n = int(rng.integers(20, 300))
    F = Delaunay(rng.random((n, 2))).simplices.astype(np.int64)
    _, h0, h1, valence, E, _ = edge_table(F, n)
    nptr, nbr = edge_neighbours(E, n)
    kind = rng.integers(0, 3, n)
    isf = rng.random(len(E)) < 0.3
    chain_ok = rng.random(n) < 0.7
    cand = np.sort(rng.choice(len(E), int(rng.integers(1, len(E))), replace=False))
    for rf in (None, np.zeros(0, np.int64), rng.choice(n, 8, replace=False)):
        ok, dir_ok = collapse_directions(E, cand, h0, h1, valence, F, nptr, nbr, kind, isf, chain_ok, remove_first=rf)
        ok_ref, dir_ref = _collapse_directions_numpy(E, cand, h0, h1, valence, F, nptr, nbr, kind, isf, chain_ok, rf)
        assert np.array_equal(ok, ok_ref) and np.array_equal(dir_ok, dir_ref)
        assert ok.any() and (~ok).any() and dir_ok.any()


@pytest.mark.parametrize("seed", range(4))
def test_element_normals_and_faces_at_match_numpy(seed):
    """The smoothing's element normals and incident-face lists in compiled passes against the
    numpy code they replaced: the corners gathered with the padding replaced by corner 0,
    ``cross_rows`` (quad diagonals, triangle sides) over ``dot_unit_rows``, degenerate
    elements zero; the faces at a set of vertices from a mask."""
    from shellmesh_mdao.core.kernels import faces_at
    from shellmesh_mdao.smooth.kernels import element_normals
    from shellmesh_mdao.mesh import vertex_faces
    from shellmesh_mdao.smooth.elements import _corner_normals
    rng = np.random.default_rng(80 + seed)
    n, m = 60, 300
    P = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-3, 3)
    faces = rng.integers(0, n, (m, 4))
    is_tri = rng.random(m) < 0.4
    faces[is_tri, 3] = -1
    faces[:5, 1] = faces[:5, 0]                          # degenerate: zero normals
    ref = _corner_normals(P[np.where(faces >= 0, faces, faces[:, :1])], is_tri)
    got = element_normals(P, faces, is_tri)
    assert np.array_equal(got, ref) and not got[:5][is_tri[:5]].any()
    ptr, vf = vertex_faces(faces, n)
    for verts in (rng.choice(n, 7, replace=False), np.zeros(0, np.int64), np.arange(n)):
        cnt = ptr[verts + 1] - ptr[verts]
        mask = np.zeros(m, bool)
        mask[vf[np.repeat(ptr[verts], cnt) + np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)]] = True
        assert np.array_equal(faces_at(ptr, vf, verts, m), np.flatnonzero(mask))
    with pytest.raises(ValueError, match="verts holds indices outside"):
        faces_at(ptr, vf, [n], m)
    with pytest.raises(ValueError, match="faces holds indices outside"):
        element_normals(P, np.where(is_tri[:, None], faces, n), is_tri)


@pytest.mark.parametrize("case", ["mesh", "flat", "spread", "duplicates", "one", "subset"])
def test_nearest_other_distance_gives_the_kd_trees_bits(case):
    """The smoothing's trust radius: the grid gives scipy's KD-tree values bit for bit on a
    surface-like point set, a flat one, a wildly uneven one, coincident points (0), a single
    point (inf) and a subset of query vertices, whatever the cell."""
    from scipy.spatial import cKDTree

    from shellmesh_mdao.smooth.kernels import nearest_other_distance

    rng = np.random.default_rng(11)
    u = rng.random((3000, 2)) * [2 * np.pi, np.pi]
    P = np.stack([np.cos(u[:, 0]) * np.sin(u[:, 1]), np.sin(u[:, 0]) * np.sin(u[:, 1]), 0.2 * np.cos(u[:, 1])], 1)
    if case == "flat":
        P[:, 2] = 0.0
    elif case == "spread":
        P = P * [1e4, 1.0, 1e-4] + np.where(rng.random((len(P), 1)) < 0.01, 1e3, 0.0)
    elif case == "duplicates":
        P = np.vstack([P, P[::97]])
    elif case == "one":
        P = P[:1]
    verts = np.arange(len(P)) if case != "subset" else np.sort(rng.choice(len(P), 700, replace=False))
    want = cKDTree(P).query(P[verts], k=2)[0][:, 1]
    for cell in (None, 0.01, 0.05, 0.3, 5.0):
        got = nearest_other_distance(P, verts, cell)
        assert np.array_equal(got, want), (case, cell)
    if case == "duplicates":
        assert len(P) == 3031 and (got[-31:] == 0).all()          # each copy's nearest is its original


def _star_rounds_reference(order, ptr, star, ntri, rounds):
    """The numpy rounds the imprint smoothing used before kernels.star_independent."""
    def ranges(a, b):
        return np.concatenate([np.arange(x, y) for x, y in zip(a, b)]) if len(a) else np.zeros(0, np.int64)
    take = []
    tri_taken = np.zeros(ntri, bool)
    for _ in range(rounds):
        if not len(order):
            break
        trs = star[ranges(ptr[order], ptr[order + 1])]
        pos = np.repeat(np.arange(len(order)), np.diff(ptr)[order])
        firstpos = np.full(ntri, len(order))
        np.minimum.at(firstpos, trs, pos)
        mine = firstpos[trs] == pos
        allmine = np.bincount(pos, weights=(~mine).astype(float), minlength=len(order)) == 0
        free = np.bincount(pos, weights=tri_taken[trs].astype(float), minlength=len(order)) == 0
        win = order[allmine & free]
        take.append(win)
        tri_taken[star[ranges(ptr[win], ptr[win + 1])]] = True
        order = order[~(allmine & free)]
    return np.concatenate(take) if take else np.zeros(0, np.int64)


@pytest.mark.parametrize("seed", range(6))
def test_star_independent_matches_the_numpy_rounds(seed):
    """The imprint smoothing's independent set of moving vertices: the same vertices in the
    same order as the numpy rounds, no two taken vertices sharing a triangle."""
    from shellmesh_mdao.imprint.kernels import star_independent
    from shellmesh_mdao.mesh import vertex_faces

    rng = np.random.default_rng(seed)
    n = 300
    T = rng.integers(0, n, size=(700, 3))
    ptr, star = vertex_faces(T, n)
    has = np.flatnonzero(np.diff(ptr) > 0)
    order = rng.permutation(has)[: int(rng.integers(1, len(has)))]
    for rounds in (1, 3, 8):
        got = star_independent(order, ptr, star, len(T), rounds)
        want = _star_rounds_reference(order, ptr, star, len(T), rounds)
        assert np.array_equal(got, want)
        assert len(got)
        # each triangle in the star of at most one taken vertex
        _, times = np.unique(np.concatenate([np.unique(star[ptr[v]:ptr[v + 1]]) for v in got]), return_counts=True)
        assert (times == 1).all()
