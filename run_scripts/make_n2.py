"""Write the N2 diagram of the ShellMeshGroup model to docs/figures/n2_shellmesh_group.html.

    python run_scripts/make_n2.py                      # -> docs/figures/n2_shellmesh_group.html
    python run_scripts/make_n2.py --out n2.html

The model is the one of ``run_scripts/wingbox_analysis.py`` (ShellMeshGroup on the bundled
default wing and its default layout -> CalculixShellAnalysis and MassComp through the discrete
``shell_mesh``). Only set up, not run (a second or two); without CalculiX installed the
analysis component is left out. Open the HTML file in a browser.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

import openmdao.api as om

from shellmesh_mdao.analysis import find_ccx
from shellmesh_mdao.components.calculix_comp import CalculixShellAnalysis
from shellmesh_mdao.components.group import ShellMeshGroup
from shellmesh_mdao.components.mass_comp import MassComp
from shellmesh_mdao.errors import SolverError
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout


def build_model(with_analysis: bool = True) -> om.Problem:
    """ShellMeshGroup -> (CalculixShellAnalysis) + MassComp, set up, not run."""
    layout = naca_wing_layout()
    prob = om.Problem(reports=False, name="n2_shellmesh_group")
    prob.model.add_subsystem("mesh", ShellMeshGroup(surface=naca_wing(), layout=layout, size=0.1), promotes=["*"])
    if with_analysis:
        prob.model.add_subsystem("fea", CalculixShellAnalysis(layout=layout),
                                 promotes_inputs=["shell_mesh", "thickness"])
    prob.model.add_subsystem("mass", MassComp(layout=layout), promotes_inputs=["shell_mesh", "thickness"])
    prob.setup()
    prob.final_setup()
    return prob


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(REPO / "docs" / "figures" / "n2_shellmesh_group.html"),
                    help="HTML file to write (default: docs/figures/n2_shellmesh_group.html)")
    args = ap.parse_args(argv)
    try:
        find_ccx()
        with_analysis = True
    except SolverError:
        with_analysis = False
        print("ccx not found: the N2 diagram leaves out CalculixShellAnalysis", file=sys.stderr)
    out = Path(args.out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:          # OpenMDAO's <name>_out folder
        os.environ.setdefault("OPENMDAO_WORKDIR", tmp)
        prob = build_model(with_analysis)
        om.n2(prob, outfile=str(out), show_browser=False, embeddable=False)
    print(f"wrote {out} ({out.stat().st_size / 1e3:.0f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
