"""A random family of aircraft meshed end to end: geometry x element size x layout, drawn from seeds.

``python run_scripts/random_family.py`` runs N draws (default 200) and writes docs/random_family.md.
Draw ``seed`` is, from ``numpy.random.default_rng(seed)`` in this order: the aircraft
(:func:`~shellmesh_mdao.geometry.draw_aircraft`: every parameter uniform in its range), the layout's
structure (:func:`~shellmesh_mdao.geometry.draw_structure`: 3-15 ribs, 1-3 spars, a rib orientation,
whether the tails get members) and the element size ``mean chord / d`` with ``d`` log-uniform in
:data:`DIVISOR_RANGE` (the mean chord: the wing's planform area over its span). The skin is
:func:`~shellmesh_mdao.geometry.aircraft_surface`; the layout
:func:`~shellmesh_mdao.geometry.aircraft_layout` at that size (wings given by stations, as
``shellmesh wings`` writes them).

Each case runs in its own child process with a time limit (:func:`run_case_in_child`) and is
classified like the real-wings matrix (:mod:`~shellmesh_mdao.benchmarks.real_wings`): **ok**
(meshed, and :func:`~shellmesh_mdao.guarantees.check_guarantees` holds), **guarantee** (meshed, a
guarantee missed), **refused** (a :class:`~shellmesh_mdao.errors.ShellMeshError`: the pipeline
refused with a message) or **crash** (any other exception, a time-out or a dead child).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .child import classify_case, run_in_child
from .page import outcome_rows

__all__ = ["DIVISOR_RANGE", "BANDS", "draw_case", "run_case", "run_case_in_child", "summary_counts",
           "describe_params", "write_page"]

#: element size = mean chord / d, d log-uniform in this range
DIVISOR_RANGE = (5.0, 60.0)
#: divisor bands of the page's second table
BANDS = ((5.0, 10.0), (10.0, 20.0), (20.0, 40.0), (40.0, 60.0))
OUTCOMES = ("ok", "guarantee", "refused", "crash")


def draw_case(seed: int) -> dict:
    """The draw of ``seed``: ``params`` (:class:`~shellmesh_mdao.geometry.AircraftParams`),
    ``structure`` (:class:`~shellmesh_mdao.geometry.StructureParams`), ``divisor``, ``mean_chord``
    and ``size`` = mean chord / divisor. The first two are those of ``random_aircraft(seed)``."""
    from ..geometry.aircraft import draw_aircraft, draw_structure, wing_planform

    rng = np.random.default_rng(seed)
    params = draw_aircraft(rng)
    structure = draw_structure(rng)
    lo, hi = DIVISOR_RANGE
    divisor = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    chord = wing_planform(params)["mean_chord"]
    return {"params": params, "structure": structure, "divisor": divisor, "mean_chord": chord,
            "size": chord / divisor}


def describe_params(params: dict) -> str:
    """A short text of the parameters that shape a case (the whole set is in the JSON)."""
    p = params
    parts = [f"AR {p['aspect_ratio']:.2f}", f"taper {p['taper']:.2f}", f"sweep {p['sweep_deg']:.1f}",
             f"dihedral {p['dihedral_deg']:.1f}", f"twist {p['twist_deg']:.1f}",
             f"t/c {p['thickness']:.3f}/{p['tip_thickness']:.3f}",
             f"TE {'blunt %.4f' % p['te_thickness'] if p['blunt_te'] else 'sharp'}", f"tip {p['tip']}"]
    if p["cranked"]:
        parts.append(f"crank {p['crank_eta']:.2f} (outer sweep {p['outer_sweep_deg']:.1f})")
    if p["winglet"] != "none":
        parts.append(f"winglet {p['winglet']} (cant {p['winglet_cant_deg']:.0f})")
    if p["fuselage"]:
        parts.append(f"fuselage (wing_z {p['wing_z']:.2f})" + "".join(
            f" {k}" for k in ("htail", "fin") if p[k]))
    else:
        parts.append("flying wing")
    return ", ".join(parts)


def run_case(seed: int) -> dict:
    """Draw, build and mesh case ``seed`` and classify it (module docstring); never raises."""
    from ..geometry.aircraft import aircraft_layout, aircraft_surface
    from ..pipeline import run_pipeline

    def run(out):
        case = draw_case(seed)
        out.update(params=case["params"].to_dict(), structure=case["structure"].to_dict(),
                   divisor=case["divisor"], size=case["size"], mean_chord=case["mean_chord"])
        out["stage"] = "geometry"
        skin = aircraft_surface(case["params"])
        lay = aircraft_layout(case["params"], case["structure"], case["size"])
        out["n_input_triangles"] = int(skin.n_faces)
        out["wings"] = [w["name"] for w in lay["wings"]]
        out["stage"] = ""
        return run_pipeline(skin, lay, case["size"], progress=False, check=False)   # classified by classify_case

    return classify_case({"seed": int(seed)}, run)


def run_case_in_child(seed: int, timeout: float = 1800.0) -> dict:
    """:func:`run_case` in a fresh child process; a time-out or a dead child is a crash (the draw's
    parameters are recorded all the same)."""
    out = run_in_child(run_case, int(seed), timeout=timeout)
    status = out.pop("status")
    if status != "ok":
        case = draw_case(seed)
        out = {"seed": int(seed), "outcome": "crash", "stage": "", "error": out.get("error", status),
               "params": case["params"].to_dict(), "structure": case["structure"].to_dict(),
               "divisor": case["divisor"], "size": case["size"], "mean_chord": case["mean_chord"]}
    return out


def summary_counts(results: list) -> dict:
    """``{row: {outcome: count}}``: a ``"total"`` row, one per divisor band of :data:`BANDS`
    (``"chord/5-10"`` ...), one per feature of the draws (winglet kinds, tips, trailing edges,
    cranked, flying wing) and of their layouts (spar count, rib orientation, tails with members)."""
    rows: dict = {}

    def add(row, r):
        rows.setdefault(row, dict.fromkeys(OUTCOMES, 0))[r["outcome"]] += 1

    for r in results:
        add("total", r)
        d = r.get("divisor")
        for lo, hi in BANDS:
            if d is not None and lo <= d <= hi:
                add(f"chord/{lo:g}-{hi:g}", r)
        p = r.get("params")
        if p:
            add(f"winglet {p['winglet']}", r)
            add(f"tip {p['tip']}", r)
            add("blunt TE" if p["blunt_te"] else "sharp TE", r)
            add("cranked" if p["cranked"] else "straight", r)
            add("fuselage" if p["fuselage"] else "flying wing", r)
        st = r.get("structure")
        if st:
            add(f"{len(st['spars'])} spar{'s' if len(st['spars']) > 1 else ''}", r)
            add(f"ribs {st['orientation']}", r)
            add("tails with members" if st["tails"] else "wing members only", r)
    order = (["total"] + [f"chord/{lo:g}-{hi:g}" for lo, hi in BANDS]
             + [f"winglet {k}" for k in ("none", "blended", "separate")] + ["tip flat", "tip round", "sharp TE",
                "blunt TE", "straight", "cranked", "fuselage", "flying wing", "1 spar", "2 spars", "3 spars"]
             + [f"ribs {o}" for o in ("normal_to_spar", "streamwise", "normal_to_midchord")]
             + ["wing members only", "tails with members"])
    return {k: rows[k] for k in order if k in rows}


def write_page(results: list, meta: dict, path) -> None:
    """docs/random_family.md: the counts (:func:`summary_counts`), the lines of
    ``meta["findings"]``, then every case that is not ok with its parameters, size and message."""
    counts = summary_counts(results)
    lo, hi = DIVISOR_RANGE
    lines = ["# Random family of aircraft", "",
             f"Generated by `python run_scripts/random_family.py` ({meta.get('date', '')}, "
             f"{meta.get('seconds', 0):.0f} s, {len(results)} draws: seeds {meta.get('seeds', '')}). Each draw is "
             "an aircraft of `shellmesh_mdao.geometry.aircraft` with every parameter uniform in its range "
             "(`RANGES`: taper 0.2-1, leading-edge sweep 0-60 deg, dihedral -5-10 deg, twist -6-4 deg, "
             "thickness 4-18 % of the chord; sharp or blunt trailing edge, flat or round tips, cranked or "
             "straight, no winglet / blended / separate, with a fuselage, horizontal tail and fin or a flying "
             "wing), a layout given by stations (3-15 ribs, 1-3 spars, a rib orientation) and an element size "
             f"mean chord / d, d log-uniform in {lo:g}-{hi:g} (the harness: "
             "`shellmesh_mdao.benchmarks.random_family`). *ok*: meshed and every guarantee of "
             "`check_guarantees` holds; *guarantee*: meshed, a guarantee missed; *refused*: the pipeline "
             "refused with a message; *crash*: anything else (an exception, a time-out, a dead child).", ""]
    lines += outcome_rows("draws", counts)
    if meta.get("findings"):
        lines += ["", "## Findings", ""] + [f"* {f}" for f in meta["findings"]]
    bad = [r for r in results if r["outcome"] != "ok"]
    if bad:
        lines += ["", "## Cases that are not ok", "",
                  "Reproduce one with `python run_scripts/random_family.py --seeds SEED` (its full parameters are "
                  "in docs/random_family.json).", "",
                  "| seed | size | outcome | stage | aircraft | layout | message |",
                  "| ---: | --- | --- | --- | --- | --- | --- |"]
        for r in bad:
            msg = r.get("error", "").replace("|", "\\|").replace("\n", " ")
            st = r.get("structure") or {}
            lay = (f"{st.get('ribs')} ribs, spars {'/'.join(f'{f:g}' for f in st.get('spars', ()))}, "
                   f"{st.get('orientation')}{', tails' if st.get('tails') else ''}") if st else ""
            size = f"{r['size']:.4g} (chord/{r['divisor']:.1f})" if "size" in r else ""
            desc = describe_params(r["params"]) if r.get("params") else ""
            lines.append(f"| {r['seed']} | {size} | {r['outcome']} | {r.get('stage', '')} | {desc} | {lay} "
                         f"| {msg[:400]} |")
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
