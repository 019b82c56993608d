"""Local repair of the imprinted skin: an editable copy of the skin (:class:`SkinPatch`) on which edge
collapses, edge splits and vertex moves are tried around each bad triangle and kept only where they
improve it; the vertex roles that decide what an operation may do (:func:`skin_roles`)."""
from __future__ import annotations

import numpy as np

from ..core.polyline import closest_on_polyline, closest_on_segments
from ..mesh import norm_rows, vertex_faces
from .common import min_angles_small, polyline_param, stands_up, unit_normals
from .crossings import kept_sharp_segments

__all__ = ["FREE", "CHAIN", "CREASE", "FIXED", "DEAD", "skin_roles", "SkinPatch"]


# improve_skin's vectorised flips and smoothing leave a few triangles below the angle bound
# where the imprint packed chain vertices closer than the element size, where a chain ends
# or crosses a crease a fraction of an element away from the crease's next vertex, or where
# two oblique members cross. These spots (a handful per model) are repaired one by one on a
# small editable copy of the skin (SkinPatch): for each bad triangle every candidate
# operation (edge collapse, edge split, vertex relocation, each followed by local
# angle-improving flips) is tried, rolled back, and the best kept if it improves the local
# angle distribution. Vertex roles decide what an operation may do:
FREE, CHAIN, CREASE, FIXED, DEAD = 0, 1, 2, 3, 4
#   FREE     on the input surface only: moves on the surface, may be collapsed into a neighbour
#   CHAIN    inside one member chain (not a crossing/end): slides along its exact arc, may be
#            collapsed along its chain into a chain neighbour
#   CREASE   inside a geometric feature line (2 crease edges, not a corner): slides along the
#            input's sharp edges, may be collapsed along the line into a line neighbour
#   FIXED    crossings, chain ends, chain/crease crossings, corners, caller-fixed vertices
_MISSING = object()
_KEY = 1 << 31


def skin_roles(n, fe, fid, fixed, chain_vs, arcs):
    """Role (FREE/CHAIN/CREASE/FIXED) and chain index (or -1) of every skin vertex."""
    kind = np.full(n, FREE, np.int8)
    chain_of = np.full(n, -1, np.int64)
    cnt = np.zeros(n, np.int64)
    end = np.zeros(n, bool)
    for i, (v, arc) in enumerate(zip(chain_vs, arcs)):      # one pass per chain
        cnt[v] += 1
        chain_of[v] = i
        if not arc.closed:
            end[v[[0, -1]]] = True
    crease_deg = np.bincount(fe[fid < 0].ravel(), minlength=n)
    on_chain = cnt > 0
    kind[fixed & ~on_chain] = FIXED
    kind[crease_deg > 0] = FIXED
    kind[(crease_deg == 2) & ~fixed & ~on_chain] = CREASE
    kind[on_chain] = CHAIN
    kind[(cnt > 1) | end | (on_chain & (crease_deg > 0))] = FIXED
    chain_of[kind != CHAIN] = -1
    return kind, chain_of


