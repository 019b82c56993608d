"""Sweep one rib station and one spar chord fraction of the default wing through the morph and CalculiX.

    python run_scripts/morph_sweep.py                      # 21 + 21 points at size 0.1 (~8 min)
    python run_scripts/morph_sweep.py --points 11 --size 0.2

The model: ``MorphComp`` (the bundled default wing, NACA 2412, 6 m semi-span, its default layout of
8 ribs and spars at 15 % and 65 % chord, meshed once at ``--size``: the reference) ->
``CalculixShellAnalysis`` (every family ``--thickness`` thick, 10 kPa on the lower-skin bays, root
clamped) and ``MassComp`` on ``x_struct0``. The sweeps move ``wing:rib_eta[--rib]`` and
``wing:spar_chord[--spar]`` by +-``--delta`` around the reference in ``--points`` steps each; every
point is a morph of the reference mesh (a new mesh only where the morph misses its checks, counted).

For each output (mass, tip deflection, the KS von Mises stress of the most loaded family, the
largest von Mises stress outside the clamp band) the smoothness figure is the largest change
between neighbouring points over the trend per step (the slope of a straight line through the
points, times the step): 1 for a straight line, the issue's target is at most 2. A curve with an
extremum inside the sweep has a small straight-line trend whatever its smoothness, so the second
figure takes the trend of a quadratic through the points: the largest neighbour change over the
quadratic's largest change per step (1 for a parabola). Each point also records the areas of the
skins, the spars and the ribs (what the mass follows). Writes ``morph_sweep.json`` and
``morph_sweep.png`` into ``--out-dir`` and prints the table.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import openmdao.api as om

from shellmesh_mdao.analysis import family_areas_at
from shellmesh_mdao.components import CalculixShellAnalysis, MassComp, MorphComp
from shellmesh_mdao.components.layout_comp import family_names
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.morph import morph_reference

OUTPUTS = (("mass", "mass [kg]", 1.0), ("tip_deflection", "tip deflection [mm]", 1e3),
           ("ks_top", "KS von Mises, most loaded family [MPa]", 1e-6),
           ("max_von_mises", "max von Mises outside the clamp band [MPa]", 1e-6))


def smoothness(y, degree: int = 1) -> float:
    """Largest neighbour change over the trend per step: the largest change between neighbouring
    points of the least-squares polynomial of ``degree`` through them (degree 1: its slope times the
    step)."""
    y = np.asarray(y, float)
    x = np.arange(len(y))
    fit = np.polyval(np.polyfit(x, y, degree), x)
    return float(np.abs(np.diff(y)).max() / max(np.abs(np.diff(fit)).max(), 1e-300))


def build(size: float, thickness: float):
    layout = naca_wing_layout()
    ref = morph_reference(naca_wing(), layout, size)
    names = family_names(layout)
    p = om.Problem()
    p.model.add_subsystem("morph", MorphComp(reference=ref), promotes=["*"])
    p.model.add_subsystem("fea", CalculixShellAnalysis(layout=layout, family_names=names, thickness=thickness),
                          promotes_inputs=["thickness"])
    p.model.add_subsystem("mass", MassComp(mesh=ref.mesh, coordinates=True, thickness=thickness),
                          promotes_inputs=["x_struct0", "thickness"])
    p.model.connect("shell_mesh", "fea.shell_mesh")
    p.setup()
    return p, ref


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=float, default=0.1, help="element size in m (default 0.1)")
    ap.add_argument("--points", type=int, default=21, help="points per sweep (default 21)")
    ap.add_argument("--delta", type=float, default=0.02, help="half range of each sweep (default 0.02)")
    ap.add_argument("--rib", type=int, default=3, help="the rib whose station moves (default 3)")
    ap.add_argument("--spar", type=int, default=0, help="the spar whose chord fraction moves (default 0)")
    ap.add_argument("--thickness", type=float, default=0.002, help="thickness of every family in m (default 0.002)")
    ap.add_argument("--out-dir", default="study_out/morph_sweep", help="output folder (default: %(default)s)")
    args = ap.parse_args(argv)
    out = Path(args.out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    p, ref = build(args.size, args.thickness)
    t_ref = time.perf_counter() - t0
    p.run_model()
    top = int(np.argmax(p["fea.ks_von_mises"]))
    kinds = np.array(["spars" if "/spar_" in n else "ribs" if "/rib_" in n else "skins"
                      for n in ref.mesh.component_names])
    base = {n: p[n].copy() for n in ("wing:rib_eta", "wing:spar_chord")}
    summary = {"size": args.size, "points": args.points, "delta": args.delta, "reference_seconds": t_ref,
               "n_elements": int(ref.mesh.n_faces), "ks_family": p.model.fea.family_names[top], "sweeps": {}}
    for label, name, idx in (("rib", "wing:rib_eta", args.rib), ("spar", "wing:spar_chord", args.spar)):
        rows = []
        for d in np.linspace(-args.delta, args.delta, args.points):
            v = base[name].copy()
            v[idx] += d
            p[name] = v
            t = time.perf_counter()
            p.run_model()
            area = family_areas_at(ref.mesh, p["x_struct0"])[0]
            rows.append({"d": float(d), "mass": float(p["mass.mass"][0]),
                         "tip_deflection": float(p["fea.tip_deflection"][0]),
                         "ks_top": float(p["fea.ks_von_mises"][top]), "max_von_mises": float(p["fea.max_von_mises"][0]),
                         "remeshed": int(p["remeshed"][0]), "morph_seconds": float(p["morph_seconds"][0]),
                         "case_seconds": time.perf_counter() - t,
                         "min_scaled_jacobian": float(p["min_scaled_jacobian"][0]),
                         **{f"area_{k}": float(area[kinds == k].sum()) for k in ("skins", "spars", "ribs")}})
            print(f"{label} {d:+.4f}: mass {rows[-1]['mass']:.4f} kg, tip {1e3 * rows[-1]['tip_deflection']:.3f} mm, "
                  f"KS {1e-6 * rows[-1]['ks_top']:.2f} MPa, morph {rows[-1]['morph_seconds']:.3f} s, "
                  f"case {rows[-1]['case_seconds']:.1f} s, remeshed {rows[-1]['remeshed']}", flush=True)
        p[name] = base[name]
        figs = {k: smoothness([r[k] for r in rows]) for k, _, _ in OUTPUTS}
        figs2 = {k: smoothness([r[k] for r in rows], 2) for k, _, _ in OUTPUTS}
        summary["sweeps"][label] = {"input": f"{name}[{idx}]", "rows": rows, "smoothness": figs,
                                    "smoothness_quadratic": figs2,
                                    "remeshed": int(sum(r["remeshed"] for r in rows)),
                                    "morph_seconds_max": max(r["morph_seconds"] for r in rows),
                                    "morph_share_of_case": float(np.mean([r["morph_seconds"] / r["case_seconds"]
                                                                          for r in rows]))}
    (out / "morph_sweep.json").write_text(json.dumps(summary, indent=1))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(len(OUTPUTS), 2, figsize=(10, 2.3 * len(OUTPUTS)), sharex="col")
    for j, label in enumerate(("rib", "spar")):
        sw = summary["sweeps"][label]
        d = [r["d"] for r in sw["rows"]]
        for i, (k, title, scale) in enumerate(OUTPUTS):
            ax[i, j].plot(d, [scale * r[k] for r in sw["rows"]], "o-", ms=3)
            ax[i, j].set_title(f"{title}  (jump/trend {sw['smoothness'][k]:.2f}, quadratic trend "
                               f"{sw['smoothness_quadratic'][k]:.2f})", fontsize=8)
        ax[-1, j].set_xlabel(f"change of {sw['input']}")
    fig.tight_layout()
    fig.savefig(out / "morph_sweep.png", dpi=90)
    print(f"\nreference mesh: {summary['n_elements']} elements in {t_ref:.1f} s; KS of {summary['ks_family']}")
    for label, sw in summary["sweeps"].items():
        figs = ", ".join(f"{k} {v:.2f} ({sw['smoothness_quadratic'][k]:.2f})" for k, v in sw["smoothness"].items())
        a = {k: sw["rows"][-1][f"area_{k}"] - sw["rows"][0][f"area_{k}"] for k in ("skins", "spars", "ribs")}
        print(f"{label} sweep ({sw['input']}): largest neighbour change / trend per step, straight line "
              f"(quadratic): {figs}; area change over the sweep: skins {a['skins']:+.5f}, spars {a['spars']:+.5f}, "
              f"ribs {a['ribs']:+.5f} m2; "
              f"remeshed {sw['remeshed']} of {len(sw['rows'])}; "
              f"morph {100 * sw['morph_share_of_case']:.1f} % of a case")
    return 0


if __name__ == "__main__":
    sys.exit(main())
