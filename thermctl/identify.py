"""The identification pipeline: data → structure → parameters → model (+ outputs).

This is what ``thermctl identify`` runs; it is a plain function so that notebooks,
the demo and the MPC examples can run exactly the same thing.
"""

from __future__ import annotations

import json
import logging
import shutil
import tempfile
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from . import __version__
from .data import Measurements
from .errors import BoundWarning, DataError, EstimationError
from .io import model_to_dict, save_model
from .model import ThermalModel
from .network import ThermalNetwork
from .structure import StructureIdentifier

__all__ = ["IdentifyOptions", "Identification", "identify", "write_outputs", "staged_output"]

logger = logging.getLogger(__name__)


CRITERIA = ("likelihood", "kstep", "simulation")
SELECTIONS = ("model", "scores")


@dataclass
class IdentifyOptions:
    """Settings of :func:`identify` (the CLI's options).

    The default is thermctl's grey-box identification: SIN proposes candidate air paths
    (walls allowed: an open door beside a wall is an air path), backward elimination by
    BIC on the Kalman-filter likelihood keeps the ones the data need, and R̄_v comes from
    the likelihood with unmeasured gains as random-walk states, with intervals. The
    paper's pipeline is ``criterion="simulation", selection="scores"``. Why the default
    differs from the paper: ``docs/identification.md`` (measured on a family of testbed
    buildings, ``benchmarks/identification.py``).

    Attributes
    ----------
    criterion : {"likelihood", "kstep", "simulation"}
        Parameter estimation criterion: Kalman likelihood (default), k-step-ahead
        prediction error from filtered states, or the paper's open-loop simulation error.
    selection : {"model", "scores"}
        ``model``: candidates pruned by an information criterion on the likelihood
        (:func:`thermctl.greybox.select_edges`); ``scores``: the paper's rule on the SIN
        scores alone (forced with ``criterion="simulation"``).
    candidates : {"sin", "sin+pairs", "all"}
        Candidates of the model-based selection: the union of SIN's argmax and threshold
        picks (walls allowed), pruned backward; ``sin+pairs``: those picks as the start,
        then forward over every pair of measured zones and backward again (finds pairs SIN
        misses, e.g. beside an open door; slower); ``all``: every pair with a known or
        estimable air path length, forward then backward. With too few days for SIN,
        ``all`` is used (noted).
    selection_criterion : {"bic", "aic", "holdout"}
    margin : float
        Criterion improvement an edge must bring to stay in the model [-].
    solar : bool
        Per-zone solar apertures on the data's ``solar:`` columns (grey-box criteria).
    intervals : {"profile", "wald", "none"}
        Uncertainty of R̄_v and τ0 (likelihood criterion).
    structure_method : {"sin", "glasso"}
        Concentration-graph method (paper: SIN).
    level : float
        SIN significance level (paper: 0.05).
    rule : {"paper", "threshold"}
        Edge selection rule of ``selection="scores"`` (paper: each zone's argmax partner).
    s_min : float
        Score threshold of the ``threshold`` rule.
    allow_parallel : bool
        ``selection="scores"``: keep zone pairs joined by a wall as candidates (the
        model-based selection always does).
    estimator : {"nlp", "single_shooting", "grid", "none"}
        ``criterion="simulation"``: ``nlp``: CasADi multiple-shooting NLP (IPOPT);
        ``single_shooting``: the same cost through the exact ZOH simulator; ``grid``: the
        paper's exhaustive search only; ``none``: keep the paper's R̄_v and C_v.
    window_hours : float
        ``criterion="simulation"``: cost window at the start of the calibration data [h]
        (paper: 12).
    initial_state : {"paper", "burn_in", "estimate"}
        ``criterion="simulation"``: initial-state handling of the cost.
    grid : bool
        ``criterion="simulation"``: also run the grid (the reference, and the J-vs-R̄_v
        figure).
    calibration, validation : tuple of str or None
        Date windows ``(start, end)``; default: :meth:`Measurements.split`.
    """

    criterion: str = "likelihood"
    selection: str = "model"
    candidates: str = "sin"
    selection_criterion: str = "bic"
    margin: float = 10.0
    solar: bool = True
    intervals: str = "profile"
    structure_method: str = "sin"
    level: float = 0.05
    rule: str = "paper"
    s_min: float = 0.25
    allow_parallel: bool = False
    estimator: str = "nlp"
    window_hours: float = 12.0
    initial_state: str = "paper"
    grid: bool = True
    calibration: tuple | None = None
    validation: tuple | None = None

    def check(self):
        for name, allowed in (("criterion", CRITERIA), ("selection", SELECTIONS),
                              ("candidates", ("sin", "sin+pairs", "all")),
                              ("selection_criterion", ("bic", "aic", "holdout")),
                              ("intervals", ("profile", "wald", "none")),
                              ("estimator", ("nlp", "single_shooting", "grid", "none"))):
            if getattr(self, name) not in allowed:
                raise DataError(f"identify option {name} must be one of {list(allowed)}, "
                                f"found {getattr(self, name)!r}")

    @property
    def paper(self) -> bool:
        """The paper's pipeline (simulation criterion, SIN-score selection)."""
        return self.criterion == "simulation"


