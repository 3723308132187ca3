"""`thermctl identify` defaults on the broadened testbed family, and what biases R̄_v there.

Two studies, each one ``thermctl.identify.identify(meas, IdentifyOptions())`` per row (the
CLI's defaults, nothing tuned), on ``--days`` of 5-min data (default 16: thermctl's
default split validates on the last quarter, calibrates on 12 days, enough for SIN on 9
measured zones):

* ``factors`` — Pugh Hall's 7-zone section with one factor of the data-generating process
  switched at a time from the default testbed, then all of them, then all of them on the
  finite-volume plant: control at the data step with exact ZOH (``control_minutes=5,
  plant="rc-exact"``), random walls (published as U-value and capacity: the homogeneous
  split the user writes, not the plant's 25/50/25 %), the same walls published exactly,
  hourly occupancy (per-day level, hourly presence, white noise), white noise on the
  conditioned neighbours (0.2 K), and the walls resolved by finite volumes (``fd``);
* ``family`` — the new layouts (a ring of offices around a circulation core; a ring
  around a conditioned core with one more office hidden; an L-shaped floor with two
  corridors, a lobby and a measured floor above; an open plan) with every factor on,
  once on the 3R2C plant with exact ZOH and once on the finite-volume plant.

Columns: ``recall`` (true air paths between measured zones found / those true air paths),
``false`` (air paths found that are not true), ``R̄v`` (geometric mean of the model's
R̄_v over its air paths), ``err`` (|R̄v / truth − 1|, truth 3.36e-4), ``90 % interval``
and ``cover`` (whether it holds the truth; shared R̄_v only), ``step`` / ``cond``
(step-response error of the identified / the conduction-only model against the truth's,
heat into each zone at minimum flow, mean of 1, 6 and 24 h; the truth is the 3R2C model
for ``rc`` plants and the finite-volume plant itself for ``fd``), and the time of
``identify``.

Every row is appended as JSON to ``benchmarks/results/family-runs.jsonl`` when it is done
(``--save``), so an interrupted study keeps what it finished; ``--table`` rebuilds the
tables from that file, with the last run of every case (a re-run replaces what it
re-measured; runs with an option, " [t]", " [fast]", " [all:holdout]" or " [predict 2]", in
a table of their own). Since session 15 the defaults include swaps: rows run with the
then-option ``--swaps`` alone count as default runs; ``--no-swaps`` runs without them.

Usage::

    nice -n 5 python benchmarks/family.py --study factors --save
    nice -n 5 python benchmarks/family.py --study family --save
    python benchmarks/family.py --table        # → benchmarks/results/family.txt
    python benchmarks/family.py --quick        # one 4-zone building, 6 days (a smoke test)
"""

from __future__ import annotations

import argparse
import json
import logging
import subprocess
import time
import warnings
from importlib import metadata
from pathlib import Path

import numpy as np
from scipy.stats import gmean

from thermctl.data import read_measurements
from thermctl.identify import EstimationOptions, IdentifyOptions, SelectionOptions, identify
from thermctl.model import ThermalModel
from thermctl.testbed import disturbances, generate
from thermctl.validate import minimum_flows, relative_error, step_response_matrix

RESULTS = Path(__file__).parent / "results"
RUNS = RESULTS / "family-runs.jsonl"
HORIZONS_H = (1.0, 6.0, 24.0)

ALL = dict(walls="random", gains="hourly", neighbour_noise=0.2, control_minutes=5)

FACTORS = {
    # name: generate() arguments on Pugh Hall (the default testbed = "baseline")
    "baseline": {},
    "control at data step (exact ZOH)": dict(control_minutes=5, plant="rc-exact"),
    "random walls, published U/C": dict(walls="random"),
    "random walls, published exactly": dict(walls="random", wall_spec="plant"),
    "hourly occupancy + noise": dict(gains="hourly"),
    "noise on neighbours 0.2 K": dict(neighbour_noise=0.2),
    "finite-volume walls": dict(plant="fd"),
    # which part of the hourly occupancy model moves R̄_v
    "hourly occupancy, no noise": dict(gains="hourly", gain_noise=0.0),
    "arrivals + 30 W noise": dict(gain_noise=30.0),
    "hourly occupancy, no weekend presence": dict(gains="hourly", _hourly_weekend=0.0),
    "all (rc, exact ZOH)": dict(ALL, plant="rc-exact"),
    "all (fd)": dict(ALL, plant="fd"),
}

