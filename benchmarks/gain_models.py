"""Which model of the unmeasured gains lets the Kalman likelihood find R̄_v?

Issue 11 asks to compare the ways of giving each zone its unknown heat gain (people,
equipment, sun): a random-walk state per zone (the offset-free disturbance model of MPC),
occupied/unoccupied levels, a small time-of-day Fourier basis, and combinations. For each
Pugh-Hall testbed building (3 seeds, 14 days, closed loop, true air paths given) this fits
:class:`thermctl.estimate.likelihood.LikelihoodEstimator` with each gain model and prints the R̄_v error,
whether the 90 % Wald interval covers the truth, the BIC, the 1-h k-step RMSE on the last
two (held-back) days, and the time.

Usage::

    python benchmarks/gain_models.py             # 3 seeds (~10 min on one core)
    python benchmarks/gain_models.py --seeds 0   # one building
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from thermctl.data import read_measurements
from thermctl.estimate.likelihood import LikelihoodEstimator, kstep_errors
from thermctl.estimate.likelihood.uncertainty import wald_intervals
from thermctl.testbed import generate

GAIN_MODELS = {
    # name: LikelihoodOptions fields
    "none (white noise only)": dict(disturbance="none"),
    "levels (occupied/unoccupied)": dict(disturbance="none", basis="levels"),
    "fourier (2 harmonics)": dict(disturbance="none", basis="fourier"),
    "random walk (default)": dict(disturbance="random_walk"),
    "random walk + levels": dict(disturbance="random_walk", basis="levels"),
    "random walk + fourier": dict(disturbance="random_walk", basis="fourier"),
}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--days", type=float, default=14.0)
    args = ap.parse_args(argv)
    rows = []
    for seed in args.seeds:
        tb = generate(days=args.days, seed=seed)
        meas = read_measurements(tb.data, tb.spec, name=f"pugh/{seed}")
        cal, val = meas.split(validation=(str((meas.end - np.timedelta64(1, "D")).date()), None))
        r_true = tb.truth.rbar_v
        for name, kw in GAIN_MODELS.items():
            t0 = time.perf_counter()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    est = LikelihoodEstimator(tb.network, **kw).fit(cal)
                    wald, _ = wald_intervals(est.problem_, est.eta_, 0.9)
                iv = wald["rbar_v"]
                ks = kstep_errors(est.problem_for(val), est.eta_, horizons=(3600.0,))
                rows.append((seed, name, abs(est.rbar_v_ / r_true - 1.0), iv.covers(r_true),
                             est.bic_, float(ks.rmse_mean[0]), time.perf_counter() - t0, ""))
            except Exception as exc:        # a failing model is a result
                rows.append((seed, name, np.nan, False, np.nan, np.nan,
                             time.perf_counter() - t0, f"{type(exc).__name__}: {exc!s:.50}"))
            r = rows[-1]
            print(f"seed {seed} {name:30s} R̄v err {r[2]:6.1%} cover {int(r[3])} BIC {r[4]:11.1f} "
                  f"1-h RMSE {r[5]:.3f} K {r[6]:5.0f} s {r[7]}", flush=True)
    print()
    head = (f"{'gain model':30s} {'R̄v err med':>11s} {'R̄v err max':>11s} {'90% cover':>9s} "
            f"{'ΔBIC vs RW':>11s} {'1-h RMSE K':>10s} {'time s':>7s}")
    print(head)
    print("-" * len(head))
    bic_rw = {s: b for s, n, _, _, b, _, _, _ in rows if n == "random walk (default)"}
    for name in GAIN_MODELS:
        rs = [r for r in rows if r[1] == name]
        err = np.array([r[2] for r in rs])
        dbic = np.array([r[4] - bic_rw.get(r[0], np.nan) for r in rs])
        print(f"{name:30s} {np.nanmedian(err):11.1%} {np.nanmax(err):11.1%} "
              f"{np.mean([r[3] for r in rs]):9.0%} {np.nanmedian(dbic):11.1f} "
              f"{np.nanmedian([r[5] for r in rs]):10.3f} {np.sum([r[6] for r in rs]):7.0f}")
    print("\nΔBIC vs RW: median over seeds of BIC(model) − BIC(random walk); negative = better "
          "(BIC is comparable between gain models on the same rows).")


if __name__ == "__main__":
    main()
