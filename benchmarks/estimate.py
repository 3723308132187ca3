"""Benchmark of parameter estimation (issue 13): the grid against the NLPs.

Prints tables (wall and CPU time: the machine may be shared, CPU time is the steadier
number) and writes the J-vs-rbar_v figure (paper Fig. 4).

1. The default testbed problem — the paper's 7-zone Pugh Hall section, 2 days of BAS
   data (noise, 0.1 °F rounding, 1-min control between 5-min samples), the first 12 h,
   the paper's zero gains — with the paper's initial state, with initial-state
   estimation, and with the testbed's true gains plus initial-state estimation.
   Grid (41 × 9, exact ZOH) vs multiple shooting (1-h nodes and a node per sample),
   single shooting, and the pure CasADi Radau NLP.
2. Per-edge rbar_v (3 edges + c_v = 4 parameters) with the grid's cost extrapolated.
3. Time as the window grows (12 h, 2 days, 7 days) and as the zones grow (7, 50, 200).

Usage: ``python benchmarks/estimate.py [--quick] [--out DIR]`` (``--quick`` skips the
200-zone and 7-day rows).
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from thermctl.errors import BoundWarning
from thermctl.estimate import EstimationData
from thermctl.estimate.simulation import CostProblem, fit, grid_search
from thermctl.testbed import generate


def timed(f, *a, **k):
    w, c = time.perf_counter(), time.process_time()
    out = f(*a, **k)
    return out, time.perf_counter() - w, time.process_time() - c


def row(cells, widths):
    return "  ".join(str(c).ljust(w) if i == 0 else str(c).rjust(w)
                     for i, (c, w) in enumerate(zip(cells, widths)))


def table(title, head, rows, widths):
    print(f"\n{title}")
    print(row(head, widths))
    print("-" * (sum(widths) + 2 * (len(widths) - 1)))
    for r in rows:
        print(row(r, widths))


def fmt_theta(r, c):
    r = np.atleast_1d(r)
    return "/".join(f"{v:.3g}" for v in r) + f", {c:.3g}"


def with_gains(tb):
    """The BAS table plus the testbed's true gains as ``Q:<zone>`` columns."""
    q = tb.gains.copy()
    q.columns = [f"Q:{z}" for z in q.columns]
    return pd.concat([tb.data, q.set_axis(tb.data.index)], axis=1)