@dataclass
class Identification:
    """Everything :func:`identify` found.

    Attributes
    ----------
    model : ThermalModel
        Spec + selected convection edges + fitted parameters.
    structure : StructureIdentifier or None
        The fitted SIN structure identifier (graphs, scores; its edges are the paper
        rule's picks). None when the data have too few days for SIN.
    estimate : EstimationResult or None
        Paper pipeline: the simulation-criterion fit.
    grid : GridResult or None
    calibration, validation : Measurements
    options : IdentifyOptions
    selection : SelectionResult or None
        Grey-box pipeline: the model-based selection (path, reasons).
    greybox : GreyboxEstimator or None
        Grey-box pipeline: the final fit of the selected structure.
    intervals : IdentifiabilityReport or None
    """

    model: ThermalModel
    structure: StructureIdentifier | None
    estimate: object
    grid: object
    calibration: Measurements
    validation: Measurements
    options: IdentifyOptions
    notes: list = field(default_factory=list)
    selection: object = None
    greybox: object = None
    intervals: object = None


def identify(meas: Measurements, options: IdentifyOptions | None = None,
             progress=None) -> Identification:
    """Identify the convection edges and their parameters from measured data.

    Parameters
    ----------
    meas : Measurements
        From :func:`thermctl.data.read_measurements`.
    options : IdentifyOptions, optional
    progress : callable, optional
        ``progress(stage, done, total)`` for progress bars.

    Returns
    -------
    Identification
    """
    opt = options or IdentifyOptions()
    opt.check()
    cal, val = meas.split(calibration=opt.calibration, validation=opt.validation)
    if opt.paper or opt.selection == "scores":
        ident = _identify_paper(meas, cal, val, opt, progress)
    else:
        ident = _identify_greybox(meas, cal, val, opt, progress)
    return ident


def _meta(meas, cal, val, opt, scores) -> dict:
    return {
        "edge_scores": scores,
        "data": {"source": meas.source, "start": str(meas.start), "end": str(meas.end),
                 "step_s": meas.step.total_seconds(), "units": meas.units,
                 "calibration": [str(cal.start), str(cal.end)],
                 "validation": [str(val.start), str(val.end)]},
        "options": asdict(opt),
        "thermctl": __version__,
    }


def _identify_paper(meas, cal, val, opt, progress) -> Identification:
    """SIN + rule, then R̄_v, C_v by the simulation criterion (or the grey-box criterion
    on the SIN-rule structure when ``selection="scores"`` with a grey-box criterion)."""
    spec = meas.spec
    net0 = ThermalNetwork(spec)
    notes = []
    if progress:
        progress("structure", 0, 1)
    sid = StructureIdentifier(method=opt.structure_method, level=opt.level, rule=opt.rule,
                              s_min=opt.s_min, allow_parallel=opt.allow_parallel)
    sid.fit(cal.frame, net0)
    if progress:
        progress("structure", 1, 1)
    net = sid.network_
    scores = {f"air:{e.a}-{e.b}": e.score for e in sid.edges_}
    est = grid = gb = ida = None
    from .model import C_V_PAPER, RBAR_V_PAPER
    rbar_v, c_v = RBAR_V_PAPER, C_V_PAPER
    if not net.convection_edges:
        notes.append("no convection edge selected: the model is conduction-only")
    elif not opt.paper:
        gb, ida = _greybox_fit(net, cal, opt, notes)
        rbar_v, c_v = gb.rbar_v_, gb.c_v_
    elif opt.estimator != "none":
        est, grid = _estimate(net, cal, opt, progress)
        if est is not None:
            rbar_v, c_v = est.rbar_v, est.c_v
        else:
            rbar_v, c_v = grid.best_rbar_v, grid.best_c_v
    meta = _meta(meas, cal, val, opt, scores)
    if gb is not None:
        meta["greybox"] = _greybox_meta(gb, ida)
    model = ThermalModel(net, rbar_v=rbar_v, c_v=c_v, meta=meta)
    return Identification(model, sid, est, grid, cal, val, opt, notes, greybox=gb, intervals=ida)


