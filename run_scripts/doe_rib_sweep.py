"""Design of experiments over rib stations and spar chord fractions of the default wing.

    python run_scripts/doe_rib_sweep.py                          # Latin hypercube, 8 cases (~1-2 min)
    python run_scripts/doe_rib_sweep.py --generator ff --levels 2   # full factorial, 2^3 = 8 cases
    mpirun -n 2 python run_scripts/doe_rib_sweep.py --parallel      # the same cases on 2 processes
    python run_scripts/doe_rib_sweep.py --morph --size 0.1          # every case a morph of one mesh
    # as root add:  --allow-run-as-root --oversubscribe  (or OMPI_ALLOW_RUN_AS_ROOT=1
    #                                                    OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1)

The model is a :class:`~shellmesh_mdao.components.group.ShellMeshGroup` (the bundled default
wing, NACA 2412, 6 m semi-span, triangulated coarsely with 24 x 16 sections, ``--ribs`` ribs
and spars at 15 % and 65 % chord, meshed at ``--size``) feeding a
:class:`~shellmesh_mdao.components.calculix_comp.CalculixShellAnalysis` (every family
``--thickness`` thick, 10 kPa on the lower-skin bays, root clamped). A ``DOEDriver``
(``components.group.DOEDriver``: ``om.DOEDriver`` that records failed cases as failed) varies
the interior rib stations ``wing:rib_eta[1:-1]`` (each within 40 % of the rib pitch of its
nominal station) and both spar chord fractions (0.10-0.25 and 0.55-0.70). Every case is
recorded by a ``SqliteRecorder`` (``<out-dir>/doe_cases.sql``; with ``--parallel`` one file per
process, ``doe_cases.sql_<rank>``, plus ``doe_cases.sql_meta``). A case whose design point
cannot be meshed is recorded with ``success = 0`` (``om.AnalysisError``) and left out of the
plot. Writes ``doe_summary.json`` (every case, sorted by design point, so a serial and a
parallel run can be compared line by line) and ``doe_rib_sweep.png`` (mass, max von Mises
stress and tip deflection against each design variable) and prints a table.

With ``--morph`` the mesh stage is a :class:`~shellmesh_mdao.components.morph_comp.MorphComp`
instead: the default layout is meshed once (the reference) and every case moves its nodes to the
case's rib stations and spar fractions (connectivity unchanged; a new mesh only where the morphed
mesh misses its checks, recorded as ``remeshed``). Each case records ``morph_seconds`` (its meshing
time) and ``ccx_seconds`` (its solver time); the summary gives their ratio per case.

Every process uses one thread (OMP/OpenBLAS), set before numpy is imported: the parallel
cases then run with exactly the arithmetic of the serial ones and give identical results.
"""
from __future__ import annotations

import os

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_k, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import openmdao.api as om  # noqa: E402

from shellmesh_mdao.components.calculix_comp import CalculixShellAnalysis  # noqa: E402
from shellmesh_mdao.components.group import DOEDriver, OneProcessModelVector, ShellMeshGroup  # noqa: E402
from shellmesh_mdao.components.morph_comp import MorphComp  # noqa: E402
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout  # noqa: E402
from shellmesh_mdao.morph import morph_reference  # noqa: E402

#: Continuous outputs recorded for every case (besides the design variables).
RESPONSES = ("mass", "max_von_mises", "tip_deflection", "n_nodes", "n_elements", "min_scaled_jacobian",
             "ccx_seconds")
#: ... and with --morph
MORPH_RESPONSES = ("remeshed", "morph_seconds")
SPAR_BOUNDS = ((0.10, 0.25), (0.55, 0.70))


def design_variables(ribs: int, scale: float = 1.0) -> list:
    """``[(name, indices, lower, upper, labels)]``: the interior rib stations (each within 40 % of
    the rib pitch around its nominal station) and the two spar chord fractions (``SPAR_BOUNDS``
    around the default layout's 0.15 and 0.65); ``scale`` shrinks every range towards the default
    layout (1: the full ranges)."""
    nominal = np.linspace(0.0, 1.0, ribs)
    out = []
    if ribs > 2:
        idx = np.arange(1, ribs - 1)
        half = scale * 0.4 / (ribs - 1)
        out.append(("wing:rib_eta", idx, nominal[idx] - half, nominal[idx] + half,
                    [f"rib_eta[{i}]" for i in idx]))
    spars = np.asarray(naca_wing_layout(ribs=max(ribs, 2))["wings"][0]["spars"]["chord_fractions"], float)
    lo = spars + scale * (np.array([b[0] for b in SPAR_BOUNDS]) - spars)
    hi = spars + scale * (np.array([b[1] for b in SPAR_BOUNDS]) - spars)
    out.append(("wing:spar_chord", np.arange(2), lo, hi, ["spar_chord[0]", "spar_chord[1]"]))
    return out


