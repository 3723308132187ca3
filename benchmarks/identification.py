"""Identification on a family of testbed buildings: structure × criterion, scored against the truth.

For every building (layout × seed) of the family this script generates closed-loop BAS
data with :func:`thermctl.testbed.generate`, identifies on the **calibration days** (all
but the last two) and scores on what the truth knows and the last two days hold.

Rows read *method × criterion*: the method chooses the convection edges, the criterion
fits their parameters.

========================  ====================================================================
method                    edges
========================  ====================================================================
true edges                the testbed's own (parameter estimation alone)
SIN + argmax              the paper: Drton–Perlman SIN graphs, each zone's best partner
SIN + threshold           SIN, every pair scoring ≥ 0.25
glasso + argmax           graphical lasso (CV penalty), each zone's best partner
glasso + threshold        graphical lasso, every pair scoring ≥ 0.25
model-based (BIC)         forward/backward selection on the Kalman likelihood, all candidate
                          pairs with a known distance or a wall (a door beside it), BIC
                          margin 10
SIN + model-based         backward elimination by BIC from the SIN picks (walls allowed):
                          ``select_air_paths(candidates="sin", direction="backward")``
conduction only           no air path (the reference every air-path model must beat)
========================  ====================================================================

========================  ====================================================================
criterion                 fit of R̄_v (and C_v)
========================  ====================================================================
simulation (paper)        open-loop simulation error over 12 h, gains taken as zero
                          (:class:`thermctl.estimate.SimulationEstimator`, the paper's J)
Kalman                    maximum likelihood through a Kalman filter with random-walk gains
                          (:class:`thermctl.estimate.likelihood.LikelihoodEstimator`, default rows: samples
                          with the supply off ≥ 3 h)
Kalman, all rows          the same on every sample
k-step 1 h                1-hour-ahead prediction error from filtered states
========================  ====================================================================

Columns, over the buildings of the family:

* ``R̄v err``: |geometric-mean R̄_v / true R̄_v − 1| (median, 90th percentile); for a
  selected structure this compares the shared value although its edges may differ;
* ``cover``: fraction of fits whose 90 % profile-likelihood interval of R̄_v covers the
  truth (Kalman-likelihood fits of the true structure only: elsewhere "the truth" of a
  shared R̄_v is not defined);
* ``step err``: median relative Frobenius error of the step-response matrix (heat into
  zone i → temperature of zone j, at 1, 6 and 24 h, supply at minimum flow) against the
  truth's, mean over the three horizons;
* ``val med`` / ``val max``: 48-h open-loop validation on the last two days (held back
  from every fit). Per building the worst zone's ``RMSE_model / RMSE_oracle − 1``, where
  the oracle is the true model simulated the same way (from the paper's initial state,
  data inputs, gains unknown so Q = 0 for both, :func:`thermctl.validate.open_loop`);
  median and maximum over the buildings;
* ``recall`` (pooled over all true edges) and ``false/bld`` (mean false edges per
  building) of the structure;
* ``time``: seconds of structure identification + fit, summed over the buildings
  (intervals and validation not counted).

The family (each layout × 3 seeds) covers closed-loop VAV control with per-zone heating
and cooling set points and a deadband, occupants who stay for hours and differ by zone
and day, 0.1 °F quantisation and sensor noise (all but ``pugh-mild``), unmeasured zones
(Pugh Hall's hallway, the corridors), gains as large as the HVAC's (``pugh-big-gains``),
the paper's mild case (``pugh-mild``: perfect sensors, inputs logged at the control step),
and an open door beside a wall (``pugh-door``). Each building's header line prints the
measured ratio of the occupied-hours gains to its VAV boxes' capacity. Nothing is tuned
to the family: every method runs with its library defaults.

Usage::

    python benchmarks/identification.py            # 6 layouts × 3 seeds, 14 days (12 + 2)
    python benchmarks/identification.py --quick    # 1 small building, 8 days (6 + 2)
"""

