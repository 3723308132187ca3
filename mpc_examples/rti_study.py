"""What real-time iteration and a coarse prediction tail cost the economic NMPC in control.

Run from the repository root::

    python -m mpc_examples.rti_study --zones 7 --hours 4 --rti 0 1 2 3 --grid uniform "6x1 5x6"
    python -m mpc_examples.rti_study --zones 7 --hours 4 --rti 0 1 3 --method sqp ipopt
    python -m mpc_examples.rti_study --zones 50 --hours 2 --rti 0 2 --grid "6x1 5x6"

For each prediction grid one :class:`~mpc_examples.economic_mpc.EconomicMPC` is built on the
testbed's *true* model (build time reported once per grid) and run in closed loop
(:func:`mpc_examples.simulator.run_mpc`: Kalman filter, 48 h of log replayed, the comfort
band narrowed by the 0.35 K back-off) from ``--start-hour`` on a Monday, once per
``--rti`` value: 0 converges IPOPT at every step, ``k > 0`` takes ``k`` iterations from the
shifted previous primal-dual solution (real-time iteration), by ``--method``: ``sqp`` (the
default: SQP steps, each a convex QP with a Gauss-Newton Hessian solved by PIQP) or
``ipopt`` (IPOPT stopped after ``k`` iterations). The
first solve of every run is cold and converged (no previous solution to shift), so it is
reported apart from the steps after it.

``--shadow``: at every step of a real-time-iteration run, a second controller of the same
grid also converges from the same state and forecast (cold start, so it never sees the RTI
iterate); the table then gives the largest difference of the applied (first) input, flow
[g/s] and supply temperature [K], over the run. It doubles the run's cost at least.

Times: wall (``time.perf_counter``) and CPU of this process (``time.process_time``) per
solve; the machine's load (``os.getloadavg``) is printed with the table.
"""

from __future__ import annotations

import argparse
import logging
import os
import time
from pathlib import Path

import numpy as np

from .common import kpis
from .economic_mpc import EconomicMPC
from .scaling import _grid_label, parse_grid
from .simulator import make_scenario, run_mpc

__all__ = ["main", "ShadowedMPC"]

log = logging.getLogger(__name__)


