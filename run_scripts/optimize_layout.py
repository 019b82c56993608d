"""Minimum-mass layout and thicknesses of the default wing (SLSQP through the morph): rib stations, spar
chord fractions and thickness groups under stress, buckling and tip-deflection limits.

    python run_scripts/optimize_layout.py                   # coarse mesh, 5 ribs (~20-30 min on 2 cores)
    python run_scripts/optimize_layout.py --ribs 4 --maxiter 10

Model: :class:`~shellmesh_mdao.components.morph_comp.MorphComp` (the bundled default wing, NACA 2412,
6 m semi-span, coarse 24 x 16 triangulation, ``--ribs`` ribs and spars at 15 % and 65 % chord meshed
once at ``--size``: the reference; ``on_failure="error"``, so the topology never changes under the
optimiser) -> ``x_struct0`` -> :class:`~shellmesh_mdao.components.calculix_comp.CalculixShellAnalysis`
(``coordinates=True``: the reference's elements at the morphed coordinates; 10 kPa on the lower-skin bays,
root clamped, ``buckling=2``) and ``MassComp`` on ``x_struct0``. The coordinates are a continuous
connection, so OpenMDAO can take total derivatives of the analysis outputs with respect to the layout (a
discrete ``shell_mesh`` connection would make ``compute_totals`` refuse: "depends upon discrete output
variables").
Design variables: the interior rib stations (each within 35 % of the rib pitch of its nominal
station, so ribs never come closer than 30 % of a pitch), both spar chord fractions (0.14-0.20 and
0.58-0.66: the box in which the morph of the reference keeps its elements above ``MIN_SJ``; farther moves
need a new reference) and five thickness groups (``optimize_thickness.py``'s: skin outside the box, upper-skin
bays, lower-skin bays, spars, ribs; 0.5-10 mm). ``om.ScipyOptimizeDriver(optimizer="SLSQP")`` minimises
the mass subject to ``ks_von_mises <= --stress-limit`` (every family, outside the clamp band),
``ks_buckling <= 1`` (no buckling below the design load) and ``tip_deflection <= --tip-limit``.

The optimiser's intermediate meshes are morphs of the reference whose elements may go down to a scaled
Jacobian of 0.1 (``MIN_SJ``; a point beyond that is a failed evaluation, which SLSQP backs away from);
the final layout is meshed anew by the pipeline (the README's gate) and analysed again: the summary's
``fresh_mesh_of_the_optimum``.

Gradients: central finite differences of the whole model (``approx_totals``, relative step 1e-2):
each step of a rib station or spar fraction is a morph of the reference mesh (tenths of a second)
and a ccx run; the mass alone has exact layout derivatives (docs/openmdao.md, 'Derivatives').

Writes ``<out-dir>/optimize_layout_history.png`` (mass and the constraint ratios against the
iteration), ``optimize_layout_final.png`` (the final layout over the initial one, in plan) and
``optimize_layout_summary.json``, and prints the optimum.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import openmdao.api as om

from optimize_thickness import GROUPS, ThicknessMap, group_matrix
from shellmesh_mdao.analysis import analyse_shell
from shellmesh_mdao.components import CalculixShellAnalysis, MassComp, MorphComp
from shellmesh_mdao.components.layout_comp import family_names
from shellmesh_mdao.errors import ShellMeshError
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.morph import morph_reference


#: bounds of the spar chord fractions: the morph of the reference (spars at 0.15 and 0.65) keeps every
#: element above MIN_SJ at every corner of the design box with the ribs at their bounds (checked at size 0.25)
SPAR_LOWER, SPAR_UPPER = [0.14, 0.58], [0.20, 0.66]
#: the optimiser's intermediate meshes (morphs of the reference) may have elements down to this scaled
#: Jacobian; the final layout is meshed anew by the pipeline (the README's gate, 0.2) and analysed again
MIN_SJ = 0.1


def build_problem(size: float = 0.25, ribs: int = 5, t0: float = 0.004, stress_limit: float = 250e6,
                  tip_limit: float = 0.3) -> tuple:
    """The optimisation problem and its reference (:class:`~shellmesh_mdao.morph.MorphReference`)."""
    layout = naca_wing_layout(ribs=ribs)
    names = family_names(layout)
    A = group_matrix(names, GROUPS)
    ref = morph_reference(naca_wing(n_chord=24, n_span=16), layout, size)
    prob = om.Problem(reports=False, name="optimize_layout")
    m = prob.model
    m.add_subsystem("morph", MorphComp(reference=ref, on_failure="error", min_scaled_jacobian=MIN_SJ),
                    promotes=["*"])
    m.add_subsystem("tmap", ThicknessMap(matrix=A, t0=t0), promotes=["*"])
    if list(ref.mesh.component_names) != names:
        raise RuntimeError(f"the reference mesh's families {ref.mesh.component_names} are not the layout's {names}")
    m.add_subsystem("fea", CalculixShellAnalysis(mesh=ref.mesh, coordinates=True, layout=layout, pressure=1.0e4,
                                                 thickness=t0, buckling=2),
                    promotes_inputs=["x_struct0", "thickness"],
                    promotes_outputs=["max_von_mises", "ks_von_mises", "tip_deflection", "ks_buckling",
                                      "buckling_factors"])
    m.add_subsystem("mass", MassComp(mesh=ref.mesh, coordinates=True, thickness=t0),
                    promotes_inputs=["x_struct0", "thickness"], promotes_outputs=["mass"])
    eta = np.asarray(ref.wings[0].rib_eta)
    pitch = 1.0 / (ribs - 1)
    inner = np.arange(1, ribs - 1)
    m.add_design_var("wing:rib_eta", indices=inner, lower=eta[inner] - 0.35 * pitch, upper=eta[inner] + 0.35 * pitch,
                     ref=0.1)
    m.add_design_var("wing:spar_chord", lower=SPAR_LOWER, upper=SPAR_UPPER, ref=0.1)
    m.add_design_var("t_group", lower=0.0005, upper=0.01, ref=1e-3)
    m.add_objective("mass", ref=100.0)
    m.add_constraint("ks_von_mises", upper=stress_limit, ref=stress_limit)
    m.add_constraint("ks_buckling", upper=1.0)
    m.add_constraint("tip_deflection", upper=tip_limit, ref=tip_limit)
    m.approx_totals(method="fd", step=1e-2, step_calc="rel", form="central")
    return prob, ref


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=float, default=0.25, help="element size in m (default 0.25)")
    ap.add_argument("--ribs", type=int, default=5, help="number of ribs (default 5)")
    ap.add_argument("--stress-limit", type=float, default=250e6, help="KS von Mises limit in Pa (default 250e6)")
    ap.add_argument("--tip-limit", type=float, default=0.3, help="tip deflection limit in m (default 0.3)")
    ap.add_argument("--t0", type=float, default=0.004, help="initial thickness in m (default 0.004)")
    ap.add_argument("--maxiter", type=int, default=30, help="SLSQP iterations (default 30)")
    ap.add_argument("--out-dir", default="study_out/optimize_layout", help="output folder (default: %(default)s)")
    args = ap.parse_args(argv)
    out = Path(args.out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    prob, ref = build_problem(args.size, args.ribs, args.t0, args.stress_limit, args.tip_limit)
    prob.driver = om.ScipyOptimizeDriver(optimizer="SLSQP", maxiter=args.maxiter, tol=1e-4, disp=True)
    prob.driver.recording_options["includes"] = ["mass", "ks_von_mises", "ks_buckling", "tip_deflection",
                                                 "wing:rib_eta", "wing:spar_chord", "t_group", "remeshed"]
    db = out / "optimize_layout_cases.sql"
    db.unlink(missing_ok=True)
    prob.driver.add_recorder(om.SqliteRecorder(str(db)))
    prob.setup()
    prob.run_model()
    start = {k: prob.get_val(k).tolist() for k in ("mass", "ks_buckling", "tip_deflection", "wing:rib_eta",
                                                  "wing:spar_chord", "t_group")}
    start["ks_max"] = float(prob.get_val("ks_von_mises").max())
    res = prob.run_driver()
    seconds = time.perf_counter() - t_start
    prob.cleanup()
    opt = {k: prob.get_val(k).tolist() for k in ("mass", "ks_buckling", "tip_deflection", "wing:rib_eta",
                                                "wing:spar_chord", "t_group", "buckling_factors")}
    opt["ks_max"] = float(prob.get_val("ks_von_mises").max())
    # the final layout meshed anew by the pipeline (its gate on) and analysed with the optimal thicknesses
    try:
        final = ref.remesh({"wing": (np.asarray(opt["wing:rib_eta"]), np.asarray(opt["wing:spar_chord"]))})
        t_fam = dict(zip(ref.mesh.component_names, map(float, prob.get_val("thickness"))))
        check = analyse_shell(final.mesh, t_fam, layout=ref.layout, clamp="root", pressure=1.0e4, buckling=2)
        fresh = {"n_elements": int(final.mesh.n_faces),
                 "min_scaled_jacobian": float(final.report["guarantees"]["min_scaled_jacobian"]),
                 "mass": float(check.mass), "ks_max": float(np.max(check.ks_von_mises)),
                 "ks_buckling": float(check.ks_buckling), "tip_deflection": float(check.tip_deflection),
                 "buckling_factors": check.buckling_factors.tolist()}
    except ShellMeshError as e:
        fresh = {"error": f"{type(e).__name__}: {e}"}
    summary = {"success": bool(res.success), "fresh_mesh_of_the_optimum": fresh,
               "iterations": int(prob.driver.iter_count), "seconds": round(seconds, 1),
               "n_elements": int(ref.mesh.n_faces), "stress_limit": args.stress_limit, "tip_limit": args.tip_limit,
               "groups": list(GROUPS), "start": start, "optimum": opt}
    (out / "optimize_layout_summary.json").write_text(json.dumps(summary, indent=1) + "\n")

    cr = om.CaseReader(str(db))
    hist = [cr.get_case(c) for c in cr.list_cases("driver", recurse=False, out_stream=None)]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 3.4), constrained_layout=True)
    ax[0].plot([c.get_val("mass")[0] for c in hist], "o-")
    ax[0].set_xlabel("driver iteration (model runs, not FD)")
    ax[0].set_ylabel("mass [kg]")
    ax[1].plot([c.get_val("ks_von_mises").max() / args.stress_limit for c in hist], "o-", label="KS stress / limit")
    ax[1].plot([c.get_val("ks_buckling")[0] for c in hist], "s-", label="KS 1 / buckling factor")
    ax[1].plot([c.get_val("tip_deflection")[0] / args.tip_limit for c in hist], "^-", label="tip deflection / limit")
    ax[1].axhline(1.0, color="k", lw=0.8, ls="--")
    ax[1].set_xlabel("driver iteration (model runs, not FD)")
    ax[1].legend(fontsize=7)
    for a in ax:
        a.grid(alpha=0.3)
    fig.savefig(out / "optimize_layout_history.png", dpi=90)
    plt.close(fig)

    # the final layout over the initial one, in plan (x aft, y span)
    lay0 = ref.layout
    lay1 = ref.layout_for({"wing": (np.asarray(opt["wing:rib_eta"]), np.asarray(opt["wing:spar_chord"]))})
    fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
    P = ref.surface.points
    ax.plot(P[:, 1], P[:, 0], ",", color="0.8")
    for lay, style, label in ((lay0, dict(color="0.5", ls="--"), "initial"), (lay1, dict(color="C3"), "optimum")):
        for k, s in enumerate(lay.members()):
            ax.plot([s.start[1], s.end[1]], [s.start[0], s.end[0]], **style, label=label if k == 0 else None)
    ax.invert_yaxis()
    ax.set_aspect("equal")
    ax.set_xlabel("y (span) [m]")
    ax.set_ylabel("x (aft) [m]")
    ax.legend(fontsize=8)
    ax.set_title(f"ribs and spars: initial and optimum ({summary['n_elements']} elements)")
    fig.savefig(out / "optimize_layout_final.png", dpi=90)
    plt.close(fig)

    print(f"SLSQP {'converged' if res.success else 'stopped'} after {summary['iterations']} model runs in "
          f"{seconds:.0f} s ({summary['n_elements']} elements)")
    print(f"mass:             {start['mass'][0]:.2f} kg -> {opt['mass'][0]:.2f} kg")
    print(f"max KS stress:    {start['ks_max'] * 1e-6:.1f} -> {opt['ks_max'] * 1e-6:.1f} MPa "
          f"(limit {args.stress_limit * 1e-6:g})")
    print(f"KS buckling:      {start['ks_buckling'][0]:.3f} -> {opt['ks_buckling'][0]:.3f} (limit 1; lowest factors "
          f"{', '.join(f'{b:.2f}' for b in opt['buckling_factors'])})")
    print(f"tip deflection:   {start['tip_deflection'][0] * 1e3:.1f} -> {opt['tip_deflection'][0] * 1e3:.1f} mm "
          f"(limit {args.tip_limit * 1e3:g})")
    print(f"rib stations:     {np.round(start['wing:rib_eta'], 3).tolist()} -> "
          f"{np.round(opt['wing:rib_eta'], 3).tolist()}")
    print(f"spar fractions:   {np.round(start['wing:spar_chord'], 3).tolist()} -> "
          f"{np.round(opt['wing:spar_chord'], 3).tolist()}")
    print("thickness [mm]:   " + ", ".join(f"{g} {t * 1e3:.2f}" for g, t in zip(GROUPS, opt["t_group"])))
    if "error" in fresh:
        print(f"a new mesh of the optimum failed: {fresh['error']}")
    else:
        print(f"a new mesh of the optimum ({fresh['n_elements']} elements, min scaled Jacobian "
              f"{fresh['min_scaled_jacobian']:.3f}): mass {fresh['mass']:.2f} kg, max KS "
              f"{fresh['ks_max'] * 1e-6:.1f} MPa, KS buckling {fresh['ks_buckling']:.3f}, tip deflection "
              f"{fresh['tip_deflection'] * 1e3:.1f} mm")
    return 0 if res.success else 1


if __name__ == "__main__":
    sys.exit(main())
