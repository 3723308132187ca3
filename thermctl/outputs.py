"""What a run leaves on disk: ``identification.json``, ``model.json``, ``validation.json``, figures.

The face side of the pipeline: :mod:`thermctl.identify` and :mod:`thermctl.validate` compute,
this module turns their results into documents and files (the CLI, the demo and notebooks
call it), so the pipeline itself needs neither :mod:`thermctl.report` nor :mod:`thermctl.plots`.
"""

from __future__ import annotations

import errno
import hashlib
import json
import secrets
import shutil
import tempfile
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import DataError
from .io import model_to_dict, save_model
from .model import ThermalModel
from .validate import support_note

if TYPE_CHECKING:  # only for annotations: keeps `import thermctl.outputs` light for the CLI
    from .identify import Identification

__all__ = ["staged_output", "write_outputs", "identification_document", "validation_document",
           "write_step_responses", "check_outdir", "check_consistent", "new_run_id",
           "STEP_RESPONSES_FILE"]


STEP_RESPONSES_FILE = "validation-step-responses.npz"
"""The step-response matrices of ``validate`` (:func:`write_step_responses`): 490 zones
made 72 MB of JSON numbers, which nothing reads back as text."""

# What thermctl writes into an output directory. The run outputs belong to one
# identification: identify replaces all of them, so none of an earlier run's survive to be
# mixed with the new one (issue 22). Files not in this list are never deleted.
RUN_FILES = ("identification.json", "model.json", "validation.json", STEP_RESPONSES_FILE,
             "reduction.json", "figures.json", "report.html")
FIGURES = "figures"
# written by thermctl but belonging to no identification (the demo's testbed data, which
# identify then reads): neither replaced nor counted as foreign
KEPT = ("testbed",)

# the documents that name the identification they belong to, and under which key
_REFERS = {"validation.json": "identification_run_id", "reduction.json": "identification_run_id"}


@dataclass
class staged_output:
    """Write into a temporary sibling directory; move files into place only on success.

    So outputs appear complete or not at all: a failed run leaves ``outdir`` as it was.

    Parameters
    ----------
    outdir : str or Path
    replace : bool
        ``True`` (identify): the staged files are the complete set of run outputs; every
        run output of an earlier run (:data:`RUN_FILES` and the figures its ``figures.json``
        lists) is removed, other files are kept. ``False`` (validate): the staged files are
        added to the run outputs already there, which must belong to the same identification.
    """

    outdir: Path
    replace: bool = False

    def __enter__(self) -> Path:
        self.outdir = Path(self.outdir)
        if self.replace:
            check_outdir(self.outdir)
        parent = self.outdir.resolve().parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
            self._tmp = Path(tempfile.mkdtemp(prefix=f".{self.outdir.name}.", dir=parent))
        except OSError as exc:
            raise DataError(f"{self.outdir}: cannot write the output directory ({exc.strerror})") from None
        if self.outdir.exists() and not self.replace:
            # keep what is already there (e.g. identify's files when validate adds its own)
            for f in ("figures.json",):
                if (self.outdir / f).exists():
                    shutil.copy2(self.outdir / f, self._tmp / f)
        return self._tmp

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            return False
        backup = None
        try:
            if not self.replace:
                problems = _problems(_documents(self.outdir) | _documents(self._tmp))
                if problems:
                    raise DataError(f"{self.outdir}: {problems[0]}; write into the model's own "
                                    "directory or an empty --out")
            old = _run_outputs(self.outdir) if self.replace else []
            new = sorted(f for f in self._tmp.rglob("*") if not f.is_dir())
            try:
                self.outdir.mkdir(parents=True, exist_ok=True)
                # the earlier run's outputs go aside first, so that a failure while moving
                # the new ones in can put them back
                backup = Path(tempfile.mkdtemp(prefix=f".{self.outdir.name}.old.",
                                               dir=self.outdir.resolve().parent)) if old else None
                for f in old:
                    _move(self.outdir / f, backup / f)
                placed = []
                try:
                    for src in new:
                        rel = src.relative_to(self._tmp)
                        _move(src, self.outdir / rel)
                        placed.append(rel)
                except BaseException:
                    for rel in placed:
                        (self.outdir / rel).unlink(missing_ok=True)
                    for f in old:
                        _move(backup / f, self.outdir / f)
                    raise
            except OSError as exc:
                raise DataError(f"{self.outdir}: cannot write the outputs ({exc.strerror})") from None
            figdir = self.outdir / FIGURES
            if old and figdir.is_dir() and not any(figdir.iterdir()):
                figdir.rmdir()
        finally:
            shutil.rmtree(self._tmp, ignore_errors=True)
            if backup is not None:
                shutil.rmtree(backup, ignore_errors=True)
        return False


