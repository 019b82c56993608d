"""Real wings: every corpus geometry meshed from layouts given by stations (issue 40).

``python run_scripts/real_wings.py`` runs the matrix and writes docs/real_wings.md. A case is a
geometry of ``manifest.json``, a layout (:data:`LAYOUTS`: ribs per wing and spar chord
fractions), a rib orientation (:data:`ORIENTATIONS`) and an element size ``semi-span / d`` for
``d`` in :data:`DIVISORS`. Its layout is the one ``shellmesh wings SURFACE --axis A --size H``
writes (:func:`~shellmesh_mdao.layout.finder.find_wings`, :func:`station_layout`): every
lifting surface found along the span axis ``A`` given by its **stations**, not its corners, the
planform (edges, chords, thickness) measured from the skin; only the ribs, spars and
orientation are set by the case (a surface too short for the ribs at that size, a tail, gets as
many as fit 1.5 sizes apart, as ``shellmesh wings`` writes them). The span axis is the coordinate axis normal to the manifest's
``up`` and to its first wing's root chord (``y``, or ``z`` for the bwb).

The **semi-span** is the largest distance of the skin from the plane through the origin normal
to the span axis (every corpus geometry has its symmetry plane there).

Each case runs in its own child process with a time limit (:func:`run_case_in_child`) and is
classified **ok** (meshed, and :func:`~shellmesh_mdao.guarantees.check_guarantees` holds; an
input skin that is not closed, a half model, is checked with ``input_closed=False`` and
``free_edges=True``: its own boundary edges are edges of the mesh), **guarantee** (meshed, a
guarantee missed), **refused** (a :class:`~shellmesh_mdao.errors.ShellMeshError`: the pipeline
refused with a message) or **crash** (any other exception, a time-out or a dead child).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .child import classify_case, run_in_child
from .page import outcome_rows

__all__ = ["LAYOUTS", "ORIENTATIONS", "DIVISORS", "span_axis", "station_layout", "semi_span", "run_case",
           "run_case_in_child", "matrix_cases", "summary_counts", "write_page"]

#: layout name -> (ribs per wing, spar chord fractions)
LAYOUTS = {"10 ribs, spars 0.15/0.65": (10, (0.15, 0.65)),
           "15 ribs, 3 spars": (15, (0.15, 0.40, 0.65)),
           "4 ribs, 1 spar": (4, (0.35,))}
#: rib orientations of the matrix
ORIENTATIONS = ("normal_to_spar", "streamwise", "normal_to_midchord")
#: element size = semi-span / divisor
DIVISORS = (20, 40, 80)


def span_axis(manifest: dict, geometry: str) -> str:
    """'x', 'y' or 'z': the coordinate axis normal to the manifest's ``up`` and to the first
    wing's root chord."""
    g = manifest["geometries"][geometry]
    w = g["wings"][0]
    n = np.cross(np.asarray(w.get("up", g["up"]), float), np.subtract(w["root_te"], w["root_le"]))
    return "xyz"[int(np.argmax(np.abs(n)))]


def semi_span(points, axis: str) -> float:
    """Largest distance of the skin from the plane through the origin normal to ``axis``."""
    return float(np.abs(np.asarray(points)[:, "xyz".index(axis)]).max())


def station_layout(points, tris, axis: str, size: float, ribs: int, spars, orientation: str) -> dict:
    """The layout ``shellmesh wings`` writes for the skin at ``size``, with ``ribs`` ribs in
    ``orientation`` and spars at ``spars``."""
    from ..layout.finder import find_wings, starting_layout

    return starting_layout(find_wings(points, tris, axis, size=size), ribs=ribs, spars=spars,
                           orientation=orientation)


