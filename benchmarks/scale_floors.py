"""Where the local path finds and misses air paths on a tall corridor building.

One corridor testbed (``thermctl.testbed.generate("corridor", zones=Z)``: floors of
offices on both sides of an unmeasured hallway), ``identify`` with the defaults (local
problems, 2 workers, no intervals), scored per floor and per air-path length, and the false
paths that share a zone with a missed true one (a neighbour standing in for the partner).

Usage::

    python benchmarks/scale_floors.py --zones 196 --seed 0

Measured (session 18, seed 0, 196 zones; docs/scale.md "Structure quality at 196 zones"):
floors 10/13, 7/13, 9/15, 6/10 true paths found with 4, 5, 4, 8 false; by length
19/20, 3/9, 9/18, 2/5 (below 3 m, 3-5, 5-7, 7 m and more); 9 of 21 false paths beside a
missed true one.
"""

from __future__ import annotations

import argparse
import time
import warnings

from thermctl.data import read_measurements
from thermctl.identify import EstimationOptions, IdentifyOptions, SplitOptions, identify
from thermctl.testbed import generate

BINS = ((0.0, 3.0), (3.0, 5.0), (5.0, 7.0), (7.0, float("inf")))
"""Air-path lengths [m]: a path's conductance is 1/(R̄_v·d), the long ones the weakest."""


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zones", type=int, default=196)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--days", type=float, default=14.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate(building="corridor", zones=args.zones, days=args.days, seed=args.seed)
        meas = read_measurements(tb.data, tb.spec, name=f"corridor {args.zones}")
        t0 = time.perf_counter()
        ident = identify(meas, IdentifyOptions(
            estimation=EstimationOptions(intervals="none"),
            split=SplitOptions(scale="local", workers=args.workers)))
    wall = time.perf_counter() - t0
    found = {tuple(sorted((e.a, e.b))) for e in ident.model.network.convection_edges}
    true = {tuple(sorted((a, b))): d for a, b, d in tb.truth.edges}
    false = sorted(found - set(true))
    missed = {z for p in set(true) - found for z in p}
    storey = {z.name: z.storey for z in tb.spec.zones}
    print(f"corridor {args.zones}, seed {args.seed}, {args.days:g} days: identify {wall:.0f} s "
          f"wall; {len(found & set(true))}/{len(true)} true paths, {len(false)} false")
    print("| floor | true paths found | false paths |")
    print("|---|---|---|")
    for f in sorted({storey[a] for a, _ in true} | {storey[a] for a, _ in false}):
        t = [p for p in true if storey[p[0]] == f]
        print(f"| {f} | {sum(p in found for p in t)} / {len(t)} | "
              f"{sum(storey[p[0]] == f for p in false)} |")
    print("by length: " + ", ".join(
        f"{lo:g}-{hi:g} m {sum(p in found for p, d in true.items() if lo <= d < hi)}/"
        f"{sum(lo <= d < hi for d in true.values())}" for lo, hi in BINS))
    beside = [p for p in false if set(p) & missed]
    print(f"false paths sharing a zone with a missed true path: {len(beside)} of {len(false)}: "
          + ", ".join(f"{a}-{b}" for a, b in beside))
    return dict(wall=wall, found=sorted(found), true=true, false=false)


if __name__ == "__main__":
    main()