LAYOUTS = {
    "ring": dict(building="ring"),
    "ring-office+hidden": dict(building="ring-office", hide=1),
    "l-shape+above": dict(building="l-shape", floor_above=True),
    "open-plan": dict(building="open-plan"),
}


def _plain(kwargs) -> dict:
    """``generate()`` arguments as JSON: a callable building or a settings object by name."""
    return {k: v if isinstance(v, (int, float, str, bool, type(None))) else
            getattr(v, "__name__", repr(v)) for k, v in kwargs.items()}


def simulate(kwargs, seed, days):
    """The testbed of a case: ``generate()`` with ``kwargs`` (keys starting with ``_`` are
    diagnostic variants, e.g. ``_hourly_weekend``, the hourly model's weekend level)."""
    gen_kw = {k: v for k, v in kwargs.items() if not k.startswith("_")}
    if callable(gen_kw.get("building")):
        # benchmarks/identification.py's pugh-door: a function giving (spec, edges)
        gen_kw["building"] = gen_kw["building"]()
    weekend = disturbances.HOURLY_WEEKEND
    try:
        # the weekend level is a module constant
        disturbances.HOURLY_WEEKEND = kwargs.get("_hourly_weekend", weekend)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return generate(days=days, seed=seed, **gen_kw)
    finally:
        disturbances.HOURLY_WEEKEND = weekend


def run_case(study, name, kwargs, seed, days, estimation=None, selection=None):
    """Generate, identify with the defaults (``estimation``, ``selection``:
    EstimationOptions, SelectionOptions fields to change), score; one dict."""
    t0 = time.perf_counter()
    tb = simulate(kwargs, seed, days)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meas = read_measurements(tb.data, tb.spec, name=name)
    t_gen = time.perf_counter() - t0
    measured = set(tb.spec.measured_zones)
    true = {tuple(sorted(e[:2])) for e in tb.truth.edges}
    visible = {p for p in true if set(p) <= measured}
    row = dict(study=study, case=name, seed=seed, days=days, session=SESSION, commit=_COMMIT,
               versions=_VERSIONS, kwargs=_plain(kwargs),
               building=tb.spec.name, zones=tb.network.n_zones, measured=len(measured),
               true=sorted(visible), hidden_true=sorted(true - visible), gen_s=round(t_gen, 1))
    if estimation:
        row["estimation"] = dict(estimation)
    if selection:
        row["selection"] = dict(selection)
    t1, c1 = time.perf_counter(), time.process_time()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ident = identify(meas, IdentifyOptions(
                estimation=EstimationOptions(**(estimation or {})),
                selection=SelectionOptions(**(selection or {}))))
    except Exception as exc:            # noqa: BLE001 - a failing run is a result
        row["error"] = f"{type(exc).__name__}: {str(exc)[:120]}"
        return row
    row["identify_s"] = round(time.perf_counter() - t1, 1)
    row["identify_cpu"] = round(time.process_time() - c1, 1)      # since session 31
    if ident.selection is not None:
        row["fits"] = int(ident.selection.n_fits)
    model = ident.model
    found = {tuple(sorted((e.a, e.b))) for e in model.network.convection_edges}
    row["found"] = sorted(found)
    row["recall_hits"] = len(found & visible)
    row["false"] = len(found - visible)
    rb = np.atleast_1d(np.asarray(model.rbar_v, float)) if found else np.array([])
    r_true = float(gmean(np.atleast_1d(tb.truth.rbar_v)))
    row["rbar_v"] = float(gmean(rb)) if rb.size else None
    row["rbar_err"] = abs(row["rbar_v"] / r_true - 1.0) if rb.size else None
    iv = getattr(ident.intervals, "intervals", {}) or {}
    if "rbar_v" in iv:
        i = iv["rbar_v"]
        row["interval"] = [float(i.lower), float(i.upper)]
        row["covers"] = bool(i.lower <= r_true <= i.upper)
    else:
        # one R̄_v per path: covered when every true path found has an interval around it
        per = [iv.get(f"rbar_v[{e.name}]") for e in model.network.convection_edges
               if tuple(sorted((e.a, e.b))) in visible]
        if per and all(i is not None for i in per):
            row["covers"] = all(i.lower <= r_true <= i.upper for i in per)
    row["notes"] = [str(n)[:200] for n in ident.notes]
    het = getattr(ident.intervals, "heterogeneity", None)
    if het:                             # since session 45: the per-path values behind it
        row["per_path_rbar_v"] = {str(k): float(v) for k, v in het["rbar_v"].items()}
    ms_min = minimum_flows(tb.inputs[:, tb.network.input_slices()["ms"]])
    if tb.settings.get("family", {}).get("plant") == "fd":
        G0 = tb.plant().step_responses(ms_min, HORIZONS_H)
    else:
        G0 = step_response_matrix(tb.model, ms_min, HORIZONS_H)
    cond = ThermalModel(tb.network.conduction_only())
    row["step_err"] = float(np.mean(relative_error(step_response_matrix(model, ms_min, HORIZONS_H), G0)))
    row["cond_err"] = float(np.mean(relative_error(step_response_matrix(cond, ms_min, HORIZONS_H), G0)))
    row["truth3r2c_err"] = float(np.mean(relative_error(
        step_response_matrix(tb.model, ms_min, HORIZONS_H), G0)))
    return row


