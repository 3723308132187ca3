"""`thermctl export`: a model file → python-control StateSpace (.npz) and CasADi functions."""

from __future__ import annotations

import functools
import json
import re
from pathlib import Path

import typer
from rich.markup import escape

from ..errors import ModelError, ThermctlError
from ..io import atomic_write_text, load_model, save_statespace
from . import app
from ._common import console, handle_errors

_OP_RE = re.compile(r"^(ms|Ts|T|Q)(?:\[([^\]]+)\])?=(.+)$")


def parse_operating_point(items: list[str]) -> dict:
    """``--op`` values → keyword arguments of ``ThermalModel.operating_point``.

    ``NAME=VALUE`` sets every node (stored under the key ``"*"`` when per-node values of
    the same NAME are given too), ``NAME[node]=VALUE`` one node; a per-node value wins
    over the value for all nodes, whatever their order: ``["T=21", "T[outside]=-5"]`` →
    ``{"T": {"*": 21.0, "outside": -5.0}}``.
    """
    out: dict = {}
    for item in items:
        m = _OP_RE.match(item.strip())
        if not m:
            raise ModelError(f"--op {item}: expected NAME=VALUE or NAME[node]=VALUE with NAME "
                             "one of ms, Ts, T, Q (e.g. --op ms=0.05 --op T[outside]=5)")
        name, node, value = m.groups()
        try:
            value = float(value)
        except ValueError:
            raise ModelError(f"--op {item}: {value!r} is not a number") from None
        key = "*" if node is None else node.strip()
        prev = out.setdefault(name, {})
        if key in prev and prev[key] != value:
            what = "every node" if key == "*" else key
            raise ModelError(f"--op {item}: {name} for {what} already given as {prev[key]:g}")
        prev[key] = value
    # a lone NAME=VALUE stays a number (the form ThermalModel.operating_point documents)
    return {k: (v["*"] if set(v) == {"*"} else v) for k, v in out.items()}


def _plain_errors(func):
    """Escape rich markup in error messages: ``T[outside]`` must print as written."""
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except ThermctlError as exc:
            raise type(exc)(escape(str(exc))) from None
    return wrapper


def _read_data(path, model, units):
    from ..data import read_measurements

    return read_measurements(path, model.network.spec, units=units)


def _identification_data(model):
    """The data the model was identified from (``meta.data.source``), if still readable."""
    info = model.meta.get("data") or {}
    src = info.get("source")
    if not src or not Path(src).is_file():
        return None
    try:
        meas = _read_data(Path(src), model, info.get("units", "si"))
    except ThermctlError as exc:
        console.print(escape(f"not using the identification data {src}: {exc}"), highlight=False,
                      soft_wrap=True)
        return None
    console.print(escape(f"typical inputs from the identification data {src} (--data to use other "
                         "data)"), highlight=False, soft_wrap=True)
    return meas