def compare(prob, label, radau=True):
    """Grid and every NLP on one problem; returns the rows and the grid."""
    rows = []
    grid, w, c = timed(grid_search, prob, warn=False)
    rows.append([f"{label}: grid 41×9", f"{grid.best_J:.5g}",
                 fmt_theta(grid.best_rbar_v, grid.best_c_v), f"{w:.2f}", f"{c:.2f}",
                 f"{grid.n_sim} sims", "exact ZOH", "bound" if grid.active_bounds else ""])
    forms = [("multiple shooting, 1-h nodes", "multiple_shooting", {}),
             ("multiple shooting, node/sample", "multiple_shooting", {"interval": prob.dt}),
             ("single shooting", "single_shooting", {})]
    if radau:
        forms.append(("pure CasADi Radau (5 sub-steps)", "casadi_radau", {}))
    times = {}
    for name, method, kw in forms:
        res, w, c = timed(fit, prob, method, identifiability=False, **kw)
        times[name] = c
        ok = "ok" if res.J <= grid.best_J * (1 + 1e-3) else "WORSE"
        disc = res.discretisation.split(";")[0].split(" (")[0]
        rows.append([f"{label}: {name}", f"{res.J:.5g}", fmt_theta(res.rbar_v, res.c_v),
                     f"{w:.2f}", f"{c:.2f}", f"{res.iterations} it / {res.n_sim} sims",
                     disc, ("bound " if res.active_bounds else "") + ok])
    ratio = times["multiple shooting, 1-h nodes"] / times["single shooting"]
    return rows, grid, ratio


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="skip the 200-zone and 7-day rows")
    ap.add_argument("--out", default="benchmarks/out", help="where to write the figure")
    args = ap.parse_args()
    warnings.simplefilter("ignore", BoundWarning)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    # ---------------------------------------------------------------- 1. default problem
    tb, w, c = timed(generate, "pugh-hall", days=8 if not args.quick else 3, seed=0)
    net = tb.network
    print(f"testbed: {net} (true rbar_v = {tb.truth.rbar_v}, c_v = {tb.truth.c_v}, "
          f"alpha = {tb.truth.alpha:.4f}); generated in {w:.1f} s")
    data0 = EstimationData.from_frame(tb.data, net)            # zero gains, as the paper
    dataQ = EstimationData.from_frame(with_gains(tb), net)     # the testbed's true gains
    widths = [52, 10, 18, 7, 7, 18, 20, 10]
    head = ["problem / method", "J [K²]", "rbar_v, c_v", "wall s", "CPU s", "work", "step",
            "vs grid"]
    all_rows, ratios, grids = [], {}, {}
    for label, data, mode in (("paper", data0, "paper"), ("x0 estimated", data0, "estimate"),
                              ("true gains, x0 est.", dataQ, "estimate")):
        prob = CostProblem(net, data, initial_state=mode)
        rows, grid, ratio = compare(prob, label, radau=(mode == "paper"))
        all_rows += rows
        ratios[label] = ratio
        grids[label] = (grid, prob)
    table("1. Default testbed problem (Pugh Hall, 12 h, 5-min samples)", head, all_rows, widths)
    print("   MS (1-h nodes) CPU time / SS CPU time: "
          + ", ".join(f"{k} {v:.2f}×" for k, v in ratios.items()) + "  (target ≤ 3×)")

    # figure (paper Fig. 4)
    from thermctl.plots.estimate import plot_cost_vs_rbar
    grid, prob = grids["paper"]
    res = fit(prob, identifiability=True)
    fig = plot_cost_vs_rbar(grid, fit=res)
    fig.savefig(out / "estimate_fig4.png", dpi=120)
    print(f"   figure: {out / 'estimate_fig4.png'}")
    print("   identifiability (paper problem):\n   "
          + res.identifiability.text.replace("\n", "\n   "))
    gq, pq = grids["true gains, x0 est."]
    rq = fit(pq)
    print("   identifiability (true gains, x0 estimated):\n   "
          + rq.identifiability.text.replace("\n", "\n   "))

    # ---------------------------------------------------------------- 2. per edge
    rows = []
    t_sim = None
    for label, (grid, prob) in grids.items():
        if label != "true gains, x0 est.":
            continue
        t_sim = grid.wall_time / grid.n_sim
        pe = CostProblem(net, dataQ, initial_state="estimate", per_edge=True)
        for name, method in (("multiple shooting", "multiple_shooting"),
                             ("single shooting", "single_shooting")):
            r, w, c = timed(fit, pe, method, identifiability=False)
            rows.append([name, f"{r.J:.5g}", fmt_theta(r.rbar_v, r.c_v), f"{w:.2f}", f"{c:.2f}",
                         f"{r.iterations} it / {r.n_sim} sims"])
        n_grid = 41 ** pe.m * 9
        rows.append([f"grid 41^{pe.m}×9 (extrapolated)", "—", "—", f"{n_grid * t_sim:.3g}", "—",
                     f"{n_grid} sims"])
        shared = grids[label][0]
        rows.append(["(shared-parameter grid, for J)", f"{shared.best_J:.5g}",
                     fmt_theta(shared.best_rbar_v, shared.best_c_v), "", "", ""])
    table(f"2. Per-edge rbar_v ({net.convection_edges.__len__()} edges + c_v), true gains, "
          f"x0 estimated; grid time at {1e3 * t_sim:.2f} ms per simulation",
          ["method", "J [K²]", "rbar_v..., c_v", "wall s", "CPU s", "work"], rows,
          [34, 10, 34, 10, 7, 20])

    # ---------------------------------------------------------------- 3a. window
    rows = []
    for days in ([0.5, 2] if args.quick else [0.5, 2, 7]):
        prob = CostProblem(net, dataQ, initial_state="estimate", window=days * 86400)
        for name, method in (("multiple shooting", "multiple_shooting"),
                             ("single shooting", "single_shooting")):
            r, w, c = timed(fit, prob, method, identifiability=False)
            rows.append([f"{days:g} d ({prob.win.K_T} steps): {name}", f"{r.J:.5g}",
                         fmt_theta(r.rbar_v, r.c_v), f"{w:.2f}", f"{c:.2f}",
                         f"{r.iterations} it", f"{prob.simulator.n_patterns}"])
    table("3a. Window length (Pugh Hall, true gains, x0 estimated, exact ZOH)",
          ["window: method", "J [K²]", "rbar_v, c_v", "wall s", "CPU s", "IPOPT", "flows"],
          rows, [40, 10, 18, 7, 7, 8, 6])

    # ---------------------------------------------------------------- 3b. zones
    rows = []
    cases = [(7, 0.5), (50, 0.5), (50, 2)] + ([] if args.quick else [(200, 0.5)])
    for zones, days in cases:
        tz, wg, _ = timed(generate, "corridor", zones=zones, days=days + 1, seed=0,
                          control_minutes=5, burn_in_days=1)
        dz = EstimationData.from_frame(with_gains(tz), tz.network)
        for simk, method in (("exact", "multiple_shooting"), ("exact", "single_shooting"),
                             ("radau", "single_shooting")):
            if simk == "exact" and tz.network.n_states > 200:
                continue      # dense eigendecompositions of every flow: minutes per J
            prob = CostProblem(tz.network, dz, initial_state="paper", window=days * 86400,
                               simulator=simk)
            r, w, c = timed(fit, prob, method, identifiability=False)
            rows.append([f"{tz.network.n_zones} zones, {tz.network.n_states} states, "
                         f"{days:g} d: {method.replace('_', ' ')} ({simk})",
                         f"{r.J:.5g}", fmt_theta(r.rbar_v, r.c_v), f"{w:.1f}", f"{c:.1f}",
                         f"{r.iterations} it / {r.n_sim} sims"])
    table("3b. Building size (corridor testbed, true gains, paper start; target: 50 zones, "
          "2 days < 60 s)", ["case", "J [K²]", "rbar_v, c_v", "wall s", "CPU s", "work"], rows,
          [64, 10, 18, 7, 7, 18])


if __name__ == "__main__":
    main()
