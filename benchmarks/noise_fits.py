"""What one likelihood fit costs with one noise level for the building and with one per zone.

Since session 20 ``identify`` fits the heat, gain and sensor noise per zone; on the twin
house N2 that made a run about 1.8x the CPU. This script shows where: the number of
likelihood evaluations L-BFGS-B needs, cold and started from the fit of one path fewer (the
selection's trial fits are warm like that), and the likelihood reached.

Rows: the twin house's 3 open doors (calibration days of the default split), then the same
plus the bedroom–doorway coupling, cold and warm. Prints a table; CPU seconds are the
steadier number on a shared machine.

Usage: ``OMP_NUM_THREADS=1 python benchmarks/noise_fits.py [--data DIR]``
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
    args = ap.parse_args(argv)
    spec = load_spec(args.data / "building.yaml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal, _ = read_measurements(args.data / "data.csv", spec).split()
    print(f"twin house N2, calibration {cal.frame.index[0]} to {cal.frame.index[-1]}, "
          "one L-BFGS-B fit per row")
    print(f"{'noise':7s} {'structure':26s} {'start':5s} {'params':>6s} {'evals':>6s} "
          f"{'CPU s':>6s} {'nll':>10s}")
    more = DOORS + [COUPLING]
    for noise in ("shared", "zone"):
        base, n, cpu = fit(spec, cal, DOORS, noise)
        rows = [("3 doors", "cold", base, n, cpu)]
        rows.append(("3 doors + bedroom-doorway", "warm",
                     *fit(spec, cal, more, noise, init=dict(base.params_))))
        rows.append(("3 doors + bedroom-doorway", "cold", *fit(spec, cal, more, noise)))
        for what, start, est, n, cpu in rows:
            print(f"{noise:7s} {what:26s} {start:5s} {len(est.params_):6d} {n:6d} "
                  f"{cpu:6.1f} {est.nll_:10.1f}")


if __name__ == "__main__":
    main()
