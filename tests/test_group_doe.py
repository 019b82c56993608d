"""ShellMeshGroup in an om.Problem, a DOE of 4 cases, the N2 diagram, and the DOE under MPI.

* the group gives exactly run_pipeline's mesh; unchanged inputs re-mesh nothing; a moved rib
  reuses the remeshed skin and gives exactly run_pipeline's mesh of the moved layout;
* a DOEDriver with 4 cases (3 valid design points + 1 with ribs out of order) through
  CalculiX: 4 recorded cases, the invalid one recorded as failed with the LayoutError
  message, the others with finite mass/stress/deflection (mass = MassComp's), one remesh;
* ``om.n2`` of the group writes its HTML;
* (slow) ``run_scripts/doe_rib_sweep.py --cases 4`` serially and under ``mpirun -n 2 ...
  --parallel`` record identical outputs, with a new mesh per case and with ``--morph --scale 0.25``
  (skipped only when mpirun, mpi4py or ccx is missing).
"""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import openmdao.api as om
import pytest

from shellmesh_mdao.components.calculix_comp import CalculixShellAnalysis
from shellmesh_mdao.components.group import DOEDriver, ShellMeshGroup
from shellmesh_mdao.components.mass_comp import MassComp
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.pipeline import run_pipeline

REPO = Path(__file__).resolve().parents[1]
DOE_SCRIPT = REPO / "run_scripts" / "doe_rib_sweep.py"
SIZE = 0.25
SURFACE = naca_wing(n_chord=24, n_span=16)
LAYOUT = naca_wing_layout(ribs=3)


from conftest import needs_ccx  # noqa: E402


@pytest.fixture(autouse=True)
def _openmdao_out(tmp_path, monkeypatch):
    monkeypatch.setenv("OPENMDAO_WORKDIR", str(tmp_path))     # OpenMDAO's <name>_out folders


def same_mesh(a, b) -> bool:
    return (np.array_equal(a.points, b.points) and np.array_equal(a.faces, b.faces)
            and np.array_equal(a.component, b.component) and a.component_names == b.component_names)


def test_group_matches_pipeline_and_caches():
    p = om.Problem(reports=False)
    p.model.add_subsystem("mesh", ShellMeshGroup(surface=SURFACE, layout=LAYOUT, size=SIZE), promotes=["*"])
    p.setup()
    p.run_model()
    g = p.model.mesh
    ref = run_pipeline(SURFACE, LAYOUT, SIZE, progress=False).mesh
    m = p.get_val("shell_mesh")
    assert same_mesh(m, ref) and m.n_tris == 0
    assert p.get_val("n_elements")[0] == ref.n_faces and p.get_val("min_scaled_jacobian")[0] > 0.2
    assert g.family_names == list(ref.component_names)
    # unchanged inputs: nothing is re-meshed, the same mesh object comes out
    p.run_model()
    assert p.get_val("shell_mesh") is m and g.quad.n_runs == 1 and g.imprint.n_runs == 1
    # a moved rib and spar: re-meshed from the cached remeshed skin, same as a fresh pipeline run
    p.set_val("wing:rib_eta", [0.0, 0.4, 1.0])
    p.set_val("wing:spar_chord", [0.2, 0.6])
    p.run_model()
    assert g.imprint.remesh_stats["hits"] == 1 and g.imprint.remesh_stats["misses"] == 1
    lay = naca_wing_layout(ribs=3, spars=(0.2, 0.6))
    lay["wings"][0]["ribs"] = {"eta": [0.0, 0.4, 1.0]}
    assert same_mesh(p.get_val("shell_mesh"), run_pipeline(SURFACE, lay, SIZE, progress=False).mesh)


def test_n2_diagram_of_the_group(tmp_path):
    p = om.Problem(reports=False)
    p.model.add_subsystem("mesh", ShellMeshGroup(surface=SURFACE, layout=LAYOUT, size=SIZE), promotes=["*"])
    p.model.add_subsystem("mass", MassComp(layout=LAYOUT), promotes_inputs=["shell_mesh"])
    p.setup()
    out = tmp_path / "n2.html"
    om.n2(p, outfile=str(out), show_browser=False)
    assert out.stat().st_size > 10_000 and "N2 diagram" in out.read_text()
    from openmdao.visualization.n2_viewer.n2_viewer import _get_viewer_data

    tree = _get_viewer_data(p)["tree"]
    group = next(c for c in tree["children"] if c["name"] == "mesh")
    stages = [c["name"] for c in group["children"]]
    assert stages == ["layout", "project", "imprint", "members", "split", "merge", "smooth", "quad"]
    quad = group["children"][-1]
    assert {"state_in", "state", "shell_mesh", "n_nodes", "n_elements", "min_scaled_jacobian"} <= \
        {c["name"] for c in quad["children"]}