def build_problem(size: float = 0.25, ribs: int = 3, thickness: float = 0.003, remesh_cache: bool = True,
                  comm=None, name: str = "doe_rib_sweep", morph: bool = False, scale: float = 1.0) -> om.Problem:
    """The model: ShellMeshGroup (coarse default wing, ``ribs`` ribs, 2 spars), or with ``morph`` a
    MorphComp on a reference mesh of the default layout, -> CalculiX."""
    layout = naca_wing_layout(ribs=ribs)
    surface = naca_wing(n_chord=24, n_span=16)
    prob = om.Problem(comm=comm, reports=False, name=name)
    if morph:
        prob.model.add_subsystem("mesh", MorphComp(reference=morph_reference(surface, layout, size)), promotes=["*"])
    else:
        prob.model.add_subsystem("mesh", ShellMeshGroup(surface=surface, layout=layout, size=size,
                                                        remesh_cache=remesh_cache), promotes=["*"])
    prob.model.add_subsystem("fea", CalculixShellAnalysis(layout=layout, thickness=thickness, pressure=1.0e4),
                             promotes_inputs=["shell_mesh"],
                             promotes_outputs=["mass", "max_von_mises", "tip_deflection", "ccx_seconds"])
    for dv_name, idx, lo, hi, _ in design_variables(ribs, scale):
        prob.model.add_design_var(dv_name, indices=idx, lower=lo, upper=hi)
    prob.model.add_objective("mass")
    return prob


def make_generator(kind: str, cases: int, levels: int, seed: int):
    if kind == "lhs":
        return om.LatinHypercubeGenerator(samples=cases, seed=seed)
    return om.FullFactorialGenerator(levels=levels)


def case_files(db: Path) -> list:
    """The recorded files of a run: ``db`` (serial) or ``db_0``, ``db_1``, ... (parallel)."""
    if db.is_file():
        return [db]
    files = sorted(db.parent.glob(db.name + "_[0-9]*"), key=lambda p: int(p.name.rsplit("_", 1)[1]))
    if not files:
        raise FileNotFoundError(f"no recorded cases at {db} (nor {db}_0, ...): run the DOE first")
    return files


def read_cases(db) -> list:
    """Every recorded driver case of a serial or parallel run as a dict (design variables,
    responses as lists, ``success``, ``msg``), sorted by design point."""
    db = Path(db)
    meta = db.parent / (db.name + "_meta")
    out = []
    for f in case_files(db):
        cr = om.CaseReader(str(f), metadata_filename=str(meta) if meta.is_file() and f != db else None)
        for cname in cr.list_cases("driver", recurse=False, out_stream=None):
            c = cr.get_case(cname)
            row = {"success": bool(c.success), "msg": (c.msg or "").strip().splitlines()[-1:] or [""]}
            row["msg"] = row["msg"][0]
            for key in ("wing:rib_eta", "wing:spar_chord") + RESPONSES + MORPH_RESPONSES:
                try:
                    row[key] = np.asarray(c.get_val(key), dtype=float).ravel().tolist()
                except KeyError:
                    pass
            out.append(row)
    out.sort(key=lambda r: tuple(r.get("wing:rib_eta", [])) + tuple(r["wing:spar_chord"]))
    return out


