"""Identification on a family of testbed buildings: structure, parameters, control relevance.

For every building (layout × seed) of the family this script generates closed-loop BAS
data with :func:`thermctl.testbed.generate` and scores

* **estimation with the true air paths**, per criterion: the paper's open-loop
  simulation error (:class:`thermctl.estimate.ConvectionEstimator`), the grey-box
  Kalman likelihood on all samples and on supply-off samples (the default), and the
  1-hour k-step prediction error from filtered states: R̄_v relative error, 90 %
  interval coverage (Kalman likelihood, robust profile), step-response error of the
  identified model against the truth (heat into zone i → T of zone j at 1, 6, 24 h,
  supply at minimum flow; mean relative Frobenius error over the horizons), run time;
* **structure**: the paper's SIN + argmax and SIN + threshold rules
  (:class:`thermctl.structure.StructureIdentifier`), the model-based forward/backward
  selection on the Kalman likelihood over all candidate pairs (BIC, margin 10), and the
  hybrid "SIN + model-based" (backward elimination by BIC from the union of the SIN
  picks): recall (pooled over edges), false edges per building, and the R̄_v /
  step-response error of the selected model.

The conduction-only model's step-response error is printed beside (what a model that
ignores air paths gets wrong). Nothing is tuned to the family: every estimator runs
with its defaults.

Usage::

    python benchmarks/identification.py            # 5 layouts × 3 seeds, 14 days (~1.5 h)
    python benchmarks/identification.py --quick    # 1 small building, 6 days (~30 s)
"""

from __future__ import annotations

import argparse
import time
import warnings
from dataclasses import dataclass

import numpy as np

from thermctl.greybox import GreyboxEstimator, identifiability
from thermctl.greybox.selection import select_edges
from thermctl.model import ThermalModel
from thermctl.testbed import generate
from thermctl.testbed.disturbances import OccupancySettings
from thermctl.validate import minimum_flows, relative_error, step_response_matrix

LAYOUTS = {
    # name: generate() arguments. "mild" is the paper's case: perfect sensors, inputs
    # logged at the control step; "big-gains": occupants and equipment about as large
    # as the VAV boxes' heating capacity.
    "pugh": dict(building="pugh-hall"),
    "pugh-mild": dict(building="pugh-hall", noise=None, control_minutes=5),
    "pugh-big-gains": dict(building="pugh-hall",
                           occupancy=OccupancySettings(equipment_person=250.0, person=100.0)),
    "corridor5": dict(building="corridor", zones=5),
    "corridor7": dict(building="corridor", zones=7),
}
QUICK = {"small": None}     # filled in main(): the tests' small building


@dataclass
class Row:
    building: str
    method: str
    rbar_err: float = np.nan
    covered: float = np.nan
    step_err: float = np.nan
    step_err_cond: float = np.nan
    recall: float = np.nan
    false_edges: float = np.nan
    seconds: float = np.nan
    n_true: int = 0
    n_hit: int = 0
    note: str = ""


def _step_error(model, truth_model, ms_min):
    G = step_response_matrix(model, ms_min)
    G0 = step_response_matrix(truth_model, ms_min)
    return float(np.mean(relative_error(G, G0)))


def _rbar(x):
    return float(np.exp(np.mean(np.log(np.atleast_1d(x)))))


