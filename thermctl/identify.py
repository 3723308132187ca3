"""The identification pipeline: data → structure → parameters → model (+ outputs).

This is what ``thermctl identify`` runs; it is a plain function so that notebooks,
the demo and the MPC examples can run exactly the same thing.
"""

from __future__ import annotations

import json
import logging
import shutil
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from . import __version__
from .data import Measurements
from .errors import DataError
from .io import model_to_dict, save_model
from .model import ThermalModel
from .network import ThermalNetwork
from .structure import StructureIdentifier

__all__ = ["IdentifyOptions", "Identification", "identify", "write_outputs", "staged_output"]

logger = logging.getLogger(__name__)


@dataclass
class IdentifyOptions:
    """Settings of :func:`identify` (the CLI's options).

    Attributes
    ----------
    structure_method : {"sin", "glasso"}
        Concentration-graph method (paper: SIN).
    level : float
        SIN significance level (paper: 0.05).
    rule : {"paper", "threshold"}
        Edge selection rule (paper: each zone's argmax partner).
    s_min : float
        Score threshold of the ``threshold`` rule.
    allow_parallel : bool
        Keep zone pairs joined by a wall as candidates.
    estimator : {"nlp", "single_shooting", "grid", "none"}
        ``nlp``: CasADi multiple-shooting NLP (IPOPT); ``single_shooting``: the same cost
        through the exact ZOH simulator; ``grid``: the paper's exhaustive search only;
        ``none``: keep the paper's R̄_v and C_v.
    window_hours : float
        Cost window at the start of the calibration data [h] (paper: 12).
    initial_state : {"paper", "burn_in", "estimate"}
        Initial-state handling of the cost.
    grid : bool
        Also run the grid (the reference, and the J-vs-R̄_v figure).
    calibration, validation : tuple of str or None
        Date windows ``(start, end)``; default: :meth:`Measurements.split`.
    """

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


@dataclass
class Identification:
    """Everything :func:`identify` found.

    Attributes
    ----------
    model : ThermalModel
        Spec + selected convection edges + fitted parameters.
    structure : StructureIdentifier
        The fitted structure identifier (graphs, scores, edges).
    estimate : EstimationResult or None
    grid : GridResult or None
    calibration, validation : Measurements
    options : IdentifyOptions
    """

    model: ThermalModel
    structure: StructureIdentifier
    estimate: object
    grid: object
    calibration: Measurements
    validation: Measurements
    options: IdentifyOptions
    notes: list = field(default_factory=list)


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
    cal, val = meas.split(calibration=opt.calibration, validation=opt.validation)
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
    est = grid = None
    from .model import C_V_PAPER, RBAR_V_PAPER
    rbar_v, c_v = RBAR_V_PAPER, C_V_PAPER
    if not net.convection_edges:
        notes.append("no convection edge selected: the model is conduction-only")
    elif opt.estimator != "none":
        est, grid = _estimate(net, cal, opt, progress)
        if est is not None:
            rbar_v, c_v = est.rbar_v, est.c_v
        else:
            rbar_v, c_v = grid.best_rbar_v, grid.best_c_v
    meta = {
        "edge_scores": scores,
        "data": {"source": meas.source, "start": str(meas.start), "end": str(meas.end),
                 "step_s": meas.step.total_seconds(), "units": meas.units,
                 "calibration": [str(cal.start), str(cal.end)],
                 "validation": [str(val.start), str(val.end)]},
        "options": asdict(opt),
        "thermctl": __version__,
    }
    model = ThermalModel(net, rbar_v=rbar_v, c_v=c_v, meta=meta)
    return Identification(model, sid, est, grid, cal, val, opt, notes)


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
        save_figure(plot_network(sid), tmp, "network", "Structure",
                    "Identified network: conduction (solid) and convection (dashed) edges (paper Fig. 3).")
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
    q = ident.calibration.quality
    edges = [{"a": e.a, "b": e.b, "score": e.score, "d": e.d} for e in sid.edges_]
    top = sorted(sid.scores_.items(), key=lambda kv: -kv[1])[:15]
    conv_tau = _edge_time_constants(model)
    doc = {
        "format": "thermctl-identification", "version": 1,
        "model": model_to_dict(model)["parameters"],
        "alpha": model.network.spec.alpha(),
        "alpha_per_wall": model.network.spec.alphas(),
        "structure": {
            "method": sid.method, "level": sid.level, "rule": sid.rule,
            "days_used": len(sid.days_used_), "days_dropped": [[str(d), r] for d, r in sid.days_dropped_],
            "edges": edges,
            "top_scores": [{"a": a, "b": b, "score": s} for (a, b), s in top],
        },
        "estimate": _estimate_summary(est),
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
        {"section": "Structure", "kind": "table", "title": "Selected convection edges",
         "content": [{"edge": f"{e['a']} – {e['b']}", "score": e["score"], "d [m]": e["d"]}
                     for e in edges] or [{"edge": "none", "score": "", "d [m]": ""}]},
        {"section": "Structure", "kind": "table", "title": "Highest pair scores (walls included)",
         "content": [{"pair": f"{a} – {b}", "score": s} for (a, b), s in top]},
    ]
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
