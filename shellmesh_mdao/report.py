"""Human-readable meshing reports: one HTML (or Markdown) page with its pictures beside it.

:func:`write_report` takes a :class:`~shellmesh_mdao.pipeline.PipelineResult` (or a bare
:class:`~shellmesh_mdao.mesh.ShellMesh`) and writes ``report.html`` (``.md`` for Markdown)
with: the inputs, the seconds per stage, element counts per family and per component, the
quality table (:func:`~shellmesh_mdao.quality.quality_summary`, acceptance ranges, flagged
counts, per component), histograms of the shape metrics (matplotlib, no display needed),
pictures of the mesh (:mod:`shellmesh_mdao.render`) and the worst elements located on the
model. The images are written next to the page as ``<stem>_*.png``, so the folder is
self-contained. :func:`report_data` returns the same content as a JSON-ready dict (the
CLI adds it to the JSON report).
"""
from __future__ import annotations

import html
import json
import logging
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from . import __version__
from .errors import OutputError
from .families import FAMILIES, component_family, name_of, padded_names
from .mesh import ShellMesh
from .quality import ACCEPTANCE, METRICS, QUAD_ANGLE_RANGE, acceptance_masks, element_quality, quality_summary

log = logging.getLogger("shellmesh_mdao")

__all__ = ["report_data", "family_counts", "worst_table", "flagged_table", "component_rows", "write_histograms", "write_report",
           "layout_up", "REPORT_EXTENSIONS"]

#: Extensions :func:`write_report` writes and their format.
REPORT_EXTENSIONS = {".html": "html", ".htm": "html", ".md": "markdown", ".markdown": "markdown"}

_HIST_METRICS = ("scaled_jacobian", "min_angle", "max_angle", "aspect", "skew", "warp")
_HIST_RANGE = {"scaled_jacobian": (-0.2, 1.0), "min_angle": (0.0, 90.0), "max_angle": (60.0, 180.0),
               "aspect": (1.0, 8.0), "skew": (0.0, 90.0), "warp": (0.0, 30.0)}
_LABEL = {"scaled_jacobian": "scaled Jacobian", "min_angle": "min corner angle [deg]",
          "max_angle": "max corner angle [deg]", "aspect": "aspect ratio", "skew": "skew [deg]",
          "warp": "warp [deg]", "taper": "taper"}


# ----------------------------------------------------------------------------- data
def family_counts(mesh: ShellMesh) -> dict:
    """Element counts per component family (skin, upper skin, lower skin, rib, spar, member):
    ``{family: {"components", "elements", "quads", "tris"}}`` in that order, families with
    elements only."""
    ncomp = max(len(mesh.component_names), int(mesh.component.max(initial=-1)) + 1)
    names = padded_names(mesh.component_names, ncomp)
    fam = np.array([component_family(n) for n in names] or ["skin"])
    per_c = np.bincount(mesh.component, minlength=ncomp)
    per_cq = np.bincount(mesh.component[mesh.is_quad], minlength=ncomp)
    out = {}
    for f in FAMILIES:
        sel = (fam == f) & (per_c > 0)
        if sel.any():
            out[f] = {"components": int(sel.sum()), "elements": int(per_c[sel].sum()),
                      "quads": int(per_cq[sel].sum()), "tris": int(per_c[sel].sum() - per_cq[sel].sum())}
    return out


def _element_rows(mesh: ShellMesh, idx: np.ndarray, q: dict) -> list[dict]:
    from .render import element_ids

    if not len(idx):
        return []
    eid = element_ids(mesh)
    masks = acceptance_masks(mesh.points, mesh.faces, q)
    cen = mesh.face_centroids()[idx]
    rows = []
    for r, i in enumerate(np.asarray(idx).tolist()):
        c = int(mesh.component[i])
        rows.append({"rank": r + 1, "element_id": int(eid[i]), "index": int(i),
                     "component": name_of(mesh.component_names, c),
                     "type": "quad" if mesh.faces[i, 3] >= 0 else "tri",
                     **{k: _num(q[k][i]) for k in METRICS},
                     "failed": [k for k in METRICS if not masks[k][i]],
                     "centroid": [float(x) for x in cen[r]]})
    return rows


