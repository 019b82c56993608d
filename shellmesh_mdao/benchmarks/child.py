"""A function call in a fresh child process, with a time limit: a hang or a crash is a result.

The benchmark and the stress sweep run every case through :func:`run_in_child`: each in a new
process started with ``multiprocessing``'s "spawn" method, so a case that hangs (it is killed at
the time limit) or crashes (Gmsh, a segfault) is recorded instead of stopping the run, and the
peak resident memory of each case (``ru_maxrss`` of its child) is its own. The function run must
be importable by module name in the child (a module-level function of an installed module).
"""
from __future__ import annotations

import multiprocessing as mp
import resource
import time
import traceback

__all__ = ["run_in_child", "failing_stage", "classify_case"]


def _child(conn, fn, args, kwargs):
    try:
        out = fn(*args, **kwargs)
        out["status"] = "ok"
    except BaseException as e:  # noqa: BLE001 -- report any failure of the case, never raise
        out = {"status": "error", "error": f"{type(e).__name__}: {e}"}
    ru = resource.getrusage(resource.RUSAGE_SELF)
    out["peak_rss_mb"] = ru.ru_maxrss / 1024.0         # Linux: kilobytes
    out["child_cpu_s"] = ru.ru_utime + ru.ru_stime
    conn.send(out)
    conn.close()


def run_in_child(fn, *args, timeout: float = 3600.0, **kwargs) -> dict:
    """Call ``fn(*args, **kwargs)`` (module-level, returning a dict) in a fresh spawned process
    with a time limit. Returns its dict with ``status`` "ok", ``peak_rss_mb`` (peak resident
    memory of the child, imports included) and ``child_cpu_s``; or ``{"status": "error",
    "error": ...}`` when it raised, ``"timeout"`` when it ran over ``timeout`` seconds (it is
    killed), ``"crashed"`` when the process died (``exit_code``)."""
    ctx = mp.get_context("spawn")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, fn, args, kwargs), daemon=True)
    t0 = time.perf_counter()
    proc.start()
    send.close()
    out = None
    if recv.poll(timeout):
        try:
            out = recv.recv()
        except EOFError:
            out = None
    elapsed = time.perf_counter() - t0
    proc.join(10 if out is not None else 0.5)
    if proc.is_alive():
        proc.kill()
        proc.join()
    recv.close()
    if out is None:
        if elapsed >= timeout:
            out = {"status": "timeout", "error": f"no result after {timeout:g} s (killed)"}
        else:
            out = {"status": "crashed", "exit_code": proc.exitcode,
                   "error": f"child process died (exit code {proc.exitcode})"}
    out["process_wall_s"] = elapsed
    return out


def failing_stage(tb, default: str = "") -> str:
    """Name of the innermost ``stage_<name>`` pipeline function a traceback ``tb`` went through (the
    stage that failed), or ``default`` when it went through none."""
    stage = default
    while tb is not None:
        name = tb.tb_frame.f_code.co_name
        if name.startswith("stage_"):
            stage = name[len("stage_"):]
        tb = tb.tb_next
    return stage


def classify_case(out: dict, run) -> dict:
    """Run one harness case and classify it into ``out``; never raises. ``run(out)`` builds the
    case (setting ``out["stage"]`` while it prepares it, and any keys of its own) and returns the
    pipeline's result, run with ``check=False``. ``out["outcome"]``: **ok** (every guarantee of
    :func:`~shellmesh_mdao.guarantees.check_guarantees` holds; ``min_sj``), **guarantee** (meshed,
    one missed), **refused** (a :class:`~shellmesh_mdao.errors.ShellMeshError`) or **crash**
    (anything else; ``traceback``), with ``error``, ``stage``, ``n_elements`` and ``seconds``."""
    from ..errors import MeshValidationError, ShellMeshError
    from ..guarantees import check_guarantees

    out.update(outcome="crash", error="", stage="")
    t0 = time.perf_counter()
    try:
        res = run(out)
        out["n_elements"] = int(res.mesh.n_faces)
        try:
            out["min_sj"] = float(check_guarantees(res)["min_scaled_jacobian"])
            out["outcome"] = "ok"
        except MeshValidationError as e:
            out["outcome"], out["stage"], out["error"] = "guarantee", "guarantees", str(e)
    except ShellMeshError as e:
        out["outcome"], out["error"] = "refused", f"{type(e).__name__}: {e}"
        out["stage"] = failing_stage(e.__traceback__) or out["stage"]
    except Exception as e:  # noqa: BLE001 -- any other exception is a crash, recorded
        out["outcome"], out["error"] = "crash", f"{type(e).__name__}: {e}"
        out["stage"] = failing_stage(e.__traceback__, out["stage"])
        out["traceback"] = traceback.format_exc()[-3000:]
    out["seconds"] = round(time.perf_counter() - t0, 1)
    return out
