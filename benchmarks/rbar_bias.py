"""What moves R̄_v on a broadened-family building whose structure is found: one factor at a time.

Issue 24 asks what in the data-generating process moves R̄_v while the interval stays
narrow. ``benchmarks/family.py --study factors`` asked it on Pugh Hall; this script asks it
on a building of the broadened family with its true air paths given, so that no selection
error enters: the ring of offices on the finite-volume plant, seed 1, where ``identify``
finds the 4 true paths and no other and still reports R̄_v 35 % low (session 37).

Each row fits the true structure once, cold, with the scorer ``identify`` hands its search
(its calibration days, gain model and noise options; ``false_path.selection_scorer``), one
R̄_v per path, and prints the geometric mean of the paths' R̄_v against the truth. A row
changes one thing:

* the data (``generate()`` arguments over the family's every-factor-on default
  ``family.ALL``): the gains, the wall constructions, the plant, the noise;
* the spec the model gets (``films``: the walls published as U-value and capacity turned
  into 3R2C with ISO 6946 surface films, 0.13 m² K/W indoors and 0.04 outdoors, at most
  60 % of the wall's resistance, and the homogeneous-slab split of the rest, instead of the
  homogeneous-slab split of the whole resistance);
* or the model (scorer options: the gain schedule, t innovations, one noise level…).

Usage::

    python benchmarks/rbar_bias.py                       # every row, the ring (≈ 1 CPU min each)
    python benchmarks/rbar_bias.py --rows default arrivals "walls exact"
    python benchmarks/rbar_bias.py --layout open-plan --plant rc-exact --seed 1
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import family  # noqa: E402
from false_path import selection_scorer  # noqa: E402

from thermctl.data import read_measurements  # noqa: E402
from thermctl.rc import homogeneous_split  # noqa: E402
from thermctl.spec import is_outdoor, spec_from_dict  # noqa: E402
from thermctl.structure.search import _cand  # noqa: E402
from thermctl.testbed import SensorNoise  # noqa: E402
# ISO 6946 surface resistances [m² K/W] and the films' largest share of a wall's resistance:
# the finite-volume plant's own
from thermctl.testbed.fdplant import FILM_MAX, R_SE, R_SI  # noqa: E402

ARRIVALS = dict(gains="arrivals")
# the model is the plant but for the gains and the sensors
CLEAN = dict(ARRIVALS, walls="types", neighbour_noise=0.0, plant="rc-exact")
# name: (generate() changes, spec "films" or None, scorer option changes)
ROWS = {
    "default": ({}, None, {}),
    "3R2C plant (exact ZOH)": (dict(plant="rc-exact"), None, {}),
    "walls by type": (dict(walls="types"), None, {}),
    "walls exact": (dict(wall_spec="plant"), None, {}),
    "no gain noise": (dict(gain_noise=0.0), None, {}),
    "no neighbour noise": (dict(neighbour_noise=0.0), None, {}),
    "hourly, walls by type, no neighbour noise, 3R2C plant": (
        dict(walls="types", neighbour_noise=0.0, plant="rc-exact"), None, {}),
    "arrivals": (ARRIVALS, None, {}),
    "arrivals, 3R2C plant": (dict(ARRIVALS, plant="rc-exact"), None, {}),
    "arrivals, walls by type": (dict(ARRIVALS, walls="types"), None, {}),
    "arrivals, walls exact": (dict(ARRIVALS, wall_spec="plant"), None, {}),
    "arrivals, 3R2C plant, walls exact": (dict(ARRIVALS, plant="rc-exact", wall_spec="plant"),
                                          None, {}),
    "arrivals, no neighbour noise": (dict(ARRIVALS, neighbour_noise=0.0), None, {}),
    "arrivals, walls by type, no neighbour noise, 3R2C plant": (CLEAN, None, {}),
    "arrivals, clean, perfect sensors": (dict(CLEAN, noise=None), None, {}),
    "arrivals, clean, no sensor offsets": (dict(CLEAN, noise=SensorNoise(T_bias_sd=0.0)), None,
                                           {}),
    "arrivals, clean, exact flow gains": (dict(CLEAN, noise=SensorNoise(flow_gain_sd=0.0)),
                                          None, {}),
    "arrivals, clean, only the zone sensors' noise and rounding": (
        dict(CLEAN, noise=SensorNoise(T_bias_sd=0.0, Ts_sd=0.0, flow_sd=0.0, flow_gain_sd=0.0,
                                      flow_quantum_cfm=0.0, solar_sd=0.0)), None, {}),
    "arrivals, clean, zone sensors exact": (
        dict(CLEAN, noise=SensorNoise(T_sd=0.0, T_bias_sd=0.0, quantum_F=0.0)), None, {}),
    "films": ({}, "films", {}),
    "arrivals, films": (ARRIVALS, "films", {}),
    "arrivals, 3R2C plant, films": (dict(ARRIVALS, plant="rc-exact"), "films", {}),
    "gain schedule": ({}, None, dict(gain_schedule="occupied")),
    "t innovations": ({}, None, dict(innovations="student")),
    "one noise level": ({}, None, dict(noise="shared")),
    "no fast gain": ({}, None, dict(fast_gain=False)),
}


def films_spec(spec):
    """``spec`` with every wall that has an area re-split as surface films plus a
    homogeneous core: the wall's series resistance and capacity are kept."""
    d = spec.to_dict()
    for w in d["walls"]:
        area = w.get("area")
        if not area:
            continue
        r_tot, c_tot = sum(w["R"]), sum(w["C"])
        ra, rb = ((R_SE if is_outdoor(n) else R_SI) / area for n in w["between"])
        k = min(1.0, FILM_MAX * r_tot / (ra + rb))
        ra, rb = ra * k, rb * k
        (r1, r2, r3), _ = homogeneous_split(r_tot - ra - rb, c_tot)
        w["R"] = [ra + r1, r2, rb + r3]
    return spec_from_dict(d, source=spec.name)