def run_case(geometry_dir, geometry: str, layout_name: str, orientation: str, divisor: int) -> dict:
    """Run one case end to end and classify it (module docstring); never raises."""
    from ..load import load_surface
    from ..pipeline import run_pipeline

    def run(out):
        manifest = json.loads((Path(geometry_dir) / "manifest.json").read_text())
        ribs, spars = LAYOUTS[layout_name]
        mesh, _ = load_surface(Path(geometry_dir) / manifest["geometries"][geometry]["file"])
        axis = span_axis(manifest, geometry)
        size = semi_span(mesh.points, axis) / divisor
        out["size"] = size
        out["stage"] = "wings"
        lay = station_layout(mesh.points, mesh.faces[:, :3], axis, size, ribs, spars, orientation)
        out["wings"] = [f"{w['name']} {w['root']:.4g}..{w['tip']:.4g}" for w in lay["wings"]]
        out["stage"] = ""
        res = run_pipeline(mesh, lay, size, progress=False, check=False)   # classified by classify_case
        out["notes"] = [n for w in res.report.get("wings", {}).values() for n in w.get("notes", [])]
        return res

    return classify_case({"geometry": geometry, "layout": layout_name, "orientation": orientation,
                          "divisor": divisor}, run)



def run_case_in_child(geometry_dir, geometry, layout_name, orientation, divisor, timeout: float = 1800.0) -> dict:
    """:func:`run_case` in a fresh child process; a time-out or a dead child is a crash."""
    out = run_in_child(run_case, str(geometry_dir), geometry, layout_name, orientation, divisor, timeout=timeout)
    status = out.pop("status")
    if status != "ok":
        out = {"geometry": geometry, "layout": layout_name, "orientation": orientation, "divisor": divisor,
               "outcome": "crash", "stage": "", "error": out.get("error", status)}
    return out


def matrix_cases(manifest: dict, only=None, layouts=None, orientations=None, divisors=None) -> list:
    """Every (geometry, layout, orientation, divisor) of the matrix, geometries in manifest order."""
    return [(g, lay, o, d) for g in manifest["geometries"] if not only or g in only
            for lay in (layouts or LAYOUTS) for o in (orientations or ORIENTATIONS) for d in (divisors or DIVISORS)]


def summary_counts(results: list) -> dict:
    """``{geometry: {outcome: count}}`` and a ``"total"`` row."""
    out: dict = {}
    for r in results:
        out.setdefault(r["geometry"], {"ok": 0, "guarantee": 0, "refused": 0, "crash": 0})[r["outcome"]] += 1
    out["total"] = {k: sum(row[k] for row in out.values()) for k in ("ok", "guarantee", "refused", "crash")}
    return out


def write_page(results: list, meta: dict, path) -> None:
    """docs/real_wings.md: the counts per geometry, the lines of ``meta["findings"]`` (what the
    cases that are not ok come from, written after a run), then every case that is not ok."""
    counts = summary_counts(results)
    lines = ["# Real wings: layouts given by stations", "",
             "Generated by `python run_scripts/real_wings.py` "
             f"({meta.get('date', '')}, {meta.get('seconds', 0):.0f} s). Each geometry of the corpus manifest, every "
             "wing given by its span axis and its root and tip stations (the planform measured from the skin, "
             "`docs/layout.md`), with the layouts "
             + ", ".join(f"*{k}*" for k in LAYOUTS) + ", the rib orientations "
             + ", ".join(f"`{o}`" for o in ORIENTATIONS) + " and element sizes semi-span / "
             + " and / ".join(str(d) for d in DIVISORS) + " (the harness: `shellmesh_mdao.benchmarks.real_wings`). "
             "*ok*: meshed and every guarantee of `check_guarantees` holds; *guarantee*: meshed, a guarantee "
             "missed; *refused*: the pipeline refused with a message; *crash*: anything else.", ""]
    lines += outcome_rows("geometry", counts)
    if meta.get("findings"):
        lines += ["", "## Findings", ""] + [f"* {f}" for f in meta["findings"]]
    bad = [r for r in results if r["outcome"] != "ok"]
    if bad:
        lines += ["", "## Cases that are not ok", "", "| geometry | layout | orientation | size | outcome | stage | "
                  "message |", "| --- | --- | --- | --- | --- | --- | --- |"]
        for r in bad:
            msg = r.get("error", "").replace("|", "\\|").replace("\n", " ")
            lines.append(f"| {r['geometry']} | {r['layout']} | {r['orientation']} | /{r['divisor']} | {r['outcome']} "
                         f"| {r.get('stage', '')} | {msg[:300]} |")
    notes = sorted({n for r in results for n in r.get("notes", [])})
    if notes:
        lines += ["", "## Notes of the layout stage", ""] + [f"* {n}" for n in notes]
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
