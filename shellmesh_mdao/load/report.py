"""What a load found and did: :class:`SurfaceReport`, and the text of a plane in its messages."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

__all__ = ["SurfaceReport", "plane_text", "AXES"]

#: The coordinate axes by index (a symmetry plane's ``axis``).
AXES = "xyz"


# =========================================================================== report
@dataclass
class SurfaceReport:
    """What :func:`load_surface` / :func:`repair_surface` found and did.

    The counts describe the returned mesh. ``repairs`` lists what :func:`repair_surface`
    changed (empty when only loaded); ``symmetry_plane`` (``normal`` pointing away from the
    surface, ``point``, ``offset`` = point . normal, ``axis`` 'x'/'y'/'z' or None) is set for a
    half model whose open boundary lies in one plane, ``symmetry_vertices`` are those
    boundary vertices (indices into the returned mesh: the clamped/symmetry boundary);
    ``closed_gaps`` the open gaps (open blunt trailing edges) :func:`repair_surface` closed by
    strips of triangles, one dict each (``n_triangles``, ``length``, ``width_min``,
    ``width_max``, ``start`` and ``end`` points, ``area``); ``warnings`` holds units warnings
    and accepted defects."""

    path: str
    format: str
    n_triangles: int
    n_quads: int
    n_vertices: int
    bbox_min: tuple
    bbox_max: tuple
    diagonal: float
    closed: bool
    n_open_boundary_edges: int
    n_nonmanifold_edges: int
    n_bodies: int
    n_inconsistent_orientation_edges: int
    n_merged_vertices: int
    n_removed_duplicate_faces: int
    n_removed_degenerate_faces: int
    n_zero_area_faces: int = 0
    n_components: int = 1
    component_names: list = field(default_factory=list)
    units: str = ""
    load_seconds: float = 0.0
    notes: list = field(default_factory=list)
    n_boundary_loops: int = 0
    symmetry_plane: dict | None = None
    symmetry_vertices: list = field(default_factory=list)
    closed_gaps: list = field(default_factory=list)
    repaired: bool = False
    repairs: list = field(default_factory=list)
    warnings: list = field(default_factory=list)

    def to_dict(self) -> dict:
        """Plain JSON-serialisable dict of every field."""
        d = asdict(self)
        d["bbox_min"] = [float(v) for v in self.bbox_min]
        d["bbox_max"] = [float(v) for v in self.bbox_max]
        return d

    @property
    def problems(self) -> list[str]:
        """One line per defect found (empty for a clean, closed, single-body surface)."""
        out = []
        if self.n_open_boundary_edges:
            sym = ""
            if self.symmetry_plane:
                sp = self.symmetry_plane
                sym = f"; all in the symmetry plane {plane_text(sp['normal'], sp['point'], sp['axis'])} (half model)"
            out.append(f"{self.n_open_boundary_edges} open boundary edges in {self.n_boundary_loops} loop(s) "
                       f"(surface is not closed){sym}")
        if self.n_nonmanifold_edges:
            out.append(f"{self.n_nonmanifold_edges} non-manifold edges (more than two faces on an edge)")
        if self.n_bodies > 1:
            out.append(f"{self.n_bodies} separate bodies")
        if self.n_inconsistent_orientation_edges:
            out.append(f"{self.n_inconsistent_orientation_edges} edges where neighbouring faces have "
                       "opposite orientation")
        if self.n_zero_area_faces:
            out.append(f"{self.n_zero_area_faces} zero-area faces (distinct but collinear nodes)")
        return out

    def summary_lines(self) -> list[str]:
        """Human-readable summary, one line per fact."""
        lo = ", ".join(f"{v:.6g}" for v in self.bbox_min)
        hi = ", ".join(f"{v:.6g}" for v in self.bbox_max)
        lines = [
            f"{self.path} ({self.format}): {self.n_triangles} triangles, {self.n_quads} quads, "
            f"{self.n_vertices} vertices, read in {self.load_seconds:.2f} s",
            f"bounding box [{lo}] .. [{hi}], diagonal {self.diagonal:.6g}; units: {self.units}",
            f"{'closed' if self.closed else 'open'}, {self.n_bodies} bod{'y' if self.n_bodies == 1 else 'ies'}, "
            f"{self.n_components} component(s): {', '.join(self.component_names)}",
            f"cleaned: merged {self.n_merged_vertices} duplicate vertices, removed "
            f"{self.n_removed_duplicate_faces} duplicate and {self.n_removed_degenerate_faces} degenerate faces",
        ]
        probs = self.problems
        lines.append("problems: " + ("; ".join(probs) if probs else "none"))
        lines.extend(f"note: {n}" for n in self.notes)
        lines.extend(f"repaired: {r}" for r in self.repairs)
        lines.extend(f"warning: {w}" for w in self.warnings)
        return lines


def plane_text(normal, point, axis) -> str:
    if axis is not None:
        return f"{axis} = {float(point[AXES.index(axis)]):.6g}"
    n = np.asarray(normal)
    return f"({', '.join(f'{v:.4g}' for v in n)}) . x = {float(np.asarray(point) @ n):.6g}"
