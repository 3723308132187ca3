"""`thermctl identify | validate | report | simulate | demo`: the end-to-end job."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pandas as pd
import typer
from rich.table import Table

from ..data import read_measurements
from ..errors import DataError, ModelError
from ..io import load_model
from ..spec import load_spec
from . import app
from ._common import console, handle_errors, progress

UNITS_HELP = "Units of the data file: si (°C, kg/s) or imperial (°F, CFM)."


def _progress_callback(bar):
    tasks = {}

    def cb(stage, done, total):
        if stage not in tasks:
            tasks[stage] = bar.add_task(stage, total=total)
        bar.update(tasks[stage], completed=done, total=total)
    return cb


def _truth_model(truth_path: Path | None, data_path: Path, spec):
    """The true model of testbed data: --truth FILE, or truth.json beside the data."""
    from ..model import ThermalModel
    from ..network import ThermalNetwork
    from ..testbed.output import load_truth

    path = truth_path or (Path(data_path).parent / "truth.json")
    if not Path(path).is_file():
        if truth_path is not None:
            raise DataError(f"{truth_path}: truth file not found")
        return None
    truth = load_truth(path)
    return ThermalModel(ThermalNetwork(spec, truth.edges), truth.rbar_v, truth.c_v)


@app.command()
@handle_errors
def identify(
    data: Path = typer.Argument(..., help="Measurements (CSV or parquet, wide: time, T:<node>, Ts:<zone>, ms:<zone>...)."),
    building: Path = typer.Option(..., "--building", "-b", help="Building spec (YAML or JSON)."),
    out: Path = typer.Option(Path("thermctl-out"), "--out", "-o", help="Output directory."),
    units: str = typer.Option("si", help=UNITS_HELP),
    method: str = typer.Option("sin", help="Concentration graphs: sin (paper) or glasso."),
    rule: str = typer.Option("paper", help="Edge selection: paper (argmax per zone) or threshold."),
    s_min: float = typer.Option(0.25, help="Score threshold for --rule threshold."),
    level: float = typer.Option(0.05, help="SIN significance level."),
    allow_parallel: bool = typer.Option(False, help="Allow air paths beside walls (open doors)."),
    estimator: str = typer.Option("nlp", help="nlp (multiple shooting, IPOPT), single_shooting, grid or none."),
    window_hours: float = typer.Option(12.0, help="Cost window at the start of the calibration data (h)."),
    initial_state: str = typer.Option("paper", help="paper (mean of ends), burn_in or estimate."),
    grid: bool = typer.Option(True, help="Also run the paper's grid search (reference, Fig. 4)."),
    calibration: str = typer.Option(None, help="Calibration window START..END (dates)."),
    validation: str = typer.Option(None, help="Validation window START..END (dates)."),
    gap_limit: str = typer.Option("30min", help="Longest gap that is interpolated."),
):
    """Identify convection edges and their parameters; write model.json, identification.json, figures.

    Example:  thermctl identify data.csv --building building.yaml --out out/
    """
    from ..identify import IdentifyOptions, identify as run_identify, write_outputs

    t0 = time.perf_counter()
    spec = load_spec(building)
    meas = read_measurements(data, spec, units=units, gap_limit=gap_limit)
    console.print(meas.quality.summary(), highlight=False)
    opt = IdentifyOptions(structure_method=method, level=level, rule=rule, s_min=s_min,
                          allow_parallel=allow_parallel, estimator=estimator,
                          window_hours=window_hours, initial_state=initial_state, grid=grid,
                          calibration=_window(calibration, "--calibration"),
                          validation=_window(validation, "--validation"))
    with progress() as bar:
        ident = run_identify(meas, opt, progress=_progress_callback(bar))
    paths = write_outputs(ident, out)
    _print_identification(ident)
    console.print(f"wrote {paths['model']} and {paths['identification']} "
                  f"({time.perf_counter() - t0:.1f} s)")
    return ident


def _window(text, what):
    if text is None:
        return None
    parts = text.split("..")
    if len(parts) != 2:
        raise DataError(f"{what} {text!r}: expected START..END, e.g. 2011-01-21..2011-02-09")
    return tuple(p or None for p in parts)


def _print_identification(ident):
    sid = ident.structure
    t = Table("convection edge", "score", "d (m)", title="Structure")
    for e in sid.edges_:
        t.add_row(f"{e.a} – {e.b}", f"{e.score:.2f}", f"{e.d:.1f}")
    console.print(t)
    m = ident.model
    if m.network.convection_edges:
        rb = np.atleast_1d(m.rbar_v)
        console.print(f"R̄_v = {', '.join(f'{v:.3g}' for v in rb)} K/(W m), C_v = {float(np.mean(m.c_v)):.3g} J/K"
                      f"  (alpha = {m.network.spec.alpha():.3f})", highlight=False)
    est = ident.estimate
    if est is not None and est.active_bounds:
        console.print(f"[yellow]estimate on a bound: {', '.join(est.active_bounds)} — the criterion, "
                      "not the building, chose it[/]")
    for n in ident.notes:
        console.print(f"note: {n}")


@app.command()
@handle_errors
def validate(
    model_path: Path = typer.Argument(..., metavar="MODEL", help="model.json from `thermctl identify`."),
    data: Path = typer.Argument(..., help="Measurements (same format as for identify)."),
    out: Path = typer.Option(None, "--out", "-o", help="Output directory (default: the model's)."),
    units: str = typer.Option("si", help=UNITS_HELP),
    hours: float = typer.Option(48.0, help="Open-loop window in hours (paper: 48)."),
    start: str = typer.Option(None, help="Window start (default: start of the validation data)."),
    validation: str = typer.Option(None, help="Validation window START..END (default as identify)."),
    truth: Path = typer.Option(None, help="truth.json of testbed data (default: beside DATA if present)."),
):
    """Compare the identified model with the conduction-only model on held-back data.

    Example:  thermctl validate out/model.json data.csv
    """
    from ..validate import validate as run_validate
    from ..identify import staged_output
    from .. import report as rep

    model = load_model(model_path)
    spec = model.network.spec
    meas = read_measurements(data, spec, units=units)
    _, val = meas.split(validation=_window(validation, "--validation")
                        or _saved_window(model, "validation"))
    truth_model = _truth_model(truth, data, spec)
    vr = run_validate(model, val, hours=hours, start=start, truth=truth_model)
    outdir = out or model_path.parent
    doc = validation_document(vr)
    with staged_output(outdir) as tmp:
        (tmp / "validation.json").write_text(json.dumps(doc, indent=2))
        from ..plots.validate import plot_open_loop, plot_step_responses
        for z in vr.zones[:4]:
            if z in vr.open_loop["identified"].zones:
                rep.save_figure(plot_open_loop(vr, z), tmp, f"openloop-{z}", "Validation",
                                f"Measured and predicted temperature of {z}: identified vs conduction-only (paper Fig. 5/6).")
        rep.save_figure(plot_step_responses(vr), tmp, "step-responses", "Validation",
                        "Step responses: temperature rise per 100 W into each zone, at the supply's minimum flow.")
    _print_validation(vr)
    console.print(f"wrote {Path(outdir) / 'validation.json'}")
    return vr


def _saved_window(model, key):
    w = model.meta.get("data", {}).get(key)
    return None if w is None else (w[0], None)


def validation_document(vr) -> dict:
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
    if sr_rows:
        blocks.append({"section": "Validation", "kind": "table",
                       "title": "Step-response error vs the truth (relative Frobenius norm)",
                       "content": sr_rows})
    blocks.append({"section": "Validation", "kind": "note", "title": "",
                   "content": "On closed-loop data the zones sit near their set points and unmeasured "
                              "gains dominate the open-loop error, so it barely separates models; the "
                              "step-response matrix shows what a controller acts through."})
    return {"format": "thermctl-validation", "version": 1, "window": list(vr.window),
            "units": vr.units, "open_loop": rows,
            "rmse_mean": {k: conv(r.rmse_mean) for k, r in vr.open_loop.items()},
            "step_response_error": {k: v.tolist() for k, v in vr.step_errors.items()},
            "step_responses_K_per_100W": {k: v.tolist() for k, v in vr.step_responses.items()},
            "horizons_h": list(vr.horizons_h), "zones": vr.zones, "report": blocks}


def _print_validation(vr):
    t = Table("zone", *[f"RMSE {k}" for k in vr.open_loop], *[f"max {k}" for k in vr.open_loop],
              title=f"Open loop {vr.window[0]} → {vr.window[1]} ({vr.units})")
    for z in vr.open_loop["identified"].zones:
        t.add_row(z, *[f"{float(vr.to_data_units(r.rmse[z])):.2f}" for r in vr.open_loop.values()],
                  *[f"{float(vr.to_data_units(r.max_abs[z])):.2f}" for r in vr.open_loop.values()])
    console.print(t)
    if vr.step_errors:
        t = Table("model", *[f"{h:g} h" for h in vr.horizons_h], title="Step-response error vs truth")
        for k, e in vr.step_errors.items():
            t.add_row(k, *[f"{100 * v:.1f} %" for v in e])
        console.print(t)


@app.command()
@handle_errors
def report(
    outdir: Path = typer.Argument(..., metavar="DIR", help="Directory written by identify/validate."),
):
    """Assemble one self-contained HTML report from an output directory.

    Example:  thermctl report out/
    """
    from ..report import build_report
    path = build_report(outdir)
    console.print(f"wrote {path}")
    return path


@app.command()
@handle_errors
def simulate(
    model_path: Path = typer.Argument(..., metavar="MODEL", help="model.json"),
    data: Path = typer.Argument(..., help="Measurements giving inputs and the initial temperatures."),
    out: Path = typer.Option(..., "--out", "-o", help="CSV of simulated zone temperatures (°C)."),
    units: str = typer.Option("si", help=UNITS_HELP),
    start: str = typer.Option(None, help="Start (default: data start)."),
    hours: float = typer.Option(None, help="Length in hours (default: to the end of the data)."),
):
    """Simulate a model open loop with measured inputs from the first sample.

    Example:  thermctl simulate out/model.json data.csv --hours 48 --out sim.csv
    """
    from ..io import atomic_write_text
    model = load_model(model_path)
    net = model.network
    meas = read_measurements(data, net.spec, units=units)
    win = meas.window(start=start, duration=None if hours is None else f"{hours}h")
    zt = win.zone_temperatures()
    T0 = [zt[z].iloc[0] if z in zt else np.nan for z in net.zones]
    Tb0 = win.frame[[f"T:{b}" for b in net.boundary]].iloc[0].to_numpy()
    if np.isnan(Tb0).any() or np.all(np.isnan(T0)):
        raise DataError(f"{data}: the first sample of the window has gaps; choose --start")
    x0 = model.initial_state(T0, Tb0)
    X = model.simulate(win.inputs(net)[:-1], win.step.total_seconds(), x0)
    df = pd.DataFrame(X[:, :net.n_zones], index=win.frame.index, columns=[f"T:{z}" for z in net.zones])
    df.index = [t.isoformat() for t in df.index]
    df.index.name = "time"
    atomic_write_text(out, df.round(4).to_csv())
    console.print(f"wrote {out}: {len(df)} samples of {net.n_zones} zones")


@app.command()
@handle_errors
def demo(
    out: Path = typer.Option(Path("demo-output"), "--out", "-o", help="Output directory."),
    days: float = typer.Option(26, help="Testbed days (paper: 26)."),
    seed: int = typer.Option(0, help="Testbed seed."),
):
    """Testbed → identify → validate → report on the built-in synthetic building (no input needed).

    Example:  thermctl demo --out demo-output
    """
    from ..testbed import generate
    t0 = time.perf_counter()
    console.rule("1/4 testbed: Pugh-Hall-like floor, 5-min BAS data")
    tb = generate(days=days, seed=seed)
    paths = tb.write(out / "testbed")
    console.print(f"wrote {paths['data']} ({len(tb.data)} samples); true air paths: "
                  + ", ".join(f"{a}–{b}" for a, b, _ in tb.truth.edges))
    console.rule("2/4 identify")
    ident = identify(paths["data"], building=paths["building"], out=out, units="si", method="sin",
                     rule="paper", s_min=0.25, level=0.05, allow_parallel=False, estimator="nlp",
                     window_hours=12.0, initial_state="paper", grid=True, calibration=None,
                     validation=None, gap_limit="30min")
    console.rule("3/4 validate")
    vr = validate(out / "model.json", paths["data"], out=out, units="si", hours=48.0, start=None,
                  validation=None, truth=paths["truth"])
    console.rule("4/4 report")
    path = report(out)
    true_edges = {frozenset((a, b)) for a, b, _ in tb.truth.edges}
    found = {frozenset((e.a, e.b)) for e in ident.structure.edges_}
    console.print(f"[bold]headline[/]: {len(found & true_edges)}/{len(true_edges)} true air paths "
                  f"found, {len(found - true_edges)} false; open-loop RMSE identified "
                  f"{vr.open_loop['identified'].rmse_mean:.2f} K vs conduction-only "
                  f"{vr.open_loop['conduction-only'].rmse_mean:.2f} K; step-response error at 6 h "
                  f"{100 * vr.step_errors['identified'][1]:.0f} % vs "
                  f"{100 * vr.step_errors['conduction-only'][1]:.0f} %", highlight=False)
    console.print(f"report: {path.resolve()}  ({time.perf_counter() - t0:.0f} s)")
