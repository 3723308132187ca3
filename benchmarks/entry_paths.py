"""What the paths that came in by the gain-schedule check's swaps and additions look like.

For every building of the broadened family where session 43's ``--schedule-adds`` rows
(``benchmarks/results/family-runs.jsonl``) kept other paths than the default's, the
structure it kept is refitted (cold) on the schedule's likelihood, and each path that came
in is removed from it (warm): its removal cost in BIC, the t statistics of its daily
likelihood gains and of its daily 6-h prediction gains (the misfit check's test), and its
R̄_v over the median of the other paths' (the local problems' window, ×0.5-2). The data and
options are identify's own: identify runs up to where its selection would start.

    python benchmarks/entry_paths.py            # ~6 CPU-min, one thread
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import family as F  # noqa: E402

from thermctl import identify as I  # noqa: E402
from thermctl.data import read_measurements  # noqa: E402
from thermctl.estimate.likelihood.scoring import _day_t  # noqa: E402
from thermctl.identify import IdentifyOptions, identify  # noqa: E402
from thermctl.model import ConvectionParameters  # noqa: E402
from thermctl.selection import air_path_scorer  # noqa: E402
from thermctl.structure.search import as_candidates  # noqa: E402

OUT = F.RESULTS / "entry_paths.txt"


class _Reached(Exception):
    """identify reached its selection: the data, options and cold start it would use."""


def _selection_inputs(meas):
    """``(spec, cal, opt, cold_start)`` of identify's whole-building selection of ``meas``."""
    def stop(spec, cal, opt, notes, progress, first, off=None, cold_start=None):
        raise _Reached(spec, cal, opt, cold_start)
    keep, I._gain_model_and_first_fit = I._gain_model_and_first_fit, stop
    try:
        identify(meas, IdentifyOptions())
    except _Reached as got:
        spec, cal, opt, cold = got.args
    finally:
        I._gain_model_and_first_fit = keep
    # every one of these buildings left the fast gain out (its rows' notes): not decided again
    opt = dataclasses.replace(opt, estimation=dataclasses.replace(opt.estimation,
                                                                  fast_gain=False))
    return spec, cal, opt, cold


def _t(g):
    """The scorer's t statistic of daily gains ``g``, the days better, the days."""
    g = np.asarray(g, float)
    return _day_t(g, 0.0, "")[0], int((g > 0).sum()), len(g)


def cases():
    """``(layout, plant, seed, kept, default)`` where session 43's schedule-adds row kept
    other paths than the default row of the same building (the last of each)."""
    last = {}
    for line in F.RUNS.read_text().splitlines():
        r = json.loads(line)
        if r["study"] == "family" and r["days"] == 16 and "error" not in r:
            adds = (r.get("selection") or {}).get("schedule_adds")
            if adds and r.get("session") != 43:
                continue
            last[(r["case"], r["seed"])] = r
    out = []
    for layout in F.LAYOUTS:
        for plant in ("rc-exact", "fd"):
            for seed in (0, 1):
                name = f"{layout} ({plant})"
                a, d = last.get((name + " [schedule adds]", seed)), last.get((name, seed))
                if a and d and a["found"] != d["found"]:
                    out.append((layout, plant, seed, a, d))
    return out


def measure(layout, plant, seed, a, d):
    name = f"{layout} ({plant})"
    tb = F.simulate(dict(F.LAYOUTS[layout], **F.ALL, plant=plant), seed, 16.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meas = read_measurements(tb.data, tb.spec, name=name)
        spec, cal, opt, cold = _selection_inputs(meas)
        sc = air_path_scorer(spec, cal, margin=opt.selection.margin, cold_start=cold,
                             gain_schedule="occupied", **I._scorer_options(opt))
        true = {tuple(p) for p in a["true"]}
        default = {tuple(p) for p in d["found"]}
        cs = as_candidates(spec, [tuple(p) for p in a["found"]])
        full, v = sc.fit(cs)
        rb = {k: x for k, x in full.params_.items() if ConvectionParameters.is_rbar(k)}
        rows = []
        for c in cs:
            if c.pair in default:
                continue
            less, v_less = sc.fit([x for x in cs if x != c], warm=full)
            key = f"rbar_v[{c.name}]"
            others = float(np.median([x for k, x in rb.items() if k != key]))
            t_l, _, _ = _t(sc._daily_gains(less, full))
            t_p, better, days = _t(sc._daily_prediction_gains(less, full))
            rows.append(f"| {name}, seed {seed} | {c.name[4:]} | "
                        f"{'true' if c.pair in true else 'false'} | {c.d:g} | "
                        f"{v_less - v:+.1f} | {t_l:.1f} | {t_p:.1f} ({better}/{days}) | "
                        f"×{rb[key] / others:.2f} |")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--save", action="store_true", help=f"write the table to {OUT}")
    args = ap.parse_args(argv)
    lines = ["| building | path | in the plant | d [m] | BIC cost of removing it | daily t "
             "| 6-h prediction t (days better) | R̄_v / the others' median |",
             "|" + "---|" * 8]
    for case in cases():
        for row in measure(*case):
            print(row, flush=True)
            lines.append(row)
    if args.save:
        OUT.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