@needs_ccx
def test_doe_four_cases_with_a_failed_case(tmp_path):
    p = om.Problem(reports=False)
    p.model.add_subsystem("mesh", ShellMeshGroup(surface=SURFACE, layout=LAYOUT, size=SIZE), promotes=["*"])
    p.model.add_subsystem("fea", CalculixShellAnalysis(layout=LAYOUT, thickness=0.003),
                          promotes_inputs=["shell_mesh", "thickness"])
    p.model.add_subsystem("mass", MassComp(layout=LAYOUT, thickness=0.003), promotes_inputs=["shell_mesh", "thickness"])
    p.model.add_design_var("wing:rib_eta", lower=0.0, upper=1.0)
    p.model.add_design_var("wing:spar_chord", lower=0.05, upper=0.95)
    p.model.add_objective("fea.mass")
    cases = [[("wing:rib_eta", [0.0, 0.4, 1.0]), ("wing:spar_chord", [0.15, 0.65])],
             [("wing:rib_eta", [0.0, 0.9, 0.3]), ("wing:spar_chord", [0.15, 0.65])],     # ribs out of order
             [("wing:rib_eta", [0.0, 0.6, 1.0]), ("wing:spar_chord", [0.2, 0.6])],
             [("wing:rib_eta", [0.0, 0.5, 1.0]), ("wing:spar_chord", [0.12, 0.68])]]
    p.driver = DOEDriver(om.ListGenerator(cases))
    p.driver.recording_options["includes"] = ["fea.max_von_mises", "fea.tip_deflection", "mass.mass", "n_elements"]
    db = tmp_path / "cases.sql"
    p.driver.add_recorder(om.SqliteRecorder(str(db)))
    p.setup()
    p.run_driver()
    p.cleanup()
    cr = om.CaseReader(str(db))
    rec = [cr.get_case(c) for c in cr.list_cases("driver", recurse=False, out_stream=None)]
    assert len(rec) == 4
    assert [c.success for c in rec] == [True, False, True, True]
    assert "LayoutError" in rec[1].msg and "out of order" in rec[1].msg
    ok = [c for c in rec if c.success]
    for c in ok:
        assert c.get_val("fea.mass")[0] == pytest.approx(c.get_val("mass.mass")[0], rel=1e-9)
        assert np.isfinite(c.get_val("fea.max_von_mises")[0]) and c.get_val("fea.max_von_mises")[0] > 0
        assert c.get_val("fea.tip_deflection")[0] > 0                  # the lift-like load bends the wing up
    # the design points differ, so do the meshes and results
    assert len({float(c.get_val("n_elements")[0]) for c in ok}) == 3
    np.testing.assert_array_equal(ok[1].get_val("wing:spar_chord"), [0.2, 0.6])
    # the skin was remeshed once for the whole DOE
    assert p.model.mesh.imprint.remesh_stats["misses"] == 1 and p.model.mesh.imprint.remesh_stats["hits"] == 2


# ----------------------------------------------------------------------------- MPI
def _mpi_command():
    exe = shutil.which("mpirun") or shutil.which("mpiexec")
    if exe is None:
        return None, "mpirun not found (apt-get install -y openmpi-bin libopenmpi-dev)"
    if importlib.util.find_spec("mpi4py") is None:
        return None, 'mpi4py is not installed (pip install -e ".[mpi]")'
    cmd = [exe, "-n", "2"]
    ver = subprocess.run([exe, "--version"], capture_output=True, text=True).stdout
    if "Open MPI" in ver or "OpenRTE" in ver:
        cmd.append("--oversubscribe")                  # 2 processes on a machine that may have fewer cores
    return cmd, ""


_NAMES_SCRIPT = """
import sys
import openmdao.api as om
from openmdao.utils.mpi import MPI
from shellmesh_mdao.components.group import DOEDriver, OneProcessModelVector
comm = MPI.COMM_WORLD if MPI is not None else None
p = om.Problem(comm=comm, reports=False)
p.model.add_subsystem("c", om.ExecComp("y = x ** 2"), promotes=["*"])
p.model.add_design_var("x", lower=0.0, upper=1.0)
p.model.add_objective("y")
p.driver = DOEDriver(om.ListGenerator([[("x", 0.1 * i)] for i in range(5)]))
if comm is not None and comm.size > 1:
    p.driver.options["run_parallel"] = True
    p.driver.options["procs_per_model"] = 1
p.driver.add_recorder(om.SqliteRecorder(sys.argv[1]))
p.setup(distributed_vector_class=OneProcessModelVector) if comm is not None and comm.size > 1 else p.setup()
p.run_driver()
p.cleanup()
# one file per process: two processes' prints to one pipe can interleave within a line
with open(f"local_cases_{comm.rank if comm is not None else 0}.txt", "w") as f:
    f.write(str(p.driver.iter_count))
"""


