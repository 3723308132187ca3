"""What a false air path of the broadened family feeds on: the L-shaped floor's a0–b0.

In 3 of the 4 L-shaped buildings of ``benchmarks/family.py`` (``l-shape+above``, both plants
at seed 0, the finite-volume plant at seed 1) ``thermctl identify`` keeps the air path
a0–b0, which the plant does not have: the offices at the two ends of the lobby. This
script takes the selection's own scorer (the one ``identify`` builds: its calibration days,
its gain model and noise options) and fits two structures cold, the true air paths ``T``
and ``T`` + a0–b0, on variants of the data-generating process and of the model, one
factor at a time. Per row:

* ``dBIC`` — BIC(T + a0–b0) − BIC(T) (the search keeps a path below −10);
* ``top day`` — the share of the likelihood gain that comes from its best day;
* ``day t`` — the daily likelihood gain's t statistic (``LikelihoodScorer.consistent``);
* ``6-h t`` — the 6-h prediction gain's t statistic and the days it is better on (the
  misfit check's test: it keeps a path with t ≥ 2);
* ``a3–b0`` — R̄_v of the true path a3–b0 in the fit of ``T`` (truth 3.36e-4 K/(W m)).

The ``nights only`` rows count the default's samples (3 h after the supply went off) between
20:00 and 06:00 only: no weekend daytime.

Usage::

    python benchmarks/false_path.py                   # every row (about 1 CPU min each)
    python benchmarks/false_path.py --rows default fd  # some of them
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import family  # noqa: E402  (benchmarks/family.py: the family's generate() arguments)

import thermctl.selection as _selection  # noqa: E402
from thermctl.data import read_measurements  # noqa: E402
from thermctl.identify import IdentifyOptions, identify  # noqa: E402
from thermctl.spec import spec_from_dict  # noqa: E402
from thermctl.structure.search import _cand  # noqa: E402
from thermctl.testbed import disturbances, generate  # noqa: E402

BASE = dict(family.ALL, building="l-shape", floor_above=True, plant="rc-exact")
FALSE = ("a0", "b0")

# name: (generate() changes, scorer option changes, make the lobby measured)
ROWS = {
    "default": ({}, {}, False),
    "fd": (dict(plant="fd"), {}, False),
    "seed 1": (dict(_seed=1), {}, False),
    "fd, seed 1": (dict(plant="fd", _seed=1), {}, False),
    "lobby measured": ({}, {}, True),
    "walls published exactly": (dict(wall_spec="plant"), {}, False),
    "walls by type": (dict(walls="types"), {}, False),
    "no neighbour or gain noise": (dict(walls="types", neighbour_noise=0.0, gain_noise=0.0), {},
                                   False),
    "arrivals, no neighbour noise": (dict(walls="types", gains="arrivals", neighbour_noise=0.0),
                                     {}, False),
    "hourly, nobody at weekends": (dict(_hourly_weekend=0.0), {}, False),
    "fast gain on": ({}, dict(fast_gain=True), False),
    "noise shared": ({}, dict(noise="shared"), False),
    "t innovations": ({}, dict(innovations="student"), False),
    "nights only": ({}, dict(_nights=True), False),
    "fd, nights only": (dict(plant="fd"), dict(_nights=True), False),
}


class _Got(Exception):
    pass


def selection_scorer(meas):
    """The :class:`LikelihoodScorer` ``identify`` hands its search (the run stops there)."""
    box = {}
    orig = _selection.search_edges

    def grab(cands, scorer, **kw):
        box["scorer"] = scorer
        raise _Got

    _selection.search_edges = grab
    try:
        identify(meas, IdentifyOptions())
    except _Got:
        pass
    finally:
        _selection.search_edges = orig
    return box["scorer"]


def data(gen, lobby_measured):
    gen = dict(BASE, **gen)
    seed = gen.pop("_seed", 0)
    weekend = disturbances.HOURLY_WEEKEND
    try:
        disturbances.HOURLY_WEEKEND = gen.pop("_hourly_weekend", weekend)
        tb = generate(days=16, seed=seed, **gen)
    finally:
        disturbances.HOURLY_WEEKEND = weekend
    spec, frame = tb.spec, tb.data
    if lobby_measured:
        # the lobby's own temperature (the plant's, plus 0.05 K of sensor noise) as a column
        d = spec.to_dict()
        d["zones"]["lobby"].pop("measured", None)
        spec = spec_from_dict(d, source="l-shape, lobby measured")
        frame = frame.copy()
        i = tb.network.zones.index("lobby")
        noise = np.random.default_rng(5).normal(0.0, 0.05, len(frame))
        frame.insert(0, "T:lobby", tb.states[:, i] + noise)
    true = sorted(tuple(sorted(e[:2])) for e in tb.truth.edges)
    return read_measurements(frame, spec, name="l-shape"), true


def row(name):
    gen, model, lobby = ROWS[name]
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meas, true = data(gen, lobby)
        sc = selection_scorer(meas)
        model = dict(model)
        spec = sc.spec
        T = [_cand(spec, p) for p in true]
        F = T + [_cand(spec, FALSE)]
        if model.pop("_nights", False):
            # the samples the default counts (3 h after the supply went off), at night only
            rows = sc.fit(T)[0].problem_for(sc.train).fit_rows
            t = sc.train.time
            hour = np.asarray(t.hour + t.minute / 60.0)
            model["fit_rows"] = rows & ((hour >= 20.0) | (hour < 6.0))
        sc.kw.update(model)
        eT, bT = sc.fit(T)
        eF, bF = sc.fit(F)
        sc.predict_t = 2.0
        g = sc._daily_gains(eT, eF)
        gk = sc._daily_prediction_gains(eT, eF)
    t = g.mean() / (g.std(ddof=1) / np.sqrt(len(g)))
    tk = gk.mean() / (gk.std(ddof=1) / np.sqrt(len(gk)))
    top = g.max() / g.sum() if g.sum() > 0 else float("nan")
    rb = eT.params_.get("rbar_v[air:a3-b0]", float("nan"))
    print(f"| {name} | {', '.join('-'.join(p) for p in true)} | {bF - bT:+.1f} | {top:.0%} | "
          f"{t:.1f} | {tk:.1f} ({int((gk > 0).sum())}/{len(gk)}) | {rb:.3g} | "
          f"{time.process_time() - t0:.0f} |", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", nargs="+", choices=list(ROWS), default=list(ROWS), metavar="ROW",
                    help="rows to run (default: all): " + "; ".join(ROWS))
    args = ap.parse_args(argv)
    print("| variant | true paths | dBIC | top day | day t | 6-h t (days better) | a3–b0 R̄v | "
          "CPU s |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.rows:
        row(name)


if __name__ == "__main__":
    main()