def _identify_greybox(meas, cal, val, opt, progress) -> Identification:
    """SIN candidates → backward elimination by BIC → grey-box fit with intervals."""
    from .greybox.selection import candidate_pairs, select_edges
    from .structure.selection import select_edges as rule_edges

    spec = meas.spec
    net0 = ThermalNetwork(spec)
    notes = []
    sid = None
    cands = start = None
    if opt.candidates in ("sin", "sin+pairs"):
        if progress:
            progress("structure", 0, 1)
        try:
            sid = StructureIdentifier(method=opt.structure_method, level=opt.level,
                                      rule="paper", s_min=opt.s_min, allow_parallel=True)
            sid.fit(cal.frame, net0)
        except DataError as exc:
            sid = None
            notes.append(f"SIN could not run ({exc}); every pair with an air path length "
                         "was a candidate instead")
        if progress:
            progress("structure", 1, 1)
        if sid is not None:
            dist = {p: spec.air_path_length(*p)[0] for p in sid.candidates_}
            picks = {tuple(sorted((e.a, e.b))) for e in sid.edges_}
            picks |= {tuple(sorted((e.a, e.b))) for e in rule_edges(
                {p: sid.scores_[p] for p in dist}, dist, sid.zones_, "threshold", opt.s_min)}
            cands = sorted(picks)
            if opt.candidates == "sin+pairs":
                # SIN's picks are the start; every measured pair may still enter, and the
                # backward pass may still drop a pick (SIN misses pairs whose partial
                # correlation another path hides, e.g. beside an open door)
                start = cands
                cands = sorted(set(cands) | {c.pair for c in candidate_pairs(
                    spec, include_unmeasured=False)})
    if cands is None:
        cands = [c.pair for c in candidate_pairs(spec)]
    scores = {} if sid is None else {f"air:{a}-{b}": sid.scores_.get((a, b), float("nan"))
                                     for a, b in cands}
    sel = gb = ida = None
    if not cands:
        notes.append("no candidate air path (no SIN pick, no pair with a length): the model "
                     "is conduction-only")
        net = net0
    else:
        n_done = [0]

        def say(msg):
            n_done[0] += 1
            if progress:
                progress("selection", min(n_done[0], len(cands)), len(cands))

        # from SIN's few picks: backward; from every pair: forward (cheaper and what
        # model-based selection does for small buildings)
        direction = "backward" if sid is not None and start is None else "both"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BoundWarning)
            sel = select_edges(spec, cal, candidates=cands, criterion=opt.selection_criterion,
                               direction=direction, margin=opt.margin, progress=say,
                               start=start or (),
                               final_criterion=opt.criterion, solar=opt.solar)
        net = ThermalNetwork(spec, sel.edges)
        if not sel.edges:
            notes.append("the data support no convection edge: the model is conduction-only")
        else:
            gb = sel.estimator
            ida = _intervals(gb, opt, notes)
            _misfit_note(ida, opt, notes)
    if gb is not None:
        rbar_v, c_v = gb.rbar_v_, gb.c_v_
    else:
        from .model import C_V_PAPER, RBAR_V_PAPER
        rbar_v, c_v = RBAR_V_PAPER, C_V_PAPER
    meta = _meta(meas, cal, val, opt, scores)
    if sel is not None:
        meta["selection"] = {"path": [[st.action, st.edge, st.value, st.delta] for st in sel.path],
                             "reasons": sel.reasons}
    if gb is not None:
        meta["greybox"] = _greybox_meta(gb, ida)
    model = ThermalModel(net, rbar_v=rbar_v, c_v=c_v, meta=meta)
    return Identification(model, sid, None, None, cal, val, opt, notes, selection=sel,
                          greybox=gb, intervals=ida)


