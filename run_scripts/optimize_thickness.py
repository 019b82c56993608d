"""Minimum-mass shell thicknesses under a stress limit (SLSQP) on a coarse mesh of the default wing.

    python run_scripts/optimize_thickness.py                     # 5 thickness groups (~5 min on 2 cores)
    python run_scripts/optimize_thickness.py --per-family        # one thickness per family (slower)

Model: :class:`~shellmesh_mdao.components.group.ShellMeshGroup` (the bundled default wing,
NACA 2412, 6 m semi-span, coarse 24 x 16 triangulation, 3 ribs, spars at 15 % and 65 % chord,
``--size`` 0.25 m) -> ``shell_mesh`` -> :class:`~shellmesh_mdao.components.calculix_comp.CalculixShellAnalysis`
(10 kPa on the lower-skin bays, root clamped). The design variables are the thicknesses of
five groups of families (``skin`` outside the box, upper-skin bays, lower-skin bays, spars,
ribs; ``--per-family``: every family), mapped onto the per-family ``thickness`` vector by a
linear component with exact partials. ``om.ScipyOptimizeDriver(optimizer="SLSQP")`` minimises
the mass subject to ``ks_von_mises <= --stress-limit`` for every family (KS aggregate of the
element von Mises stresses, see docs/analysis.md), thicknesses in [--t-min, --t-max].

The mesh does not change during the optimisation: the ShellMeshGroup's stages see the same
input objects at every run and give their previous outputs again (no re-meshing). The
gradients are central finite differences of the whole model over the design variables
(``approx_totals``: two ccx runs per design variable and iteration), cheaper than the
component's own FD partials over all families.

Writes ``<out-dir>/optimize_history.png`` (mass and the largest stress ratio against the
iteration), ``optimize_summary.json`` and ``optimize_cases.sql`` (the driver's iterations)
and prints the optimum.
"""
from __future__ import annotations

import argparse
import fnmatch
import json
import sys
import time
from pathlib import Path

import numpy as np
import openmdao.api as om

from shellmesh_mdao.components.calculix_comp import CalculixShellAnalysis
from shellmesh_mdao.components.group import ShellMeshGroup, family_names
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout

#: Thickness groups: name -> fnmatch patterns of the families in the group (first match wins).
GROUPS = {"skin": ["skin"], "upper_skin": ["*/upper_skin/*"], "lower_skin": ["*/lower_skin/*"],
          "spars": ["*/spar_*"], "ribs": ["*/rib_*"]}


def group_matrix(names: list, groups: dict) -> np.ndarray:
    """(n_families, n_groups) 0/1 matrix: family i takes the thickness of its (first) group."""
    A = np.zeros((len(names), len(groups)))
    for i, n in enumerate(names):
        for j, pats in enumerate(groups.values()):
            if any(fnmatch.fnmatchcase(n, p) for p in pats):
                A[i, j] = 1.0
                break
        else:
            raise ValueError(f"family {n!r} is in no thickness group; add a pattern for it to GROUPS")
    return A


class ThicknessMap(om.ExplicitComponent):
    """``thickness = A @ t_group``: group thicknesses -> per-family thicknesses (exact partials)."""

    def initialize(self):
        self.options.declare("matrix", types=np.ndarray, desc="(n_families, n_groups) 0/1 group matrix")
        self.options.declare("t0", default=0.003, desc="initial group thickness")

    def setup(self):
        A = self.options["matrix"]
        self.add_input("t_group", val=np.full(A.shape[1], self.options["t0"]), desc="thickness of each group")
        self.add_output("thickness", val=A @ np.full(A.shape[1], self.options["t0"]), desc="per-family thickness")
        r, c = np.nonzero(A)
        self.declare_partials("thickness", "t_group", rows=r, cols=c, val=A[r, c])

    def compute(self, inputs, outputs):
        outputs["thickness"] = self.options["matrix"] @ inputs["t_group"]


