"""Benchmark of model reduction: states needed for a given step-response error, and time.

For corridor office buildings of about 7, 50 and 200 zones (the testbed's
``corridor_floor_spec``: exterior walls with windows, partitions, corridor walls, slabs,
true air paths; paper values of ``rbar_v`` and ``c_v``), linearized at a design supply flow:

* full states; for each method the states needed (total and per zone) for a 1 % and a
  0.1 % step-response error at 1, 6 and 24 h (headline error of
  :class:`thermctl.reduce.StepError`: scaled inputs — heat per kW, temperatures per K,
  flow per 0.1 kg/s);
* the error at the standard orders (structured 2 states per zone, balanced 3 per zone)
  and the time to reduce at that order, from scratch (no cached eigendecomposition);
* a flow sweep (no flow, minimum, design, maximum): network reductions relinearized at each
  flow, the balanced one frozen at its design flow.

The orders are searched on a grid of states per zone and refined by bisection to
0.1 state per zone (the error is assumed to fall with the order between grid points).

The linear MPC comparison (full vs reduced model inside ``mpc_examples.linear_mpc``) is
the hook :func:`mpc_comparison` (``--mpc``; about 5 minutes for the 7-zone Pugh Hall
section over 12 occupied hours). It belongs to the MPC examples issue, which owns the
scenario and the controller settings.

Usage::

    .venv/bin/python benchmarks/reduce.py                 # 7, 50, 200 zones (several minutes)
    .venv/bin/python benchmarks/reduce.py --sizes 7,50    # quicker

BLAS runs single-threaded (threadpoolctl): on the shared 2-core machine threads only
oversubscribe.
"""

from __future__ import annotations

import argparse
import logging
import time

import pandas as pd
from threadpoolctl import threadpool_limits

from thermctl.model import ThermalModel
from thermctl.network import ThermalNetwork
from thermctl.reduce import (DEFAULT_TIMES, BalancedContext, Reference, StructuredContext,
                             balanced_reduction, flow_sweep, kron, linearize, lumped, structured)
from thermctl.reduce import _lti

SIZES = {7: (3, 1), 50: (24, 1), 200: (25, 4)}  # zones → (offices per side, floors)
GRID = (1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0)  # states per zone searched
TOLS = (0.01, 0.001)
# flows per zone [kg/s]: off, the testbed's VAV minimum (30 % of 0.122), design, maximum
FLOWS = {"off": 0.0, "min": 0.037, "design": 0.06, "max": 0.122}


def building(zones: int):
    """The testbed corridor building with about ``zones`` zones (own generator if absent)."""
    n, floors = SIZES[zones]
    from thermctl.testbed import corridor_floor_spec
    spec, edges = corridor_floor_spec(n, floors=floors, seed=0)
    return ThermalModel(ThermalNetwork(spec, edges))


def design_point(model):
    b = model.network.boundary
    T = {n: (5.0 if n == "outside" else 20.0) for n in b}  # January outdoor, heated space below
    return model.operating_point(ms=FLOWS["design"], Ts=14.0, T=T, Q=200.0)