def _greybox_fit(net, cal, opt, notes):
    """Grey-box fit of a given structure (``selection="scores"`` with a grey-box criterion)."""
    from .greybox import GreyboxEstimator
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", BoundWarning)
        gb = GreyboxEstimator(net, criterion=opt.criterion, solar=opt.solar).fit(cal)
    return gb, _intervals(gb, opt, notes)


def _intervals(gb, opt, notes):
    if opt.intervals == "none" or gb.criterion != "likelihood":
        return None
    from .greybox import identifiability
    try:
        return identifiability(gb, params=("rbar_v", "tau0"), method=opt.intervals)
    except (EstimationError, np.linalg.LinAlgError) as exc:
        notes.append(f"no intervals: {exc}")
        return None


def _misfit_note(ida, opt, notes):
    """Say so when the innovations are far from white: BIC then overstates the evidence."""
    iv = None if ida is None else ida.intervals.get("rbar_v")
    if iv is None or iv.inflation <= 4.0:
        return
    notes.append(
        f"the model's one-step innovations are far from white (sandwich/Hessian variance ratio "
        f"{iv.inflation:.0f} for R̄_v): the likelihood overstates the evidence, so "
        f"{opt.selection_criterion.upper()} differences of edges are inflated about that much and "
        "edges kept with a margin of "
        f"{opt.margin:g} may be spurious. Check the structure with --selection-criterion holdout "
        "(held-back days) or a larger --margin, and the spec (zone heat capacities, missing "
        "internal mass) — measured on the twin house in benchmarks/results/twinhouse.txt.")


def _greybox_meta(gb, ida) -> dict:
    out = {"criterion": gb.criterion, "params": dict(gb.params_), "nll": gb.nll_,
           "aic": gb.aic_, "bic": gb.bic_, "n_obs": gb.n_obs_, "rows": gb.problem_.fit_rule,
           "at_bounds": list(gb.result_.at_bounds), "fit_time_s": gb.fit_time_}
    if ida is not None:
        out["intervals"] = {k: {"value": iv.value, "lower": iv.lower, "upper": iv.upper,
                                "level": iv.level, "method": iv.method, "unit": iv.unit,
                                "identifiable": iv.identifiable}
                            for k, iv in ida.intervals.items()
                            if k.startswith(("rbar_v", "tau0"))}
        out["verdicts"] = dict(ida.verdicts)
    return out


def _estimate(net, cal, opt, progress):
    from .estimate import CostProblem, EstimationData, fit, grid_search

    data = EstimationData.from_frame(cal.frame, net)
    problem = CostProblem(net, data, window=opt.window_hours * 3600.0,
                          initial_state=opt.initial_state)
    grid = None
    if opt.grid or opt.estimator == "grid":
        grid = grid_search(problem, progress=progress)
    est = None
    if opt.estimator in ("nlp", "single_shooting"):
        method = "multiple_shooting" if opt.estimator == "nlp" else "single_shooting"
        theta0 = None if grid is None else (grid.best_rbar_v, grid.best_c_v)
        est = fit(problem, method=method, theta0=theta0, progress=progress)
    return est, grid


@dataclass
class staged_output:
    """Write into a temporary sibling directory; move files into place only on success.

    So outputs appear complete or not at all: a failed run leaves ``outdir`` as it was.
    """

    outdir: Path

    def __enter__(self) -> Path:
        self.outdir = Path(self.outdir)
        parent = self.outdir.resolve().parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
            self._tmp = Path(tempfile.mkdtemp(prefix=f".{self.outdir.name}.", dir=parent))
        except OSError as exc:
            raise DataError(f"{self.outdir}: cannot write the output directory ({exc.strerror})") from None
        if self.outdir.exists():
            # keep what is already there (e.g. identify's files when validate adds its own)
            for f in ("figures.json",):
                if (self.outdir / f).exists():
                    shutil.copy2(self.outdir / f, self._tmp / f)
        return self._tmp

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            return False
        try:
            self.outdir.mkdir(parents=True, exist_ok=True)
            for src in sorted(self._tmp.rglob("*")):
                dst = self.outdir / src.relative_to(self._tmp)
                if src.is_dir():
                    dst.mkdir(parents=True, exist_ok=True)
                else:
                    src.replace(dst)
        finally:
            shutil.rmtree(self._tmp, ignore_errors=True)
        return False