def build_problem(size: float = 0.25, ribs: int = 3, per_family: bool = False, t0: float = 0.004,
                  t_min: float = 0.0005, t_max: float = 0.01, stress_limit: float = 250e6,
                  name: str = "optimize_thickness") -> tuple:
    """The optimisation problem and the names of its thickness groups."""
    layout = naca_wing_layout(ribs=ribs)
    names = family_names(layout)
    groups = {n: [n] for n in names} if per_family else GROUPS
    A = group_matrix(names, groups)
    prob = om.Problem(reports=False, name=name)
    m = prob.model
    m.add_subsystem("mesh", ShellMeshGroup(surface=naca_wing(n_chord=24, n_span=16), layout=layout, size=size),
                    promotes=["*"])
    m.add_subsystem("tmap", ThicknessMap(matrix=A, t0=t0), promotes=["*"])
    m.add_subsystem("fea", CalculixShellAnalysis(layout=layout, pressure=1.0e4, thickness=t0),
                    promotes_inputs=["shell_mesh", "thickness"],
                    promotes_outputs=["mass", "max_von_mises", "ks_von_mises", "tip_deflection"])
    m.add_design_var("t_group", lower=t_min, upper=t_max, ref=1e-3)
    m.add_objective("mass", ref=100.0)
    m.add_constraint("ks_von_mises", upper=stress_limit, ref=stress_limit)
    # gradients: central FD of the whole model over the few design variables (two ccx runs each; a
    # forward difference from the uniform start would measure the jump of ccx's shell model where
    # neighbouring thicknesses become different, docs/analysis.md 'Partials'); the mesh stages are
    # memoized, so a perturbed run costs one ccx run only
    m.approx_totals(method="fd", step=1e-2, step_calc="rel", form="central")
    return prob, list(groups)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=float, default=0.25, help="target quad edge length in m (default 0.25)")
    ap.add_argument("--ribs", type=int, default=3, help="number of ribs (default 3)")
    ap.add_argument("--per-family", action="store_true", help="one design variable per family")
    ap.add_argument("--stress-limit", type=float, default=250e6, help="KS von Mises limit in Pa (default 250e6)")
    ap.add_argument("--t0", type=float, default=0.004, help="initial thickness in m (default 0.004)")
    ap.add_argument("--t-min", type=float, default=0.0005, help="lower thickness bound in m (default 0.0005)")
    ap.add_argument("--t-max", type=float, default=0.01, help="upper thickness bound in m (default 0.01)")
    ap.add_argument("--maxiter", type=int, default=20, help="SLSQP iterations (default 20)")
    ap.add_argument("--out-dir", default="study_out/optimize_thickness", help="output folder (default: %(default)s)")
    args = ap.parse_args(argv)

    out = Path(args.out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    prob, groups = build_problem(args.size, args.ribs, args.per_family, args.t0, args.t_min, args.t_max,
                                 args.stress_limit)
    prob.driver = om.ScipyOptimizeDriver(optimizer="SLSQP", maxiter=args.maxiter, tol=1e-4, disp=True)
    prob.driver.recording_options["includes"] = ["mass", "max_von_mises", "tip_deflection"]
    db = out / "optimize_cases.sql"
    db.unlink(missing_ok=True)
    prob.driver.add_recorder(om.SqliteRecorder(str(db)))
    prob.setup()
    t0 = time.perf_counter()
    prob.run_model()
    start = {"mass": float(prob.get_val("mass")[0]), "max_von_mises": float(prob.get_val("max_von_mises")[0]),
             "ks_max": float(prob.get_val("ks_von_mises").max()), "tip_deflection": float(prob.get_val("tip_deflection")[0])}
    res = prob.run_driver()
    seconds = time.perf_counter() - t0
    prob.cleanup()

    t_opt = prob.get_val("t_group")
    ks = prob.get_val("ks_von_mises")
    fea = prob.model.fea
    summary = {
        "success": bool(res.success), "iterations": int(prob.driver.iter_count), "seconds": round(seconds, 1),
        "n_elements": int(prob.get_val("n_elements")[0]), "stress_limit": args.stress_limit,
        "start": start, "optimum": {
            "mass": float(prob.get_val("mass")[0]), "max_von_mises": float(prob.get_val("max_von_mises")[0]),
            "ks_max": float(ks.max()), "tip_deflection": float(prob.get_val("tip_deflection")[0]),
            "t_group": dict(zip(groups, map(float, t_opt))),
            "ks_von_mises": dict(zip(fea.family_names, map(float, ks)))},
        "mesh_stage_runs": {n: getattr(prob.model.mesh, n).n_runs
                            for n in ("project", "imprint", "members", "split", "merge", "smooth", "quad")},
    }
    (out / "optimize_summary.json").write_text(json.dumps(summary, indent=1) + "\n")

    cr = om.CaseReader(str(db))
    hist = [cr.get_case(c) for c in cr.list_cases("driver", recurse=False, out_stream=None)]
    mass_h = np.array([c.get_val("mass")[0] for c in hist])
    ratio_h = np.array([c.get_val("ks_von_mises").max() / args.stress_limit for c in hist])
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(9, 3.4), constrained_layout=True)
    ax[0].plot(mass_h, "o-")
    ax[0].set_xlabel("driver iteration (model runs, not FD)")
    ax[0].set_ylabel("mass [kg]")
    ax[1].plot(ratio_h, "o-", color="C3")
    ax[1].axhline(1.0, color="k", lw=0.8, ls="--")
    ax[1].set_xlabel("driver iteration (model runs, not FD)")
    ax[1].set_ylabel("max KS stress / limit")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle(f"SLSQP, {len(groups)} thickness variables, {summary['n_elements']} elements, "
                 f"limit {args.stress_limit * 1e-6:g} MPa")
    fig.savefig(out / "optimize_history.png", dpi=90)
    plt.close(fig)

    o = summary["optimum"]
    print(f"SLSQP {'converged' if res.success else 'stopped'} after {summary['iterations']} model runs in "
          f"{seconds:.0f} s ({summary['n_elements']} elements; mesh stages ran "
          f"{summary['mesh_stage_runs']['quad']} time(s))")
    print(f"mass:           {start['mass']:.2f} kg -> {o['mass']:.2f} kg")
    print(f"max KS stress:  {start['ks_max'] * 1e-6:.1f} MPa -> {o['ks_max'] * 1e-6:.1f} MPa "
          f"(limit {args.stress_limit * 1e-6:g} MPa)")
    print(f"tip deflection: {start['tip_deflection'] * 1e3:.1f} mm -> {o['tip_deflection'] * 1e3:.1f} mm")
    print("thickness [mm]: " + ", ".join(f"{g} {t * 1e3:.2f}" for g, t in o["t_group"].items()))
    print(f"wrote {out / 'optimize_history.png'}, {out / 'optimize_summary.json'}, {db}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
