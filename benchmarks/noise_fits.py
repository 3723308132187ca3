"""What one likelihood fit costs with one noise level for the building and with one per zone.

Since session 20 ``identify`` fits the heat, gain and sensor noise per zone; on the twin
house N2 that made a run about 1.8x the CPU. This script shows where: the number of
likelihood evaluations L-BFGS-B needs, cold and started from the fit of one path fewer (the
selection's trial fits are warm like that), and the likelihood reached.

Rows: the twin house's 3 open doors (calibration days of the default split), then the same
plus the bedroom–doorway coupling, cold and warm, then the 3 doors again, warm from the fit
with the coupling: a backward removal trial of the selection. Prints a table; CPU seconds
are the steadier number on a shared machine.

Session 23 added the last row, and found that with one noise level per zone the likelihood
has more than one optimum: a zone may explain its misfit as sensor noise, or (sensor noise
at its lower bound 1e-4 K, the filter trusting the reading) as heat noise, and L-BFGS-B
stays in the mode its start leads to. The warm fits ended above the cold ones (negative
log-likelihood -57302.0 against -57491.8 with the coupling, started from the 3 doors' fit;
-57009.0 against -57023.2 for the 3 doors, started from the fit with the coupling); three
restarts of L-BFGS-B from the warm optimum move it by 1e-5, so it is a local optimum, not an
early stop. In a selection that is a removal cost or a gain wrong by 28 to 380 of BIC.
Restarts tried (session 23, not kept): the sensor noises found on the bound back at 0.02 K
reached the cold optimum in one run of two; every noise parameter back at its default start
(the physical ones kept) reached -57491.6 with the coupling, but took the cold 3 doors'
fit to -56959.5 (worse, so the first run is kept) and costs 100-300 evaluations more per fit
(on the twin house nearly every fit ends with a sensor noise on its bound); the same reset
only on fits that grow a structure improved 1 of 22 fits on the twin house, which ended at
the same 3 doors for 2.5x the CPU (docs/identification.md).

Session 32 moved the noise intensities on ``asinh(σ/σ0)`` instead of ``log σ``
(``--noise-step log`` gives the earlier step): a needless noise then reaches its bound in a
step instead of crawling there.

Usage: ``OMP_NUM_THREADS=1 python benchmarks/noise_fits.py [--data DIR] [--noise-step log]``
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

from thermctl.data import read_measurements
from thermctl.estimate.likelihood import LikelihoodEstimator, LikelihoodOptions
from thermctl.estimate.likelihood import problem as _problem
from thermctl.network import ThermalNetwork
from thermctl.spec import load_spec

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "twinhouse-n2"
DOORS = [("bath", "corridor"), ("child", "corridor"), ("corridor", "living")]
COUPLING = ("bedroom", "doorway")


class _Counter:
    """Counts the likelihood evaluations (value and gradient) of every problem."""

    def __init__(self):
        self.n = 0
        self._orig = _problem.LikelihoodProblem.nll_grad

    def __enter__(self):
        orig, counter = self._orig, self

        def counted(pb, eta, *a, **k):
            counter.n += 1
            return orig(pb, eta, *a, **k)

        _problem.LikelihoodProblem.nll_grad = counted
        return self

    def __exit__(self, *exc):
        _problem.LikelihoodProblem.nll_grad = self._orig


def fit(spec, cal, pairs, noise, init=None):
    """One fit: (estimator, evaluations, CPU seconds)."""
    edges = [(a, b, spec.air_path_length(a, b)[0]) for a, b in pairs]
    est = LikelihoodEstimator(ThermalNetwork(spec, edges), "likelihood",
                              options=LikelihoodOptions(noise=noise, solar=True))
    t = time.process_time()
    with _Counter() as c, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.fit(cal, init=init)
    return est, c.n, time.process_time() - t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA, help="twinhouse-n2 directory")
    ap.add_argument("--noise-step", choices=("asinh", "log"), default="asinh",
                    help="how L-BFGS-B moves the noise intensities (optimize.NOISE_STEP; "
                         "log: before session 32)")
    args = ap.parse_args(argv)
    from thermctl.estimate.likelihood import optimize
    optimize.NOISE_STEP = args.noise_step
    spec = load_spec(args.data / "building.yaml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal, _ = read_measurements(args.data / "data.csv", spec).split()
    print(f"twin house N2, calibration {cal.frame.index[0]} to {cal.frame.index[-1]}, "
          f"one L-BFGS-B fit per row, noise step {args.noise_step}")
    print(f"{'noise':7s} {'structure':28s} {'start':5s} {'params':>6s} {'evals':>6s} "
          f"{'CPU s':>6s} {'nll':>10s}")
    more = DOORS + [COUPLING]
    for noise in ("shared", "zone"):
        base, n, cpu = fit(spec, cal, DOORS, noise)
        rows = [("3 doors", "cold", base, n, cpu)]
        rows.append(("3 doors + bedroom-doorway", "warm",
                     *fit(spec, cal, more, noise, init=dict(base.params_))))
        big = fit(spec, cal, more, noise)
        rows.append(("3 doors + bedroom-doorway", "cold", *big))
        rows.append(("3 doors, from the row above", "warm",
                     *fit(spec, cal, DOORS, noise, init=dict(big[0].params_))))
        for what, start, est, n, cpu in rows:
            print(f"{noise:7s} {what:28s} {start:5s} {len(est.params_):6d} {n:6d} "
                  f"{cpu:6.1f} {est.nll_:10.1f}")


if __name__ == "__main__":
    main()