def _recorded_names(files, meta=None) -> dict:
    """case name -> recorded x of every driver case in the files."""
    out = {}
    for f in files:
        cr = om.CaseReader(str(f), metadata_filename=str(meta) if meta is not None else None)
        for name in cr.list_cases("driver", recurse=False, out_stream=None):
            assert name not in out, f"case name {name} recorded twice"
            out[name] = float(cr.get_case(name).get_val("x")[0])
    return out


def test_doe_case_names_serial(tmp_path):
    """Serially, DOEDriver keeps OpenMDAO's case names: rank0:<driver>|i, i the case's index."""
    script = tmp_path / "names.py"
    script.write_text(_NAMES_SCRIPT)
    env = {**os.environ, "OPENMDAO_WORKDIR": str(tmp_path),
           "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, str(script), "cases.sql"], capture_output=True, text=True, env=env,
                       timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    names = _recorded_names(tmp_path.rglob("cases.sql"))
    assert names == {f"rank0:DOEDriver_List|{i}": pytest.approx(0.1 * i) for i in range(5)}


def test_doe_case_names_unique_across_ranks(tmp_path):
    """Under mpirun -n 2 each process records its own cases; the names are unique across the two
    files (rank of the process, index of the case in the whole design) and name the right case
    (OpenMDAO alone names both files' cases rank0:...|0, |1, ...)."""
    mpi, why = _mpi_command()
    if mpi is None:
        pytest.skip(why)
    script = tmp_path / "names.py"
    script.write_text(_NAMES_SCRIPT)
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OPENMDAO_WORKDIR": str(tmp_path),
           "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([*mpi, sys.executable, str(script), "cases.sql"], capture_output=True, text=True, env=env,
                       timeout=300, cwd=tmp_path)
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-3000:])
    assert sorted(int(f.read_text()) for f in tmp_path.glob("local_cases_*.txt")) == [2, 3]
    files = sorted(tmp_path.rglob("cases.sql_[0-9]"))
    assert len(files) == 2
    meta = next(tmp_path.rglob("cases.sql_meta"))
    names = _recorded_names(files, meta)
    # case i of the design ran on rank i % 2 and carries x = 0.1 i
    assert names == {f"rank{i % 2}:DOEDriver_List|{i}": pytest.approx(0.1 * i) for i in range(5)}


#: recorded wall times: they differ between runs
TIMINGS = ("ccx_seconds", "morph_seconds")


@pytest.mark.slow
@needs_ccx
@pytest.mark.parametrize("morph", [False, True], ids=["remesh", "morph"])
def test_doe_serial_and_mpi_record_identical_outputs(tmp_path, morph):
    """The script serially and on two processes records the same cases exactly (with --morph: every case a
    morph of the same reference mesh, whichever process runs it, or a new mesh where the morph misses
    its checks)."""
    mpi, why = _mpi_command()
    if mpi is None:
        pytest.skip(why)
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OPENMDAO_WORKDIR": str(tmp_path)}
    args = ["--cases", "4", "--no-plot"] + (["--morph", "--scale", "0.25"] if morph else [])
    serial = subprocess.run([sys.executable, str(DOE_SCRIPT), *args, "--out-dir", str(tmp_path / "serial")],
                            capture_output=True, text=True, env=env, timeout=900)
    assert serial.returncode == 0, serial.stderr[-3000:]
    par = subprocess.run([*mpi, sys.executable, str(DOE_SCRIPT), *args, "--parallel",
                          "--out-dir", str(tmp_path / "parallel")],
                         capture_output=True, text=True, env=env, timeout=900)
    assert par.returncode == 0, (par.stdout[-2000:], par.stderr[-3000:])
    # the script's summaries: every recorded case, read back from the recorder files, sorted by design
    # point (floats written by json as repr, read back exactly)
    ser, par = (json.loads((tmp_path / d / "doe_summary.json").read_text()) for d in ("serial", "parallel"))
    assert (tmp_path / "parallel" / "doe_cases.sql_1").is_file()      # really two recording processes
    assert par["processes"] == 2 and len(par["records"]) == 2 and len(ser["records"]) == 1
    a, b = ([{k: v for k, v in c.items() if k not in TIMINGS} for c in s["case_list"]] for s in (ser, par))
    assert len(a) == len(b) == 4 and all(c["success"] for c in a)
    assert a == b                                                       # identical recorded outputs, exactly
    assert all(c["ccx_seconds"][0] > 0 for c in ser["case_list"])
    if morph:
        # a morphed case has the reference's elements; the summary counts the cases meshed anew
        ref = run_pipeline(SURFACE, LAYOUT, SIZE, progress=False).mesh
        morphed = [c for c in a if c["remeshed"] == [0.0]]
        assert morphed and all(c["n_elements"] == [float(ref.n_faces)] for c in morphed)
        assert ser["morph_summary"]["remeshed"] == len(a) - len(morphed)
        assert all(c["morph_seconds"][0] > 0 for c in ser["case_list"])
