"""Paths one end keeps: the AND rule against ``split.one_sided`` on the same local results.

For every corridor building (``thermctl.testbed.generate("corridor", zones=Z, days=14,
seed=S)``) this script runs ``identify`` with the defaults at ``scale="local"`` (one worker,
intervals off), keeps its local results (cached as a pickle, since a combination costs no
fit), and combines them twice: by the AND rule alone (``one_sided=None``) and with the
default ``one_sided`` (:data:`thermctl.local.ONE_SIDED`). Each row gives the true paths found,
the false ones, and the step-response error of both models: the mean relative error of the
1-, 6- and 24-h step responses from heat into every zone, against the testbed's model
(:func:`thermctl.validate.step_response_matrix`, minimum supply flows).

Usage::

    python benchmarks/one_sided.py --zones 49 --seeds 0 1 2 3          # ~1.5 min a building
    python benchmarks/one_sided.py --zones 196 --seeds 4 5 --cache /tmp/local-results
"""
from __future__ import annotations

import argparse
import math
import pickle
import time
import warnings
from pathlib import Path

import numpy as np

from thermctl.data import read_measurements
from thermctl.identify import EstimationOptions, IdentifyOptions, SplitOptions, identify
from thermctl.local import ONE_SIDED, assemble, local_problems
from thermctl.model import ThermalModel
from thermctl.testbed import generate
from thermctl.validate import minimum_flows, relative_error, step_response_matrix

HORIZONS_H = (1.0, 6.0, 24.0)


def _pair(a, b):
    return tuple(sorted((a, b)))


def local_results(tb, meas, cache: Path | None, tag: str):
    """The default run's local results (from ``cache`` when there)."""
    path = None if cache is None else cache / f"local_{tag}.pkl"
    if path is not None and path.exists():
        return pickle.loads(path.read_bytes())
    opt = IdentifyOptions(estimation=EstimationOptions(intervals="none"),
                          split=SplitOptions(scale="local", workers=1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        results = identify(meas, opt).local.results
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(pickle.dumps(results))
    return results


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zones", type=int, nargs="+", default=[49])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--days", type=float, default=14.0)
    ap.add_argument("--cache", type=Path, default=None,
                    help="folder for the local results (a second run only combines)")
    args = ap.parse_args(argv)
    print(f"| building | seed | AND rule: true, false | one_sided {ONE_SIDED:g}: true, false "
          "| step error | conduction only | s |")
    print("|---|---|---|---|---|---|---|")
    for z in args.zones:
        for seed in args.seeds:
            t0 = time.process_time()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                tb = generate(building="corridor", zones=z, days=args.days, seed=seed)
                meas = read_measurements(tb.data, tb.spec, name=f"corridor {z}")
            results = local_results(tb, meas, args.cache, f"{z}_{seed}_{args.days:g}")
            spec = meas.spec
            true = {_pair(a, b) for a, b, _ in tb.truth.edges}
            probs = local_problems(spec, meas.frame.columns)
            if [p.zone for p in probs] != [r.zone for r in results]:
                raise SystemExit(f"corridor {z} seed {seed}: cached results of other problems")
            ms = minimum_flows(tb.inputs[:, tb.network.input_slices()["ms"]])
            G0 = step_response_matrix(tb.model, ms, HORIZONS_H)
            cond = ThermalModel(tb.network.conduction_only())
            cells, errs = [], []
            for t in (None, ONE_SIDED):
                li = assemble(probs, results, "both", 10.0, math.nan, 2.0, t)
                found = {_pair(a, b) for a, b, _ in li.edges}
                cells.append(f"{len(found & true)}/{len(true)}, {len(found - true)}")
                G = step_response_matrix(li.model(spec), ms, HORIZONS_H)
                errs.append(100 * float(np.mean(relative_error(G, G0))))
            e_cond = 100 * float(np.mean(relative_error(
                step_response_matrix(cond, ms, HORIZONS_H), G0)))
            print(f"| {z} zones | {seed} | {cells[0]} | {cells[1]} | {errs[0]:.1f} → "
                  f"{errs[1]:.1f} % | {e_cond:.1f} % | {time.process_time() - t0:.0f} |",
                  flush=True)


if __name__ == "__main__":
    main()