def write_outputs(ident: Identification, outdir) -> dict:
    """Write ``model.json``, ``identification.json`` and the figures into ``outdir``.

    Returns
    -------
    dict
        Role → path.
    """
    from .plots.structure import plot_correlations, plot_network, plot_scores
    from .report import save_figure

    with staged_output(outdir) as tmp:
        save_model(ident.model, tmp / "model.json")
        sid = ident.structure
        if sid is not None:
            how = ("SIN candidates, kept by " + ident.options.selection_criterion.upper()
                   if ident.selection is not None else f"{sid.method}, rule={sid.rule}")
            save_figure(plot_network(sid, network=ident.model.network,
                                     title=f"{ident.model.network.spec.name}: identified network ({how})"),
                        tmp, "network", "Structure",
                        "Identified network: conduction (solid) and convection (dashed) edges, "
                        "labelled with their SIN scores (paper Fig. 3).")
            save_figure(plot_scores(sid), tmp, "scores", "Structure",
                        "Edge scores s_ij: fraction of the time-of-day graphs with the edge.")
            save_figure(plot_correlations(sid), tmp, "correlations", "Structure",
                        "Marginal vs partial correlation over the day (paper Fig. 7).")
        if ident.grid is not None:
            from .plots.estimate import plot_cost_vs_rbar
            save_figure(plot_cost_vs_rbar(ident.grid, fit=ident.estimate), tmp, "cost", "Parameters",
                        "Prediction cost J vs R̄_v for several τ0 = R̄_v·C_v (paper Fig. 4).")
        doc = identification_document(ident)
        (tmp / "identification.json").write_text(json.dumps(doc, indent=2, default=_plain))
    out = Path(outdir)
    return {"model": out / "model.json", "identification": out / "identification.json"}