class OrderSearch:
    """Errors of one method by order, cached; smallest order meeting a tolerance."""

    def __init__(self, make, ref, nz, r_min, r_max):
        self.make, self.ref, self.nz = make, ref, nz
        self.r_min, self.r_max = r_min, r_max
        self.cache = {}

    def err(self, r):
        if r not in self.cache:
            self.cache[r] = self.ref.step_error(self.make(r).sys).rel
        return self.cache[r]

    def needed(self, tol, k):
        """Smallest order with error ≤ tol at time index k (None if above the grid)."""
        grid = sorted({min(self.r_max, max(self.r_min, int(round(g * self.nz)))) for g in GRID})
        prev = None
        for r in grid:
            if self.err(r)[k] <= tol:
                break
            prev = r
        else:
            return None
        if prev is None:
            return r
        lo, hi = prev, r  # lo fails, hi meets
        step = max(1, self.nz // 10)
        while hi - lo > step:
            mid = (lo + hi) // 2
            if self.err(mid)[k] <= tol:
                hi = mid
            else:
                lo = mid
        return hi


def timed(fn):
    _lti._EIG_CACHE.clear()  # time from scratch
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def run_size(zones: int, log):
    model = building(zones)
    net = model.network
    nz, n = net.n_zones, net.n_states
    op = design_point(model)
    log(f"\n=== {net.spec.name}: {nz} zones, {n} states ({n / nz:.1f} per zone), "
        f"{len(net.convection_edges)} air paths ===")
    t0 = time.perf_counter()
    ref = Reference(linearize(model, op), capacitances=model.capacitances())
    ref.steps
    t_ref = time.perf_counter() - t0

    rows, errs = [], []
    # ---- standard orders, timed from scratch ------------------------------------------
    std = {"balanced": lambda: balanced_reduction(model, op, order=3 * nz),
           "truncate": lambda: balanced_reduction(model, op, order=3 * nz, method="truncate"),
           "structured": lambda: structured(model, op, order=2 * nz),
           "kron": lambda: kron(model, op),
           "lumped": lambda: lumped(model, op)}
    reds = {}
    for name, fn in std.items():
        red, dt = timed(fn)
        reds[name] = red
        e = ref.step_error(red.sys).rel
        errs.append({"zones": nz, "method": name, "order": red.order, "per zone": red.order / nz,
                     "time [s]": dt, **{f"err {t / 3600:g} h": f"{100 * v:.3g} %"
                                        for t, v in zip(DEFAULT_TIMES, e)},
                     "bound": red.error_bound})

    # ---- orders needed -------------------------------------------------------------------
    bctx = BalancedContext.build(model, op)
    sctx = StructuredContext(model, op)
    searches = {
        "balanced": OrderSearch(lambda r: bctx.reduction(min(r, bctx.bal.n_min)), ref, nz, 1, bctx.bal.n_min),
        "truncate": OrderSearch(lambda r: bctx.reduction(min(r, bctx.bal.n_min), "truncate"), ref, nz, 1,
                                bctx.bal.n_min),
        "structured": OrderSearch(lambda r: sctx.reduction(r - nz), ref, nz, nz, n),
    }
    for name, s in searches.items():
        row = {"zones": nz, "full": n, "method": name}
        for tol in TOLS:
            for k, t in enumerate(DEFAULT_TIMES):
                r = s.needed(tol, k)
                row[f"{100 * tol:g}% @{t / 3600:g}h"] = "—" if r is None else f"{r} ({r / nz:.2g})"
        rows.append(row)
    for name in ("kron", "lumped"):
        red = reds[name]
        e = ref.step_error(red.sys).rel
        row = {"zones": nz, "full": n, "method": name}
        for tol in TOLS:
            for k, t in enumerate(DEFAULT_TIMES):
                row[f"{100 * tol:g}% @{t / 3600:g}h"] = (f"{red.order} ({red.order / nz:.2g})"
                                                          if e[k] <= tol else "fails")
        rows.append(row)

    # ---- flow sweep ------------------------------------------------------------------------
    multi, _ = timed(lambda: structured(model, op, order=2 * nz, design_ms=[FLOWS["off"], FLOWS["max"]]))
    multi.method = "structured (4 flows)"
    sweep = flow_sweep(model, [reds["structured"], multi, reds["balanced"], reds["lumped"]],
                       list(FLOWS.values()))
    sweep["zones"] = nz
    sweep["flow"] = sweep["flow"].map({v: f"{k} {v:g}" for k, v in FLOWS.items()})
    log(f"reference responses: {t_ref:.1f} s")
    return rows, errs, sweep


def mpc_comparison(zones: int = 7, hours: float = 12.0, start_hour: float = 6.0):
    """HOOK (MPC examples issue): linear MPC with the full and the reduced model.

    ``ReducedNetwork`` answers the ThermalModel interface that ``mpc_examples``' LinearMPC,
    GainKalmanFilter and ``run_mpc`` use (``network``, ``operating_point``,
    ``to_statespace``, ``matrices``, ``affine``, ``capacitances``, ``initial_state``), so
    the comparison is: the same scenario, ``LinearMPC(model, ...)`` vs
    ``LinearMPC(red.network, ...)``; report solve time per step, energy and comfort.
    Runs end to end (``--mpc``); the MPC examples issue owns the scenario and the settings
    (step 15 min, horizon 8 h here), so the numbers belong in its benchmark.
    """
    from mpc_examples.model import controller_model
    from mpc_examples.simulator import kpi_table, make_scenario, run_mpc
    from mpc_examples.linear_mpc import LinearMPC

    scn = make_scenario(zones, seed=0, hours=hours, horizon_hours=8.0, start_hour=start_hour)
    model = controller_model(scn.tb, "true", end=scn.start)
    nz = model.network.n_zones
    op = model.operating_point(ms=dict(zip(model.network.zones, scn.hvac.ms_min)), Ts=12.8,
                               T=15.0, Q=0.0)
    results = []
    for label, m in (("full", model), ("structured 2/zone", structured(model, op, order=2 * nz).network),
                     ("lumped", lumped(model, op).network)):
        mpc = LinearMPC(m, scn.hvac, scn.comfort_zones, dt=900.0, horizon=32)
        results.append(run_mpc(scn, mpc, m, f"linear MPC ({label}, {m.network.n_states} states)"))
    return kpi_table(results, scn.hvac, scn.band, scn.comfort_zones)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", default="7,50,200", help="comma-separated zone counts among 7, 50, 200")
    p.add_argument("--mpc", action="store_true", help="also run the MPC hook (mpc_comparison, ~5 min)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    pd.set_option("display.width", 250)
    pd.set_option("display.max_columns", 30)
    sizes = [int(s) for s in args.sizes.split(",")]
    all_rows, all_errs, all_sweeps = [], [], []
    with threadpool_limits(1):
        for z in sizes:
            rows, errs, sweep = run_size(z, print)
            all_rows += rows
            all_errs += errs
            all_sweeps.append(sweep)
            print(pd.DataFrame(errs).to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    print("\n## States needed (total (per zone)) for a step-response error of 1 % / 0.1 % at 1, 6, 24 h")
    print(pd.DataFrame(all_rows).to_string(index=False))
    print("\n## Standard orders: error and time to reduce (from scratch, 1 thread)")
    print(pd.DataFrame(all_errs).to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    print("\n## Flow sweep: step-response error at 1, 6, 24 h")
    sw = pd.concat(all_sweeps, ignore_index=True)
    for c in [c for c in sw.columns if c.startswith("err_")]:
        sw[c] = sw[c].map(lambda v: f"{100 * v:.3g} %")
    print(sw[["zones", "method", "order", "flow"] + [c for c in sw.columns if c.startswith("err_")]]
          .to_string(index=False))
    if args.mpc:
        print("\n## Linear MPC, full vs reduced (hook; Pugh Hall section, 12 occupied hours)")
        print(mpc_comparison().to_string(float_format=lambda v: f"{v:.4g}"))
    else:
        print("\n## Linear MPC, full vs reduced: HOOK — run with --mpc (see mpc_comparison)")


if __name__ == "__main__":
    main()