@app.command()
@handle_errors
@_plain_errors
def export(
    model_path: Path = typer.Argument(..., metavar="MODEL", help="model.json from `thermctl identify`."),
    statespace: Path = typer.Option(None, "--statespace", help="Write the linearized StateSpace (.npz) "
                                    "with the operating point, disturbance inputs and Kalman filter."),
    casadi_path: Path = typer.Option(None, "--casadi", help="Write CasADi f(x,u) with the identified "
                                     "parameters built in (Function.save); also FILE.step with "
                                     "F(x,u,dt) and FILE.json (names, p, operating point, "
                                     "disturbances, noise model)."),
    op: list[str] = typer.Option([], "--op", help="Operating point: NAME=VALUE (every node) or "
                                 "NAME\\[node]=VALUE (one node, wins), NAME in ms (kg/s; with --data "
                                 "only zones with supply air), Ts (°C), T (°C, boundary), Q (W). "
                                 "Repeatable. Not given: typical values of --data, else stated "
                                 "defaults. The state is the steady state for these inputs."),
    data: Path = typer.Option(None, "--data", help="Measurements of this building: typical flow "
                              "and supply temperature of the zones with supply air, mean boundary "
                              "temperatures, for what --op does not give (default: the data the "
                              "model was identified from, if that file is still there)."),
    units: str = typer.Option("si", help="Units of --data: si (°C, kg/s) or imperial (°F, CFM)."),
    dt: float = typer.Option(None, "--dt", help="Discretise the StateSpace by ZOH with this step (s); "
                             "also the stationary Kalman gain at this step."),
    substeps: int = typer.Option(5, "--substeps", help="Sub-steps of the CasADi discrete step."),
    kalman_max_states: int = typer.Option(
        None, "--kalman-max-states", min=1, show_default=False,
        help="Above this many filter states --dt leaves out the stationary Kalman gain "
             "(dense, ~n³: 5 s at 707 states, about 2 min at 2 000); default 2000. The "
             "continuous noise model is exported either way."),
):
    """Export an identified model for control design.

    The operating point is printed and stored in the files; the Ts columns of B are zero
    at zero flow, so give --data or --op ms\\[zone]=... for zones with supply air.

    Examples:
      thermctl export out/model.json --statespace ss.npz --data data.csv --dt 600
      thermctl export out/model.json --statespace ss.npz --op ms=0.05 --op Ts=14 --op T=21 --op "T\\[outside]=-5"
      thermctl export out/model.json --casadi f.casadi --data data.csv
    """
    from .. import export as ex

    model = load_model(model_path)
    if statespace is None and casadi_path is None:
        raise ModelError("nothing to export: give --statespace FILE and/or --casadi FILE")
    given = parse_operating_point(op)
    meas = _read_data(data, model, units) if data is not None else _identification_data(model)
    point = ex.export_point(model, given, data=meas)
    console.print(escape(point.describe()), highlight=False, soft_wrap=True)
    dist = ex.disturbances(model)
    from ..export.kalman import KALMAN_DT_MAX_STATES
    kf = ex.kalman_filter(model, point.op, dt=dt, max_states=kalman_max_states or KALMAN_DT_MAX_STATES)
    info = {"operating_point": point.to_dict(), "disturbances": dist.to_dict(),
            "model": str(model_path)}
    if kf is not None and kf.note:
        info["kalman_note"] = kf.note
    if dist.names:
        console.print(escape(f"disturbance inputs (identified): {', '.join(dist.names)}"),
                      highlight=False)
    if kf is None:
        # a local-path model written before its zones' noise was carried over has none
        why = ("identified by local problems, written without their noise parameters"
               if model.meta.get("local") else "identified with --criterion simulation")
        console.print(f"no Kalman filter exported: the model has no identified noise model "
                      f"({why})", highlight=False)
    else:
        src = (" from the local problems (a measured zone's from its own, an unmeasured "
               "zone's the median of those reaching it)"
               if (model.meta.get("greybox") or {}).get("source") == "local" else "")
        console.print(escape(f"Kalman filter: {len(kf.states)} states ({len(kf.states) - model.network.n_states} "
                             f"gain/sensor states), noise{src}: {kf.describe_noise()}"
                             + ("" if dt else "; give --dt for the stationary gain")), highlight=False)
        if kf.note:
            console.print(escape(f"NOTE: {kf.note}; --kalman-max-states raises the limit"),
                          highlight=False)
    if statespace is not None:
        sys, _ = ex.statespace(model, point.op, dt=dt)
        save_statespace(sys, statespace, op=point.op, info=info,
                        kalman=None if kf is None else kf.arrays())
        kind = f"discrete, dt={dt:g} s" if dt else "continuous"
        console.print(f"wrote {statespace}: {sys.nstates} states, {sys.ninputs} inputs, "
                      f"{sys.noutputs} outputs ({kind}); load with thermctl.load_statespace")
    if casadi_path is not None:
        f, F, doc = ex.casadi_functions(model, substeps, info=info, dist=dist, kf=kf)
        casadi_path.parent.mkdir(parents=True, exist_ok=True)
        f.save(str(casadi_path))
        F.save(str(casadi_path) + ".step")
        atomic_write_text(str(casadi_path) + ".json", json.dumps(doc, indent=2))
        console.print(f"wrote {casadi_path} (f(x,u)), {casadi_path}.step (F(x,u,dt)) and "
                      f"{casadi_path}.json; load with casadi.Function.load")