def _plain(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return v.item()
    return str(v)


def identification_document(ident: Identification) -> dict:
    """The content of ``identification.json`` (with the report blocks)."""
    sid, est, grid, model = ident.structure, ident.estimate, ident.grid, ident.model
    sel, gb, ida = ident.selection, ident.greybox, ident.intervals
    q = ident.calibration.quality
    scores = model.meta.get("edge_scores", {})
    edges = [{"a": e.a, "b": e.b, "d": e.d, "score": scores.get(e.name),
              "parallel_to_wall": frozenset((e.a, e.b)) in model.network.spec.wall_pairs()}
             for e in model.network.convection_edges]
    top = [] if sid is None else sorted(sid.scores_.items(), key=lambda kv: -kv[1])[:15]
    conv_tau = _edge_time_constants(model)
    opt = ident.options
    doc = {
        "format": "thermctl-identification", "version": 2,
        "method": ("paper (SIN rule + simulation criterion)" if opt.paper else
                   f"grey-box ({opt.criterion}; structure: "
                   + ("model-based selection" if sel is not None else "SIN rule") + ")"),
        "model": model_to_dict(model)["parameters"],
        "alpha": model.network.spec.alpha(),
        "alpha_per_wall": model.network.spec.alphas(),
        "structure": {
            "method": None if sid is None else sid.method,
            "level": None if sid is None else sid.level,
            "rule": None if sid is None else sid.rule,
            "days_used": None if sid is None else len(sid.days_used_),
            "days_dropped": [] if sid is None else [[str(d), r] for d, r in sid.days_dropped_],
            "sin_edges": [] if sid is None else [{"a": e.a, "b": e.b, "score": e.score}
                                                 for e in sid.edges_],
            "edges": edges,
            "top_scores": [{"a": a, "b": b, "score": s} for (a, b), s in top],
            "selection": None if sel is None else {
                "criterion": sel.criterion, "margin": opt.margin,
                "candidates": [c.name for c in sel.candidates],
                "path": [{"action": st.action, "edge": st.edge, "value": st.value,
                          "delta": st.delta, "edges": st.edges, "note": st.note}
                         for st in sel.path],
                "reasons": sel.reasons, "per_edge_rbar_v": sel.per_edge,
                "fits": sel.n_fits, "time_s": sel.time},
        },
        "estimate": _estimate_summary(est),
        "greybox": model.meta.get("greybox"),
        "grid": None if grid is None else {
            "best_rbar_v": grid.best_rbar_v, "best_c_v": grid.best_c_v, "best_J": grid.best_J,
            "n_points": int(np.size(grid.J)), "wall_time_s": grid.wall_time,
            "active_bounds": list(grid.active_bounds)},
        "edge_time_constants_s": conv_tau,
        "data_quality": q.to_dict(),
        "notes": ident.notes,
    }
    blocks = [
        {"section": "Data quality", "kind": "text", "title": "Summary", "content": q.summary()},
        {"section": "Structure", "kind": "text", "title": "Method", "content": doc["method"]},
        {"section": "Structure", "kind": "table", "title": "Selected convection edges",
         "content": [{"edge": f"{e['a']} – {e['b']}", "SIN score": e["score"], "d [m]": e["d"],
                      "beside a wall": "yes" if e["parallel_to_wall"] else "no"}
                     for e in edges] or [{"edge": "none", "SIN score": "", "d [m]": "",
                                          "beside a wall": ""}]},
    ]
    if sel is not None:
        blocks.append({"section": "Structure", "kind": "table",
                       "title": f"Model-based selection ({sel.criterion.upper()}, margin {opt.margin:g})",
                       "content": [{"step": st.action, "edge": st.edge or "",
                                    sel.criterion.upper(): st.value, "change": st.delta,
                                    "note": st.note} for st in sel.path]})
        blocks.append({"section": "Structure", "kind": "table", "title": "Why each candidate is in or out",
                       "content": [{"candidate": k, "reason": v} for k, v in sel.reasons.items()]})
    if top:
        blocks.append({"section": "Structure", "kind": "table",
                       "title": "Highest SIN pair scores (walls included)",
                       "content": [{"pair": f"{a} – {b}", "score": s} for (a, b), s in top]})
    if gb is not None:
        g = doc["greybox"]
        rows = [{"parameter": k, "value": v} for k, v in g["params"].items()]
        blocks.append({"section": "Parameters", "kind": "table",
                       "title": f"Grey-box estimate ({g['criterion']}, {g['n_obs']} observations, "
                                f"rows: {g['rows']})", "content": rows})
        if ida is not None:
            blocks.append({"section": "Parameters", "kind": "text", "title": "Identifiability",
                           "content": "\n".join(ida.verdicts.values())})
    if est is not None or grid is not None:
        rows = []
        if grid is not None:
            rows.append({"method": "grid (reference)", "R̄_v [K/(W m)]": grid.best_rbar_v,
                         "C_v [J/K]": grid.best_c_v, "J [K²]": grid.best_J,
                         "time [s]": grid.wall_time, "on a bound": ", ".join(grid.active_bounds) or "no"})
        if est is not None:
            rows.append({"method": est.method, "R̄_v [K/(W m)]": float(np.mean(est.rbar_v)),
                         "C_v [J/K]": est.c_v, "J [K²]": est.J, "time [s]": est.wall_time,
                         "on a bound": ", ".join(est.active_bounds) or "no"})
        blocks.append({"section": "Parameters", "kind": "table", "title": "Estimates", "content": rows})
        if est is not None and est.identifiability is not None:
            blocks.append({"section": "Parameters", "kind": "note", "title": "Identifiability",
                           "content": str(getattr(est.identifiability, "verdict", est.identifiability))})
        if (est is not None and est.active_bounds) or (grid is not None and grid.active_bounds):
            blocks.append({"section": "Parameters", "kind": "note", "title": "",
                           "content": "The optimum lies on a bound of the search range: the "
                                      "criterion, not the building, chose that value."})
    blocks.append({"section": "Model", "kind": "table", "title": "alpha and convection time constants",
                   "content": [{"quantity": "alpha used (median of walls)", "value": doc["alpha"]}]
                   + [{"quantity": f"slowest time constant of {k} [s]", "value": v}
                      for k, v in conv_tau.items()]})
    doc["report"] = blocks
    return doc


def _estimate_summary(est):
    if est is None:
        return None
    out = {k: getattr(est, k) for k in ("rbar_v", "c_v", "tau0", "J", "method", "discretisation",
                                        "status", "success", "iterations", "wall_time",
                                        "active_bounds", "initial_state") if hasattr(est, k)}
    ida = getattr(est, "identifiability", None)
    if ida is not None:
        out["identifiability"] = str(getattr(ida, "verdict", ida))
    return out


def _edge_time_constants(model: ThermalModel) -> dict:
    """Slowest time constant of each convection edge's own 3R2C chain [s]."""
    from . import rc
    out = {}
    p = model.p
    m = len(model.network.convection_edges)
    for k, e in enumerate(model.network.convection_edges):
        R = p[k] * e.d
        out[e.name] = rc.time_constant([R, R, R], [p[m + k], p[m + k]])
    return out