class SkinPatch:
    """Editable triangle skin for the local repairs of :func:`improve_skin`: per-vertex face
    lists (CSR plus overrides for the touched vertices), feature edges (sorted keys plus
    overrides), vertex roles and chains, all changed through methods that write an undo
    journal, so a candidate operation can be tried and rolled back. Work per operation is
    local (the faces around a few vertices)."""

    COS_TURN = np.cos(np.radians(45.0))        # no face may turn more than this in one operation
    COS_FLIP = np.cos(np.radians(35.0))        # largest dihedral across a flipped edge

    def __init__(self, P, T, C, fe, fid, kind, chain_of, chains, arcs, chain_member, locator):
        n, m = len(P), len(T)
        self.P = np.zeros((n + 64, 3))
        self.P[:n] = P
        self.n = n
        self.T = np.zeros((m + 128, 3), np.int64)
        self.T[:m] = T
        self.m = m
        self.C = np.zeros(m + 128, C.dtype)
        self.C[:m] = C
        self.alive = np.zeros(m + 128, bool)
        self.alive[:m] = True
        self.kind = np.full(n + 64, DEAD, np.int8)
        self.kind[:n] = kind
        self.chain_of = np.full(n + 64, -1, np.int64)
        self.chain_of[:n] = chain_of
        self.ptr, self.star = vertex_faces(T, n)
        self.over = {}
        keys = fe[:, 0] * _KEY + fe[:, 1]
        o = np.argsort(keys, kind="stable")
        self.fkeys, self.fids = keys[o], np.asarray(fid)[o]
        self.fover = {}
        self.chains = list(chains)
        # a chain vertex collapse may not make a chain edge longer than 1.3 x the chain's
        # longest edge as imprinted (nor than 1.5 x the longer of the two edges it joins)
        self.chain_lmax = [1.3 * float(norm_rows(np.diff(P[c], axis=0), axis=1).max()) if len(c) > 1
                           else np.inf for c in self.chains]
        self.arcs = arcs
        self.chain_member = chain_member
        self.locator = locator
        self.eps = 1e-9 * locator.diagonal
        self._soup = None
        self._crease0 = (np.asarray(P).copy(), fe[np.asarray(fid) < 0])   # the lines remeshing kept
        self.journal = []
        self.region = None
        self.killed_out = []
        self.applied = {"collapse": 0, "split": 0, "move": 0, "flip": 0}

    # ------------------------------------------------------------ journaled storage
    def _grow(self):
        if self.n + 1 >= len(self.P):
            k = len(self.P)
            self.P = np.vstack([self.P, np.zeros((k, 3))])
            self.kind = np.concatenate([self.kind, np.full(k, DEAD, np.int8)])
            self.chain_of = np.concatenate([self.chain_of, np.full(k, -1, np.int64)])
        if self.m + 4 >= len(self.T):
            k = len(self.T)
            self.T = np.vstack([self.T, np.zeros((k, 3), np.int64)])
            self.C = np.concatenate([self.C, np.zeros(k, self.C.dtype)])
            self.alive = np.concatenate([self.alive, np.zeros(k, bool)])

    def faces(self, v):
        r = self.over.get(v)
        if r is not None:
            return r
        if v < len(self.ptr) - 1:
            return self.star[self.ptr[v]:self.ptr[v + 1]]
        return np.zeros(0, np.int64)

    def _set_over(self, v, arr):
        self.journal.append(("over", v, self.over.get(v, _MISSING)))
        self.over[v] = arr

    def kill(self, f):
        if self.region is not None and f not in self.region:
            self.killed_out.append(float(min_angles_small(self.P[self.T[f:f + 1]])[0]))
        self.journal.append(("kill", f))
        self.alive[f] = False
        for v in self.T[f].tolist():
            fs = self.faces(v)
            self._set_over(v, fs[fs != f])

    def add(self, tri, comp):
        self._grow()
        f = self.m
        self.T[f] = tri
        self.C[f] = comp
        self.alive[f] = True
        self.m += 1
        self.journal.append(("add",))
        for v in self.T[f].tolist():
            self._set_over(v, np.append(self.faces(v), f))
        return f

    def set_point(self, v, x):
        self.journal.append(("P", v, self.P[v].copy()))
        self.P[v] = x

    def add_point(self, x, kind, chain):
        self._grow()
        v = self.n
        self.P[v] = x
        self.kind[v] = kind
        self.chain_of[v] = chain
        self.n += 1
        self.journal.append(("addP",))
        return v

    def set_kind(self, v, k):
        self.journal.append(("kind", v, self.kind[v]))
        self.kind[v] = k

    def feat(self, a, b):
        """Feature id of edge a-b (member component id, -1 for a crease) or None."""
        a, b = (a, b) if a < b else (b, a)
        key = a * _KEY + b
        r = self.fover.get(key, _MISSING)
        if r is not _MISSING:
            return r
        i = int(np.searchsorted(self.fkeys, key))
        if i < len(self.fkeys) and self.fkeys[i] == key:
            return int(self.fids[i])
        return None

    def set_feat(self, a, b, val):
        a, b = (a, b) if a < b else (b, a)
        key = a * _KEY + b
        self.journal.append(("feat", key, self.fover.get(key, _MISSING)))
        self.fover[key] = val

    def set_chain(self, ci, arr):
        self.journal.append(("chain", ci, self.chains[ci]))
        self.chains[ci] = arr

    def undo(self, mark):
        while len(self.journal) > mark:
            e = self.journal.pop()
            k = e[0]
            if k == "over" or k == "feat":
                d = self.over if k == "over" else self.fover
                if e[2] is _MISSING:
                    del d[e[1]]
                else:
                    d[e[1]] = e[2]
            elif k == "kill":
                self.alive[e[1]] = True
            elif k == "add":
                self.m -= 1
                self.alive[self.m] = False
            elif k == "P":
                self.P[e[1]] = e[2]
            elif k == "addP":
                self.n -= 1
                self.kind[self.n] = DEAD
                self.chain_of[self.n] = -1
            elif k == "kind":
                self.kind[e[1]] = e[2]
            elif k == "chain":
                self.chains[e[1]] = e[2]

    # ------------------------------------------------------------ queries
    def neighbours(self, v):
        u = np.unique(self.T[self.faces(v)])
        return u[u != v]

    def oriented(self, a, b):
        """The two faces of edge a-b as ``((f0, r), (f1, s))``: f0 runs a->b with opposite
        corner r, f1 runs b->a with opposite corner s; None unless exactly two such faces."""
        fs = self.faces(a)
        fs = fs[(self.T[fs] == b).any(1)]
        if len(fs) != 2:
            return None
        out = {}
        for f in fs.tolist():
            t = self.T[f]
            i = int(np.flatnonzero(t == a)[0])
            if t[(i + 1) % 3] == b:
                out[0] = (f, int(t[(i + 2) % 3]))
            else:
                out[1] = (f, int(t[(i + 1) % 3]))
        return (out[0], out[1]) if len(out) == 2 else None

    def on_crease(self, q):
        """Closest points on the input's sharp edges (the lines remeshing kept) and distances."""
        if self._soup is None:
            pts, crease = self._crease0
            self._soup = kept_sharp_segments(self.locator.points, self.locator.triangles, pts, crease, self.eps)
        a, b = self._soup
        q = np.atleast_2d(q)
        if not len(a):
            return q, np.full(len(q), np.inf)
        return closest_on_segments(q, a, b)

    def turned(self, new_tris, old_tris):
        """True where a new triangle is degenerate, turned more than 45 degrees from the face
        it replaces (``old_tris``, row for row) or standing up off the input surface where that
        face did not (:func:`~.common.stands_up`, the rule of every move of skin vertices)."""
        X0, X1 = self.P[np.asarray(old_tris)], self.P[np.asarray(new_tris)]
        return (np.einsum("ij,ij->i", unit_normals(X1), unit_normals(X0)) <= self.COS_TURN) | stands_up(
            X0, X1, self.locator)

    # ------------------------------------------------------------ operations
    def flip(self, a, b, min_gain):
        """Flip edge a-b (not a chain/crease edge, faces of one component, dihedral below 35
        degrees) when that raises the pair's smallest angle by more than ``min_gain``.
        Returns the new edge's ends (r, s), or False."""
        if self.feat(a, b) is not None:
            return False
        o = self.oriented(a, b)
        if o is None:
            return False
        (f0, r), (f1, s) = o
        if r == s or self.C[f0] != self.C[f1]:
            return False
        tt = np.array([self.T[f0], self.T[f1], [r, s, b], [s, r, a]])
        X = self.P[tt]
        ang = min_angles_small(X)
        if min(ang[2], ang[3]) <= min(ang[0], ang[1]) + min_gain:
            return False
        nn = unit_normals(X)
        if nn[0] @ nn[1] < self.COS_FLIP:
            return False
        navg = nn[0] + nn[1]
        navg /= max(np.linalg.norm(navg), 1e-300)
        if nn[2] @ navg <= self.COS_TURN or nn[3] @ navg <= self.COS_TURN:
            return False
        if (self.T[self.faces(r)] == s).any():              # edge r-s exists already
            return False
        c0, c1 = self.C[f0], self.C[f1]
        self.kill(f0)
        self.kill(f1)
        self.add(tt[2], c0)
        self.add(tt[3], c1)
        return r, s

    def local_flips(self, faces, min_gain=0.01, limit=24):
        """Angle-improving flips of the edges of ``faces``, spreading to the edges around each
        flip (a queue; at most ``limit`` flips). Returns the number of flips."""
        queue = []
        for f in faces:
            t = self.T[f].tolist()
            queue += [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]
        done, i = 0, 0
        seen = set()
        while i < len(queue) and done < limit:
            a, b = queue[i]
            i += 1
            key = (a, b) if a < b else (b, a)
            if key in seen:
                continue
            seen.add(key)
            o = self.flip(a, b, min_gain)
            if o:
                done += 1
                r, s = o
                queue += [(a, r), (r, b), (b, s), (s, a)]
                for e in ((a, r), (r, b), (b, s), (s, a)):
                    seen.discard(e if e[0] < e[1] else (e[1], e[0]))
        return done

    def collapse(self, v, u):
        """Remove vertex v by merging it into its neighbour u (u keeps its position). A free
        vertex may merge into any neighbour; a chain or crease vertex only along its line."""
        k = self.kind[v]
        fid = self.feat(u, v)
        if k == FREE:
            if fid is not None:
                return False
        elif k == CHAIN:
            if fid is None or fid < 0:
                return False
        elif k == CREASE:
            if fid != -1:
                return False
        else:
            return False
        o = self.oriented(u, v)
        if o is None:
            return False
        (fa, r), (fb, s) = o
        nv = self.neighbours(v)
        common = np.intersect1d(nv, self.neighbours(u))        # link condition
        if len(common) != 2 or sorted(common.tolist()) != sorted((r, s)):
            return False
        moved = []
        for w in nv.tolist():
            if w == u:
                continue
            i = self.feat(v, w)
            if i is not None:
                if k == FREE or w in (r, s):
                    return False
                moved.append((w, i))
        if k != FREE and len(moved) != 1:
            return False
        if k == CHAIN:
            w = moved[0][0]
            lw = float(np.linalg.norm(self.P[u] - self.P[w]))
            if lw > self.chain_lmax[int(self.chain_of[v])] or lw > 1.5 * max(
                    float(np.linalg.norm(self.P[u] - self.P[v])), float(np.linalg.norm(self.P[v] - self.P[w]))):
                return False
        fv = self.faces(v)
        keep = fv[(fv != fa) & (fv != fb)]
        new = self.T[keep].copy()
        new[new == v] = u
        if self.turned(new, self.T[keep]).any():
            return False
        comps = self.C[keep].copy()
        for f in fv.tolist():
            self.kill(f)
        for t, c in zip(new, comps):
            self.add(t, c)
        self.set_feat(u, v, None)
        for w, i in moved:
            self.set_feat(v, w, None)
            self.set_feat(u, w, i)
        if k == CHAIN:
            ci = int(self.chain_of[v])
            arr = self.chains[ci]
            self.set_chain(ci, arr[arr != v])
        self.set_kind(v, DEAD)
        return True

    def _chain_of_edge(self, a, b, fid):
        """Index of the chain (of member ``fid``) having a and b as consecutive vertices."""
        for c in np.flatnonzero(self.chain_member == fid).tolist():
            arr = self.chains[c]
            ia, ib = np.flatnonzero(arr == a), np.flatnonzero(arr == b)
            if len(ia) and len(ib):
                d = abs(int(ia[0]) - int(ib[0]))
                if d == 1 or (self.arcs[c].closed and d == len(arr) - 1):
                    return c
        return -1

    def split(self, a, b, t):
        """Split edge a-b near parameter t: the new vertex lies on the input surface, on the
        exact arc for a chain edge (inserted into the chain), on the input's sharp edge for
        a crease edge. Both faces of the edge are split in two."""
        o = self.oriented(a, b)
        if o is None:
            return False
        (f0, r), (f1, s) = o
        x0 = self.P[a] + t * (self.P[b] - self.P[a])
        fid = self.feat(a, b)
        ci = -1
        if fid is None:
            x, kind = self.locator.closest(x0)[0][0], FREE
        elif fid >= 0:
            ci = self._chain_of_edge(a, b, fid)
            if ci < 0:
                return False
            x, kind = closest_on_polyline(x0, self.arcs[ci].points, self.arcs[ci].closed)[0], CHAIN
        else:
            xs, d = self.on_crease(np.vstack([x0, self.P[a], self.P[b]]))
            if d[1] > self.eps or d[2] > self.eps or d[0] > 0.25 * np.linalg.norm(self.P[b] - self.P[a]):
                return False
            x, kind = xs[0], CREASE
        self._grow()
        n = self.n
        self.P[n] = x                      # scratch slot for the check; add_point writes it again
        new = np.array([[a, n, r], [n, b, r], [b, n, s], [n, a, s]])
        if self.turned(new, self.T[[f0, f0, f1, f1]]).any():
            return False
        n = self.add_point(x, kind, ci)
        c0, c1 = self.C[f0], self.C[f1]
        self.kill(f0)
        self.kill(f1)
        for tri, c in zip(new, (c0, c0, c1, c1)):
            self.add(tri, c)
        if fid is not None:
            self.set_feat(a, b, None)
            self.set_feat(a, n, fid)
            self.set_feat(n, b, fid)
        if ci >= 0:
            arr = self.chains[ci]
            ia, ib = int(np.flatnonzero(arr == a)[0]), int(np.flatnonzero(arr == b)[0])
            self.set_chain(ci, np.insert(arr, max(ia, ib) if abs(ia - ib) == 1 else len(arr), n))
        return True

    def _candidates(self, v):
        """Candidate positions of vertex v: on the input surface around it (free), along its
        exact arc towards its chain neighbours (chain), along the input's sharp edge towards
        its line neighbours (crease)."""
        k = self.kind[v]
        x = self.P[v]
        nb = self.neighbours(v)
        if k == FREE:
            L = float(np.mean(norm_rows(self.P[nb] - x, axis=1)))
            tri = self.T[self.faces(v)]
            nrm = np.cross(self.P[tri[:, 1]] - self.P[tri[:, 0]], self.P[tri[:, 2]] - self.P[tri[:, 0]]).sum(0)
            nrm /= max(np.linalg.norm(nrm), 1e-300)
            e1 = np.cross(nrm, [1.0, 0.0, 0.0])
            if np.linalg.norm(e1) < 0.5:
                e1 = np.cross(nrm, [0.0, 1.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(nrm, e1)
            th = np.radians(np.arange(0.0, 360.0, 30.0))
            dirs = np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2
            r = L * np.array([0.4, 0.2, 0.1, 0.05, 0.02])
            cen = self.P[nb].mean(0)
            q = np.vstack([x + (r[:, None, None] * dirs[None]).reshape(-1, 3), cen, 0.5 * (x + cen)])
            return self.locator.closest(q)[0]
        if k == CHAIN:
            ci = int(self.chain_of[v])
            arr = self.chains[ci]
            i = int(np.flatnonzero(arr == v)[0])
            arc = self.arcs[ci]
            if not arc.closed and (i == 0 or i == len(arr) - 1):
                return np.zeros((0, 3))
            nbs = [arr[(i - 1) % len(arr)], arr[(i + 1) % len(arr)]]
            pts = np.vstack([arc.points, arc.points[:1]]) if arc.closed else arc.points
            cum = np.concatenate([[0.0], np.cumsum(norm_rows(np.diff(pts, axis=0), axis=1))])
            s = polyline_param(np.vstack([x, self.P[nbs]]), pts, cum)
            d = s[1:] - s[0]
            if arc.closed:
                d = np.where(np.abs(d) > 0.5 * cum[-1], d - np.sign(d) * cum[-1], d)
            sp = s[0] + (np.array([0.05, 0.1, 0.2, 0.3, 0.4, 0.5])[None] * d[:, None]).ravel()
            sp = np.mod(sp, cum[-1]) if arc.closed else np.clip(sp, 0.0, cum[-1])
            q = np.stack([np.interp(sp, cum, pts[:, j]) for j in range(3)], 1)
            # the chain's spacing bound of collapse(): no chain edge at v longer than 1.3 x the chain's
            # longest edge as imprinted (or than the longer of the two now, if that is already over)
            lq = norm_rows(q[:, None, :] - self.P[nbs][None], axis=2).max(1)
            lim = max(self.chain_lmax[ci], float(norm_rows(self.P[nbs] - x, axis=1).max()))
            return q[lq <= lim]
        if k == CREASE:
            ws = [w for w in nb.tolist() if self.feat(v, w) == -1]
            if len(ws) != 2 or self.on_crease(x)[1][0] > self.eps:
                return np.zeros((0, 3))
            a = np.array([0.05, 0.1, 0.2, 0.3, 0.4, 0.5])
            q = np.vstack([x + a[:, None] * (self.P[w] - x) for w in ws])
            xs, d = self.on_crease(q)
            return xs[d <= 0.1 * norm_rows(q - x, axis=1) + self.eps]
        return np.zeros((0, 3))

    def move(self, v, iters=4):
        """Hill-climb vertex v over its candidate positions to raise its star's smallest
        angle (no face turning more than 45 degrees from where it started, nor standing up off
        the input surface: :func:`~.common.stands_up`, the smoothing rounds' rule)."""
        if self.kind[v] not in (FREE, CHAIN, CREASE):
            return False
        tri = self.T[self.faces(v)]
        if not len(tri):
            return False
        n0 = unit_normals(self.P[tri])
        which = (tri == v)[None, :, :, None]
        moved = False
        for _ in range(iters):
            X = self.P[tri]
            cur = min_angles_small(X).min()
            q = self._candidates(v)
            if not len(q):
                break
            Xc = np.where(which, q[:, None, None, :], X[None]).reshape(-1, 3, 3)   # (k * f, 3, 3)
            ang = min_angles_small(Xc).reshape(len(q), len(tri))
            turn = np.einsum("kfi,fi->kf", unit_normals(Xc).reshape(len(q), len(tri), 3), n0) <= self.COS_TURN
            turn |= stands_up(np.broadcast_to(X, Xc.reshape(len(q), len(tri), 3, 3).shape).reshape(-1, 3, 3), Xc,
                              self.locator).reshape(len(q), len(tri))
            score = np.where(turn.any(1), -1.0, ang.min(1))
            j = int(np.argmax(score))
            if score[j] <= cur + 1e-6:
                break
            self.set_point(v, q[j])
            moved = True
        return moved

    # ------------------------------------------------------------ driver
    def _ring_faces(self, verts):
        fs = np.unique(np.concatenate([self.faces(v) for v in verts]))
        return np.unique(np.concatenate([self.faces(int(v)) for v in np.unique(self.T[fs])]))

    @staticmethod
    def _better(a, b, cap):
        """Lexicographic comparison of the sorted (capped) smallest angles: is a better than b?"""
        k = max(len(a), len(b))
        a = np.concatenate([np.sort(a), np.full(k - len(a), cap)])
        b = np.concatenate([np.sort(b), np.full(k - len(b), cap)])
        d = np.flatnonzero(np.abs(a - b) > 1e-7)
        return bool(len(d)) and bool(a[d[0]] > b[d[0]])

    def _apply(self, cand):
        op = cand[0]
        if op == "flip":
            return True                     # the local flips that follow every candidate
        if op == "collapse":
            return self.collapse(cand[1], cand[2])
        if op == "split":
            return self.split(cand[1], cand[2], cand[3])
        return self.move(cand[1])

    def _trial(self, cand, f):
        m0 = self.m
        if not self._apply(cand):
            return False
        self.local_flips(list(range(m0, self.m)) + ([f] if self.alive[f] else []))
        return True

    def repair_face(self, f, cap):
        """Try every candidate operation on face f (collapse of each short edge either way,
        split of the longest edge at the foot of the opposite corner and at its midpoint,
        relocation of each corner; each followed by local flips); keep the one that best
        improves the sorted smallest angles of the faces around f. Returns whether one was
        kept."""
        t = self.T[f].tolist()
        R0 = self._ring_faces(t)
        q_old = np.minimum(min_angles_small(self.P[self.T[R0]]), cap)
        X = self.P[t]
        L = norm_rows(X[[1, 2, 0]] - X, axis=1)          # edge i joins corners i, i+1
        cands = [("flip",)]
        for i in range(3):
            a, b = t[i], t[(i + 1) % 3]
            if L[i] <= 0.6 * L.max():                        # short edge: collapse either way
                cands += [("collapse", a, b), ("collapse", b, a)]
        i = int(np.argmax(L))                                # longest edge: split
        a, b = t[i], t[(i + 1) % 3]
        ab = X[(i + 1) % 3] - X[i]
        foot = float(np.clip((X[(i + 2) % 3] - X[i]) @ ab / max(ab @ ab, 1e-300), 0.15, 0.85))
        cands.append(("split", a, b, foot))
        if abs(foot - 0.5) > 0.1:
            cands.append(("split", a, b, 0.5))
        cands += [("move", v) for v in t if self.kind[v] in (FREE, CHAIN, CREASE)]
        best, best_q = None, None
        region = set(R0.tolist())
        for cand in cands:
            mark = len(self.journal)
            m0 = self.m
            self.region, self.killed_out = region, []
            if self._trial(cand, f):
                new_f = np.concatenate([R0, np.arange(m0, self.m)])
                q_new = np.minimum(min_angles_small(self.P[self.T[new_f[self.alive[new_f]]]]), cap)
                old = np.concatenate([q_old, np.minimum(self.killed_out, cap)])
                if self._better(q_new, old, cap) and (best is None or self._better(q_new, best_q, cap)):
                    best, best_q = cand, q_new
            self.region = None
            self.undo(mark)
        if best is None:
            return False
        self._trial(best, f)
        self.applied[best[0]] += 1
        return True

    def bad_faces(self, target):
        """Live faces with an angle below ``target``, worst first."""
        f = np.flatnonzero(self.alive[:self.m])
        a = min_angles_small(self.P[self.T[f]])
        o = np.argsort(a, kind="stable")
        return f[o[a[o] < target]]

    def export(self):
        """Compacted ``(P, T, C, feature_edges, feature_ids, chains, old_to_new)``: dead faces
        dropped, unreferenced vertices removed (old_to_new -1, and dropped from the chains, as a
        collapse drops the vertex it removes: a chain never lists a vertex that is not in the
        mesh), surviving order kept."""
        alive = np.flatnonzero(self.alive[:self.m])
        T = self.T[alive]
        used = np.zeros(self.n, bool)
        used[T.ravel()] = True
        remap = np.full(self.n, -1, np.int64)
        remap[used] = np.arange(int(used.sum()))
        okeys = np.array(sorted(self.fover), np.int64)
        base = ~np.isin(self.fkeys, okeys)
        ov = [(k, self.fover[k]) for k in okeys.tolist() if self.fover[k] is not None]
        keys = np.concatenate([self.fkeys[base], np.array([k for k, _ in ov], np.int64)])
        ids = np.concatenate([self.fids[base], np.array([i for _, i in ov], np.int64)]).astype(np.int32)
        fe = remap[np.stack([keys // _KEY, keys % _KEY], 1)]
        chains = [remap[c] for c in self.chains]
        chains = [c[c >= 0] for c in chains]
        return (self.P[:self.n][used], remap[T], self.C[alive], fe, ids, chains, remap)