from __future__ import annotations

import argparse
import logging
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import gmean

from thermctl.estimate import EstimationData
from thermctl.estimate.likelihood import LikelihoodEstimator, identifiability
from thermctl.selection import select_air_paths
from thermctl.model import ThermalModel
from thermctl.spec import spec_from_dict
from thermctl.testbed import generate, pugh_hall_spec
from thermctl.testbed.disturbances import OccupancySettings
from thermctl.validate import minimum_flows, open_loop, relative_error, step_response_matrix

VAL_DAYS = 2.0          # the paper's 48-h validation window, held back from every fit


def pugh_door():
    """Pugh Hall with its three air paths plus an open door in the r241|r242 partition.

    The door's air path runs parallel to the partition wall (conduction and convection
    between the same two zones). Its true length is the distance between the two room
    centres (widths 3.6 and 4.4 m → 4.0 m). The spec is Pugh Hall's unchanged: like most
    spec authors it lists air-path lengths through the hallway only, so a method must
    consider wall pairs on its own (:meth:`BuildingSpec.air_path_length`) to find the door.
    """
    spec, edges = pugh_hall_spec()
    return spec, list(edges) + [("r241", "r242", 4.0)]


LAYOUTS = {
    # name: generate() arguments (a callable "building" is called for the spec and edges).
    # "mild" is the paper's case: perfect sensors, inputs logged at the control step;
    # "big-gains": occupants and equipment about as large as the VAV boxes' capacity.
    "pugh": dict(building="pugh-hall"),
    "pugh-mild": dict(building="pugh-hall", noise=None, control_minutes=5),
    "pugh-big-gains": dict(building="pugh-hall",
                           occupancy=OccupancySettings(equipment_person=250.0, person=100.0)),
    "pugh-door": dict(building=pugh_door),
    "corridor5": dict(building="corridor", zones=5),
    "corridor7": dict(building="corridor", zones=7),
}

QUICK_SPEC = {
    "name": "quick", "capacity_multiplier": 5,
    "zones": {"a": {"volume": 60}, "b": {"volume": 50}, "c": {"volume": 55}},
    "boundary": ["outside"],
    "walls": [{"between": ["a", "outside"], "area": 12, "u_value": 0.45, "heat_capacity": 1.2e5},
              {"between": ["b", "outside"], "area": 10, "u_value": 0.45, "heat_capacity": 1.2e5},
              {"between": ["c", "outside"], "area": 11, "u_value": 0.45, "heat_capacity": 1.2e5},
              {"between": ["a", "b"], "area": 9, "u_value": 1.8, "heat_capacity": 2.5e4}],
    "distances": [{"between": ["a", "c"], "d": 4.0}, {"between": ["b", "c"], "d": 6.0},
                  {"between": ["a", "b"], "d": 3.0}]}
QUICK_EDGES = [("a", "c")]

# (method, criterion) of every row, in table order
TRUE, COND = "true edges", "conduction only"
SIM, KAL, KAL_ALL, KSTEP = "simulation (paper)", "Kalman", "Kalman, all rows", "k-step 1 h"
ROWS = [(TRUE, SIM), (TRUE, KAL), (TRUE, KAL_ALL), (TRUE, KSTEP),
        ("SIN + argmax", SIM), ("SIN + argmax", KAL), ("SIN + threshold", KAL),
        ("glasso + argmax", KAL), ("glasso + threshold", KAL),
        ("model-based (BIC)", KAL), ("SIN + model-based", KAL), (COND, "—")]
STRUCTURE = {"SIN + argmax": ("sin", "paper"), "SIN + threshold": ("sin", "threshold"),
             "glasso + argmax": ("glasso", "paper"), "glasso + threshold": ("glasso", "threshold")}


