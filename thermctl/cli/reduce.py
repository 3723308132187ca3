"""`thermctl reduce`: a model file → a control-sized reduced model (.npz) with its errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import typer
from rich.table import Table

from ..errors import ModelError
from ..io import atomic_write_text, load_model
from ..model import ThermalModel
from ..network import ThermalNetwork
from ..spec import load_spec
from . import app
from ._common import console, handle_errors
from .export import parse_operating_point

METHODS = ("structured", "balanced", "truncate", "kron", "lumped")


def _load(path: Path) -> ThermalModel:
    """A model file, or a building spec (conduction-only model) for quick studies."""
    if path.suffix.lower() in (".yaml", ".yml"):
        return ThermalModel(ThermalNetwork(load_spec(path)))
    return load_model(path)


def _floats(text: str | None, what: str) -> list[float]:
    if not text:
        return []
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ModelError(f"{what}: expected comma-separated numbers [kg/s], found {text!r}") from None
    if any(v < 0 for v in vals):
        raise ModelError(f"{what}: supply flows must be ≥ 0 [kg/s], found {text!r}")
    return vals


def _reduce(model, op, method, order, tol, design_ms):
    from .. import reduce as R
    nz = model.network.n_zones
    if method in ("kron", "lumped"):
        if order is not None or tol is not None:
            raise ModelError(f"--method {method} has a fixed order; drop --order/--tol")
        return (R.kron if method == "kron" else R.lumped)(model, op)
    if method == "structured":
        if order is None and tol is None:
            order = 2 * nz
        return R.structured(model, op, order=order, tol=tol, design_ms=design_ms or None)
    if order is None and tol is None:
        order = 3 * nz
    return R.balanced_reduction(model, op, order=order, tol=tol,
                                method="matchdc" if method == "balanced" else "truncate")


def _pct(x: float) -> str:
    return f"{100 * x:.3g} %"


@app.command()
@handle_errors
def reduce(
    model_path: Path = typer.Argument(..., metavar="MODEL",
                                      help="model.json from `thermctl identify` (or a building spec "
                                           ".yaml: its conduction-only model)."),
    out: Path = typer.Option(..., "--out", help="Reduced model file (.npz; load with "
                                                "thermctl.reduce.load_reduction)."),
    method: str = typer.Option("structured", "--method",
                               help="structured (keeps every T\\[z] as a state; valid at every flow), "
                                    "balanced (DC-matching), truncate, kron (fast states only), "
                                    "lumped (one state per zone)."),
    order: int = typer.Option(None, "--order", help="Number of states (default: 2 per zone "
                                                    "structured, 3 per zone balanced)."),
    tol: float = typer.Option(None, "--tol", help="Error tolerance instead of --order \\[K per scaled "
                              "input: per kW of heat, per K, per 0.1 kg/s]: balanced uses the a-priori "
                              "bound 2Σσ, structured the H∞ error on a frequency grid."),
    op: list[str] = typer.Option([], "--op", "--operating-point",
                                 help="Design point: NAME=VALUE or NAME\\[node]=VALUE, NAME in ms \\[kg/s], "
                                      "Ts \\[°C], T \\[°C, boundary], Q \\[W]. Repeatable; the state is the "
                                      "steady state for these inputs."),
    design_ms: str = typer.Option(None, "--design-ms", help="structured: further design flows, "
                                  "comma-separated \\[kg/s], for one model over a flow range."),
    sweep: str = typer.Option(None, "--sweep", help="Flows for a flow-sweep table, comma-separated "
                              "\\[kg/s], e.g. 0,0.05,0.3."),
    report: Path = typer.Option(None, "--report", help="Directory for figures and reduction.json "
                                "(Hankel singular values, step responses, error vs order)."),
):
    """Reduce a model to a control-sized one and say how large the error is.

    Example:  thermctl reduce out/model.json --method structured --op ms=0.05 --op Ts=14 --op T=5 --out red.npz
    """
    from .. import reduce as R

    if method not in METHODS:
        raise ModelError(f"--method must be one of {', '.join(METHODS)}; found {method!r}")
    model = _load(model_path)
    net = model.network
    nz = net.n_zones
    point = model.operating_point(**parse_operating_point(op))
    red = _reduce(model, point, method, order, tol, _floats(design_ms, "--design-ms"))
    path = red.save(out)

    full = R.linearize(model, point)
    ref = R.Reference(full, capacitances=model.capacitances())
    err = ref.step_error(red.sys)
    console.print(f"[bold]{net.spec.name}[/]: {net.n_states} states, {nz} zones → "
                  f"[bold]{method}[/] {red.order} states ({red.order / nz:.3g} per zone) "
                  f"in {red.elapsed:.2f} s")
    if red.error_bound is not None:
        console.print(f"a-priori H∞ bound 2Σσ_tail = {red.error_bound:.4g} K per scaled input unit")
    t = Table("step error", *[f"{x / 3600:g} h" for x in ref.times])
    t.add_row("all inputs (scaled)", *[_pct(e) for e in err.rel])
    for k, g in enumerate(err.groups):
        t.add_row(f"  {g}[·] → T (own scale)", *[_pct(e) for e in err.group_rel[:, k]])
    console.print(t)

    orders = sorted({nz, 2 * nz, 3 * nz, red.order} & set(range(nz if method == "structured" else 1,
                                                                  net.n_states + 1)))
    tables = []
    if method in ("structured", "balanced", "truncate"):
        tables.append(R.error_vs_order(model, point, method, orders, reference=ref))
    tables.append(R.error_vs_order(model, point, "lumped", [nz], reference=ref))
    table = pd.concat(tables, ignore_index=True)
    _print_df(table, "error vs order")

    sweep_df = None
    flows = _floats(sweep, "--sweep")
    if flows:
        sweep_df = R.flow_sweep(model, [red], flows)
        _print_df(sweep_df, "flow sweep (full and network models relinearized at each flow)")

    if report is not None:
        _write_report(report, model, point, red, full, table, sweep_df, err)
    console.print(f"wrote {path}; load with thermctl.reduce.load_reduction")


def _print_df(df: pd.DataFrame, title: str):
    t = Table(*[str(c) for c in df.columns], title=title)
    for _, row in df.iterrows():
        t.add_row(*[_pct(v) if str(c).startswith("err_") else
                    (f"{v:.4g}" if isinstance(v, float) and np.isfinite(v) else str(v))
                    for c, v in row.items()])
    console.print(t)


def _write_report(outdir: Path, model, point, red, full, table, sweep_df, err):
    from .. import reduce as R
    from ..plots.reduce import plot_error_vs_order, plot_hsv, plot_step_responses
    from ..report import save_figure

    nz = model.network.n_zones
    outdir.mkdir(parents=True, exist_ok=True)
    hsv = red.hsv if red.hsv is not None else R.hankel_singular_values(model, point)
    save_figure(plot_hsv(hsv, order=red.order if red.hsv is not None else None, n_zones=nz), outdir,
                "reduction-hsv", "Reduction",
                "Hankel singular values of the scaled linearized model and the a-priori H∞ bound "
                "2Σσ_tail of a balanced reduction to each order.")
    reduced = {red.method: red.sys}
    if red.method != "lumped":
        reduced["lumped"] = R.lumped(model, point).sys
    save_figure(plot_step_responses(full, reduced, capacitances=model.capacitances()), outdir,
                "reduction-steps", "Reduction", "Step responses: full model vs reduced models.")
    save_figure(plot_error_vs_order(table), outdir, "reduction-error-vs-order", "Reduction",
                "Step-response error at 1, 6 and 24 h vs states per zone.")
    blocks = [
        {"section": "Reduction", "kind": "text", "title": "Reduced model",
         "content": f"{red.method}: {red.full_order} → {red.order} states "
                    f"({red.order / nz:.3g} per zone), {red.elapsed:.2f} s."
                    + (f" A-priori H∞ bound {red.error_bound:.4g} K per scaled input unit."
                       if red.error_bound is not None else "")},
        {"section": "Reduction", "kind": "table", "title": "Error vs order",
         "content": json.loads(table.to_json(orient="records"))},
    ]
    if sweep_df is not None:
        blocks.append({"section": "Reduction", "kind": "table", "title": "Flow sweep",
                       "content": json.loads(sweep_df.to_json(orient="records"))})
    atomic_write_text(outdir / "reduction.json", json.dumps(
        {"method": red.method, "order": red.order, "full_order": red.full_order,
         "error_bound": red.error_bound, "step_error": dict(zip([f"{t / 3600:g}h" for t in err.times],
                                                                err.rel.tolist())),
         "report": blocks}, indent=2))
