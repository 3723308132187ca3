"""Solve time against building size: the same MPCs on the testbed corridor floor.

Run from the repository root::

    python -m mpc_examples.scaling                   # 7 (Pugh Hall) and 50 zones
    python -m mpc_examples.scaling --zones 7 20 50 --hours 3

For each size, a short receding-horizon run starting at 06:00 on a weekday (warm-up and
occupancy: the hardest part of the day for the solver) with the *true* model inside the MPC
(structure identification of a 50-zone floor needs 52+ days of data; the solve time does
not depend on where the parameters came from), full and reduced to a few states per zone
(:func:`mpc_examples.model.reduced_model`). Prints and saves a table: states, decision
variables, build time, solve time median / max (wall) and median CPU time, iterations.
Wall times include whatever else runs on the machine; CPU time is the process's own
(single-threaded, so set ``OMP_NUM_THREADS=1``).
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

import numpy as np
import pandas as pd

from .common import format_table
from .model import controller_model, reduced_model
from .simulator import make_scenario, run_mpc

__all__ = ["main"]


def _measure(kind, zones, per_zone, args):
    scn = make_scenario(zones, args.seed, args.hours, args.horizon, start_day=3,
                        start_hour=args.start_hour)  # day 3 of the default start = a Monday
    model = controller_model(scn.tb, "true")
    if per_zone:
        model = reduced_model(scn.tb, model, per_zone * model.network.n_zones)
    N = int(round(args.horizon * 60.0 / args.step))
    t0 = time.perf_counter()
    if kind == "economic":
        from .economic_mpc import EconomicMPC
        mpc = EconomicMPC(model, scn.hvac, scn.comfort_zones, dt=args.step * 60.0, horizon=N)
    else:
        from .linear_mpc import LinearMPC
        mpc = LinearMPC(model, scn.hvac, scn.comfort_zones, dt=args.step * 60.0, horizon=N)
    build = time.perf_counter() - t0
    its = []
    solve = mpc.solve

    def counted(x0, fc):
        sol = solve(x0, fc)
        its.append(sol.iterations)
        return sol

    mpc.solve = counted
    res = run_mpc(scn, mpc, model, kind)
    st, ct = np.asarray(res.solve_time), np.asarray(res.cpu_time)
    return {"MPC": kind, "zones": len(scn.tb.network.zones), "states": model.network.n_states,
            "variables": getattr(mpc, "n_variables", np.nan), "build [s]": build,
            "solve median [s]": float(np.median(st)), "solve max [s]": float(st.max()),
            "CPU median [s]": float(np.median(ct)), "iterations median": float(np.median(its)),
            "solves": len(st), "failures": res.failures}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--zones", type=int, nargs="+", default=[7, 50])
    p.add_argument("--mpc", nargs="+", choices=["economic", "linear"], default=["economic", "linear"])
    p.add_argument("--hours", type=float, default=2.0, help="closed-loop length per size [h]")
    p.add_argument("--start-hour", type=float, default=6.0)
    p.add_argument("--step", type=float, default=15.0, help="MPC step [min]")
    p.add_argument("--horizon", type=float, default=6.0, help="prediction horizon [h]")
    p.add_argument("--per-zone", type=int, nargs="+", default=[0, 3],
                   help="states per zone of the MPC's model: 0 = the full model, k = structure-"
                        "preserving reduction to k·n_zones states")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("mpc-output"))
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    rows = []
    for z in args.zones:
        for per_zone in args.per_zone:
            for kind in args.mpc:
                rows.append(_measure(kind, z, per_zone, args))
                r = rows[-1]
                print(f"  {kind}, {r['zones']} zones, {r['states']} states: median "
                      f"{r['solve median [s]']:.3f} s", flush=True)
    df = pd.DataFrame(rows).set_index("MPC")
    print(format_table(df))
    args.out.mkdir(parents=True, exist_ok=True)
    df.to_csv(args.out / "scaling.csv")
    (args.out / "scaling.txt").write_text(format_table(df) + "\n")
    return df


if __name__ == "__main__":
    main()
