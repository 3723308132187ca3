"""Which input timing ``identify --input-timing auto`` picks, and by how much BIC.

For every building it fits the conduction-only model with the inputs held as logged and
centred on the step (:meth:`thermctl.data.Measurements.centred_inputs`), as ``identify``
does before anything else, and prints the choice and the BIC change of centring
(negative: centred is better; it is used below ``-margin`` = −10). Buildings: the family
with every factor on (:data:`family.LAYOUTS` × 3R2C / finite-volume plant), the Pugh Hall
testbed, and a real data file given with ``--data DATA --building SPEC`` (e.g. the twin
house N2, whose values are 10-min means stamped at the end of their interval).

Run::

    python benchmarks/input_timing.py                       # family + Pugh Hall, ~6 min
    python benchmarks/input_timing.py --quick               # Pugh Hall only, ~10 s
    python benchmarks/input_timing.py --no-family --data data.csv --building building.yaml
"""

from __future__ import annotations

import argparse
import re
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from family import ALL, LAYOUTS  # noqa: E402

from thermctl.data import read_measurements  # noqa: E402
from thermctl.identify import IdentifyOptions, _resolve_input_timing  # noqa: E402
from thermctl.spec import load_spec  # noqa: E402
from thermctl.testbed import generate  # noqa: E402


def decide(meas):
    """``(timing, BIC change of centring)`` of the ``auto`` decision on ``meas``."""
    opt = IdentifyOptions()
    cal, val = meas.split(calibration=opt.calibration, validation=opt.validation)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        *_, o, note, _ = _resolve_input_timing(meas, cal, val, opt)
    return o.estimation.input_timing, float(re.search(r"BIC by ([-+0-9.]+)", note).group(1))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="the Pugh Hall testbed only")
    ap.add_argument("--no-family", action="store_true", help="no family buildings")
    ap.add_argument("--days", type=float, default=16.0, help="generated days (default 16)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--data", type=Path, help="a measured data file")
    ap.add_argument("--building", type=Path, help="its building spec")
    args = ap.parse_args(argv)
    cases = [("pugh-hall", "rc", dict(building="pugh-hall"))]
    if not (args.quick or args.no_family):
        cases += [(name, plant, dict(kw, **ALL, plant=plant))
                  for name, kw in LAYOUTS.items() for plant in ("rc-exact", "fd")]
    print(f"# input timing decided by conduction-only BIC ({args.days:g} generated days, "
          f"seed {args.seed}; OMP_NUM_THREADS as set)")
    print(f"{'building':24s} {'plant':8s} {'chosen':8s} {'ΔBIC centred':>12s} {'s':>5s}")
    for name, plant, kw in cases:
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tb = generate(days=args.days, seed=args.seed, **kw)
        timing, d = decide(read_measurements(tb.data, tb.spec, name=name))
        print(f"{name:24s} {plant:8s} {timing:8s} {d:+12.1f} {time.perf_counter() - t:5.0f}",
              flush=True)
    if args.data is not None:
        if args.building is None:
            ap.error("--data needs --building")
        t = time.perf_counter()
        timing, d = decide(read_measurements(args.data, load_spec(args.building)))
        print(f"{args.data.parent.name or str(args.data):24s} {'data':8s} {timing:8s} {d:+12.1f} "
              f"{time.perf_counter() - t:5.0f}", flush=True)


if __name__ == "__main__":
    main()