def _fmt(v, spec):
    return "—" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, spec)


SESSION = 45
_COMMIT = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                         cwd=Path(__file__).parent).stdout.strip() or None
"""Written into every row: the defaults changed with sessions (see ``_as_default``)."""
_VERSIONS = {m: metadata.version(m) for m in ("numpy", "scipy", "casadi")}
"""Also in every row (since session 43): the open-plan 3R2C seed-1 selection of session 42
(9 paths before the misfit check, 165 fits) was not session 41's (6, 73), though no commit
between them touched the selection; the virtual environment is made anew from ranges."""


def _as_default(row):
    """A row's case name as it differs from today's defaults.

    A row run with ``--swaps`` alone (session 15, before swaps became the default) is a
    run of today's default: its case name loses " [swaps]". Before session 20 the default
    noise was one σ of each for the building: such rows get " [noise shared]"; a row of
    session 20 or later run with ``--noise zone`` is a default run and loses the label
    (earlier ``--noise zone`` rows keep it: session 20 fixed the Wald intervals that the
    misfit check's trigger reads, which were NaN there). Session 22's rows run with
    ``--adds`` alone (before additions became the default) are default runs and lose
    " [adds]"; earlier rows stay default rows (the studies re-run then: the factors, the
    first family, and the broadened family's rows that say session 22). Rows run with
    ``--schedule-check`` alone (session 41, before the gain-schedule check became the
    default) are default runs and lose " [schedule check]"; the factor study's rows are
    from before it. Session 43's ``--schedule-adds`` rows were run before a path that
    comes in by the check was asked anything more: they read " [schedule adds, no entry
    test]"; the two of commit 93ac9b9 (session 44) asked it the 6-h prediction test, which
    was not kept: " [schedule adds, 6-h entry test]".
    """
    if row.get("selection") == {"swaps": True} and not row.get("estimation"):
        row = dict(row, case=row["case"].replace(" [swaps]", ""))
    if row.get("selection") == {"adds": True} and row.get("session", 0) >= 22:
        row = dict(row, case=row["case"].replace(" [adds]", ""))
    if row.get("selection") == {"schedule_check": True}:
        row = dict(row, case=row["case"].replace(" [schedule check]", ""))
    if (row.get("selection") or {}).get("schedule_adds"):
        tag = (" [schedule adds, no entry test]" if row.get("session", 0) < 44 else
               " [schedule adds, 6-h entry test]" if row.get("commit") == "93ac9b9" else None)
        if tag:
            row = dict(row, case=row["case"].replace(" [schedule adds]", tag))
    noise = (row.get("estimation") or {}).get("noise")
    if row.get("session", 0) < 20 and noise is None:
        row = dict(row, case=row["case"] + " [noise shared]")
    elif row.get("session", 0) >= 20 and noise == "zone":
        row = dict(row, case=row["case"].replace(" [noise zone]", ""))
    return row