def run_building(name, kwargs, seed, days, do_selection, do_paper, quick_spec=None):
    rows = []
    t = time.perf_counter()
    if quick_spec is not None:
        tb = generate(quick_spec, days=days, seed=seed)
    else:
        tb = generate(days=days, seed=seed, **kwargs)
    label = f"{name}/{seed}"
    truth = tb.model
    true_pairs = {tuple(sorted(e[:2])) for e in tb.truth.edges}
    r_true = _rbar(tb.truth.rbar_v) if true_pairs else np.nan
    sl = tb.network.input_slices()
    ms_min = minimum_flows(tb.inputs[:, sl["ms"]])
    cond = ThermalModel(tb.network.conduction_only())
    e_cond = _step_error(cond, truth, ms_min)
    print(f"# {label}: {tb.network}, true edges {sorted(true_pairs)}, generated in "
          f"{time.perf_counter() - t:.0f} s", flush=True)

    def fit_row(method, make):
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model, extra = make()
            err = abs(_rbar(model.rbar_v) / r_true - 1.0) if true_pairs else np.nan
            row = Row(label, method, err, step_err=_step_error(model, truth, ms_min),
                      step_err_cond=e_cond, seconds=time.perf_counter() - t0, **extra)
        except Exception as exc:        # a failing method is a result, not a crash
            row = Row(label, method, note=f"failed: {type(exc).__name__}: {str(exc)[:60]}",
                      seconds=time.perf_counter() - t0)
        rows.append(row)
        print(f"  {method:22s} rbar err {row.rbar_err:6.1%}  step err {row.step_err:6.1%} "
              f"(cond. {e_cond:6.1%})  cover {row.covered}  {row.seconds:5.0f} s {row.note}",
              flush=True)

    if do_paper:
        def paper():
            from thermctl.estimate import ConvectionEstimator
            est = ConvectionEstimator(identifiability=False).fit(tb.network, tb.data)
            return est.model_, {}
        fit_row("simulation (paper)", paper)

    def kalman(**kw):
        def make():
            est = GreyboxEstimator(tb.network, **kw).fit(tb.data)
            extra = {"note": f"rows={est.problem_.fit_rule}"}
            if (kw.get("criterion", "likelihood") == "likelihood" and kw.get("fit_rows") is None
                    and true_pairs):
                rep = identifiability(est, params=("rbar_v",))
                iv = rep.intervals["rbar_v"]
                extra["covered"] = float(iv.covers(r_true))
                extra["note"] += f" 90%: [{iv.lower:.3g}, {iv.upper:.3g}]"
            return est.model_, extra
        return make

    fit_row("kalman (supply off)", kalman())
    fit_row("kalman (all rows)", kalman(fit_rows="all"))
    fit_row("kstep 1 h", kalman(criterion="kstep"))

    sin_pairs = None
    if do_paper:
        from thermctl.structure import StructureIdentifier
        for rule in ("paper", "threshold"):
            t0 = time.perf_counter()
            method = f"SIN + {'argmax' if rule == 'paper' else 'threshold'} (paper)"
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    sid = StructureIdentifier(rule=rule).fit(tb.data, tb.network.conduction_only())
                found = {tuple(sorted((e.a, e.b))) for e in sid.edges_}
                sin_pairs = found if sin_pairs is None else sin_pairs | found
                rows.append(Row(label, method, n_true=len(true_pairs), n_hit=len(found & true_pairs),
                                false_edges=len(found - true_pairs),
                                seconds=time.perf_counter() - t0))
            except Exception as exc:
                rows.append(Row(label, method, note=f"failed: {exc!s:.60}"))
            r = rows[-1]
            print(f"  {method:22s} hits {r.n_hit}/{r.n_true} false {r.false_edges} "
                  f"{r.seconds:5.0f} s {r.note}", flush=True)

    def selection(method, **kw):
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sel = select_edges(tb.spec, tb.data, **kw)
        found = {tuple(sorted(e[:2])) for e in sel.edges}
        est = sel.estimator
        row = Row(label, method, n_true=len(true_pairs), n_hit=len(found & true_pairs),
                  false_edges=len(found - true_pairs), seconds=time.perf_counter() - t0,
                  step_err=_step_error(est.model_, truth, ms_min), step_err_cond=e_cond,
                  note=f"{sel.n_fits} fits; extra {sorted(found - true_pairs)}; "
                       f"missed {sorted(true_pairs - found)}")
        if found and true_pairs:
            row.rbar_err = abs(_rbar(est.rbar_v_) / r_true - 1.0)
        rows.append(row)
        print(f"  {method:22s} hits {row.n_hit}/{row.n_true} false {row.false_edges} "
              f"rbar err {row.rbar_err:6.1%} step err {row.step_err:6.1%} {row.seconds:5.0f} s "
              f"{row.note}", flush=True)

    if do_selection:
        selection("model-based (BIC)")
        if sin_pairs:
            # SIN proposes, the likelihood disposes: backward elimination from SIN's picks
            selection("SIN + model-based", candidates=sorted(sin_pairs), direction="backward")

    return rows


