"""The main job: mesh the bundled default wing box and analyse it with CalculiX, through OpenMDAO.

    python run_scripts/wingbox_analysis.py                 # size 0.1 m (~1-2 min on 2 cores)
    python run_scripts/wingbox_analysis.py --size 0.15     # coarser, faster

Model (``om.Problem``): :class:`~shellmesh_mdao.components.group.ShellMeshGroup` on the bundled
default wing (NACA 2412, 6 m semi-span, ``geometry.naca_wing()``) with its default layout
(8 ribs, spars at 15 % and 65 % chord, ``geometry.naca_wing_layout()``) -> ``shell_mesh`` ->
:class:`~shellmesh_mdao.components.calculix_comp.CalculixShellAnalysis` (aluminium, every family
``--thickness`` thick, ``--pressure`` on the lower-skin bays along up, root clamped) and
:class:`~shellmesh_mdao.components.mass_comp.MassComp`. Writes into ``--out-dir``:

* ``default_wing_mesh.bdf`` (Nastran, one PSHELL per family with the thicknesses used) and
  ``default_wing_mesh.vtu`` (cell data: component, von_mises in Pa, scaled_jacobian);
* ``default_wing_families.png`` (the mesh coloured by family), ``default_wing_wingbox.png`` (the
  wing box with the upper skin hidden) and ``default_wing_stress.png`` (von Mises stress on the
  deflected shape, displacements scaled so the largest is 5 % of the span), drawn off-screen
  with pyvista;
* ``default_wing_summary.json``;

and prints the mesh figures, the mass, the maximum von Mises stress and the tip deflection.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import openmdao.api as om

from shellmesh_mdao.components.calculix_comp import CalculixShellAnalysis
from shellmesh_mdao.components.group import ShellMeshGroup
from shellmesh_mdao.components.mass_comp import MassComp
from shellmesh_mdao.errors import ShellMeshError
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout

STEM = "default_wing"


def build_problem(size: float, thickness: float, pressure: float, name: str = "wingbox_analysis") -> om.Problem:
    """ShellMeshGroup (default wing, default layout) -> CalculiX analysis and mass."""
    surface, layout = naca_wing(), naca_wing_layout()
    prob = om.Problem(reports=False, name=name)
    prob.model.add_subsystem("mesh", ShellMeshGroup(surface=surface, layout=layout, size=size), promotes=["*"])
    prob.model.add_subsystem("fea", CalculixShellAnalysis(layout=layout, thickness=thickness, pressure=pressure),
                             promotes_inputs=["shell_mesh", "thickness"])
    prob.model.add_subsystem("mass", MassComp(layout=layout, thickness=thickness),
                             promotes_inputs=["shell_mesh", "thickness"])
    return prob


def stress_picture(mesh, result, out_png: Path, span: float) -> Path:
    """Von Mises stress (MPa) on the deflected mesh, displacements scaled so the largest is 5 % of
    the span."""
    import pyvista as pv

    from shellmesh_mdao.render import check_offscreen, to_pyvista

    check_offscreen()
    u = result.displacement
    umax = float(np.linalg.norm(u, axis=1).max())
    scale = 0.05 * span / umax if umax > 0 else 0.0
    poly = to_pyvista(mesh)
    poly.points = mesh.points + scale * u
    poly.cell_data["von Mises [MPa]"] = result.von_mises * 1e-6
    undeformed = to_pyvista(mesh)
    pl = pv.Plotter(off_screen=True, window_size=[1000, 625])
    pl.set_background("white")
    pl.add_mesh(undeformed, color=(0.8, 0.8, 0.8), opacity=0.25, show_edges=False)
    vm = result.von_mises * 1e-6
    top = float(np.percentile(vm, 99.5))         # one clamped-edge element would wash out the rest
    pl.add_mesh(poly, scalars="von Mises [MPa]", cmap="turbo", show_edges=False, clim=[0.0, top],
                scalar_bar_args=dict(vertical=True, position_x=0.86, position_y=0.15, width=0.06, height=0.65,
                                     color="black", fmt="%.0f", title_font_size=16, label_font_size=14))
    pl.add_text(f"von Mises stress on the deflected wing (displacements x {scale:.2g}: largest = 5 % of the span); "
                f"grey: undeformed\ncolour range clipped at the 99.5th percentile ({top:.0f} MPa); "
                f"maximum {vm.max():.0f} MPa",
                position="upper_left", font_size=11, color="black")
    c = 0.5 * (mesh.points.min(0) + mesh.points.max(0))
    pl.camera.focal_point = c
    pl.camera.position = c + np.array([-0.55, -0.62, 0.56]) * 1.7 * span
    pl.camera.up = (0, 0, 1)
    pl.reset_camera()
    pl.camera.zoom(1.2)
    pl.screenshot(str(out_png))
    pl.close()
    return out_png


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=float, default=0.1, help="target quad edge length in m (default 0.1)")
    ap.add_argument("--thickness", type=float, default=0.002, help="shell thickness of every family in m "
                                                                   "(default 0.002)")
    ap.add_argument("--pressure", type=float, default=1.0e4, help="pressure on the lower-skin bays in Pa "
                                                                  "(default 1e4)")
    ap.add_argument("--out-dir", default="study_out/wingbox_analysis", help="output folder (default: %(default)s)")
    ap.add_argument("--no-pictures", action="store_true", help="do not draw the PNG pictures")
    args = ap.parse_args(argv)

    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    try:
        prob = build_problem(args.size, args.thickness, args.pressure)
        prob.setup()
        prob.run_model()
    except (ShellMeshError, om.AnalysisError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    seconds = time.perf_counter() - t0
    from shellmesh_mdao.export import write_mesh
    from shellmesh_mdao.quality import scaled_jacobian

    mesh = prob.get_val("shell_mesh")
    fea = prob.model.fea
    r = fea.last_result
    state = prob.get_val("mesh.quad.state")
    t = prob.get_val("thickness")
    t_mesh = t[[fea.family_names.index(n) for n in mesh.component_names]]
    sj = scaled_jacobian(mesh)
    written = [write_mesh(mesh, out / f"{STEM}_mesh.bdf", thickness=t_mesh),
               write_mesh(mesh, out / f"{STEM}_mesh.vtu", quality={"von_mises": r.von_mises, "scaled_jacobian": sj})]
    if not args.no_pictures:
        from shellmesh_mdao.render import render_mesh

        written.append(render_mesh(mesh, out / f"{STEM}_families.png", color="component", view="iso",
                                   up=r.up, title=f"default wing, size {args.size:g} m: {mesh.n_faces} elements "
                                                  f"({mesh.n_quads} quads), {mesh.n_points} nodes"))
        written.append(render_mesh(mesh, out / f"{STEM}_wingbox.png", color="component", view="wingbox", up=r.up))
        span = float(np.ptp(mesh.points[:, 1]))
        written.append(stress_picture(mesh, r, out / f"{STEM}_stress.png", span))
    k_max = int(np.argmax(np.where(r.in_clamp_band, -np.inf, r.von_mises)))   # outside the band at the clamp
    summary = {
        "size": args.size, "thickness": args.thickness, "pressure": args.pressure,
        "n_nodes": int(prob.get_val("n_nodes")[0]), "n_elements": int(prob.get_val("n_elements")[0]),
        "n_quads": int(mesh.n_quads), "n_tris": int(mesh.n_tris),
        "min_scaled_jacobian": float(prob.get_val("min_scaled_jacobian")[0]),
        "mass_kg": float(prob.get_val("fea.mass")[0]), "mass_masscomp_kg": float(prob.get_val("mass.mass")[0]),
        "max_von_mises_pa": float(prob.get_val("fea.max_von_mises")[0]),
        "tip_deflection_m": float(prob.get_val("fea.tip_deflection")[0]),
        "load_n": float(np.linalg.norm(r.load)) if np.ndim(r.load) else float(r.load),
        "max_von_mises_family": mesh.component_names[mesh.component[k_max]],
        "max_von_mises_at": mesh.face_centroids()[k_max].round(4).tolist(),
        "clamp_band_m": float(r.clamp_band), "peak_von_mises_pa": float(r.peak_von_mises),
        "max_deflection_m": float(prob.get_val("fea.max_deflection")[0]),
        "ccx_seconds": round(float(r.seconds), 2), "stage_seconds": state.report["stages"],
        "total_seconds": round(seconds, 2),
        "ks_von_mises_pa": dict(zip(fea.family_names, (float(v) for v in prob.get_val("fea.ks_von_mises")))),
    }
    (out / f"{STEM}_summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    written.append(out / f"{STEM}_summary.json")
    print(f"default wing (NACA 2412, 6 m semi-span), default layout (8 ribs, 2 spars), size {args.size:g} m")
    print(f"mesh:            {summary['n_elements']} elements ({summary['n_quads']} quads, {summary['n_tris']} "
          f"triangles), {summary['n_nodes']} nodes, {len(mesh.component_names)} families, "
          f"min scaled Jacobian {summary['min_scaled_jacobian']:.3f}")
    print(f"load:            {args.pressure:g} Pa on the lower-skin bays ({summary['load_n']:.0f} N), root clamped, "
          f"t = {args.thickness * 1e3:g} mm")
    print(f"mass:            {summary['mass_kg']:.2f} kg")
    at = summary["max_von_mises_at"]
    print(f"max stress:      {summary['max_von_mises_pa'] * 1e-6:.1f} MPa (von Mises), in "
          f"{summary['max_von_mises_family']} at x={at[0]:.2f} y={at[1]:.2f} z={at[2]:.2f} m, outside "
          f"{summary['clamp_band_m']:.2f} m of the clamp (there: {summary['peak_von_mises_pa'] * 1e-6:.1f} MPa)")
    print(f"tip deflection:  {summary['tip_deflection_m'] * 1e3:.1f} mm (mean over the tip rib; largest "
          f"{summary['max_deflection_m'] * 1e3:.1f} mm)")
    print("seconds:         " + ", ".join(f"{k} {v:.1f}" for k, v in state.report["stages"].items())
          + f", ccx {summary['ccx_seconds']:.1f}; total {seconds:.1f}")
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


if __name__ == "__main__":
    sys.exit(main())