def latest(rows):
    """The last run of every (study, case, seed, days): a re-run replaces what it
    re-measured."""
    last = {}
    for r in rows:
        last[(r["study"], r["case"], r["seed"], r["days"])] = r
    return list(last.values())


def table(rows, study):
    rows = [r for r in rows if r["study"] == study]
    head = (f"| case | seed | days | zones (meas) | recall | false | R̄v | err | 90 % interval "
            f"| cover | step | cond | 3R2C truth | s |")
    lines = [head, "|" + "---|" * 14]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['case']} | {r['seed']} | {r['days']:g} | {r['zones']} "
                         f"({r['measured']}) | failed: {r['error']} |" + " |" * 9)
            continue
        n_true = len(r["true"])
        iv = r.get("interval")
        lines.append(
            f"| {r['case']} | {r['seed']} | {r['days']:g} | {r['zones']} ({r['measured']}) | "
            f"{r['recall_hits']}/{n_true} | {r['false']} | {_fmt(r['rbar_v'], '.3g')} | "
            f"{_fmt(r['rbar_err'], '.0%')} | "
            + (f"[{iv[0]:.3g}, {iv[1]:.3g}]" if iv else "—") + " | "
            + ("yes" if r.get("covers") else "no" if "covers" in r else "—") + " | "
            f"{_fmt(r['step_err'], '.1%')} | {_fmt(r['cond_err'], '.1%')} | "
            f"{_fmt(r['truth3r2c_err'], '.1%')} | {r.get('identify_s', 0):.0f} |")
    ok = [r for r in rows if "error" not in r]
    if ok:
        n_true = sum(len(r["true"]) for r in ok)
        errs = [r["rbar_err"] for r in ok if r["rbar_err"] is not None]
        cov = [r["covers"] for r in ok if "covers" in r]
        lines.append(
            f"| **all {len(ok)}** | | | | {sum(r['recall_hits'] for r in ok) / max(n_true, 1):.2f} | "
            f"{np.mean([r['false'] for r in ok]):.2f}/bld | | "
            f"med {_fmt(float(np.median(errs)) if errs else None, '.0%')} | | "
            f"{sum(cov)}/{len(cov)} | med {np.median([r['step_err'] for r in ok]):.1%} | "
            f"med {np.median([r['cond_err'] for r in ok]):.1%} | | |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--study", choices=["factors", "family", "original"], default="factors",
                    help="factors: Pugh Hall, one factor at a time; family: the broadened "
                         "layouts with every factor on; original: the 6 layouts of "
                         "benchmarks/identification.py (the family of the first table)")
    ap.add_argument("--cases", nargs="+", help="only these case names")
    ap.add_argument("--plants", nargs="+", default=["rc-exact", "fd"],
                    help="family study: plants (default both)")
    ap.add_argument("--days", type=float, default=16.0)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--save", action="store_true", help=f"append rows to {RUNS}")
    ap.add_argument("--table", action="store_true", help=f"print the tables of {RUNS}")
    ap.add_argument("--quick", action="store_true", help="one small building, 6 days")
    ap.add_argument("--innovations", choices=["gaussian", "student"], default="gaussian",
                    help="identify's innovation distribution (student: case names get ' [t]')")
    ap.add_argument("--fast-gain", action="store_true",
                    help="identify with a fast gain per zone (case names get ' [fast]')")
    ap.add_argument("--noise", choices=["shared", "zone"], default=None,
                    help="identify's --noise (case names get ' [noise NOISE]'; the default, "
                         "per zone, since session 20)")
    ap.add_argument("--common-gain", type=int, default=0, metavar="N",
                    help="identify's --common-gain (case names get ' [common N]')")
    ap.add_argument("--gain-schedule", choices=["occupied"], default=None,
                    help="identify's estimation.gain_schedule: the gains wander faster in "
                         "occupied hours (case names get ' [schedule occupied]')")
    ap.add_argument("--loop-gain", action="store_true",
                    help="identify's estimation.loop_gain: a fitted gain per zone with supply "
                         "air for its loop acting between samples (case names get ' [loop]')")
    ap.add_argument("--per-path-p", type=float, default=0.0, metavar="P",
                    help="identify's estimation.per_path_p: R̄_v per path when Cochran's Q's "
                         "p-value is below P (case names get ' [per path p P]')")
    ap.add_argument("--selection", metavar="CANDIDATES:CRITERION",
                    help="identify's --candidates and --selection-criterion, e.g. all:holdout "
                         "(case names get ' [all:holdout]')")
    ap.add_argument("--predict-t", type=float, default=None, metavar="T",
                    help="identify's --predict-t (case names get ' [predict T]')")
    ap.add_argument("--no-swaps", action="store_true",
                    help="identify's --no-swaps (case names get ' [no swaps]'; the rows named "
                         "' [swaps]' were run when swaps were an option: --table shows them "
                         "as the default)")
    ap.add_argument("--no-adds", action="store_true",
                    help="identify's --no-adds (case names get ' [no adds]'; session 22's rows "
                         "named ' [adds]' were run when additions were an option: --table "
                         "shows them as the default)")
    ap.add_argument("--no-schedule-check", action="store_true",
                    help="identify's --no-schedule-check, the default before session 41 "
                    "(case names get ' [no schedule check]')")
    ap.add_argument("--schedule-adds", action="store_true",
                    help="selection.schedule_adds: the gain-schedule check also swaps and "
                         "adds (case names get ' [schedule adds]')")
    ap.add_argument("--union", action="store_true",
                    help="identify's --union (case names get ' [union]')")
    ap.add_argument("--per-edge", action="store_true",
                    help="identify's --per-edge (case names get ' [per edge]')")
    ap.add_argument("--shared-rbar", action="store_true",
                    help="identify's --shared-rbar: one R̄_v even where the misfit check runs "
                         "(case names get ' [shared]')")
    ap.add_argument("--recheck", type=float, default=None, metavar="R",
                    help="identify's --recheck (0: the backward pass tries every path every "
                         "round, the search before session 31; case names get ' [recheck R]')")
    ap.add_argument("--noise-step", choices=("log", "asinh"), default=None,
                    help="how L-BFGS-B moves noise intensities (thermctl.estimate.likelihood."
                         "optimize.NOISE_STEP; log: before session 32; case names get "
                         "' [noise step S]')")
    ap.add_argument("--misfit-ratio", type=float, default=None, metavar="R",
                    help="identify's --misfit-ratio (0: no misfit check; case names get "
                         "' [misfit R]'; default rows before session 17 ran without the check)")
    args = ap.parse_args(argv)
    logging.getLogger("thermctl").setLevel(logging.ERROR)
    if args.table:
        rows = latest(_as_default(json.loads(line)) for line in RUNS.read_text().splitlines()
                      if line.strip())
        # the defaults, then the runs with an option (case names with " [...]")
        plain = [r for r in rows if " [" not in r["case"]]
        opts = [r for r in rows if " [" in r["case"]]
        out = ["The defaults include swaps since session 15 (rows run with the then-option "
               "--swaps count as default runs; since session 16 a swap round refits two "
               "different pairs); the earlier default runs stay in family-runs.jsonl. Since "
               "session 17 the misfit check runs where R̄_v's variance ratio is above 4, and "
               "since session 18 the model then carries R̄_v per path (the 8 cases it "
               "concerns were re-run; the others are unchanged by it). Since session 20 the noise "
               "is per zone (rows before it, with one σ of each for the building, are "
               "labelled [noise shared]; session 20's --noise zone runs are the defaults). "
               "Since session 21 a swap may replace a kept edge whose own daily gain has t "
               "below 2 on the criterion alone; the rows of the studies re-run then say "
               "session 21 in family-runs.jsonl. Since session 22 the search also tries "
               "additions (--adds; a path beside a wall only in place of another): the "
               "factors and the first family were re-run, and the family rows that say "
               "session 22 (the finite-volume l-shape seed 1: session 23). Since session 34 "
               "the search's fits stop once 20 evaluations gain less than 0.05 nats (the "
               "factor study and both families were re-run). Since session 41 the "
               "gain-schedule check runs after the selection (both families were re-run "
               "with it; the factor study was not, its rows are without it; the broadened "
               "family's rows other than the open plans of seed 1 and three l-shapes ran "
               "before its intervals took in the default gain model's, see "
               "docs/identification.md). A per-path model's R̄v "
               "is the geometric mean of its paths' values; it covers when every true "
               "path's interval does.", ""]
        for study in ("factors", "family", "original"):
            if not any(r["study"] == study for r in rows):
                continue
            out += [f"## {study}", "", table(plain, study), ""]
            if any(r["study"] == study for r in opts):
                out += [f"## {study}, with an option", "", table(opts, study), ""]
        text = "\n".join(out)
        (RESULTS / "family.txt").write_text(text + "\n")
        print(text)
        return rows
    if args.quick:
        jobs = [("quick", "quick", dict(building="ring", zones=7, **ALL, plant="fd"), 0, 6.0)]
    elif args.study == "factors":
        jobs = [("factors", n, k, s, args.days) for n, k in FACTORS.items()
                for s in args.seeds if not args.cases or n in args.cases]
    elif args.study == "original":
        from identification import LAYOUTS as ORIGINAL
        jobs = [("original", n, k, s, args.days) for n, k in ORIGINAL.items()
                for s in args.seeds if not args.cases or n in args.cases]
    else:
        jobs = [("family", f"{n} ({p})", dict(k, **ALL, plant=p), s, args.days)
                for n, k in LAYOUTS.items() for p in args.plants for s in args.seeds
                if not args.cases or n in args.cases]
    rows = []
    for study, name, kw, seed, days in jobs:
        est = {}
        if args.innovations != "gaussian":
            name, est["innovations"] = name + " [t]", args.innovations
        if args.fast_gain:
            name, est["fast_gain"] = name + " [fast]", True
        if args.noise is not None:
            name, est["noise"] = name + f" [noise {args.noise}]", args.noise
        if args.per_edge:
            name, est["per_edge"] = name + " [per edge]", True
        if args.shared_rbar:
            name, est["per_edge"] = name + " [shared]", False
        if args.common_gain:
            name, est["common_gain"] = name + f" [common {args.common_gain}]", args.common_gain
        if args.gain_schedule:
            name, est["gain_schedule"] = name + f" [schedule {args.gain_schedule}]", \
                args.gain_schedule
        if args.loop_gain:
            name, est["loop_gain"] = name + " [loop]", True
        if args.per_path_p:
            name, est["per_path_p"] = name + f" [per path p {args.per_path_p:g}]", \
                args.per_path_p
        sel = {}
        if args.selection:
            cand, _, crit = args.selection.partition(":")
            sel = dict(candidates=cand, criterion=crit or "bic")
            name += f" [{args.selection}]"
        if args.predict_t is not None:
            sel["predict_t"] = args.predict_t
            name += f" [predict {args.predict_t:g}]"
        if args.no_swaps:
            sel["swaps"] = False
            name += " [no swaps]"
        if args.no_adds:
            sel["adds"] = False
            name += " [no adds]"
        if args.union:
            sel["union"] = True
            name += " [union]"
        if args.no_schedule_check:
            sel["schedule_check"] = False
            name += " [no schedule check]"
        if args.schedule_adds:
            sel["schedule_adds"] = True
            name += " [schedule adds]"
        if args.recheck is not None:
            sel["recheck"] = args.recheck or None
            name += f" [recheck {args.recheck:g}]"
        if args.noise_step is not None:
            from thermctl.estimate.likelihood import optimize
            optimize.NOISE_STEP = args.noise_step
            name += f" [noise step {args.noise_step}]"
        if args.misfit_ratio is not None:
            sel["misfit_ratio"] = args.misfit_ratio
            name += f" [misfit {args.misfit_ratio:g}]"
        row = run_case(study, name, kw, seed, days, estimation=est, selection=sel)
        rows.append(row)
        print(json.dumps(row), flush=True)
        if args.save:
            with RUNS.open("a") as f:
                f.write(json.dumps(row) + "\n")
    print()
    print(table(rows, jobs[0][0] if jobs else "factors"))
    return rows


if __name__ == "__main__":
    main()