@dataclass
class Row:
    """One (building, method, criterion) result; NaN where a measure does not apply."""

    building: str
    method: str
    criterion: str
    rbar_err: float = np.nan
    covered: float = np.nan
    step_err: float = np.nan
    val: float = np.nan
    val_zone: str = ""
    n_true: int = 0
    n_hit: int = 0
    false_edges: float = np.nan
    seconds: float = np.nan
    note: str = ""

    @property
    def structural(self) -> bool:
        return self.method not in (TRUE, COND)


@dataclass
class Building:
    """What a building's run saw: name, windows, true edges, gains over HVAC capacity."""

    label: str
    calibration: tuple
    validation: tuple
    true_edges: list
    gain_ratio: float
    rows: list = field(default_factory=list)


@dataclass
class Result:
    buildings: list
    rows: list
    table: str
    seconds: float


# ---------------------------------------------------------------------------- measures
def _rbar(x):
    return float(gmean(np.atleast_1d(x)))


def _step_error(model, truth_model, ms_min):
    G = step_response_matrix(model, ms_min)
    G0 = step_response_matrix(truth_model, ms_min)
    return float(np.mean(relative_error(G, G0)))


class Validator:
    """48-h open-loop RMSE per zone against the oracle's (the true model, same start, Q = 0)."""

    def __init__(self, tb, frame):
        net = tb.network
        gd = EstimationData.from_frame(frame, net)   # no Q: columns → Q = 0 (gains unknown)
        self.dt = gd.dt
        self.U = gd.U[:-1]
        self.Y = np.full((len(gd), net.n_zones), np.nan)
        for j, z in enumerate(gd.zones):
            self.Y[:, net.zones.index(z)] = gd.Y[:, j]
        self.Tb0 = frame[[f"T:{b}" for b in net.boundary]].iloc[0].to_numpy(float)
        self.zones = list(gd.zones)
        self.oracle = self.rmse(tb.model)

    def rmse(self, model):
        return open_loop(model, self.U, self.Y, self.dt, self.Tb0, zones=self.zones).rmse

    def ratio(self, model):
        """Worst zone's ``RMSE_model / RMSE_oracle − 1`` [-] and that zone."""
        r = self.rmse(model)
        q = {z: r[z] / self.oracle[z] - 1.0 for z in self.zones}
        z = max(q, key=q.get)
        return q[z], z


def _gain_ratio(tb):
    """Median over offices of (99th percentile of occupied-hours gain) / VAV capacity.

    Capacity = max(cooling: ms_max·cp·(cool set point − T_ahu), heating at the dual
    maximum: ms_heat_max·cp·(Ts_max − heat set point)).
    """
    boxes = tb.truth.details.get("vav_boxes", {})
    hv = tb.settings["hvac"]
    cp = tb.spec.cp
    out = []
    for z, b in boxes.items():
        cap = max(b["ms_max"] * cp * (b["cool_setpoint"] - hv["T_ahu"]),
                  b["ms_heat_max"] * cp * (hv["Ts_max"] - b["heat_setpoint"]))
        out.append(np.percentile(tb.gains[z].to_numpy(), 99) / cap)
    return float(np.median(out)) if out else np.nan


