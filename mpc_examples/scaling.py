"""Solve time against building size: the MPCs on Pugh Hall (7 zones) and the corridor floor.

Run from the repository root::

    python -m mpc_examples.scaling                          # 7, 50 and 200 zones
    python -m mpc_examples.scaling --zones 7 50 --mpc linear --hours 1

For each size, a short receding-horizon run from 06:00 on a Monday (warm-up and occupancy:
the hardest part of the day for the solver) with the testbed's *true* model inside the MPC
(the solve time does not depend on where the parameters came from) and the plant's true
state fed back (no estimator: a Kalman filter on 2 348 states would dominate the loop and
measure nothing about the MPC). Every size is run; nothing is skipped above a state count.
For each model and form the table gives the states, decision variables, stored nonzeros of
the QP (H and A) or of the NLP's constraint Jacobian and Lagrangian Hessian, build time,
solve time median / max (wall) and median CPU time, and failures.

Models: ``full`` (the network as it is), ``no-conv`` (convection-edge states eliminated
by singular perturbation, :func:`mpc_examples.sparse.eliminate_fast_edges`: as sparse as
the full model) and ``structured k/zone`` (:func:`thermctl.reduce.structured`, dense edge
modes); the reductions' step-response errors are printed with the table. Forms: for the
linear MPC ``zoh`` (dense exported ``A_k``), ``euler`` and ``radau`` (sparse implicit
rows), each with the QP solvers asked for; for the economic NMPC the implicit Radau gaps
(sparse) and IPOPT with MUMPS. A dense form whose QP would hold more than
``--max-dense-nnz`` nonzeros is listed with that count and not built (the 200-zone ZOH
QP: 36 · 2 348² ≈ 2·10⁸ nonzeros, 1.6 GB of values alone).

``--grid`` gives both MPCs a non-uniform prediction grid (:class:`LinearMPC` and
:class:`EconomicMPC` ``steps``): fine steps first, where the applied input is decided, long
ones after; the forms are then labelled e.g. ``euler 6x10+10x30min``. ``--rti`` runs the
economic NMPC once per value: 0 converges IPOPT every step, ``k`` stops it after ``k``
iterations from the shifted previous solution (real-time iteration; solver ``ipopt rti k``).
The first solve of a run is always cold and converged; ``first [s]`` is its wall time and
``max after first [s]`` the largest wall time of the steps after it.

Wall times include whatever else runs on the machine; CPU time is the process's own
(single-threaded: set ``OMP_NUM_THREADS=1``).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import time
from pathlib import Path

import numpy as np
import pandas as pd

from .common import format_table
from .economic_mpc import EconomicMPC
from .linear_mpc import LinearMPC
from .model import min_flow_point
from .simulator import box_inputs, make_scenario
from .sparse import eliminate_fast_edges

__all__ = ["main", "state_feedback_run"]

log = logging.getLogger(__name__)


def state_feedback_run(scn, mpc, to_model_state, n_solves: int):
    """``n_solves`` receding-horizon steps on a fresh plant with its true state fed back.

    Returns
    -------
    wall, cpu : ndarray, shape (n_solves,)
        Solve times [s].
    failures : int
    """
    plant = scn.plant()
    every = int(round(mpc.dt / scn.dt))   # plant steps per control step (the grid's first)
    steps = getattr(mpc, "steps", None)    # a LinearMPC's non-uniform prediction grid
    sup = scn.hvac.supplied
    nz = len(scn.tb.network.zones)
    wall, cpu, fails = [], [], 0
    for j in range(n_solves):
        meas = plant.measure()
        fc = scn.forecast(j * every, mpc.N, every, np.zeros(nz), meas.T_ahu, steps=steps)
        sol = mpc.solve(to_model_state(plant.x), fc)
        wall.append(sol.solve_time)
        cpu.append(sol.cpu_time)
        fails += not sol.success
        ms, Ts = box_inputs(sol.ms[0], sol.Ts[0], sup, meas.T_ahu)
        for _ in range(every):
            plant.step(ms, Ts)
    return np.asarray(wall), np.asarray(cpu), fails


def _models(scn, per_zone, log_errors):
    """``[(name, model, to_model_state, info)]`` for the full and reduced models."""
    tb = scn.tb
    full = tb.model
    net = full.network
    op = min_flow_point(tb, full)
    out = [("full", full, lambda x: x, {})]
    rnet, info = eliminate_fast_edges(full, op)
    out.append(("no-conv", rnet, rnet.from_full_state, info))
    for k in per_zone:
        from thermctl.reduce import Reference, linearize, structured
        t0 = time.perf_counter()
        red = structured(full, op, order=k * net.n_zones, design_ms=[0.0])
        info = {"states": (net.n_states, red.network.n_states), "time [s]": time.perf_counter() - t0}
        if net.n_states <= 800:
            err = Reference(linearize(full, op)).step_error(red.sys)
            info["step error"] = dict(zip((f"{t / 3600:g} h" for t in err.times),
                                          (float(v) for v in err.rel)))
        out.append((f"structured {k}/zone", red.network, red.network.from_full_state, info))
    for name, _, _, info in out[1:]:
        log_errors.append((len(net.zones), name, info))
    return out


def _row(kind, form, solver, zones, name, model, **kw):
    r = {"MPC": kind, "zones": zones, "model": name, "states": model.network.n_states,
         "form": form, "solver": solver, "variables": np.nan, "nonzeros": np.nan,
         "build [s]": np.nan, "solve median [s]": np.nan, "solve max [s]": np.nan,
         "CPU median [s]": np.nan, "first [s]": np.nan, "max after first [s]": np.nan,
         "solves": 0, "failures": 0, "note": ""}
    r.update(kw)
    return r


def parse_grid(spec, step: float, horizon: float):
    """Step multiples of a prediction grid from ``"3x1 11x3"`` (three steps of 1·``step``,
    then eleven of 3·``step``); ``None`` or ``"uniform"``: all 1. Must sum to the horizon.

    Parameters
    ----------
    spec : str or None
    step : float
        Control step [min].
    horizon : float
        [h]
    """
    n = int(round(horizon * 60.0 / step))
    if spec in (None, "", "uniform"):
        return None
    steps = []
    for part in spec.replace(",", " ").split():
        k, _, m = part.partition("x")
        steps += [int(m)] * int(k) if m else [int(k)]
    if sum(steps) != n:
        raise ValueError(f"grid {spec!r} covers {sum(steps)} steps of {step:g} min, the "
                         f"horizon {n}")
    return steps


def _grid_label(steps, step):
    """``"3x10+11x30min"`` for ``[1, 1, 1, 3, ..., 3]`` at a 10-min step."""
    out, k = [], 0
    while k < len(steps):
        j = k
        while j < len(steps) and steps[j] == steps[k]:
            j += 1
        out.append(f"{j - k}x{steps[k] * step:g}")
        k = j
    return "+".join(out) + "min"


def _measure(kind, form, solver, scn, name, model, to_x, args, rti=None):
    steps = parse_grid(args.grid, args.step, args.horizon)
    N = int(round(args.horizon * 60.0 / args.step)) if steps is None else len(steps)
    zones = len(scn.tb.network.zones)
    nx = model.network.n_states
    if steps is not None:
        form = f"{form} {_grid_label(steps, args.step)}"
    if kind == "linear" and form.split()[0] == "zoh" and N * nx * nx > args.max_dense_nnz:
        nnz = N * nx * nx
        return _row(kind, form, solver, zones, name, model, nonzeros=float(nnz),
                    note=f"not built: dense A_k, {nnz / 1e6:.0f} M nonzeros")
    t0 = time.perf_counter()
    if kind == "linear":
        mpc = LinearMPC(model, scn.hvac, scn.comfort_zones, dt=args.step * 60.0, horizon=N,
                        solver=solver, transcription=form.split()[0], steps=steps)
    else:
        mpc = EconomicMPC(model, scn.hvac, scn.comfort_zones, dt=args.step * 60.0, horizon=N,
                          transcription=form.split()[0], steps=steps, rti_iter=rti or None,
                          rti_method=solver.split()[0] if rti else "sqp")
    build = time.perf_counter() - t0
    n_solves = args.solves if nx <= 1000 else args.solves_large
    wall, cpu, fails = state_feedback_run(scn, mpc, to_x, n_solves)
    if kind == "linear":
        build = mpc.build_time   # the constructor and the first QP's solver
        nnz = mpc.n_nonzeros
    else:
        nnz = mpc.n_nonzeros
    return _row(kind, form, solver, zones, name, model, variables=float(mpc.n_variables),
                nonzeros=np.nan if nnz is None else float(nnz), **{"build [s]": build,
                                       "solve median [s]": float(np.median(wall)),
                                       "solve max [s]": float(wall.max()),
                                       "CPU median [s]": float(np.median(cpu)),
                                       "first [s]": float(wall[0]),
                                       "max after first [s]": (float(wall[1:].max())
                                                               if len(wall) > 1 else np.nan),
                                       "solves": len(wall), "failures": fails})


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--zones", type=int, nargs="+", default=[7, 50, 200])
    p.add_argument("--mpc", nargs="+", choices=["economic", "linear"], default=["linear", "economic"])
    p.add_argument("--forms", nargs="+", default=["zoh", "euler", "radau"],
                   help="linear MPC transcriptions (mpc_examples.sparse.TRANSCRIPTIONS)")
    p.add_argument("--solvers", nargs="+", default=["piqp", "osqp"],
                   help="casadi.conic plugins for the linear MPC's sparse forms")
    p.add_argument("--models", nargs="+", default=["full", "no-conv", "structured 3/zone"],
                   help="which of the models below to run")
    p.add_argument("--economic-max-zones", type=int, default=50,
                   help="run the economic NMPC up to this size (its target is 50 zones)")
    p.add_argument("--solves", type=int, default=6, help="MPC steps per run")
    p.add_argument("--solves-large", type=int, default=2,
                   help="MPC steps per run for models above 1000 states (the 200-zone floor)")
    p.add_argument("--osqp-max-states", type=int, default=100,
                   help="run OSQP only up to this many states (51 s CPU for one QP of the "
                        "50-zone floor, measured: ADMM needs thousands of iterations here)")
    p.add_argument("--start-hour", type=float, default=6.0)
    p.add_argument("--step", type=float, default=10.0, help="MPC step [min]")
    p.add_argument("--horizon", type=float, default=6.0, help="prediction horizon [h]")
    p.add_argument("--grid", default=None,
                   help="both MPCs: non-uniform prediction grid in multiples of --step, e.g. "
                        "'6x1 10x3' (an hour of 10-min steps, then 30-min steps to 6 h: 16 "
                        "instead of 36 steps); the control step stays --step")
    p.add_argument("--rti", type=int, nargs="+", default=[0],
                   help="economic NMPC: real-time iterations per step after the first solve, "
                        "one run per value (0: converge every step)")
    p.add_argument("--rti-method", choices=["sqp", "ipopt"], default="sqp",
                   help="economic NMPC's real-time iteration: SQP steps with a convex QP "
                        "(PIQP) or IPOPT stopped after k iterations")
    p.add_argument("--economic-forms", nargs="+", default=["implicit"],
                   choices=["implicit", "euler", "explicit"],
                   help="economic NMPC step rows (mpc_examples.economic_mpc.TRANSCRIPTIONS)")
    p.add_argument("--per-zone", type=int, nargs="*", default=[3],
                   help="states per zone of the structured reductions")
    p.add_argument("--max-dense-nnz", type=float, default=2e7,
                   help="list, do not build, a dense (zoh) QP with more nonzeros")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("mpc-output"))
    p.add_argument("--save", type=Path, default=None,
                   help="also write the table here (e.g. benchmarks/results/mpc_scaling.txt)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    rows, errors = [], []
    args.out.mkdir(parents=True, exist_ok=True)
    for z in args.zones:
        hours = (max(args.solves, args.solves_large) + 1) * args.step / 60.0
        scn = make_scenario(z, args.seed, hours, args.horizon, start_day=3,
                            start_hour=args.start_hour)  # day 3 from 2011-01-21: a Monday
        for name, model, to_x, _ in _models(scn, args.per_zone, errors):
            if name not in args.models:
                continue
            jobs = []
            if "linear" in args.mpc:
                for form in args.forms:
                    for solver in (args.solvers if form != "zoh" else args.solvers[:1]):
                        if solver == "osqp" and model.network.n_states > args.osqp_max_states:
                            continue
                        jobs.append(("linear", form, solver))
            if "economic" in args.mpc and z <= args.economic_max_zones:
                jobs += [("economic", form, f"{args.rti_method} rti {k}" if k else "ipopt")
                         for form in args.economic_forms for k in args.rti]
            for kind, form, solver in jobs:
                try:
                    rti = int(solver.split()[-1]) if " rti " in solver else None
                    rows.append(_measure(kind, form, solver, scn, name, model, to_x, args, rti))
                except MemoryError as exc:   # report, do not hide
                    rows.append(_row(kind, form, solver, z, name, model, note=f"failed: {exc!r}"))
                r = rows[-1]
                print(f"  {kind} {form} {solver}, {r['zones']} zones, {name} ({r['states']} "
                      f"states, {r['variables']:.0f} variables, {r['nonzeros']:.0f} nonzeros): "
                      f"build {r['build [s]']:.2f} s, median {r['solve median [s]']:.3f} s, "
                      f"max {r['solve max [s]']:.3f} s, CPU median {r['CPU median [s]']:.3f} s, "
                      f"first {r['first [s]']:.3f} s, max after first {r['max after first [s]']:.3f} s, "
                      f"failures {r['failures']} {r['note']}", flush=True)
                # the table so far, in case a long run is stopped
                pd.DataFrame(rows).set_index("MPC").to_csv(args.out / "scaling.partial.csv")
    df = pd.DataFrame(rows).set_index("MPC")
    text = format_table(df)
    err_lines = ["", "reductions (step-response error, relative, of the linearization at the "
                 "boxes' minimum flows):"]
    for z, name, info in errors:
        se = info.get("step error")
        se = ", ".join(f"{k} {v:.2%}" for k, v in se.items()) if se else "not measured (> 800 states)"
        err_lines.append(f"  {z} zones, {name}: {info['states'][0]} -> {info['states'][1]} "
                         f"states in {info['time [s]']:.1f} s; {se}")
    text = text + "\n" + "\n".join(err_lines)
    load = os.getloadavg()
    text += (f"\nload average (1/5/15 min) at the end: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} "
             f"({os.cpu_count()} cores)")
    print(text)
    args.out.mkdir(parents=True, exist_ok=True)
    df.to_csv(args.out / "scaling.csv")
    (args.out / "scaling.txt").write_text(text + "\n")
    if args.save:
        args.save.parent.mkdir(parents=True, exist_ok=True)
        args.save.write_text(text + "\n")
    return df


if __name__ == "__main__":
    main()
