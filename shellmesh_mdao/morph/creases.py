"""The input's crease lines (trailing edges, tip and root outlines) as polylines with arc lengths: the
morph slides the nodes of the reference mesh's geometric feature lines along them."""
from __future__ import annotations

import numpy as np

from ..core.polyline import closest_on_segments
from ..mesh import ShellMesh
from .plan import dot

__all__ = ["Creases", "CREASE_ANGLE"]

#: input edges whose faces turn by more than this (degrees) are creases (the remesh's feature angle):
#: the reference mesh's nodes of geometric feature lines slide along them
CREASE_ANGLE = 30.0


class Creases:
    """The input's crease lines (edges sharper than ``angle``, open boundaries) as polylines with arc
    lengths: segment ``k`` runs from ``a[k]`` to ``b[k]``, at arc length ``s0[k]`` of line ``line[k]``
    (length ``length[line]``, ``closed`` or not; its segments ``first[line]`` onwards, in order)."""

    def __init__(self, locator, angle):
        from ..core.supports import polylines_from_edges

        mesh = ShellMesh(locator.points, np.column_stack([locator.triangles, np.full(len(locator.triangles), -1)]))
        lines = polylines_from_edges(mesh.points, mesh.sharp_edges(angle))
        a, b, line, s0, first, length, closed = [], [], [], [], [], [], []
        k = 0
        for li, (idx, cl) in enumerate(lines):
            pts = mesh.points[np.concatenate([idx, idx[:1]]) if cl else idx]
            seg_len = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            a.append(pts[:-1])
            b.append(pts[1:])
            line.append(np.full(len(seg_len), li))
            s0.append(np.concatenate([[0.0], np.cumsum(seg_len)[:-1]]))
            first.append(k)
            length.append(seg_len.sum())
            closed.append(cl)
            k += len(seg_len)
        cat = (lambda x, shape: np.concatenate(x) if x else np.zeros(shape))
        self.a, self.b = cat(a, (0, 3)), cat(b, (0, 3))
        self.line = cat(line, 0).astype(np.int64)
        self.s0 = cat(s0, 0)
        self.seg_len = np.linalg.norm(self.b - self.a, axis=1)
        self.first = np.array(first + [k], np.int64)
        self.length = np.array(length)
        self.closed = np.array(closed, bool)
        # arc lengths on one increasing axis, line after line (a gap of one between lines)
        self.base = np.concatenate([[0.0], np.cumsum(self.length + 1.0)[:-1]]) if len(self.length) else np.zeros(0)
        self.g0 = self.s0 + (self.base[self.line] if len(self.line) else 0.0)

    def locate(self, x, which, tol):
        """Segment and arc length (on its line) of the closest crease point of the points ``x[which]``
        within ``tol`` of a crease: ``(seg (n,), s (n,))``, -1 and 0 elsewhere."""
        n = len(x)
        seg = np.full(n, -1, np.int64)
        s = np.zeros(n)
        rows = np.flatnonzero(which)
        if not len(rows) or not len(self.a):
            return seg, s
        _, dist, c, t = closest_on_segments(x[rows], self.a, self.b, full=True)
        ok = dist <= tol
        seg[rows[ok]] = c[ok]
        s[rows[ok]] = self.s0[c[ok]] + t[ok] * self.seg_len[c[ok]]
        return seg, s

    def segment_at(self, line, s):
        """The segment of line ``line`` (k,) at arc length ``s`` (real, k): wrapped on closed lines,
        the end segments beyond the ends of open ones."""
        L = self.length[line]
        s = np.where(self.closed[line], np.mod(s, np.maximum(L, 1e-300)), s)
        lo, hi = self.first[line], self.first[line + 1]
        idx = np.searchsorted(self.g0, self.base[line] + s, side="right") - 1
        return np.clip(idx, lo, hi - 1)

    def point(self, seg, s):
        """The crease point at arc length ``s`` (complex allowed) on segment ``seg`` (wrapped onto a
        closed line's first lap; clamped to the ends of an open line)."""
        line = self.line[seg]
        L = self.length[line]
        wraps = np.where(self.closed[line], np.floor(s.real / np.maximum(L, 1e-300)), 0.0)
        s = s - wraps * L
        u = (s - self.s0[seg]) / self.seg_len[seg]
        open_ = ~self.closed[line]
        last = seg == self.first[line + 1] - 1
        firsts = seg == self.first[line]
        u = np.where(open_ & firsts & (u.real < 0), 0.0 * u, u)
        u = np.where(open_ & last & (u.real > 1), 1.0 + 0.0 * u, u)
        return self.a[seg] + u[:, None] * (self.b[seg] - self.a[seg])

    def crossing(self, seg, m, dm):
        """The point where segment ``seg`` crosses the plane ``m . x = dm`` (complex allowed)."""
        fa = dot(self.a[seg], m) - dm
        fb = dot(self.b[seg], m) - dm
        u = fa / (fa - fb)
        return self.a[seg] + u[:, None] * (self.b[seg] - self.a[seg])

    def crossing_segment(self, seg_guess, m, dm):
        """For each row, the segment of ``seg_guess``'s line that the plane ``m . x = dm`` (real) crosses
        nearest to ``seg_guess`` (the guess itself where none does)."""
        out = seg_guess.copy()
        if not len(seg_guess):
            return out
        line = self.line[seg_guess]
        cnt = self.first[line + 1] - self.first[line]
        owner = np.repeat(np.arange(len(seg_guess)), cnt)
        segs = np.repeat(self.first[line] - np.concatenate([[0], np.cumsum(cnt)[:-1]]), cnt) + np.arange(cnt.sum())
        fa = dot(self.a[segs], m[owner]) - dm[owner]
        fb = dot(self.b[segs], m[owner]) - dm[owner]
        cross = (fa <= 0) != (fb <= 0)
        dist = np.abs(segs - seg_guess[owner]).astype(float)
        dist[~cross] = np.inf
        o = np.lexsort((segs, dist, owner))
        pick = o[np.r_[True, owner[o][1:] != owner[o][:-1]]]
        found = np.isfinite(dist[pick])
        out[owner[pick][found]] = segs[pick][found]
        return out