def worst_table(mesh: ShellMesh, n: int = 10, metrics: dict | None = None) -> list[dict]:
    """The ``n`` elements with the lowest scaled Jacobian, worst first: rank, ``element_id``
    (as numbered in every written file: .bdf/.inp/.msh ids, .vtu cell index + 1), ``index``
    (face index in the in-memory mesh), component, type, the
    metric values, ``failed`` (metrics outside their acceptance range) and the centroid."""
    from .render import worst_elements

    q = element_quality(mesh.points, mesh.faces) if metrics is None else metrics
    return _element_rows(mesh, worst_elements(mesh, n, "scaled_jacobian", q), q)


def flagged_table(mesh: ShellMesh, n: int = 20, metrics: dict | None = None) -> tuple[int, list[dict]]:
    """``(n_flagged, rows)``: how many elements are outside an acceptance range, and the first
    ``n`` of them by increasing scaled Jacobian, as rows like :func:`worst_table`."""
    from .quality import flag_elements

    q = element_quality(mesh.points, mesh.faces) if metrics is None else metrics
    bad = np.flatnonzero(flag_elements(mesh.points, mesh.faces, q))
    order = bad[np.argsort(q["scaled_jacobian"][bad], kind="stable")]
    return int(len(bad)), _element_rows(mesh, order[:max(0, int(n))], q)


def _num(x):
    x = float(x)
    return x if np.isfinite(x) else None


def layout_up(report: dict | None):
    """The ``up`` direction of the first wing (or the layout's top-level ``up``) recorded in a
    pipeline report, or ``None``."""
    lay = (report or {}).get("inputs", {}).get("layout")
    if not isinstance(lay, dict):
        return None
    for w in lay.get("wings") or []:
        if isinstance(w, dict) and w.get("up") is not None:
            return [float(x) for x in w["up"]]
    if lay.get("up") is not None:
        return [float(x) for x in lay["up"]]
    return None


def _split(result) -> tuple[ShellMesh, dict]:
    if isinstance(result, ShellMesh):
        return result, {}
    mesh = getattr(result, "mesh", None)
    if not isinstance(mesh, ShellMesh):
        raise OutputError(f"write_report needs a PipelineResult or a ShellMesh, got {type(result).__name__}")
    return mesh, dict(getattr(result, "report", None) or {})


def report_data(result, *, metrics: dict | None = None, worst: int = 10) -> dict:
    """The report content as a JSON-ready dict: ``inputs``, ``stages`` (seconds), ``stage``,
    ``counts``, ``families`` (:func:`family_counts`), ``quality`` (:func:`quality_summary` by
    component), ``worst_elements`` (:func:`worst_table`) and ``version``."""
    mesh, rep = _split(result)
    q = element_quality(mesh.points, mesh.faces) if metrics is None else metrics
    counts = rep.get("counts") or {"n_points": int(mesh.n_points), "n_faces": int(mesh.n_faces),
                                   "n_tris": int(mesh.n_tris), "n_quads": int(mesh.n_quads),
                                   "n_feature_edges": int(len(mesh.feature_edges))}
    qs = rep.get("quality")
    if not (isinstance(qs, dict) and "components" in qs):
        qs = quality_summary(mesh, by_component=True)
    return {"version": __version__, "inputs": rep.get("inputs", {}), "stages": dict(rep.get("stages", {})),
            "stage": rep.get("stage"), "counts": counts, "families": family_counts(mesh), "quality": qs,
            "worst_elements": worst_table(mesh, worst, q), "members": rep.get("members", {})}