def plot(cases: list, ribs: int, out_png: Path, title: str) -> Path:
    """Mass, max von Mises stress and tip deflection against each design variable (matplotlib)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = []
    for dv_name, idx, _, _, labels in design_variables(ribs):
        for j, lab in zip(idx, labels):
            cols.append((dv_name, int(j), lab))
    rows = [("mass", 1.0, "mass [kg]"), ("max_von_mises", 1e-6, "max von Mises [MPa]"),
            ("tip_deflection", 1e3, "tip deflection [mm]")]
    ok = [c for c in cases if c["success"]]
    fig, axes = plt.subplots(len(rows), len(cols), figsize=(3.0 * len(cols) + 1.2, 2.5 * len(rows) + 0.6),
                             squeeze=False, sharey="row", constrained_layout=True)
    for i, (key, scale, ylab) in enumerate(rows):
        y = np.array([c[key][0] * scale for c in ok])
        for j, (dv, k, lab) in enumerate(cols):
            ax = axes[i, j]
            x = np.array([c[dv][k] for c in ok])
            sc = ax.scatter(x, y, c=[c["n_elements"][0] for c in ok], cmap="viridis", s=28, edgecolors="k",
                            linewidths=0.4)
            if i == len(rows) - 1:
                ax.set_xlabel(lab)
            if j == 0:
                ax.set_ylabel(ylab)
            ax.grid(alpha=0.3)
    fig.colorbar(sc, ax=axes, shrink=0.6, label="elements", pad=0.02)
    n_fail = len(cases) - len(ok)
    fig.suptitle(title + (f"  ({n_fail} failed case{'s' if n_fail != 1 else ''} not shown)" if n_fail else ""))
    fig.savefig(out_png, dpi=90)
    plt.close(fig)
    return out_png


def format_table(cases: list) -> str:
    head = (f"{'rib_eta':>18s} {'spar_chord':>14s} {'ok':>3s} {'elements':>8s} {'min SJ':>7s} {'mass kg':>8s} "
            f"{'max vM MPa':>10s} {'tip mm':>8s}")
    lines = [head]
    for c in cases:
        eta = ",".join(f"{v:.3f}" for v in c.get("wing:rib_eta", []))
        sc = ",".join(f"{v:.3f}" for v in c["wing:spar_chord"])
        if c["success"]:
            lines.append(f"{eta:>18s} {sc:>14s} {'yes':>3s} {c['n_elements'][0]:8.0f} "
                         f"{c['min_scaled_jacobian'][0]:7.3f} {c['mass'][0]:8.2f} "
                         f"{c['max_von_mises'][0] * 1e-6:10.1f} {c['tip_deflection'][0] * 1e3:8.2f}")
        else:
            lines.append(f"{eta:>18s} {sc:>14s} {'NO':>3s}  {c['msg'][:90]}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--generator", choices=("lhs", "ff"), default="lhs",
                    help="lhs: Latin hypercube (--cases); ff: full factorial (--levels per variable)")
    ap.add_argument("--cases", type=int, default=8, help="Latin hypercube samples (default 8)")
    ap.add_argument("--levels", type=int, default=2, help="full-factorial levels per variable (default 2)")
    ap.add_argument("--seed", type=int, default=0, help="Latin hypercube seed (default 0)")
    ap.add_argument("--size", type=float, default=0.25, help="target quad edge length in m (default 0.25)")
    ap.add_argument("--ribs", type=int, default=3, help="number of ribs (default 3)")
    ap.add_argument("--thickness", type=float, default=0.003, help="shell thickness of every family (m)")
    ap.add_argument("--parallel", action="store_true", help="run the cases in parallel under mpirun (mpi4py)")
    ap.add_argument("--no-remesh-cache", action="store_true", help="remesh the skin in every case (timing)")
    ap.add_argument("--scale", type=float, default=1.0,
                    help="shrink every design range towards the default layout by this factor (default 1)")
    ap.add_argument("--morph", action="store_true",
                    help="mesh the default layout once and morph it to every case (MorphComp)")
    ap.add_argument("--out-dir", default="study_out/doe_rib_sweep", help="output folder (default: %(default)s)")
    ap.add_argument("--no-plot", action="store_true", help="no matplotlib picture")
    args = ap.parse_args(argv)

    if not 0.0 < args.scale <= 1.0:
        print(f"--scale must be in (0, 1] (a share of the full design ranges), got {args.scale}", file=sys.stderr)
        return 2
    from openmdao.utils.mpi import MPI

    comm = MPI.COMM_WORLD if MPI is not None else None
    rank, nproc = (comm.rank, comm.size) if comm is not None else (0, 1)
    if args.parallel and (MPI is None or nproc < 2):
        print("--parallel needs mpi4py and at least 2 processes: mpirun -n 2 python run_scripts/doe_rib_sweep.py "
              "--parallel (install: apt-get install -y openmpi-bin libopenmpi-dev; pip install -e \".[mpi]\")",
              file=sys.stderr)
        return 2
    if not args.parallel and nproc > 1:
        print("running under mpirun without --parallel: every process would run every case; add --parallel",
              file=sys.stderr)
        return 2
    out = Path(args.out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("OPENMDAO_WORKDIR", str(out))      # OpenMDAO's own <name>_out folder goes there
    db = out / "doe_cases.sql"
    if rank == 0:                     # results of an earlier run (serial or parallel) must not be mixed in
        for f in [db, out / "doe_cases.sql_meta", *out.glob("doe_cases.sql_[0-9]*")]:
            f.unlink(missing_ok=True)
    if comm is not None:
        comm.barrier()

    prob = build_problem(args.size, args.ribs, args.thickness, remesh_cache=not args.no_remesh_cache,
                         comm=comm, morph=args.morph, scale=args.scale)
    driver = prob.driver = DOEDriver(make_generator(args.generator, args.cases, args.levels, args.seed))
    if args.parallel:
        driver.options["run_parallel"] = True
        driver.options["procs_per_model"] = 1
    driver.recording_options["includes"] = list(RESPONSES + (MORPH_RESPONSES if args.morph else ()))
    driver.add_recorder(om.SqliteRecorder(str(db)))
    if args.parallel:
        # each case runs on a one-process model (procs_per_model=1): no distributed vectors are
        # needed, so petsc4py is not required (see OneProcessModelVector)
        prob.setup(distributed_vector_class=OneProcessModelVector)
    else:
        prob.setup()
    t0 = time.perf_counter()
    prob.run_driver()
    wall = time.perf_counter() - t0
    prob.cleanup()
    stats = (dict(hits=0, misses=0, seconds=0.0) if args.morph else prob.model.mesh.imprint.remesh_stats)
    n_local = prob.driver.iter_count
    stats_all = comm.gather((n_local, stats, wall), root=0) if comm is not None and nproc > 1 else [
        (n_local, stats, wall)]
    if rank != 0:
        return 0

    cases = read_cases(db)
    n_cases = len(cases)
    n_ok = sum(c["success"] for c in cases)
    summary = {"generator": args.generator, "cases": n_cases, "succeeded": n_ok, "processes": nproc,
               "size": args.size, "ribs": args.ribs, "thickness": args.thickness,
               "remesh_cache": not args.no_remesh_cache, "morph": args.morph, "scale": args.scale,
               "wall_seconds": round(wall, 2),
               "seconds_per_case": round(wall * nproc / max(n_cases, 1), 2),
               "per_process": [{"cases": n, "remesh_hits": s["hits"], "remesh_misses": s["misses"],
                                "remesh_seconds": round(s["seconds"], 2), "wall_seconds": round(w, 2)}
                               for n, s, w in stats_all],
               "records": [str(f) for f in case_files(db)], "case_list": cases}
    if args.morph:
        ok = [c for c in cases if c["success"]]
        share = [c["morph_seconds"][0] / c["ccx_seconds"][0] for c in ok]
        summary["morph_summary"] = {
            "remeshed": int(sum(c["remeshed"][0] for c in ok)),
            "meshing_over_ccx_median": float(np.median(share)) if share else None,
            "meshing_over_ccx_max": float(max(share)) if share else None,
            "meshing_over_ccx_max_morphed": float(max((x for x, c in zip(share, ok) if not c["remeshed"][0]),
                                                      default=float("nan")))}
    (out / "doe_summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(format_table(cases))
    head = (f"{n_ok}/{n_cases} cases succeeded on {nproc} process{'es' if nproc > 1 else ''} in {wall:.1f} s "
            f"({summary['seconds_per_case']:.1f} s per case per process); ")
    if args.morph:
        ms = summary["morph_summary"]
        med, big = (100 * (ms[k] or 0.0) for k in ("meshing_over_ccx_median", "meshing_over_ccx_max"))
        print(head + f"morph: {ms['remeshed']} case(s) meshed anew; meshing time / ccx time per case: median "
              f"{med:.1f} %, largest {big:.1f} % (morphed cases: {100 * ms['meshing_over_ccx_max_morphed']:.1f} %)")
    else:
        print(head + "remesh: " + ", ".join(f"{s['hits']} cached / {s['misses']} run ({s['seconds']:.1f} s)"
                                          for _, s, _ in stats_all))
    written = [out / "doe_summary.json"] + case_files(db)
    if not args.no_plot and n_ok:
        title = (f"{'Latin hypercube' if args.generator == 'lhs' else 'full factorial'} DOE, {n_cases} cases, "
                 f"size {args.size:g} m, t = {args.thickness * 1e3:g} mm")
        written.append(plot(cases, args.ribs, out / "doe_rib_sweep.png", title))
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


if __name__ == "__main__":
    sys.exit(main())