# ---------------------------------------------------------------------------- one building
def run_building(name, kwargs, seed, days, *, selection=True, paper=True, verbose=True):
    """All rows of one building; fits see the calibration days only.

    Parameters
    ----------
    name : str
    kwargs : dict
        :func:`thermctl.testbed.generate` arguments (``building`` may be a callable).
    seed : int
    days : float
        Generated days [d]; the last :data:`VAL_DAYS` are held back for validation.
    selection, paper : bool
        Include the model-based selection rows / the paper's simulation criterion.
    """
    say = print if verbose else (lambda *a, **k: None)
    kwargs = dict(kwargs)
    if callable(kwargs.get("building")):
        kwargs["building"] = kwargs["building"]()
    t = time.perf_counter()
    tb = generate(days=days, seed=seed, **kwargs)
    label = f"{name}/{seed}"
    step = tb.data.index[1] - tb.data.index[0]
    n_val = int(round(VAL_DAYS * 86400.0 / step.total_seconds()))
    cal, val = tb.data.iloc[:-n_val], tb.data.iloc[-n_val:]
    truth = tb.model
    true_pairs = {tuple(sorted(e[:2])) for e in tb.truth.edges}
    r_true = _rbar(tb.truth.rbar_v) if true_pairs else np.nan
    ms_min = minimum_flows(tb.inputs[:, tb.network.input_slices()["ms"]])
    validator = Validator(tb, val)
    cond = ThermalModel(tb.network.conduction_only())
    b = Building(label, (cal.index[0], cal.index[-1]), (val.index[0], val.index[-1]),
                 sorted(true_pairs), _gain_ratio(tb))
    walls = {frozenset((w.a, w.b)) for w in tb.spec.walls}
    parallel = [p for p in true_pairs if frozenset(p) in walls]
    say(f"# {label}: {tb.network}; true edges {sorted(true_pairs)}"
        + (f" ({parallel} beside a wall)" if parallel else "")
        + f"; unmeasured {tb.truth.details['unmeasured_zones']}; gains p99 / VAV capacity "
        f"{b.gain_ratio:.2f}; calibration {len(cal)} samples to {cal.index[-1]:%m-%d %H:%M}, "
        f"validation {val.index[0]:%m-%d %H:%M}–{val.index[-1]:%m-%d %H:%M}; generated in "
        f"{time.perf_counter() - t:.0f} s", flush=True)

    def score(row, model, found=None, est=None):
        """Fill the truth-side measures of a fitted model."""
        row.step_err = _step_error(model, truth, ms_min)
        row.val, row.val_zone = validator.ratio(model)
        edges = [e for e in model.network.convection_edges]
        if edges and true_pairs:
            row.rbar_err = abs(_rbar(model.rbar_v) / r_true - 1.0)
        if found is not None:
            row.n_true, row.n_hit = len(true_pairs), len(found & true_pairs)
            row.false_edges = len(found - true_pairs)
            extra, missed = sorted(found - true_pairs), sorted(true_pairs - found)
            row.note += (f" extra {extra}" if extra else "") + (f" missed {missed}" if missed else "")
        if (est is not None and getattr(est, "criterion", "") == "likelihood" and true_pairs
                and (found is None or found == true_pairs)):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    iv = identifiability(est, params=("rbar_v",)).intervals["rbar_v"]
                row.covered = float(iv.covers(r_true))
                row.note += f" 90%: [{iv.lower:.3g}, {iv.upper:.3g}]"
            except Exception as exc:    # an interval that fails is a result, not a crash
                row.note += f" interval failed: {type(exc).__name__}"

    def fit(network, criterion):
        """(model, estimator) of ``network`` fitted on the calibration days."""
        if not network.convection_edges and criterion == SIM:
            return ThermalModel(network), None      # nothing to estimate
        if criterion == SIM:
            from thermctl.estimate import SimulationEstimator
            est = SimulationEstimator(network, identifiability=False).fit(cal)
            return est.model_, est
        kw = {KAL: {}, KAL_ALL: {"fit_rows": "all"}, KSTEP: {"criterion": "kstep"}}[criterion]
        est = LikelihoodEstimator(network, **kw).fit(cal)
        return est.model_, est

    def row(method, criterion, work):
        r = Row(label, method, criterion)
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model, est, found, note = work()
            r.seconds = time.perf_counter() - t0
            r.note = note
            if est is not None and hasattr(est, "problem_") and hasattr(est.problem_, "fit_rule"):
                r.note += f" rows={est.problem_.fit_rule}"
            score(r, model, found, est)
        except Exception as exc:        # a failing method is a result, not a crash
            r.seconds = time.perf_counter() - t0
            r.note = f"failed: {type(exc).__name__}: {str(exc)[:80]}"
        b.rows.append(r)
        say(f"  {method:19s} {criterion:18s} R̄v err {r.rbar_err:6.1%} step err {r.step_err:6.1%} "
            f"val {r.val:+7.2%} ({r.val_zone or '-'}) cover {r.covered:3.0f} "
            + (f"hits {r.n_hit}/{r.n_true} false {r.false_edges:.0f} " if r.structural else "")
            + f"{r.seconds:5.0f} s{r.note}", flush=True)

    crits = [c for c in (SIM, KAL, KAL_ALL, KSTEP) if paper or c != SIM]
    for c in crits:
        row(TRUE, c, lambda c=c: (*fit(tb.network, c), None, ""))

    sid_nets = {}
    for method, (graph, rule) in STRUCTURE.items():
        def structure(graph=graph, rule=rule, method=method):
            from thermctl.structure import StructureIdentifier
            t0 = time.perf_counter()
            sid = StructureIdentifier(method=graph, rule=rule).fit(cal, tb.network.conduction_only())
            sid_nets[method] = (sid.network_, {tuple(sorted((e.a, e.b))) for e in sid.edges_},
                                time.perf_counter() - t0)
        for c in ([SIM, KAL] if method == "SIN + argmax" and paper else [KAL]):
            def work(method=method, c=c, structure=structure):
                if method not in sid_nets:
                    structure()
                net, found, _ = sid_nets[method]
                model, est = fit(net, c)
                return model, est, found, ""
            row(method, c, work)

    if selection:
        def select(**kw):
            def work():
                sel = select_air_paths(tb.spec, cal, **kw)
                found = {tuple(sorted(e[:2])) for e in sel.edges}
                return sel.estimator.model_, sel.estimator, found, f" {sel.n_fits} fits;"
            return work
        row("model-based (BIC)", KAL, select())
        row("SIN + model-based", KAL, select(candidates="sin", direction="backward"))

    r = Row(label, COND, "—", seconds=0.0, n_true=len(true_pairs), n_hit=0,
            false_edges=0.0)
    score(r, cond)
    b.rows.append(r)
    say(f"  {COND:19s} {'—':18s} step err {r.step_err:6.1%} val {r.val:+7.2%} ({r.val_zone})",
        flush=True)
    return b