def table(rows):
    """One line per method: medians / means over the buildings (recall pooled over edges)."""
    def agg(rs, attr, fn):
        v = np.array([getattr(r, attr) for r in rs], dtype=float)
        return fn(v[np.isfinite(v)]) if np.isfinite(v).any() else np.nan

    def fmt(v, spec, width):
        return format(v, spec).rjust(width) if np.isfinite(v) else "—".rjust(width)

    head = (f"{'method':24s} {'n':>3s} {'R̄v err med':>11s} {'R̄v err p90':>11s} {'90% cover':>9s} "
            f"{'step err':>9s} {'cond-only':>9s} {'recall':>7s} {'false/bld':>9s} {'time s':>7s}")
    out = [head, "-" * len(head)]
    for m in dict.fromkeys(r.method for r in rows):
        rs = [r for r in rows if r.method == m]
        out.append(" ".join([
            f"{m:24s}", f"{len(rs):3d}",
            fmt(agg(rs, "rbar_err", np.median), ".1%", 11),
            fmt(agg(rs, "rbar_err", lambda v: np.percentile(v, 90)), ".1%", 11),
            fmt(agg(rs, "covered", np.mean), ".0%", 9),
            fmt(agg(rs, "step_err", np.median), ".1%", 9),
            fmt(agg(rs, "step_err_cond", np.median), ".1%", 9),
            fmt(sum(r.n_hit for r in rs) / sum(r.n_true for r in rs)
                if sum(r.n_true for r in rs) and np.isfinite(agg(rs, "false_edges", np.mean))
                else np.nan, ".2f", 7),
            fmt(agg(rs, "false_edges", np.mean), ".2f", 9),
            fmt(agg(rs, "seconds", np.sum), ".0f", 7)]))
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="one small building, 6 days")
    ap.add_argument("--days", type=float, default=14.0)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--layouts", nargs="+", default=list(LAYOUTS))
    ap.add_argument("--no-selection", action="store_true")
    ap.add_argument("--no-paper", action="store_true", help="skip the paper's methods")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    if args.quick:
        from thermctl.spec import spec_from_dict
        spec = spec_from_dict({
            "name": "quick", "capacity_multiplier": 5,
            "zones": {"a": {"volume": 60}, "b": {"volume": 50}, "c": {"volume": 55}},
            "boundary": ["outside"],
            "walls": [{"between": ["a", "outside"], "area": 12, "u_value": 0.45, "heat_capacity": 1.2e5},
                      {"between": ["b", "outside"], "area": 10, "u_value": 0.45, "heat_capacity": 1.2e5},
                      {"between": ["c", "outside"], "area": 11, "u_value": 0.45, "heat_capacity": 1.2e5},
                      {"between": ["a", "b"], "area": 9, "u_value": 1.8, "heat_capacity": 2.5e4}],
            "distances": [{"between": ["a", "c"], "d": 4.0}, {"between": ["b", "c"], "d": 6.0},
                          {"between": ["a", "b"], "d": 3.0}]})
        rows += run_building("quick", {}, args.seeds[0], 6.0, not args.no_selection,
                             not args.no_paper, quick_spec=(spec, [("a", "c")]))
    else:
        for name in args.layouts:
            for seed in args.seeds:
                rows += run_building(name, LAYOUTS[name], seed, args.days, not args.no_selection,
                                     not args.no_paper)
    print()
    print(table(rows))
    print(f"\n{len({r.building for r in rows})} building(s), {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