def row(name, layout, plant, seed, days):
    gen, spec_kind, model = ROWS[name]
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = family.simulate({**family.ALL, **family.LAYOUTS[layout], "plant": plant, **gen},
                             seed, days)
        spec = films_spec(tb.spec) if spec_kind == "films" else tb.spec
        meas = read_measurements(tb.data, spec, name=layout)
        sc = selection_scorer(meas)
        sc.kw.update(model)
        true = sorted(tuple(sorted(e[:2])) for e in tb.truth.edges
                      if all(z in meas.spec.measured_zones for z in e[:2]))
        est, bic = sc.fit([_cand(sc.spec, p) for p in true])
    r_true = float(np.exp(np.mean(np.log(np.atleast_1d(tb.truth.rbar_v)))))
    per = {k.removeprefix("rbar_v[air:").rstrip("]"): v / r_true - 1.0
           for k, v in est.params_.items() if k.startswith("rbar_v[")}
    err = float(np.exp(np.mean(np.log([1.0 + e for e in per.values()])))) - 1.0
    fast = "on" if sc.kw.get("fast_gain") else "off"
    print(f"| {name} | {err:+.0%} | " + ", ".join(f"{k} {v:+.0%}" for k, v in per.items())
          + f" | {bic:.1f} | {fast} | {time.process_time() - t0:.0f} |", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layout", choices=list(family.LAYOUTS), default="ring")
    ap.add_argument("--plant", choices=("fd", "rc-exact"), default="fd",
                    help="the plant of the default row (rows may replace it)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--days", type=float, default=16.0)
    ap.add_argument("--rows", nargs="+", choices=list(ROWS), default=list(ROWS), metavar="ROW")
    args = ap.parse_args(argv)
    print(f"# {args.layout} ({args.plant} plant), seed {args.seed}, {args.days:g} days; the true "
          f"air paths, one cold fit each by the selection's scorer, one R̄_v per path")
    print("| row | R̄_v error (geometric mean) | per path | BIC | fast gain | CPU s |")
    print("|---|---|---|---|---|---|")
    for name in args.rows:
        row(name, args.layout, args.plant, args.seed, args.days)


if __name__ == "__main__":
    main()