def _move(src: Path, dst: Path) -> None:
    """Rename ``src`` to ``dst`` (a file), across file systems if need be."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        src.replace(dst)
    except OSError as exc:
        if exc.errno != errno.EXDEV:
            raise
        shutil.copy2(src, dst)   # the staging directory is a sibling: --out may be a mount point
        src.unlink()


def _run_outputs(outdir: Path) -> list[Path]:
    """Run outputs of an earlier run in ``outdir``, relative to it: only files thermctl wrote."""
    if not outdir.is_dir():
        return []
    out = [Path(f) for f in RUN_FILES if (outdir / f).is_file()]
    # figures: only those the manifest lists (save_figure writes both); anything else a
    # user put in figures/ stays
    for entry in _figure_manifest(outdir):
        rel = Path(FIGURES) / f"{entry}.png"
        if (outdir / rel).is_file():
            out.append(rel)
    return out


def _figure_manifest(outdir: Path) -> list[str]:
    try:
        manifest = json.loads((outdir / "figures.json").read_text())
        return [str(m["name"]) for m in manifest if "/" not in str(m["name"])]
    except (OSError, ValueError, TypeError, KeyError):
        return []


def check_outdir(outdir) -> None:
    """Refuse an output directory that holds other files and no thermctl outputs.

    thermctl replaces its own outputs in ``outdir`` and never deletes other files; but
    writing into a directory of someone else's files (``--out .`` in a home directory, the
    data directory) would mix them, so that is refused. Hidden files (``.gitignore``) and the
    demo's ``testbed/`` do not count. Cheap: the CLI may call it before a long identification.

    Raises
    ------
    DataError
        ``outdir`` is a file, or a non-empty directory with no thermctl outputs.
    """
    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise DataError(f"{outdir}: exists and is not a directory; choose another --out")
    if not outdir.is_dir():
        return
    names = {p.name for p in outdir.iterdir() if not p.name.startswith(".")}
    ours = names & (set(RUN_FILES) | {FIGURES})
    foreign = sorted(names - set(RUN_FILES) - {FIGURES} - set(KEPT))
    if foreign and not ours:
        raise DataError(f"{outdir}: not empty and holds no thermctl outputs ({', '.join(foreign[:3])}"
                        f"{', ...' if len(foreign) > 3 else ''}); choose an empty or new --out directory")


def new_run_id(model: ThermalModel, created: str) -> str:
    """Identifier of one identification: hex digest of the model document, its creation time and a nonce.

    Parameters
    ----------
    model : ThermalModel
    created : str
        Creation time (ISO 8601, UTC).

    Returns
    -------
    str
        16 hex digits (64 bits: two runs never share one in practice).
    """
    doc = model_to_dict(model)
    doc["meta"] = {k: v for k, v in doc["meta"].items() if k not in ("run_id", "created")}
    # and a nonce: the same model written twice within a clock tick is still two runs
    body = json.dumps(doc, sort_keys=True, default=_plain) + created + secrets.token_hex(8)
    return hashlib.sha256(body.encode()).hexdigest()[:16]


def _documents(outdir: Path) -> dict:
    """File name → parsed JSON (or the exception) of the run documents in ``outdir``."""
    docs = {}
    for name in ("identification.json", "model.json", *_REFERS):
        p = Path(outdir) / name
        if p.is_file():
            try:
                docs[name] = json.loads(p.read_text())
            except (OSError, ValueError) as exc:
                docs[name] = exc
    return docs


def _problems(docs: dict) -> list[str]:
    out = [f"{name}: unreadable ({exc})" for name, exc in docs.items() if isinstance(exc, Exception)]
    docs = {k: v for k, v in docs.items() if isinstance(v, dict)}
    ident = docs.get("identification.json", {}).get("run_id")
    model = (docs.get("model.json", {}).get("meta") or {}).get("run_id")
    if "identification.json" in docs and "model.json" in docs and ident != model:
        out.append(f"model.json (run {model}) is not the model of identification.json (run {ident}); "
                   "re-run `thermctl identify`")
    ref = ident or model
    for name, key in _REFERS.items():
        if name not in docs or ref is None:
            continue   # nothing to belong to, or outputs from before run ids: cannot tell
        got = docs[name].get(key)
        if got is None:
            out.append(f"{name} does not name the identification it belongs to (no run id), "
                       f"and run {ref} is here; re-run it")
        elif got != ref:
            out.append(f"{name} belongs to identification run {got}, not to run {ref} here; re-run it")
    return out


def check_consistent(outdir) -> list[str]:
    """Problems that show the outputs in ``outdir`` come from more than one run.

    Every identification has a ``run_id`` (``identification.json["run_id"]``,
    ``model.json["meta"]["run_id"]``); ``validation.json`` (and ``reduction.json``, when it
    says) name the run they belong to as ``identification_run_id``. A report built from
    pieces of different runs would show, e.g., a validation of a model that is no longer there.

    Parameters
    ----------
    outdir : str or Path

    Returns
    -------
    list of str
        One line per problem, naming the file; empty when the pieces belong together (or
        ``outdir`` holds no identification to compare with).
    """
    return _problems(_documents(Path(outdir)))


def write_outputs(ident: Identification, outdir) -> dict:
    """Write ``model.json``, ``identification.json`` and the figures into ``outdir``.

    They replace every output of an earlier run there (``validation.json``, ``figures/``, the
    report...): these would describe another model. Files thermctl did not write are kept;
    a non-empty ``outdir`` without thermctl outputs is refused (:func:`check_outdir`). The
    identification gets a ``run_id`` (:func:`new_run_id`, also put in ``ident.model.meta``).

    Returns
    -------
    dict
        Role → path.

    Raises
    ------
    DataError
        ``outdir`` cannot be written, or holds other files and no thermctl outputs.
    """
    from .plots.structure import plot_correlations, plot_network, plot_scores
    from .report import save_figure

    check_outdir(outdir)   # before drawing figures: refusing is cheap
    meta = ident.model.meta
    if "run_id" not in meta:   # the same identification written again keeps its id
        meta["created"] = datetime.now(timezone.utc).isoformat()
        meta["run_id"] = new_run_id(ident.model, meta["created"])
    with staged_output(outdir, replace=True) as tmp:
        save_model(ident.model, tmp / "model.json")
        sid = ident.structure
        if sid is not None:
            sel = ident.options.selection
            how = (("SIN" if sel.candidates == "sin" else sel.candidates) + " candidates, kept by "
                   + sel.criterion.upper()
                   if ident.selection is not None else f"{sid.method}, rule={sid.rule}")
            save_figure(plot_network(sid, network=ident.model.network,
                                     title=f"{ident.model.network.spec.name}: identified network ({how})"),
                        tmp, "network", "Structure",
                        "Identified network: conduction (solid) and convection (dashed) edges, "
                        "labelled with their SIN scores (paper Fig. 3).")
            save_figure(plot_scores(sid), tmp, "scores", "Structure",
                        "Edge scores s_ij: fraction of the time-of-day graphs with the edge.")
            if hasattr(sid, "graphs_"):    # the building's graphs (not the neighbourhoods')
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
        "run_id": model.meta.get("run_id"), "created": model.meta.get("created"),
        "method": ("paper (SIN rule + simulation criterion)" if opt.paper else
                   f"grey-box ({opt.estimation.criterion}; structure: "
                   + ("model-based selection" if sel is not None else
                      "model-based selection in one local problem per measured zone"
                      if ident.local is not None else "SIN rule") + ")"),
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
                "criterion": sel.criterion, "margin": opt.selection.margin,
                "candidates": [c.name for c in sel.candidates],
                "path": [{"action": st.action, "edge": st.edge, "value": st.value,
                          "delta": st.delta, "edges": st.edges, "note": st.note}
                         for st in sel.path],
                "reasons": sel.reasons, "per_edge_rbar_v": sel.per_edge,
                "fits": sel.n_fits, "time_s": sel.time},
            "stability": (model.meta.get("selection") or {}).get("stability"),
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
                       "title": f"Model-based selection ({sel.criterion.upper()}, margin {opt.selection.margin:g})",
                       "content": [{"step": st.action, "edge": st.edge or "",
                                    sel.criterion.upper(): st.value, "change": st.delta,
                                    "note": st.note} for st in sel.path]})
        blocks.append({"section": "Structure", "kind": "table", "title": "Why each candidate is in or out",
                       "content": [{"candidate": k, "reason": v} for k, v in sel.reasons.items()]})
    stab = doc["structure"]["stability"]
    if stab:
        from .network import air_path_name
        final = {air_path_name(e["a"], e["b"]) for e in edges}
        blocks.append({
            "section": "Structure", "kind": "table",
            "title": (f"Stability selection ({stab['ok']} resamples of half the "
                      f"{stab['block_days']}-day blocks; threshold {stab['threshold']:g})"),
            "content": [{"candidate": nm, "chosen on [-]": f,
                         "in the model": ("yes" if nm in final else
                                          "dropped: below threshold" if nm in stab["dropped"]
                                          else "no")}
                        for nm, f in sorted(stab["frequency"].items(), key=lambda kv: -kv[1])]})
    if top:
        blocks.append({"section": "Structure", "kind": "table",
                       "title": "Highest SIN pair scores (walls included)",
                       "content": [{"pair": f"{a} – {b}", "score": s} for (a, b), s in top]})
    if gb is not None or (doc.get("greybox") or {}).get("params"):
        # a local model without a whole-building refit carries its zones' parameters too
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
    from .model import ConvectionParameters
    cp = ConvectionParameters.from_model(model)
    out = {}
    for e, rb, cv in zip(model.network.convection_edges, cp.rbar_v, cp.c_v):
        R = rb * e.d
        out[e.name] = rc.time_constant([R, R, R], [cv, cv])
    return out


def write_step_responses(vr, path) -> None:
    """``validate``'s step-response matrices as ``.npz``: one array per model (``identified``,
    ``conduction-only``, ``truth``), ``G[h, j, i]`` the rise of zone ``j`` [K] at horizon
    ``h`` after 100 W into zone ``i`` (:func:`thermctl.validate.step_response_matrix`),
    with ``zones`` and ``horizons_h`` [h]. ``validation.json`` names the file.

    Examples
    --------
    >>> import numpy as np                                             # doctest: +SKIP
    >>> f = np.load("out/validation-step-responses.npz")               # doctest: +SKIP
    >>> f["identified"][0][:, 2]    # 1 h after heating the third zone # doctest: +SKIP
    """
    np.savez_compressed(path, zones=np.array(vr.zones), horizons_h=np.asarray(vr.horizons_h, float),
                        **{k: np.asarray(v, float) for k, v in vr.step_responses.items()})


def validation_document(vr, model: ThermalModel | None = None) -> dict:
    """The content of ``validation.json`` (with the report blocks).

    Parameters
    ----------
    vr : ValidationReport
    model : ThermalModel, optional
        The validated model: its ``meta["run_id"]`` goes in as ``identification_run_id``,
        so that :func:`check_consistent` can tell a validation of another run.
    """
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
    for n in vr.notes:
        blocks.append({"section": "Validation", "kind": "note", "title": "Not computed",
                       "content": n})
    blocks.append({"section": "Validation", "kind": "note", "title": "What the data can support",
                   "content": support_note(vr)})
    return {"format": "thermctl-validation", "version": 2,
            "identification_run_id": None if model is None else model.meta.get("run_id"),
            # the verdict weighs every horizon; its per-horizon numbers travel with it
            "verdict": vr.verdict.to_dict(),
            "window": list(vr.window),
            "units": vr.units, "open_loop": rows,
            "rmse_mean": {k: conv(r.rmse_mean) for k, r in vr.open_loop.items()},
            "step_response_error": {k: v.tolist() for k, v in vr.step_errors.items()},
            "step_responses": {"file": STEP_RESPONSES_FILE, "unit": "K per 100 W",
                               "models": list(vr.step_responses),
                               "shape": "(horizon, zone responding, zone heated)"},
            "horizons_h": list(vr.horizons_h), "zones": vr.zones,
            "kstep_rmse": {k: {"horizons_s": r.horizons.tolist(), "zones": r.zones,
                               "rmse": np.vectorize(conv)(r.rmse).tolist(),
                               "rmse_mean": [conv(v) for v in r.rmse_mean],
                               "n": r.n.tolist()} for k, r in vr.kstep.items()},
            "notes": list(vr.notes),
            "report": blocks}