class ShadowedMPC:
    """An MPC whose every solve is also done, converged, by a second controller.

    Parameters
    ----------
    mpc : EconomicMPC
        The controller that acts (e.g. real-time iteration).
    reference : EconomicMPC
        Same grid, ``rti_iter=None``; solved cold at every step.

    Attributes
    ----------
    d_ms : list of float
        Per step, the largest difference of the first supply flow [kg/s] over the boxes.
    d_Ts : list of float
        The same for the supply temperature [K], where the reference flow is above 1 g/s
        (a temperature without air is not an input).
    """

    def __init__(self, mpc, reference):
        self.mpc, self.reference = mpc, reference
        self.dt, self.N, self.steps = mpc.dt, mpc.N, mpc.steps
        self.d_ms, self.d_Ts = [], []

    def solve(self, x0, fc):
        sol = self.mpc.solve(x0, fc)
        self.reference.reset()
        ref = self.reference.solve(x0, fc)
        sup = self.mpc.sup
        self.d_ms.append(float(np.max(np.abs(sol.ms[0, sup] - ref.ms[0, sup]))))
        air = ref.ms[0, sup] > 1e-3
        self.d_Ts.append(float(np.max(np.abs(sol.Ts[0, sup] - ref.Ts[0, sup])[air], initial=0.0)))
        return sol


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--zones", type=int, default=7)
    p.add_argument("--hours", type=float, default=4.0, help="closed-loop length [h]")
    p.add_argument("--start-hour", type=float, default=5.0,
                   help="start on Monday (day 3 of the testbed run) at this hour [h]")
    p.add_argument("--step", type=float, default=10.0, help="MPC step [min]")
    p.add_argument("--horizon", type=float, default=6.0, help="prediction horizon [h]")
    p.add_argument("--grid", nargs="+", default=["uniform", "6x1 5x6"],
                   help="prediction grids in multiples of --step ('uniform': all 1)")
    p.add_argument("--rti", type=int, nargs="+", default=[0, 1, 2, 3],
                   help="IPOPT iterations per step after the first (0: converge)")
    p.add_argument("--transcription", choices=["implicit", "euler"], default="implicit",
                   help="the economic MPC's step rows: Radau (default) or implicit Euler")
    p.add_argument("--method", nargs="+", choices=["sqp", "ipopt"], default=["sqp"],
                   help="real-time iteration: SQP steps with a convex QP (PIQP; default) and/or "
                        "IPOPT stopped after k iterations")
    p.add_argument("--shadow", action="store_true",
                   help="also converge every RTI step from the same state (first-input error)")
    p.add_argument("--warmup", type=float, default=48.0, help="hours of log the filter replays")
    p.add_argument("--seed", type=int, default=0, help="testbed seed")
    p.add_argument("--save", type=Path, default=None, help="also write the table here")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    scn = make_scenario(args.zones, args.seed, args.hours, args.horizon, start_day=3,
                        start_hour=args.start_hour)   # day 3 from 2011-01-21: a Monday
    model = scn.tb.model
    n_uniform = int(round(args.horizon * 60.0 / args.step))
    head = (f"{scn.tb.spec.name}: {len(model.network.zones)} zones, {model.network.n_states} "
            f"states, true model; closed loop from {scn.start:%a %Y-%m-%d %H:%M} for "
            f"{args.hours:g} h, step {args.step:g} min, horizon {args.horizon:g} h")
    print(head, flush=True)
    lines = []
    for spec in args.grid:
        steps = parse_grid(spec, args.step, args.horizon)
        N = n_uniform if steps is None else len(steps)
        label = ("uniform" if steps is None else _grid_label(steps, args.step)) + (
            ", Euler" if args.transcription == "euler" else "")
        t0, c0 = time.perf_counter(), time.process_time()
        mpc = EconomicMPC(model, scn.hvac, scn.comfort_zones, dt=args.step * 60.0, horizon=N,
                          steps=steps, transcription=args.transcription)
        build = (time.perf_counter() - t0, time.process_time() - c0)
        ref = None
        if args.shadow and any(args.rti):
            ref = EconomicMPC(model, scn.hvac, scn.comfort_zones, dt=args.step * 60.0,
                              horizon=N, steps=steps, transcription=args.transcription)
        print(f"grid {label}: N={N}, {mpc.n_variables} variables, {mpc.n_nonzeros} nonzeros "
              f"(Jacobian + Hessian); build {build[0]:.1f} s wall, {build[1]:.1f} s CPU",
              flush=True)
        runs = [(k, m) for k in args.rti for m in (args.method if k else [None])]
        for k, method in runs:
            mpc.reset()
            mpc.rti_iter = k or None
            mpc.rti_method = method or mpc.rti_method
            ctrl = ShadowedMPC(mpc, ref) if (ref is not None and k) else mpc
            name = f"{label}, {'converged' if not k else f'RTI {k} it {method}'}"
            res = run_mpc(scn, ctrl, model, name, warmup_hours=args.warmup)
            kp = kpis(res, scn.hvac, scn.band, scn.comfort_zones)
            w, c = np.asarray(res.solve_time), np.asarray(res.cpu_time)
            row = {"run": name, "site energy [kWh]": kp["site energy [kWh]"],
                   "discomfort [K·h]": kp["discomfort [K·h]"],
                   "max violation [K]": kp["max violation [K]"],
                   "first wall [s]": w[0], "first CPU [s]": c[0],
                   "median wall [s]": float(np.median(w[1:])) if w.size > 1 else np.nan,
                   "max wall [s]": float(np.max(w[1:])) if w.size > 1 else np.nan,
                   "median CPU [s]": float(np.median(c[1:])) if c.size > 1 else np.nan,
                   "max CPU [s]": float(np.max(c[1:])) if c.size > 1 else np.nan,
                   "steps": w.size, "failures": res.failures}
            if ctrl is not mpc:
                row["first input vs converged"] = (f"flow {1e3 * max(ctrl.d_ms):.2g} g/s, "
                                                   f"supply {max(ctrl.d_Ts):.2g} K")
            line = (f"  {name:<34} {row['site energy [kWh]']:9.4f} kWh  "
                    f"{row['discomfort [K·h]']:6.3f} K·h  max {row['max violation [K]']:5.3f} K  "
                    f"first {w[0]:7.2f} s ({c[0]:6.2f} CPU)  after: median "
                    f"{row['median wall [s]']:6.3f} s, max {row['max wall [s]']:6.3f} s, "
                    f"CPU median {row['median CPU [s]']:6.3f} s, max {row['max CPU [s]']:6.3f} s; "
                    f"{w.size} steps, {res.failures} failures")
            if "first input vs converged" in row:
                line += "; first input vs converged: " + row["first input vs converged"]
            print(line, flush=True)
            lines.append(line)
        lines.insert(len(lines) - len(runs),
                     f"grid {label}: N={N}, {mpc.n_variables} variables, {mpc.n_nonzeros} "
                     f"nonzeros; build {build[0]:.1f} s wall, {build[1]:.1f} s CPU")
    load = os.getloadavg()
    tail = f"load average (1/5/15 min) at the end: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}"
    print(tail)
    if args.save:
        args.save.parent.mkdir(parents=True, exist_ok=True)
        with open(args.save, "a") as f:
            f.write("\n".join([head, *lines, tail]) + "\n")
    return lines


if __name__ == "__main__":
    main()
