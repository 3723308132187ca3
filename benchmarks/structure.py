"""Benchmark of structure identification (paper III-A): speed, memory, and accuracy.

Part 1 — wall and CPU time and peak memory (tracemalloc) of ``StructureIdentifier.fit`` for K = 288
(5-minute data) with n = 7, 50, 200 measured zones, SIN and graphical lasso, on synthetic
zone temperatures (a chain of coupled zones). Cases with n >= N - 1 days show what SIN
requires (it refuses) and what the graphical lasso does instead.

Part 2 — precision and recall of the selected convection edges on the testbed's default
building (true air paths known) vs the number of days (10, 20, 40), both methods, both
selection rules.

Usage::

    .venv/bin/python benchmarks/structure.py            # everything (a few minutes)
    .venv/bin/python benchmarks/structure.py --quick    # skip the n = 200 glasso rows

BLAS runs single-threaded (threadpoolctl): thousands of small batched decompositions gain
nothing from threads, and on a shared machine oversubscription made them 5-10× slower.
"""

from __future__ import annotations

import argparse
import logging
import time
import tracemalloc
import warnings

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits

from thermctl.errors import DataError
from thermctl.network import ThermalNetwork
from thermctl.spec import spec_from_dict
from thermctl.structure import StructureIdentifier


def synthetic(n: int, n_days: int, seed: int = 0):
    """Chain-coupled zone temperatures on a 5-minute grid, and a network with distances."""
    rng = np.random.default_rng(seed)
    K = 288
    zones = [f"z{i:03d}" for i in range(n)]
    X = rng.standard_normal((n_days * K, n))
    X[:, 1:] += 0.5 * X[:, :-1]
    idx = pd.date_range("2024-01-01", periods=n_days * K, freq="5min", tz="UTC")
    df = pd.DataFrame(21.0 + X, index=idx, columns=[f"T:{z}" for z in zones])
    spec = spec_from_dict({
        "name": f"chain{n}", "zones": {z: {"volume": 50.0} for z in zones}, "boundary": ["out"],
        "walls": [{"between": [z, "out"], "R": [.02, .06, .02], "C": [1e6, 1e6]} for z in zones],
        "distances": [{"between": [zones[i], zones[i + 1]], "d": 4.0} for i in range(n - 1)]})
    return df, ThermalNetwork(spec)


def timed_fit(est, df, net):
    tracemalloc.start()
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est.fit(df, net)
        out = (f"{time.perf_counter() - t0:8.2f} s {time.process_time() - c0:8.2f} s "
               f"{tracemalloc.get_traced_memory()[1] / 1e6:8.0f} MB")
        note = f"{int(est.graphs_.sum() / 2 / est.graphs_.shape[0]):5d} edges/graph"
        if est.method == "glasso":
            note += f", alpha={est.alpha_:.3f}, ADMM iters <= {est.n_iter_.max()}"
    except DataError as exc:
        out = f"{'refused':>10} {'':>10} {'':>11}"
        note = str(exc).split(";")[0]
    finally:
        tracemalloc.stop()
    return out, note


def part1(quick: bool):
    print("Part 1: fit time and peak memory, K = 288 (5 min), synthetic chain data")
    print(f"{'n':>4} {'N':>4} {'method':<12} {'wall':>10} {'CPU':>10} {'peak mem':>11}  notes")
    cases = [(7, 26), (50, 60), (50, 26), (200, 210), (200, 26)]
    methods = (("sin", {}), ("glasso-cv", {"alpha": "cv"}), ("glasso-level", {"alpha": "level"}))
    for n, N in cases:
        df, net = synthetic(n, N)
        for name, kw in methods:
            if n == 200 and name == "glasso-cv" or quick and n == 200 and name != "sin":
                continue  # CV at n = 200: 12 penalties x 120 problems of 200 x 200, minutes
            out, note = timed_fit(StructureIdentifier(method=name.split("-")[0], **kw), df, net)
            print(f"{n:>4} {N:>4} {name:<12} {out}  {note}")
    print()


def part2(seeds=(0, 1, 2)):
    try:
        from thermctl.testbed import generate
    except ImportError as exc:
        print(f"Part 2 skipped: thermctl.testbed not available ({exc})")
        return
    print("Part 2: selected convection edges vs truth, testbed default building (3 true air "
          f"paths), seeds {list(seeds)}; TP/FP/FN summed over seeds")
    print(f"{'days':>4} {'method':<10} {'rule':<10} {'TP':>3} {'FP':>3} {'FN':>3} {'precision':>9} "
          f"{'recall':>6}  {'true-edge scores (min-max)':<26} best false candidate")
    methods = (("sin", {}), ("glasso-cv", {"alpha": "cv"}), ("glasso-lvl", {"alpha": "level"}))
    for days in (10, 20, 40):
        rows = {}
        for seed in seeds:
            tb = generate(days=days, seed=seed)
            truth = {tuple(sorted(e[:2])) for e in tb.truth.edges}
            for name, kw in methods:
                for rule in ("paper", "threshold"):
                    row = rows.setdefault((name, rule), [0, 0, 0, [], []])
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        sid = StructureIdentifier(method=name.split("-")[0], rule=rule, **kw)
                        sid.fit(tb.data, tb.network)
                    got = {(e.a, e.b) for e in sid.edges_}
                    row[0] += len(got & truth)
                    row[1] += len(got - truth)
                    row[2] += len(truth - got)
                    row[3] += [sid.scores_[p] for p in truth]
                    row[4].append(max(sid.scores_[p] for p in sid.candidates_ if p not in truth))
        for (name, rule), (tp, fp, fn, ts, fs) in rows.items():
            print(f"{days:>4} {name:<10} {rule:<10} {tp:>3} {fp:>3} {fn:>3} "
                  f"{tp / max(1, tp + fp):>9.2f} {tp / max(1, tp + fn):>6.2f}  "
                  f"{min(ts):.2f}-{max(ts):.2f}{'':<17} {max(fs):.2f}")
    print()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="skip the slowest rows (n=200 glasso)")
    ap.add_argument("--part", type=int, choices=(1, 2), help="run one part only")
    args = ap.parse_args()
    logging.disable(logging.WARNING)  # the library's advice to users would flood the table
    with threadpool_limits(1):
        if args.part in (None, 1):
            part1(args.quick)
        if args.part in (None, 2):
            part2()


if __name__ == "__main__":
    main()
