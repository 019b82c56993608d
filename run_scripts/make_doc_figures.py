"""Regenerate the pictures of the documentation (docs/figures/*.png) and print how long each took.

    python run_scripts/make_doc_figures.py                    # the bundled default wing (~1 min)
    python run_scripts/make_doc_figures.py --corpus ../shared/geometry   # + the Cessna 210 wing box (~3 min)

The default wing is meshed end to end at size 0.1 (the ``shellmesh demo`` run); its pictures show
the families, the wing box with the upper skin hidden, the scaled Jacobian, the worst elements
and the quality histograms. With ``--corpus`` the Cessna 210 of the benchmark corpus is meshed at
size 0.25 with 10 ribs and 2 spars per wing (the docs/cli.md example) for a whole-aircraft and a
wing-box picture. Pictures are 1000x625 pixels to keep the repository small.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.pipeline import run_pipeline
from shellmesh_mdao.quality import element_quality
from shellmesh_mdao.render import render_mesh, render_worst, render_worst_closeups
from shellmesh_mdao.report import layout_up, write_histograms

WINDOW = (1000, 625)


def timed(label, fn, *a, **k):
    t0 = time.perf_counter()
    out = fn(*a, **k)
    print(f"  {label:<34s} {time.perf_counter() - t0:6.2f} s  -> {out}")
    return out


def figures(result, out: Path, stem: str, views=("iso", "wingbox", "quality", "worst", "closeups", "histograms")):
    mesh = result.mesh
    up = layout_up(result.report)
    q = element_quality(mesh.points, mesh.faces)
    print(f"{stem}: {mesh.n_faces} elements ({mesh.n_quads} quads), stages "
          + ", ".join(f"{k} {v:.1f}" for k, v in result.report["stages"].items()))
    if "iso" in views:
        timed("iso, by family", render_mesh, mesh, out / f"{stem}_iso.png", up=up, window_size=WINDOW)
    if "top" in views:
        timed("top, by family", render_mesh, mesh, out / f"{stem}_top.png", view="top", up=up, window_size=WINDOW)
    if "wingbox" in views:
        timed("wing box, upper skin hidden", render_mesh, mesh, out / f"{stem}_wingbox.png", view="wingbox", up=up,
              window_size=WINDOW)
    if "quality" in views:
        timed("scaled Jacobian", render_mesh, mesh, out / f"{stem}_quality.png", color="scaled_jacobian", up=up,
              window_size=WINDOW, metrics=q)
    if "worst" in views:
        timed("worst elements located", render_worst, mesh, out / f"{stem}_worst.png", 10, up=up,
              window_size=WINDOW, metrics=q)
    if "closeups" in views:
        timed("worst elements close-ups", render_worst_closeups, mesh, out / f"{stem}_worst_closeups.png", 6,
              window_size=(1200, 700), metrics=q)
    if "histograms" in views:
        timed("histograms", write_histograms, mesh, out / f"{stem}_histograms.png", q)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(REPO / "docs" / "figures"), help="folder for the PNGs (default docs/figures)")
    ap.add_argument("--corpus", help="benchmark corpus folder (with manifest.json): add the Cessna 210 pictures")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res = run_pipeline(naca_wing(), naca_wing_layout(), 0.1, progress=False)
    figures(res, out, "default_wing")
    if args.corpus:
        corpus = Path(args.corpus)
        man = json.loads((corpus / "manifest.json").read_text())["geometries"]["cessna210"]
        wings = [dict(w, ribs={"count": 10}, spars={"chord_fractions": [0.15, 0.65]}) for w in man["wings"]]
        res = run_pipeline(str(corpus / man["file"]), {"up": man["up"], "wings": wings}, 0.25, progress=False)
        figures(res, out, "cessna210", views=("iso", "wingbox", "worst"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