# ---------------------------------------------------------------------------- table
def _agg(rs, attr, fn):
    v = np.array([getattr(r, attr) for r in rs], dtype=float)
    v = v[np.isfinite(v)]
    return float(fn(v)) if v.size else np.nan


def summarize(rows):
    """Per (method, criterion): the table's numbers (dict of column → value)."""
    out = {}
    for key in dict.fromkeys((r.method, r.criterion) for r in rows):
        rs = [r for r in rows if (r.method, r.criterion) == key]
        n_true = sum(r.n_true for r in rs)
        structural = key[0] != TRUE
        out[key] = {
            "n": len(rs),
            "failed": sum(r.note.startswith("failed") for r in rs),
            "rbar_med": _agg(rs, "rbar_err", np.median),
            "rbar_p90": _agg(rs, "rbar_err", lambda v: np.percentile(v, 90)),
            "cover": _agg(rs, "covered", np.mean),
            "n_cover": int(np.isfinite([r.covered for r in rs]).sum()),
            "step": _agg(rs, "step_err", np.median),
            "val_med": _agg(rs, "val", np.median),
            "val_max": _agg(rs, "val", np.max),
            "recall": (sum(r.n_hit for r in rs if np.isfinite(r.false_edges)) / n_true
                       if structural and n_true else np.nan),
            "false": _agg(rs, "false_edges", np.mean) if structural else np.nan,
            "time": _agg(rs, "seconds", np.sum),
        }
    return out