# ----------------------------------------------------------------------------- histograms
def write_histograms(mesh: ShellMesh, out_png, metrics: dict | None = None) -> Path:
    """One PNG with a histogram per shape metric (scaled Jacobian, min/max angle, aspect, skew,
    warp): quads and triangles stacked, log counts, the acceptance limits as vertical lines
    (solid quads, dashed triangles) and values beyond the axis gathered in the end bins.
    Written atomically with matplotlib's Agg canvas (no display, no global backend change)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from .export import atomic_write

    q = element_quality(mesh.points, mesh.faces) if metrics is None else metrics
    quad = mesh.is_quad
    fig = Figure(figsize=(13, 7.5), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 3)
    for ax, k in zip(axes.ravel(), _HIST_METRICS):
        lo, hi = _HIST_RANGE[k]
        v = np.clip(np.nan_to_num(np.asarray(q[k], float), nan=hi, posinf=hi, neginf=lo), lo, hi)
        bins = np.linspace(lo, hi, 41)
        hq = np.histogram(v[quad], bins)[0] if quad.any() else np.zeros(len(bins) - 1, int)
        ht = np.histogram(v[~quad], bins)[0] if (~quad).any() else np.zeros(len(bins) - 1, int)
        if quad.any():                   # stacked: triangles on top of quads
            ax.stairs(hq, bins, fill=True, color="#4292c6", label=f"quads ({int(quad.sum())})")
        if (~quad).any():
            ax.stairs(hq + ht, bins, baseline=hq, fill=True, color="#fd8d3c",
                      label=f"triangles ({int((~quad).sum())})")
        ax.set_ylim(0.7, max(2.0, float((hq + ht).max()) * 1.5))
        ax.set_yscale("log")
        for t, style in (("quad", "-"), ("tri", "--")):
            if (t == "quad" and not quad.any()) or (t == "tri" and quad.all()):
                continue
            for x in ACCEPTANCE[t][k]:
                if x is not None and lo <= x <= hi:
                    ax.axvline(x, color="#b00000", linestyle=style, linewidth=1.2)
        nbad = int((~acceptance_masks(mesh.points, mesh.faces, q)[k]).sum())
        ax.set_title(f"{_LABEL[k]}: {nbad} outside range", fontsize=10)
        ax.set_xlim(lo, hi)
        ax.set_ylabel("elements")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper left")
    fig.suptitle("element quality (red lines: acceptance limits, solid quads / dashed triangles)", fontsize=11)
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.06, top=0.9, wspace=0.25, hspace=0.3)
    return atomic_write(Path(out_png), lambda p: fig.savefig(p, format="png"))


# ----------------------------------------------------------------------------- formatting
def _f(v, nd=4) -> str:
    if v is None:
        return "-"
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        return str(int(v))
    v = float(v)
    if abs(v) < 5e-5:
        v = 0.0
    return f"{v:.{nd}g}"


def _rng(r) -> str:
    lo, hi = r
    if lo is None and hi is None:
        return "any"
    if lo is None:
        return f"<= {_f(hi)}"
    if hi is None:
        return f">= {_f(lo)}"
    return f"[{_f(lo)}, {_f(hi)}]"


def _inputs_rows(inputs: dict) -> list[tuple[str, str]]:
    rows = []
    for k, v in inputs.items():
        if k == "layout" and isinstance(v, dict):
            wings = v.get("wings") or []
            parts = []
            for w in wings:
                ribs = w.get("ribs") or {}
                nr = ribs.get("count", len(ribs.get("eta", []) or []))
                ns = len((w.get("spars") or {}).get("chord_fractions", []) or [])
                parts.append(f"{w.get('name')}: {nr} ribs, {ns} spars")
            if v.get("members"):
                parts.append(f"{len(v['members'])} explicit members")
            rows.append(("layout", "; ".join(parts) or "(empty)"))
        elif isinstance(v, (dict, list)):
            rows.append((k, json.dumps(v, default=str)))
        else:
            rows.append((k, str(v)))
    return rows


def _quality_rows(s: dict) -> list[list[str]]:
    acc = s.get("acceptance") or {t: {k: list(ACCEPTANCE[t][k]) for k in METRICS} for t in ACCEPTANCE}
    rows = []
    for k in METRICS:
        d = s[k]
        fw = d.get("fraction_within")
        rows.append([k, *(_f(d[c]) for c in ("min", "p1", "mean", "median", "p99", "max")),
                     "-" if fw is None else f"{100 * fw:.1f}%",
                     f"{_rng(acc['quad'][k])} | {_rng(acc['tri'][k])}"])
    return rows


_Q_HEAD = ["metric", "min", "p1", "mean", "median", "p99", "max", "within", "acceptance quad | tri"]
_C_HEAD = ["component", "family", "elements", "quads", "tris", "folded", "flagged", "min SJ", "min angle",
           "max angle", "max aspect", "max warp"]


def component_rows(qs: dict) -> tuple[list[str], list[list[str]], list[bool]]:
    """``(head, rows, flagged)``: one row per component of a :func:`quality_summary` made with
    ``by_component=True`` (elements, quads, tris, folded, flagged, worst values) and whether
    the component has flagged or folded elements."""
    rows = _component_rows(qs)
    return list(_C_HEAD), [r for r, _ in rows], [f for _, f in rows]


def _component_rows(qs: dict) -> list[tuple[list[str], bool]]:
    rows = []
    for name, s in (qs.get("components") or {}).items():
        rows.append(([name, component_family(name), _f(s["n_elements"]), _f(s["n_quads"]), _f(s["n_tris"]),
                      _f(s["n_folded"]), _f(s["n_flagged"]), _f(s["scaled_jacobian"]["min"], 3),
                      _f(s["min_angle"]["min"], 3), _f(s["max_angle"]["max"], 3), _f(s["aspect"]["max"], 3),
                      _f(s["warp"]["max"], 3)], s["n_flagged"] > 0 or s["n_folded"] > 0))
    return rows


_CAPTIONS = {
    "iso": "The mesh from above, ahead and aside, coloured by component family (each component a shade).",
    "top": "The mesh from above (parallel projection).",
    "wingbox": "Close-up of the first wing box with its upper skin bays hidden: ribs, spars and lower skin; "
               "the rest of the skin faint.",
    "quality": "Scaled Jacobian of every element (1 ideal, at or below 0 folded).",
    "worst": "The elements with the lowest scaled Jacobian located on the model (1 = worst; see the table).",
    "worst_closeups": "Each of the worst elements (red) in its neighbourhood.",
    "histograms": "Distributions of the shape metrics with the acceptance limits.",
}


def _caption(path: Path, stem: str) -> str:
    key = path.stem[len(stem) + 1:] if path.stem.startswith(stem + "_") else path.stem
    return _CAPTIONS.get(key, key)


_CSS = """body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1250px;margin:2em auto;
padding:0 1em;color:#222}table{border-collapse:collapse;margin:.6em 0 1.2em}th,td{border:1px solid #ccc;
padding:3px 8px;text-align:right;font-size:13px}th{background:#f0f0f0}td:first-child,th:first-child{text-align:left}
tr.flag td{background:#fff1f0}h1{font-size:1.6em}h2{border-bottom:1px solid #ddd;padding-bottom:.2em;margin-top:1.6em}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}figcaption{font-size:13px;color:#555}
.note{background:#fff8e1;border:1px solid #f0d070;padding:.5em 1em}code{background:#f5f5f5;padding:0 3px}"""


def _html_table(head, rows, flags=None) -> str:
    out = ["<table><tr>" + "".join(f"<th>{html.escape(str(h))}</th>" for h in head) + "</tr>"]
    for i, r in enumerate(rows):
        cls = ' class="flag"' if flags is not None and flags[i] else ""
        out.append(f"<tr{cls}>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _md_table(head, rows) -> str:
    esc = lambda c: str(c).replace("|", "\\|")  # noqa: E731
    lines = ["| " + " | ".join(esc(h) for h in head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(esc(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def _sections(data: dict, images: list[Path], stem: str, links: list[tuple[str, str]], note: str | None):
    """Report content as a list of (kind, payload) blocks shared by the HTML and Markdown writers."""
    qs = data["quality"]
    c = data["counts"]
    title = "shellmesh report"
    surf = data["inputs"].get("surface")
    if surf:
        title += f": {Path(str(surf)).name if '/' in str(surf) or os.sep in str(surf) else surf}"
    blocks = [("h1", title),
              ("p", f"shellmesh_mdao {data['version']}; last stage run: {data.get('stage') or '-'}. "
                    f"{c['n_faces']} elements ({c['n_quads']} quads, {c['n_tris']} triangles), {c['n_points']} nodes; "
                    f"{qs['n_folded']} folded, {qs['n_flagged']} outside an acceptance range.")]
    if note:
        blocks.append(("note", note))
    if links:
        blocks.append(("links", links))
    if data["inputs"]:
        blocks += [("h2", "Inputs"), ("table", (["input", "value"], _inputs_rows(data["inputs"]), None))]
    if data["stages"]:
        st = data["stages"]
        rows = [[k, f"{float(v):.2f}"] for k, v in st.items()] + [["total", f"{sum(map(float, st.values())):.2f}"]]
        blocks += [("h2", "Seconds per stage"), ("table", (["stage", "seconds"], rows, None))]
    fam = data["families"]
    blocks += [("h2", "Element counts"),
               ("table", (["family", "components", "elements", "quads", "triangles"],
                          [[f, v["components"], v["elements"], v["quads"], v["tris"]] for f, v in fam.items()]
                          + [["all", sum(v["components"] for v in fam.values()), c["n_faces"], c["n_quads"],
                              c["n_tris"]]], None))]
    lo, hi = QUAD_ANGLE_RANGE
    qa = qs.get("quad_angles_ok_fraction")
    blocks += [("h2", "Quality"),
               ("p", f"All elements: {qs['n_elements']} ({100 * qs['quad_fraction']:.1f}% quads); "
                     f"{qs['n_folded']} folded (scaled Jacobian <= 0); {qs['n_flagged']} outside an acceptance "
                     f"range; quads with all corner angles in [{lo:g}, {hi:g}] deg: "
                     + ("-" if qa is None else f"{100 * qa:.1f}%") + ". Definitions and sources: docs/quality.md."),
               ("table", (_Q_HEAD, _quality_rows(qs), None))]
    crow = _component_rows(qs)
    if crow:
        blocks += [("h3", "Per component (rows with flagged or folded elements highlighted)"),
                   ("table", (_C_HEAD, [r for r, _ in crow], [f for _, f in crow]))]
    hist = [p for p in images if p.stem.endswith("_histograms")]
    for p in hist:
        blocks.append(("img", (p.name, _caption(p, stem))))
    pics = [p for p in images if p not in hist and "worst" not in p.stem]
    if pics:
        blocks.append(("h2", "Pictures"))
        blocks += [("img", (p.name, _caption(p, stem))) for p in pics]
    wt = data["worst_elements"]
    if wt:
        blocks += [("h2", "Worst elements (lowest scaled Jacobian)"),
                   ("p", "Element ids are those of the written files (.bdf/.inp/.msh element ids; in the .vtu the "
                         "cell index + 1). 'fails' lists the metrics outside their acceptance range."),
                   ("table", (["#", "element id", "component", "type", "scaled Jacobian", "min angle",
                               "max angle", "aspect", "warp", "fails", "centroid"],
                              [[w["rank"], w["element_id"], w["component"], w["type"],
                                _f(w["scaled_jacobian"], 3), _f(w["min_angle"], 3), _f(w["max_angle"], 3),
                                _f(w["aspect"], 3), _f(w["warp"], 3), ", ".join(w["failed"]) or "-",
                                "(" + ", ".join(f"{x:.4g}" for x in w["centroid"]) + ")"] for w in wt], None))]
        blocks += [("img", (p.name, _caption(p, stem))) for p in images if "worst" in p.stem]
    return blocks


def _render_html(blocks) -> str:
    body = []
    for kind, x in blocks:
        if kind in ("h1", "h2", "h3"):
            body.append(f"<{kind}>{html.escape(x)}</{kind}>")
        elif kind == "p":
            body.append(f"<p>{html.escape(x)}</p>")
        elif kind == "note":
            body.append(f'<p class="note">{html.escape(x)}</p>')
        elif kind == "links":
            body.append("<p>Files: " + ", ".join(f'<a href="{html.escape(h)}">{html.escape(t)}</a>' for t, h in x)
                        + "</p>")
        elif kind == "table":
            body.append(_html_table(*x))
        elif kind == "img":
            src, cap = x
            body.append(f'<figure><a href="{html.escape(src)}"><img src="{html.escape(src)}" alt="{html.escape(cap)}">'
                        f"</a><figcaption>{html.escape(cap)}</figcaption></figure>")
    title = next((x for k, x in blocks if k == "h1"), "shellmesh report")
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")


def _render_md(blocks) -> str:
    out = []
    for kind, x in blocks:
        if kind == "h1":
            out.append(f"# {x}")
        elif kind == "h2":
            out.append(f"## {x}")
        elif kind == "h3":
            out.append(f"### {x}")
        elif kind == "p":
            out.append(x)
        elif kind == "note":
            out.append(f"> **Note:** {x}")
        elif kind == "links":
            out.append("Files: " + ", ".join(f"[{t}]({h})" for t, h in x))
        elif kind == "table":
            out.append(_md_table(x[0], x[1]))
        elif kind == "img":
            out.append(f"![{x[1]}]({x[0]})\n\n*{x[1]}*")
    return "\n\n".join(out) + "\n"


# ----------------------------------------------------------------------------- public entry
def write_report(result, out_path, pictures: bool = True, *, links=(), worst: int = 10, up=None,
                 data: dict | None = None, window_size=(1600, 1000)) -> Path:
    """Write the human report of ``result`` (a :class:`PipelineResult` or a :class:`ShellMesh`)
    to ``out_path`` (``.html``/``.htm``, or ``.md``/``.markdown`` for Markdown) with its images
    next to it as ``<stem>_histograms.png`` and, with ``pictures``, ``<stem>_iso.png``,
    ``_top``, ``_wingbox`` (if the mesh has a wing box), ``_quality``, ``_worst``,
    ``_worst_closeups`` (see :func:`shellmesh_mdao.render.render_views`). ``links``: (text,
    path) pairs of other outputs to link (paths relative to the report's folder). ``up``:
    the model's up direction for the pictures (default: from the layout in the report).
    ``data``: a precomputed :func:`report_data`. If no picture can be rendered (no
    off-screen OpenGL) the report is still written, with a note saying how to fix it.
    Everything is written atomically: the images go to a temporary folder first and are
    moved in place just before the page; nothing is left behind on error. Returns the path."""
    from .export import atomic_write, check_output_path

    t0 = time.perf_counter()
    out = Path(out_path)
    fmt = REPORT_EXTENSIONS.get(out.suffix.lower())
    if fmt is None:
        raise OutputError(f"cannot write {out.name}: unknown report extension {out.suffix or '(none)'!r}; "
                          f"use one of {', '.join(REPORT_EXTENSIONS)}")
    check_output_path(out, formats=REPORT_EXTENSIONS)
    mesh, rep = _split(result)
    q = element_quality(mesh.points, mesh.faces)
    data = report_data(result, metrics=q, worst=worst) if data is None else data
    if up is None:
        up = layout_up(rep)
    stem = out.stem
    tmp = Path(tempfile.mkdtemp(prefix=f".{stem}.", suffix=".tmp", dir=out.parent))
    note = None
    try:
        images = [write_histograms(mesh, tmp / f"{stem}_histograms.png", q)]
        if pictures:
            from .render import render_views

            try:
                images += render_views(mesh, tmp, stem, up=up, worst=worst, window_size=window_size, metrics=q)
            except OutputError as e:
                note = f"No pictures: {e}"
                log.warning("report without pictures: %s", e)
                for p in tmp.glob(f"{stem}_*.png"):
                    if p not in images:
                        p.unlink()
        blocks = _sections(data, images, stem, [(t, str(h)) for t, h in links], note)
        text = _render_html(blocks) if fmt == "html" else _render_md(blocks)
        final = []
        try:
            for p in images:
                dst = out.parent / p.name
                os.replace(p, dst)
                final.append(dst)
            atomic_write(out, lambda p: p.write_text(text, encoding="utf-8"))
        except BaseException:
            for dst in final:            # no page: take its images away again
                dst.unlink(missing_ok=True)
            raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    log.info("wrote %s with %d images in %.2f s", out, len(final), time.perf_counter() - t0)
    return out
