"""The benchmark's page: docs/benchmarks.md rendered from the raw figures of
:func:`~shellmesh_mdao.benchmarks.corpus.run_benchmark` (what docs/benchmarks.json holds).

:func:`write_outputs` writes the page and the JSON beside it; a hand-kept part below the line
:data:`KEEP_MARKER` of the existing page is carried over unchanged (:func:`kept_part`).
:func:`render_page` is deterministic: the same figures give the same page.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

from .corpus import (GMSH_FEATURE_ANGLE, MEMORY_BUDGET_GB, PERTURB_SCALE, PIPELINE_LAZY_IMPORTS, RIBS, SPARS,
                     pair_medians, pair_row)
from .figures import TARGETS, target_checks

__all__ = ["KEEP_MARKER", "kept_part", "render_page", "robustness_section", "write_outputs", "outcome_rows"]

KEEP_MARKER = "<!-- everything below this line is kept by run_scripts/benchmark.py -->"


def outcome_rows(first: str, counts: dict) -> list[str]:
    """A markdown table of outcome counts (``{row: {"ok", "guarantee", "refused", "crash": n}}``,
    the row ``"total"`` in bold) whose first column is headed ``first``."""
    lines = [f"| {first} | cases | ok | guarantee | refused | crash |", "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for row, c in counts.items():
        name = f"**{row}**" if row == "total" else row
        lines.append(f"| {name} | {sum(c.values())} | {c['ok']} | {c['guarantee']} | {c['refused']} | {c['crash']} |")
    return lines


def _f(v, fmt="{:.3f}", none="—"):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return none
    return fmt.format(v)


def _i(v):
    return "—" if v is None else f"{int(v):,}"


def _mark(ok):
    return "—" if ok is None else ("pass" if ok else "**FAIL**")


def _status(r):
    return r.get("status", "not run") if r else "not run"


def _bound_text(kind, bound):
    if kind == "min":
        return f"≥ {bound:g}"
    if kind == "max":
        return f"≤ {bound:g}"
    return f"{bound[0]:g}–{bound[1]:g}"


def _target_value(key, f):
    v = f.get(key)
    if key in ("quad_percent", "angles_ok_percent"):
        return _f(v, "{:.2f} %")
    if key == "n_sj_le_0.2":
        return _i(v)
    if key == "warp_p99":
        return _f(v, "{:.2f}°")
    return _f(v)


def _stage_items(stages: dict) -> list[tuple[str, float]]:
    """(stage, seconds) in pipeline order (the JSON's keys are sorted)."""
    from ..pipeline import STAGES

    rank = {k: i for i, k in enumerate(STAGES)}
    return sorted(stages.items(), key=lambda kv: (rank.get(kv[0], len(rank)), kv[0]))


def _quality_rows(case: dict) -> list[str]:
    rows = []
    for who, label in (("ours", "shellmesh (skin + members)"), ("gmsh", "Gmsh (skin only)")):
        r = case.get(who)
        if r is None:
            continue
        head = f"| {case['name']} | {case['size']:g} | {label} "
        if r.get("status") != "ok":
            rows.append(head + f"| {r.get('status')}: {r.get('error', '')} " + "| " * 13 + "|")
            continue
        f = r["figures"]
        rows.append(head + "| " + " | ".join([
            _i(f["n_elements"]), _i(f["n_skin"]), _f(f["quad_percent"], "{:.2f} %"), _i(f["n_folded"]),
            _i(f["n_sj_le_0.2"]), _f(f["sj_min"]), _f(f["sj_mean"]), _f(f["min_angle"], "{:.1f}°"),
            _f(f["max_angle"], "{:.1f}°"), _f(f["angles_ok_percent"], "{:.2f} %"), _f(f["warp_p99"], "{:.2f}°"),
            _f(f["median_edge_ratio"], "{:.2f}"), "yes" if f["valid"] else "**no**"]) + " |")
    return rows


def _time_row(case: dict) -> str:
    g, o = case.get("gmsh") or {}, case["ours"]

    def t(r):
        if r.get("status") != "ok":
            return f"{r.get('status', 'not run')}", "—", "—"
        return f"{r['wall_s']:.1f}", f"{r['cpu_s']:.1f}", f"{r['peak_rss_mb']:,.0f}"

    ow, oc, om = t(o)
    gw, gc, gm = t(g) if g else ("not run", "—", "—")
    return (f"| {case['name']} | {case['size']:g} | {case['ribs_per_wing']} | {ow} | {oc} | {om} | {gw} | {gc} | {gm} | "
            f"{_f(case.get('time_ratio'), '{:.1f}')} | {_f(case.get('cpu_ratio'), '{:.1f}')} | "
            f"{case['load_before']:.1f} / {case['load_after']:.1f} |")


def robustness_section(rob: list) -> list[str]:
    """The page's section on the perturbed runs: per case and target, how many runs meet it and
    the range of its figure; the wall-time range and how many runs needed the second final pass."""
    scale = rob[0].get("scale", PERTURB_SCALE)
    L = ["## Robustness under input perturbation", "",
         (f"Each case again on {len(rob[0]['runs'])} copies of its input whose coordinates are multiplied by "
         f"`1 + {scale:g} g` (`g` standard normal, seeds 0, 1, ...; `--perturb`): the same geometry to far below "
         "any tolerance, other rounding, as another machine's maths library or another export of the same CAD "
         "would give. The meshes differ (the discrete stages branch on rounding), so each figure below is a "
         "range, followed by how many runs meet its target. A target met in the table above but not in every "
         "run here has a margin below the run-to-run spread."), "",
         "| geometry | size | ribs / wing | " + " | ".join(f"{TARGETS[k][0]} ({_bound_text(*TARGETS[k][1:])})"
                                                    for k in TARGETS) + " | all targets | second final pass | wall s |",
         "| --- | --- | --- | " + " | ".join("---" for _ in TARGETS) + " | --- | --- | --- |"]
    for c in rob:
        ok = [r for r in c["runs"] if r.get("status") == "ok"]
        n = len(c["runs"])
        if not ok:
            L.append(f"| {c['name']} | {c['size']:g} | {c['ribs_per_wing']} | no run finished: "
                     f"{_status(c['runs'][0]) if c['runs'] else '—'} |" + " — |" * (len(TARGETS) + 2))
            continue
        cells = []
        for k in TARGETS:
            vals = [r["figures"][k] for r in ok if r["figures"].get(k) is not None]
            if not vals:
                cells.append("—")
                continue
            met = sum(bool(target_checks(r["figures"])[k]) for r in ok)
            fmt = "{:.0f}" if k == "n_sj_le_0.2" else ("{:.2f}" if k in ("quad_percent", "angles_ok_percent",
                                                                         "warp_p99") else "{:.4f}")
            rng = fmt.format(min(vals)) if min(vals) == max(vals) else f"{fmt.format(min(vals))}–{fmt.format(max(vals))}"
            cells.append(f"{rng}; {met}/{n}")
        allm = sum(all(v is not False for v in target_checks(r["figures"]).values()) for r in ok)
        walls = [r["wall_s"] for r in ok]
        L.append(f"| {c['name']} | {c['size']:g} | {c['ribs_per_wing']} | " + " | ".join(cells)
                 + f" | {allm}/{n} | {sum(bool(r.get('second_pass')) for r in ok)}/{len(ok)} | "
                 f"{min(walls):.1f}–{max(walls):.1f} |")
    return L + [""]


def render_page(res: dict, keep: str = "") -> str:
    """The Markdown page of the results ``res`` of :func:`run_benchmark`; ``keep`` (the
    hand-kept part of the previous page) is appended after :data:`KEEP_MARKER`."""
    m = res["machine"]
    L = ["# Benchmarks", ""]
    mode = " (`--quick`: small cases)" if res.get("quick") else (f" (`--only {res['only']}`)" if res.get("only") else "")
    L += [f"Generated by `python run_scripts/benchmark.py`{mode} on {res['started']}: {m['cpus']} cores, "
          f"{m['memory_gb']} GB, Python {m['python']}, numpy {m['numpy']}, scipy {m['scipy']}, trimesh {m['trimesh']}, "
          f"Gmsh {m['gmsh']}. The machine was shared with other jobs: 1-minute load average {res['load_start']:.1f} at "
          f"the start, {res['load_end']:.1f} at the end, per case below; with 2 cores, a load above 2 means every "
          f"process got less than a core, so wall times are inflated (compare the CPU times, and allow ±30 %). "
          f"Whole run: {res['total_s'] / 60:.1f} min. Mesh figures are deterministic; times and memory are not.", ""]
    L += ["Each case runs in its own fresh process (imports excluded from the times, included in the peak "
          "memory; the libraries the stages import on first use, "
          + ", ".join(f"`{m}`" for m in PIPELINE_LAZY_IMPORTS) + ", and the pipeline's own stage modules "
          "(`shellmesh_mdao.remesh`, `.imprint`, ...) are imported before the clock starts, as `gmsh` is, and "
          "the compiled kernels (`core/kernels.py` and each stage's `kernels.py`) are loaded from numba's cache by "
          "`shellmesh_mdao.kernels.warm_up()`, about 0.3 s, compiled on a new install). Layouts: "
          "`layout_from_manifest(manifest, name, ribs, spars=(0.15, 0.65))`, i.e. ribs per wing and 2 spars. "
          "Gmsh remeshes the bare skin STL: `classifySurfaces` "
          f"({GMSH_FEATURE_ANGLE:g}° feature angle, reparametrisation) + `createGeometry`, Frontal-Delaunay for quads "
          "(`Mesh.Algorithm = 8`), Blossom (`Mesh.RecombinationAlgorithm = 1`, `RecombineAll`), one all-quad "
          "subdivision (`Mesh.SubdivisionAlgorithm = 1`), one thread. Gmsh meshes at `2 × size`, the pipeline at "
          f"`{res.get('remesh_factor', 2.0):g} × size` (`pipeline.REMESH_FACTOR`); both subdivide once, so both aim "
          "at quads of edge `size` (median edge / size checks it).", ""]

    # ---- targets
    L += ["## Quality targets (the pipeline's final mesh)", ""]
    keys = list(TARGETS)
    L += ["| geometry | size | " + " | ".join(f"{TARGETS[k][0]} ({_bound_text(*TARGETS[k][1:])})" for k in keys)
          + " | all pass |",
          "| --- | --- | " + " | ".join("---" for _ in keys) + " | --- |"]
    for case in res["corpus"]:
        o = case["ours"]
        if o.get("status") != "ok":
            L.append(f"| {case['name']} | {case['size']:g} | {o.get('status')}: {o.get('error', '')} |"
                     + " |" * len(keys))
            continue
        f, t = o["figures"], case["targets"]
        cells = [f"{_target_value(k, f)} {_mark(t[k])}" if t[k] is not None else "—" for k in keys]
        allok = all(v for v in t.values() if v is not None)
        L.append(f"| {case['name']} | {case['size']:g} | " + " | ".join(cells) + f" | {'yes' if allok else '**no**'} |")
    L += ["", "SJ = scaled Jacobian (Verdict; 1 for a square, ≤ 0 folded). Members are the components named "
          "`<wing>/rib_k` or `<wing>/spar_j` (and their segments); the rest is skin. Warp p99 over quads; median "
          "edge over unique edges.", ""]

    # ---- comparison
    L += ["## Side by side with Gmsh's all-quad remesh of the skin", "",
          "| geometry | size | mesher | elements | skin elements | quads | folded (SJ ≤ 0) | SJ ≤ 0.2 | min SJ "
          "| mean SJ | min angle | max angle | quads, angles in [45°, 135°] | warp p99 | median edge / size | valid |",
          "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for case in res["corpus"]:
        L += _quality_rows(case)
    L += ["", "\"valid\": `ShellMesh.check()` finds no duplicate node, degenerate face, inconsistent orientation "
          "or hanging node. The quality figures do not depend on orientation (corner angles and Jacobians are "
          "measured against each element's own normal).", ""]
    probs = [(c["name"], who, r["figures"]["problems"]) for c in res["corpus"] for who, r in
             (("shellmesh", c["ours"]), ("Gmsh", c.get("gmsh") or {})) if r.get("status") == "ok"
             and r["figures"].get("problems")]
    if probs:
        L += ["Problems `check()` found:", ""] + [f"- {n}, {who}: " + "; ".join(p) for n, who, p in probs] + [""]
    L += ["### Time and memory", "",
          "| geometry | size | ribs / wing | shellmesh wall s | CPU s | peak MB | Gmsh wall s | CPU s | peak MB "
          "| time ratio (wall) | time ratio (CPU) | load before / after |",
          "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for case in res["corpus"]:
        L.append(_time_row(case))
    L += ["", "Time ratio = shellmesh / Gmsh (below 1: the pipeline is faster). shellmesh's time is the whole "
          "`run_pipeline` (read, repair, project, remesh, imprint, members, split, merge, smooth, subdivide; skin "
          "and members); Gmsh's from `merge` to the extracted arrays (skin only). CPU time counts every thread of "
          "the process.", ""]

    # ---- stages
    stages = [c for c in res["corpus"] if c["ours"].get("status") == "ok"]
    if stages:
        names = [k for k, _ in _stage_items({k: 0 for c in stages for k in c["ours"]["stages"]})]
        L += ["### Pipeline stages (wall seconds)", "",
              "| geometry | input triangles | " + " | ".join(names) + " | split LP | merge MIP (gap) |",
              "| --- | --- | " + " | ".join("---" for _ in names) + " | --- | --- |"]
        for c in stages:
            o = c["ours"]
            sp, me = o.get("split") or {}, o.get("merge") or {}
            L.append(f"| {c['name']} | {_i(o.get('n_input_triangles'))} | "
                     + " | ".join(_f(o["stages"].get(k), "{:.1f}") for k in names)
                     + f" | {sp.get('status', '—')} | {me.get('status', '—')} ({_f(me.get('mip_gap'), '{:.3f}')}) |")
        L.append("")

    # ---- performance target
    p = res.get("performance")
    if p is not None:
        g, o = p.get("gmsh") or {}, p["ours"]
        rows = p.get("pairs") or [pair_row(p)]            # pages of runs before the pairs: their one pair
        med = p.get("median") or pair_medians(rows)
        L += ["## Performance target", "",
              f"Target: the full run on {p['name']} with 2 wings × ({p['ribs_per_wing']} ribs + {len(p['spars'])} "
              f"spars) at size {p['size']:g} takes less time than Gmsh's skin-only remesh of the same file at the same "
              "size, measured side by side: Gmsh first, then the pipeline, in consecutive processes, "
              f"{len(rows)} such pair{'s' if len(rows) != 1 else ''} one after the other. The verdict is on the median "
              "of the pairs' time ratios: one pair's ratio moves by up to a third with the machine's load.", "",
              "| pair | shellmesh wall s | CPU s | Gmsh wall s | CPU s | time ratio (wall) | time ratio (CPU) "
              "| load before / after |",
              "| --- | --- | --- | --- | --- | --- | --- | --- |"]
        for k, r in enumerate(rows, 1):
            ow = _f(r.get("wall_s"), "{:.2f}") if r.get("status") == "ok" else str(r.get("status"))
            gw = _f(r.get("gmsh_wall_s"), "{:.2f}") if r.get("gmsh_status") == "ok" else str(r.get("gmsh_status"))
            L.append(f"| {k} | {ow} | {_f(r.get('cpu_s'), '{:.2f}')} | {gw} | {_f(r.get('gmsh_cpu_s'), '{:.2f}')} | "
                     f"{_f(r.get('time_ratio'), '{:.2f}')} | {_f(r.get('cpu_ratio'), '{:.2f}')} | "
                     f"{_f(r.get('load_before'), '{:.1f}')} / {_f(r.get('load_after'), '{:.1f}')} |")
        L.append(f"| median ({med['n']} of {len(rows)}) | {_f(med['wall_s'], '{:.2f}')} | "
                 f"{_f(med['cpu_s'], '{:.2f}')} | "
                 f"{_f(med['gmsh_wall_s'], '{:.2f}')} | {_f(med['gmsh_cpu_s'], '{:.2f}')} | "
                 f"{_f(med['time_ratio'], '{:.2f}')} | {_f(med['cpu_ratio'], '{:.2f}')} | |")
        L.append("")
        if med["time_ratio"] is not None:
            met = med["time_ratio"] < 1.0
            lo, hi = med["time_ratio_range"]
            plural = "s" if med["n"] != 1 else ""
            L += [f"Result: **{'met' if met else 'not met'}** — median over {med['n']} pair{plural}: the pipeline "
                  f"{med['wall_s']:.2f} s ({med['cpu_s']:.2f} s CPU) for "
                  f"{_i((o.get('figures') or {}).get('n_elements'))} quads of skin and members, Gmsh "
                  f"{med['gmsh_wall_s']:.2f} s ({med['gmsh_cpu_s']:.2f} s CPU) for "
                  f"{_i((g.get('figures') or {}).get('n_elements'))} quads of skin: {med['time_ratio']:.2f}× (wall; "
                  f"the pairs {lo:.2f}–{hi:.2f}×), {med['cpu_ratio']:.2f}× (CPU). Peak memory (first pair): the "
                  f"pipeline {_f(o.get('peak_rss_mb'), '{:,.0f}')} MB, Gmsh {_f(g.get('peak_rss_mb'), '{:,.0f}')} MB. "
                  "Stages (first pair): " + ", ".join(f"{k} {v:.1f}" for k, v in _stage_items(o.get("stages") or {}))
                  + " s.", ""]
        else:
            L += [f"Result: not measured (shellmesh: {_status(o)}, Gmsh: {_status(g)}).", ""]

    # ---- robustness
    if res.get("robustness"):
        L += robustness_section(res["robustness"])

    # ---- memory target
    mm = res.get("memory")
    if mm is not None:
        o, ref = mm["ours"], mm["refined"]
        L += ["## Memory target", "",
              f"Target: a run on a 1M-triangle input completes within {MEMORY_BUDGET_GB:g} GB. Input: {mm['name']} "
              f"midpoint-subdivided {ref['levels']} times (`trimesh.remesh.subdivide`, each triangle → 4, the same "
              f"faceted surface) to {ref['n_triangles']:,} triangles; the pipeline at size {mm['size']:g} with "
              f"{RIBS} ribs + {len(SPARS)} spars per wing, in a fresh process; peak = `ru_maxrss` of that process.", ""]
        if o.get("status") == "ok":
            f = o["figures"]
            L += ["| input triangles | peak memory | wall s | CPU s | output quads | mean SJ | SJ ≤ 0.2 | median edge / "
                  "size | load before / after | within budget |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
                  f"| {ref['n_triangles']:,} | {o['peak_rss_mb'] / 1024:.2f} GB | {o['wall_s']:.0f} | {o['cpu_s']:.0f} | "
                  f"{f['n_elements']:,} | {f['sj_mean']:.3f} | {f['n_sj_le_0.2']:,} | {f['median_edge_ratio']:.2f} | "
                  f"{mm['load_before']:.1f} / {mm['load_after']:.1f} | {'yes' if mm['within_budget'] else '**no**'} |",
                  "", "Stages (s): " + ", ".join(f"{k} {v:.1f}" for k, v in _stage_items(o["stages"])) + ".", ""]
            base = [c for c in res["corpus"] if c["name"] == mm["name"] and c["size"] == mm["size"]
                    and c["ribs_per_wing"] == RIBS and c["ours"].get("status") == "ok"]
            if base:
                b = base[0]["ours"]
                L += [f"The same geometry from its original {_i(b.get('n_input_triangles'))} triangles (corpus run "
                      f"above): {b['figures']['n_elements']:,} quads, mean SJ {b['figures']['sj_mean']:.3f}, "
                      f"{b['wall_s']:.0f} s, peak {b['peak_rss_mb'] / 1024:.2f} GB: the output follows the size, "
                      "not the input's triangle count.", ""]
        else:
            L += [f"Result: {o.get('status')}: {o.get('error', '')} (peak {o.get('peak_rss_mb', float('nan')):.0f} MB).",
                  ""]

    L += ["Raw figures of every case: [benchmarks.json](benchmarks.json).", ""]
    if keep.strip():
        L += [KEEP_MARKER, "", keep.strip("\n"), ""]
    return "\n".join(L)


def kept_part(page_path) -> str:
    """The hand-kept part of an existing page: everything after :data:`KEEP_MARKER` ('' if none)."""
    p = Path(page_path)
    if not p.is_file():
        return ""
    text = p.read_text()
    i = text.find(KEEP_MARKER)
    return text[i + len(KEEP_MARKER):] if i >= 0 else ""


def write_outputs(res: dict, out_md) -> tuple[Path, Path]:
    """Write the page (keeping the hand-kept part of the existing one) and the JSON beside it
    (same stem, ``.json``; keys sorted). Returns both paths."""
    out_md = Path(out_md)
    page = render_page(res, kept_part(out_md))
    out_md.parent.mkdir(parents=True, exist_ok=True)
    out_md.write_text(page)
    js = out_md.with_suffix(".json")
    js.write_text(json.dumps(res, indent=1, sort_keys=True, default=float) + "\n")
    return out_md, js