COLUMNS = [  # key, header, format, width
    ("n", "n", "d", 3), ("rbar_med", "R̄v err med", ".1%", 10), ("rbar_p90", "R̄v err p90", ".1%", 10),
    ("cover", "cover", ".0%", 6), ("step", "step err", ".1%", 8), ("val_med", "val med", "+.2%", 8),
    ("val_max", "val max", "+.2%", 8), ("recall", "recall", ".2f", 6), ("false", "false/bld", ".2f", 9),
    ("time", "time s", ".0f", 7)]


def table(rows):
    """One line per method × criterion (medians / pooled over the buildings)."""
    def fmt(v, spec, width):
        return format(v, spec).rjust(width) if np.isfinite(v) else "—".rjust(width)

    head = f"{'method':19s} {'criterion':18s} " + " ".join(h.rjust(w) for _, h, _, w in COLUMNS)
    lines = [head, "-" * len(head)]
    for (m, c), s in summarize(rows).items():
        cells = [fmt(s[k], f, w) if k != "n" else f"{s[k]:{w}d}" for k, _, f, w in COLUMNS]
        extra = f"  ({s['failed']} failed)" if s["failed"] else ""
        lines.append(f"{m:19s} {c:18s} " + " ".join(cells) + extra)
    return "\n".join(lines)


def targets(rows):
    """Which rows meet each of the issue's targets (lines of text)."""
    s = summarize(rows)
    name = lambda k: f"{k[0]} × {k[1]}" if k[1] != "—" else k[0]       # noqa: E731

    def who(ok):
        hits = [name(k) for k, v in s.items() if ok(v)]
        return ", ".join(hits) if hits else "none"

    return [
        "targets (issue 11):",
        "  recall >= 0.9 and <= 0.2 false edges per building: "
        + who(lambda v: v["recall"] >= 0.9 and v["false"] <= 0.2),
        "  median R̄v error <= 25 %: " + who(lambda v: v["rbar_med"] <= 0.25),
        "  90 % intervals cover the truth in >= 80 % of cases: "
        + who(lambda v: v["n_cover"] > 0 and v["cover"] >= 0.8),
        "  median step-response error <= 10 %: " + who(lambda v: v["step"] <= 0.10),
        "  48-h validation <= 2 % worse than the oracle on every zone of every building: "
        + who(lambda v: v["val_max"] <= 0.02),
    ]


# ---------------------------------------------------------------------------- main
def main(argv=None) -> Result:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="one small building, 8 days (6 + 2)")
    ap.add_argument("--days", type=float, default=14.0,
                    help=f"generated days; the last {VAL_DAYS:g} validate (default 14)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--layouts", nargs="+", default=list(LAYOUTS), choices=list(LAYOUTS))
    ap.add_argument("--no-selection", action="store_true", help="skip the model-based rows")
    ap.add_argument("--no-paper", action="store_true", help="skip the simulation criterion")
    ap.add_argument("--quiet", action="store_true", help="print only the table")
    args = ap.parse_args(argv)
    # the library's log warnings (bounds, CV penalties) would interleave with the table
    logging.getLogger("thermctl").setLevel(logging.ERROR)
    t0 = time.perf_counter()
    kw = dict(selection=not args.no_selection, paper=not args.no_paper, verbose=not args.quiet)
    if args.quick:
        jobs = [("quick", dict(building=(spec_from_dict(QUICK_SPEC, source="quick"), QUICK_EDGES)),
                 args.seeds[0], 8.0)]
    else:
        jobs = [(n, LAYOUTS[n], s, args.days) for n in args.layouts for s in args.seeds]
    buildings = [run_building(n, k, s, d, **kw) for n, k, s, d in jobs]
    rows = [r for b in buildings for r in b.rows]
    text = table(rows)
    seconds = time.perf_counter() - t0
    print()
    print(text)
    print()
    print("\n".join(targets(rows)))
    print(f"\n{len(buildings)} building(s), {seconds:.0f} s")
    return Result(buildings, rows, text, seconds)


if __name__ == "__main__":
    main()
