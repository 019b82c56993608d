"""Accuracy of CalculixShellAnalysis's thickness partials (central differences, relative step ``--step``).

    python run_scripts/thickness_partials.py            # default wing, 3 ribs, size 0.2 (~3 min)
    python run_scripts/thickness_partials.py --ks-ref 2.5e8

For every family with faces, the central difference of step ``--step`` (the component's ``fd_step``)
of the tip deflection, ``max_von_mises`` and every ``ks_von_mises`` with respect to the family's
thickness, against two references: Richardson's extrapolation of central differences of half and the
whole step (fourth order) and a fourth-order difference with steps of 5 and 10 times the step. Prints,
per output and band of relative sensitivity ``|t/f df/dt|``, the largest and median relative error and
how many entries are above 1e-3 (docs/analysis.md, 'Partials').
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from shellmesh_mdao.analysis import analyse_shell
from shellmesh_mdao.components.layout_comp import family_names
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.pipeline import run_pipeline


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=float, default=0.2, help="element size in m (default 0.2)")
    ap.add_argument("--ribs", type=int, default=3, help="number of ribs (default 3)")
    ap.add_argument("--thickness", type=float, default=0.003, help="thickness of every family in m (default 0.003)")
    ap.add_argument("--step", type=float, default=1e-2, help="relative step (default 1e-2, the component's)")
    ap.add_argument("--ks-ref", type=float, default=None, help="KS reference stress (default: none, self-referenced)")
    args = ap.parse_args(argv)
    layout = naca_wing_layout(ribs=args.ribs)
    mesh = run_pipeline(naca_wing(n_chord=24, n_span=16), layout, args.size, progress=False).mesh
    nf = len(family_names(layout))
    t0 = np.full(nf, args.thickness)
    kw = dict(layout=layout, pressure=1.0e4, ks_ref=args.ks_ref)

    def f(t):
        r = analyse_shell(mesh, t, **kw)
        return np.concatenate([[r.tip_deflection], [r.max_von_mises], r.ks_von_mises])

    base = f(t0)
    nz = np.flatnonzero(np.bincount(mesh.component, minlength=nf) > 0)
    sens, err = [], {"Richardson": [], "wide": []}
    for i in nz:
        e = np.eye(nf)[i]
        h = args.step * t0[i]
        d = {k: f(t0 + k * h * e) for k in (-10, -5, -1, -0.5, 0.5, 1, 5, 10)}
        c1 = (d[1] - d[-1]) / (2 * h)
        c_half = (d[0.5] - d[-0.5]) / h
        ref = {"Richardson": (4 * c_half - c1) / 3,
               "wide": (8 * (d[5] - d[-5]) - (d[10] - d[-10])) / (60 * h)}
        sens.append(np.abs(ref["Richardson"] * t0[i] / np.where(base != 0, base, 1)))
        for k, r in ref.items():
            err[k].append(np.abs(c1 / np.where(r != 0, r, 1) - 1))
    S = np.array(sens)
    print(f"{mesh.n_faces} elements, {len(nz)} families with faces, step {args.step:g}, ks_ref {args.ks_ref}")
    for name, E in err.items():
        E = np.array(E)
        print(f"central {args.step:g} against the {name} reference:")
        for lab, cols in (("tip_deflection", [0]), ("max_von_mises", [1]), ("ks_von_mises", list(range(2, 2 + nf)))):
            s, e = S[:, cols].ravel(), E[:, cols].ravel()
            for thr in (0.1, 0.01):
                k = s >= thr
                if k.any():
                    print(f"  {lab:15s} sensitivity >= {thr:<4g}: {k.sum():3d} entries, max {e[k].max():.2e}, "
                          f"median {np.median(e[k]):.2e}, above 1e-3: {(e[k] > 1e-3).sum()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
