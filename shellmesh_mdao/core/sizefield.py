"""A local element-size field: sizes asked for at points, graded back to the element size
(:class:`SizeField`).

The pipeline's element size ``h`` holds wherever nothing asks for less. A stage that knows a
place needs smaller elements (two members closer than ``h``, later a tight curvature or a thin
feature) gives points there with their local size; the field at any point ``x`` is

    ``h(x) = min(cap, min_i(size_i + grading * |x - p_i|))``

so sizes grow away from every point by ``grading`` per unit length (``grading`` 0.25: each
element at most 1.25 times its neighbour towards the coarse side) until they reach the
``cap`` (the element size). The stages that place nodes (remesh, imprint, members) evaluate
it where they work, in their own units (:meth:`SizeField.scaled`).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["SizeField", "SIZE_GRADING"]

#: growth of the local size per unit length away from a field point: an element at most 1.25
#: times its neighbour's size (the remesh grades its own curvature sizing at 0.5 of its edge
#: length, twice the quad size: the same 0.25 of the quad size)
SIZE_GRADING = 0.25


@dataclass(frozen=True)
class SizeField:
    """Local element sizes ``sizes`` (k,) asked for at ``points`` (k, 3), growing away from them
    by ``grading`` per unit length (module docstring). ``reasons``: why (dicts for the report,
    e.g. ``{"why": "close members", "members": [a, b], "gap": g, "size": s}``). An empty field
    (no points) asks for nothing."""

    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    sizes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    grading: float = SIZE_GRADING
    reasons: tuple = ()

    def __post_init__(self):
        p = np.ascontiguousarray(np.asarray(self.points, np.float64).reshape(-1, 3))
        s = np.ascontiguousarray(np.asarray(self.sizes, np.float64).reshape(-1))
        if len(p) != len(s):
            raise ValueError(f"SizeField needs one size per point, got {len(p)} points and {len(s)} sizes")
        if not (np.isfinite(p).all() and np.isfinite(s).all() and (s > 0).all()):
            raise ValueError("SizeField points and sizes must be finite and the sizes positive")
        if not (np.isfinite(self.grading) and self.grading > 0):
            raise ValueError(f"SizeField grading must be positive, got {self.grading!r}")
        p.flags.writeable = False
        s.flags.writeable = False
        object.__setattr__(self, "points", p)
        object.__setattr__(self, "sizes", s)
        object.__setattr__(self, "_tree", cKDTree(p) if len(p) else None)

    def __len__(self) -> int:
        return len(self.sizes)

    @property
    def empty(self) -> bool:
        return len(self.sizes) == 0

    def union(self, other: "SizeField") -> "SizeField":
        """The field asking for the smaller of the two fields' sizes everywhere (their points,
        sizes and reasons together; the same grading)."""
        if other.empty:
            return self
        if self.empty:
            return other
        if self.grading != other.grading:
            raise ValueError(f"SizeField.union needs one grading, got {self.grading!r} and {other.grading!r}")
        return SizeField(np.vstack([self.points, other.points]), np.concatenate([self.sizes, other.sizes]),
                         self.grading, self.reasons + other.reasons)

    def scaled(self, factor: float) -> "SizeField":
        """The same field in units ``factor`` times larger (sizes and grading both scaled: the
        remesh works at twice the quad size)."""
        return SizeField(self.points, self.sizes * float(factor), self.grading * float(factor), self.reasons)

    def at(self, x, cap: float = np.inf) -> np.ndarray:
        """The field at points ``x`` (m, 3): ``min(cap, min_i(size_i + grading |x - p_i|))``,
        exact (every field point within reach of ``cap`` is looked at)."""
        x = np.asarray(x, np.float64).reshape(-1, 3)
        out = np.full(len(x), float(cap))
        if self.empty or not len(x):
            return out
        smin = float(self.sizes.min())
        if np.isfinite(cap):
            if cap <= smin:
                return out
            reach = (cap - smin) / self.grading
        else:
            reach = np.inf
        if not np.isfinite(reach):
            d, i = self._tree.query(x, k=len(self.sizes))
            d, i = d.reshape(len(x), -1), i.reshape(len(x), -1)
            return (self.sizes[i] + self.grading * d).min(1)
        pairs = cKDTree(x).sparse_distance_matrix(self._tree, reach, output_type="ndarray")
        if len(pairs):
            np.minimum.at(out, pairs["i"], self.sizes[pairs["j"]] + self.grading * pairs["v"])
        return out

    def digest(self) -> str:
        """SHA-1 of the points, sizes and grading (equal digests, equal fields)."""
        h = hashlib.sha1()
        for a in (self.points, self.sizes, np.float64(self.grading)):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()

    def summary(self, size: float) -> dict:
        """The report's ``size_field``: the smallest and largest local size (``size`` where the
        field asks for nothing), the grading and why."""
        smin = float(min(self.sizes.min(), size)) if not self.empty else float(size)
        return {"min": smin, "max": float(size), "grading": float(self.grading), "n_points": len(self),
                "reasons": [dict(r) for r in self.reasons]}
