"""Does a joint problem of a kept air path's two ends reject the local problems' false paths?

Runs the local path of ``identify`` (``thermctl.local.identify_local`` with the options
``identify`` gives its local fits) on a corridor testbed, then tests every kept path between
two measured zones again in one problem of both ends (``thermctl.local.joint_local``), with
or without a common gain (one first-order disturbance both ends feel, each with its own
loading: ``LikelihoodOptions.common_gain``). Prints each kept path, whether the testbed has it,
and the joint verdict.

Session 27 (docs/identification.md, "Joint problems of a path's two ends"): at 49 zones every
path the AND rule keeps passes its joint test; with ``--confirm`` and ``--common-gain 1`` two of
the five false north-side neighbour pairs fail it (daily t 1.5) and three pass.

Usage: ``OMP_NUM_THREADS=1 python benchmarks/joint_check.py --zones 50 --seed 0 [--confirm]
[--common-gain 1]``
"""

from __future__ import annotations

import argparse
import time
import warnings

from thermctl.data import read_measurements
from thermctl.identify import IdentifyOptions
from thermctl.local import identify_local, joint_local
from thermctl.testbed import generate


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zones", type=int, default=50, help="corridor testbed size (default 50)")
    ap.add_argument("--days", type=float, default=14.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--confirm", action="store_true", help="split.confirm before the joint test")
    ap.add_argument("--common-gain", type=int, default=0, metavar="N",
                    help="common gains in the joint problems (default 0)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    kw = IdentifyOptions().local_fit_options()     # what identify asks every local fit
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate("corridor", zones=args.zones, days=args.days, seed=args.seed)
        cal, _ = read_measurements(tb.data, tb.spec, name="corridor").split()
        true = {frozenset((a, b)) for a, b, _ in tb.truth.edges}
        t = time.process_time()
        li = identify_local(tb.spec, cal.frame, workers=args.workers, confirm=args.confirm, **kw)
        c_local = time.process_time() - t + li.cpu
        t = time.process_time()
        out = joint_local(tb.spec, cal.frame, li, workers=args.workers,
                          common_gain=args.common_gain, **kw)
        c_joint = out.cpu - li.cpu + time.process_time() - t
    print(f"corridor {args.zones}, seed {args.seed}, {args.days:g} days, confirm "
          f"{args.confirm}, common gains in the joint problems {args.common_gain}")
    print(f"{'air path':22s} {'true':5s} {'joint':5s} joint test")
    for v, w in zip(li.verdicts, out.verdicts):
        if not v.kept:
            continue
        what = w.reason.split("joint check", 1)[-1]
        print(f"{v.name:22s} {'yes' if frozenset((v.a, v.b)) in true else 'no':5s} "
              f"{'in' if w.kept else 'out':5s} {what[:110]}")
    for name, li_ in (("local", li), ("after the joint test", out)):
        got = {frozenset((a, b)) for a, b, _ in li_.edges}
        print(f"{name}: {len(got & true)}/{len(true)} true, {len(got - true)} false")
    print(f"CPU: local {c_local:.0f} s, joint tests {c_joint:.0f} s")


if __name__ == "__main__":
    main()
