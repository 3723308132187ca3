"""What a run leaves on disk: ``identification.json``, ``model.json``, ``validation.json``, figures.

The face side of the pipeline: :mod:`thermctl.identify` and :mod:`thermctl.validate` compute,
this module turns their results into documents and files (the CLI, the demo and notebooks
call it), so the pipeline itself needs neither :mod:`thermctl.report` nor :mod:`thermctl.plots`.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import DataError
from .io import model_to_dict, save_model
from .model import ThermalModel

if TYPE_CHECKING:  # only for annotations: keeps `import thermctl.outputs` light for the CLI
    from .identify import Identification

__all__ = ["staged_output", "write_outputs", "identification_document", "validation_document",
           "support_note"]


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


def validation_document(vr) -> dict:
    """The content of ``validation.json`` (with the report blocks)."""
    conv = lambda v: float(vr.to_data_units(v))  # noqa: E731
    rows = []
    for z in vr.open_loop["identified"].zones:
        row = {"zone": z}
        for name, r in vr.open_loop.items():
            row[f"RMSE {name}"] = conv(r.rmse[z])
            row[f"max {name}"] = conv(r.max_abs[z])
        rows.append(row)
    sr_rows = []
    for name, err in vr.step_errors.items():
        sr_rows.append({"model": name, **{f"{h:g} h": float(e) for h, e in zip(vr.horizons_h, err)}})
    blocks = [
        {"section": "Validation", "kind": "text", "title": "Open-loop prediction",
         "content": f"Simulated from {vr.window[0]} to {vr.window[1]} with measured inputs, "
                    f"from the paper's initial state; errors in {vr.units} (differences)."},
        {"section": "Validation", "kind": "table", "title": "Per-zone error", "content": rows},
    ]
    ks_rows = []
    for name, r in vr.kstep.items():
        ks_rows.append({"model": name, **{f"{h / 3600:g} h": conv(v)
                                          for h, v in zip(r.horizons, r.rmse_mean)}})
    if ks_rows:
        blocks.append({"section": "Validation", "kind": "table",
                       "title": f"k-step-ahead RMSE from Kalman-filtered states ({vr.units}, all zones)",
                       "content": ks_rows})
    if sr_rows:
        blocks.append({"section": "Validation", "kind": "table",
                       "title": "Step-response error vs the truth (relative Frobenius norm)",
                       "content": sr_rows})
    blocks.append({"section": "Validation", "kind": "note", "title": "What the data can support",
                   "content": support_note(vr)})
    return {"format": "thermctl-validation", "version": 1, "window": list(vr.window),
            "units": vr.units, "open_loop": rows,
            "rmse_mean": {k: conv(r.rmse_mean) for k, r in vr.open_loop.items()},
            "step_response_error": {k: v.tolist() for k, v in vr.step_errors.items()},
            "step_responses_K_per_100W": {k: v.tolist() for k, v in vr.step_responses.items()},
            "horizons_h": list(vr.horizons_h), "zones": vr.zones,
            "kstep_rmse": {k: {"horizons_s": r.horizons.tolist(), "zones": r.zones,
                               "rmse": np.vectorize(conv)(r.rmse).tolist(),
                               "rmse_mean": [conv(v) for v in r.rmse_mean],
                               "n": r.n.tolist()} for k, r in vr.kstep.items()},
            "report": blocks}


def support_note(vr) -> str:
    """Which of the three measures separates the models on these data, in words."""
    out = []
    ol = {k: r.rmse_mean for k, r in vr.open_loop.items()}
    if "identified" in ol and "conduction-only" in ol:
        gain = 1.0 - ol["identified"] / ol["conduction-only"]
        out.append(f"48-h open loop: the identified model is {100 * gain:+.0f} % better than "
                   "conduction-only" + (" — within what unmeasured gains and the unknown initial "
                                        "wall states move, so this measure cannot tell the "
                                        "models apart here" if abs(gain) < 0.05 else "") + ".")
    if "identified" in vr.kstep and "conduction-only" in vr.kstep:
        a, b = vr.kstep["identified"].rmse_mean, vr.kstep["conduction-only"].rmse_mean
        rel = 1.0 - a / b
        parts = ", ".join(f"{h / 3600:g} h {100 * r:+.0f} %" for h, r in zip(vr.kstep["identified"].horizons, rel))
        out.append(f"k-step ahead from filtered states (identified vs conduction-only): {parts}"
                   + (" — the data support the air paths at the horizons an MPC uses."
                      if np.nanmax(rel) > 0.05 else
                      " — no clear difference: on these data the air paths matter little "
                      "for prediction, or the gains hide them."))
    if vr.step_errors:
        e = vr.step_errors
        out.append(f"step responses vs the truth at 6 h: identified {100 * e['identified'][1]:.0f} %, "
                   f"conduction-only {100 * e['conduction-only'][1]:.0f} % — what a controller acts "
                   "through; only testbed data have a truth to compare with.")
    else:
        out.append("step responses: no truth to compare with on measured data; the figure shows "
                   "how far the identified couplings move heat between zones.")
    return " ".join(out)
