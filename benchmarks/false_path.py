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
* ``a3–b0`` — R̄_v of the true path a3–b0 in the fit of ``T`` (truth 3.36e-4 K/(W m));
  ``true R̄v`` — the geometric mean over the true paths;
* with ``--removals``, a line more: BIC(T without p) − BIC(T) for each true path p (the
  search removes a path whose removal costs less than 10) and the daily t of its likelihood
  gain (``--min-t`` asks for at least that).

``--building open-plan`` and ``--building ring`` ask the same of the family's other false
paths at seed 0 (p00–p12 on the open plan, 3R2C plant; n2–s0 on the ring, finite-volume
plant); the ``plant`` of a row replaces the building's.

The ``nights only`` rows count the default's samples (3 h after the supply went off) between
20:00 and 06:00 only: no weekend daytime.

``--fit`` instead fits whole structures with the same scorer (cold) and prints each one's
BIC − BIC(T): a search that ends above the true structure lost it in the search, not in the
likelihood (session 25: the open plan's found structure is 62.0 above T).

``--family`` asks that of every building of the broadened family (``benchmarks/family.py
--study family``) whose latest default row selected other paths than the truth: cold fits of
the truth ``T``, of the selection ``S`` and of their union, each by the selection's scorer
on the building's own data. ``S − T`` above 0: the likelihood prefers the truth and the
search did not reach it; below 0: the likelihood itself prefers what was selected (a false
path that a better search would keep as well). ``T ∪ S − T`` below −10: the false paths
gain on top of the truth.

Usage::

    python benchmarks/false_path.py                   # every row (1-4 CPU min each)
    python benchmarks/false_path.py --rows default fd  # some of them
    python benchmarks/false_path.py --building open-plan --rows default "hourly, nobody at weekends"
    python benchmarks/false_path.py --building open-plan \
        --fit "p00-p10 p00-p12 p01-p02 p01-p11 p10-p11 p11-p12" \
              "p00-p10 p00-p12 p01-p02 p01-p11 p10-p11 p11-p12 p02-p12"
    python benchmarks/false_path.py --family [--cases "open-plan (fd)|0" ...]
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
from thermctl.estimate.likelihood.scoring import _day_t  # noqa: E402
from thermctl.identify import IdentifyOptions, identify  # noqa: E402
from thermctl.spec import spec_from_dict  # noqa: E402
from thermctl.structure.search import _cand  # noqa: E402

# --building: (generate() arguments with every family factor on, the false path it keeps)
BUILDINGS = {
    "l-shape": (dict(family.ALL, building="l-shape", floor_above=True, plant="rc-exact"),
                ("a0", "b0")),
    # the family's other false paths at seed 0: the open plan's diagonal p00-p12 (3R2C
    # plant) and the ring's n2-s0 (finite-volume plant)
    "open-plan": (dict(family.ALL, building="open-plan", plant="rc-exact"), ("p00", "p12")),
    "ring": (dict(family.ALL, building="ring", plant="fd"), ("n2", "s0")),
}

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
    "gain schedule": ({}, dict(gain_schedule="occupied"), False),
    "fd, gain schedule": (dict(plant="fd"), dict(gain_schedule="occupied"), False),
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


def data(building, gen, lobby_measured):
    gen = dict(BUILDINGS[building][0], **gen)
    tb = family.simulate(gen, gen.get("_seed", 0), 16)
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
    return read_measurements(frame, spec, name=building), true


def row(name, building="l-shape", removals=False):
    """Print the table row ``name`` of ``building`` (and its removal costs)."""
    gen, model, lobby = ROWS[name]
    false = BUILDINGS[building][1]
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meas, true = data(building, gen, lobby)
        sc = selection_scorer(meas)
        model = dict(model)
        spec = sc.spec
        T = [_cand(spec, p) for p in true]
        F = T + [_cand(spec, false)]
        if model.pop("_nights", False):
            # the samples the default counts (3 h after the supply went off), at night only
            rows = sc.fit(T)[0].problem_for(sc.train).fit_rows
            stamps = sc.train.time
            hour = np.asarray(stamps.hour + stamps.minute / 60.0)
            model["fit_rows"] = rows & ((hour >= 20.0) | (hour < 6.0))
        sc.kw.update(model)
        eT, bT = sc.fit(T)
        eF, bF = sc.fit(F)
        # --removals: what each true path costs to remove, BIC(T − p) − BIC(T), and the
        # daily t of its likelihood gain (what --min-t would ask of it)
        cost = {}
        for c in (T if removals else ()):
            e_minus, b_minus = sc.fit([x for x in T if x is not c])
            cost[c.name] = (b_minus - bT, _day_t(sc._daily_gains(e_minus, eT), 0.0, "")[0])
        sc.predict_t = 2.0
        g = sc._daily_gains(eT, eF)
        gk = sc._daily_prediction_gains(eT, eF)
    t, tk = _day_t(g, 0.0, "")[0], _day_t(gk, 0.0, "")[0]
    # the best day's share means something only where the path gains overall
    top = f"{g.max() / g.sum():.0%}" if bF < bT else "—"
    rb = eT.params_.get("rbar_v[air:a3-b0]", float("nan"))
    rbs = [v for k, v in eT.params_.items() if k.startswith("rbar_v[")]
    print(f"| {name} | {', '.join('-'.join(p) for p in true)} | {bF - bT:+.1f} | {top} | "
          f"{t:.1f} | {tk:.1f} ({int((gk > 0).sum())}/{len(gk)}) | {rb:.3g} | "
          f"{float(np.exp(np.mean(np.log(rbs)))):.3g} | {time.process_time() - t0:.0f} |",
          flush=True)
    if cost:
        print("|   removal costs of the true paths | " + ", ".join(
            f"{k.removeprefix('air:')} {v:+.1f} (t {t:.1f})" for k, (v, t) in cost.items())
              + " |", flush=True)


def fit_structures(building, structures):
    """Print BIC(S) − BIC(T) for each structure S (air paths as "a-b" words), on the
    default data of ``building``, cold fits by the selection's scorer."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meas, true = data(building, {}, False)
        sc = selection_scorer(meas)
        _, bT = sc.fit([_cand(sc.spec, p) for p in true])
        print(f"T = {', '.join('-'.join(p) for p in true)}: BIC {bT:.1f}")
        for words in structures:
            pairs = [tuple(w.split("-")) for w in words.split()]
            t0 = time.process_time()
            _, b = sc.fit([_cand(sc.spec, p) for p in pairs])
            print(f"| {words} | {b - bT:+.1f} | {time.process_time() - t0:.0f} s |", flush=True)


def family_errors(cases=None):
    """Print, for every wrong selection of the broadened family (the latest default rows of
    ``family.RUNS``), the cold BIC of the selection ``S`` and of ``T ∪ S`` against the
    truth ``T``. ``cases``: "case|seed" strings (default: every wrong one)."""
    import json
    rows = [json.loads(line) for line in family.RUNS.read_text().splitlines() if line.strip()]
    rows = [r for r in family.latest(rows) if r["study"] == "family" and "[" not in r["case"]
            and "error" not in r]
    print("| building | seed | T | S: missed, false | S − T | T ∪ S − T | CPU s |")
    print("|---|---|---|---|---|---|---|")
    for r in sorted(rows, key=lambda r: (r["case"], r["seed"])):
        T = sorted(tuple(sorted(p)) for p in r["true"])
        S = sorted(tuple(sorted(p)) for p in r["found"])
        if cases is not None and f"{r['case']}|{r['seed']}" not in cases or (
                cases is None and S == T):
            continue
        layout, plant = r["case"].removesuffix(")").split(" (")
        BUILDINGS["_family"] = (dict(family.ALL, **family.LAYOUTS[layout], plant=plant), None)
        t0 = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            meas, true = data("_family", {"_seed": r["seed"]}, False)
            # a path to a hidden zone is in the plant, not in what a model can select
            if sorted(true) != sorted(T + [tuple(sorted(p)) for p in r.get("hidden_true", [])]):
                raise SystemExit(f"{r['case']} seed {r['seed']}: the building generated now "
                                 f"has other true paths than the row ({true} against {T})")
            sc = selection_scorer(meas)
            bic = {name: sc.fit([_cand(sc.spec, p) for p in st])[1]
                   for name, st in (("T", T), ("S", S), ("U", sorted(set(T) | set(S))))}
        missed = ", ".join("-".join(p) for p in T if p not in S) or "—"
        false = ", ".join("-".join(p) for p in S if p not in T) or "—"
        print(f"| {r['case']} | {r['seed']} | {len(T)} | {missed}; {false} | "
              f"{bic['S'] - bic['T']:+.1f} | {bic['U'] - bic['T']:+.1f} | "
              f"{time.process_time() - t0:.0f} |", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--building", choices=list(BUILDINGS), default="l-shape",
                    help="the layout and its false path (default: l-shape, a0-b0)")
    ap.add_argument("--rows", nargs="+", choices=list(ROWS), default=list(ROWS), metavar="ROW",
                    help="rows to run (default: all): " + "; ".join(ROWS))
    ap.add_argument("--removals", action="store_true",
                    help="also fit T without each true path: what removing it costs in BIC")
    ap.add_argument("--fit", nargs="+", metavar="STRUCTURE",
                    help='fit these structures instead (each a quoted list of "a-b" paths) '
                         "and print BIC - BIC(T)")
    ap.add_argument("--family", action="store_true",
                    help="every wrong selection of the broadened family: cold BIC of the "
                         "selection and of its union with the truth against the truth")
    ap.add_argument("--cases", nargs="+", metavar="CASE|SEED",
                    help='with --family: only these, e.g. "open-plan (fd)|0"')
    args = ap.parse_args(argv)
    if args.family:
        family_errors(args.cases)
        return
    if args.fit:
        fit_structures(args.building, args.fit)
        return
    print(f"{args.building}, false path {'-'.join(BUILDINGS[args.building][1])}")
    print("| variant | true paths | dBIC | top day | day t | 6-h t (days better) | a3–b0 R̄v | "
          "true R̄v (geometric mean) | CPU s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.rows:
        row(name, args.building, args.removals)


if __name__ == "__main__":
    main()
