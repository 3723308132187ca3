"""`thermctl export`: a model file → python-control StateSpace (.npz) and CasADi functions."""

from __future__ import annotations

import json
import re
from pathlib import Path

import casadi as ca
import typer

from ..errors import ModelError
from ..io import atomic_write_text, load_model, save_statespace
from . import app
from ._common import console, handle_errors

_OP_RE = re.compile(r"^(ms|Ts|T|Q)(?:\[([^\]]+)\])?=(.+)$")


def parse_operating_point(items: list[str]) -> dict:
    """``["ms=0.05", "T[outside]=5", "Ts=14"]`` → kwargs for ``model.operating_point``."""
    out: dict = {}
    for item in items:
        m = _OP_RE.match(item.strip())
        if not m:
            raise ModelError(f"--op {item!r}: expected NAME=VALUE or NAME[node]=VALUE with NAME "
                             "one of ms, Ts, T, Q (e.g. --op ms=0.05 --op 'T[outside]=5')")
        name, node, value = m.groups()
        try:
            value = float(value)
        except ValueError:
            raise ModelError(f"--op {item!r}: {value!r} is not a number") from None
        if node is None:
            if isinstance(out.get(name), dict):
                raise ModelError(f"--op {item!r}: {name} already given per node")
            out[name] = value
        else:
            prev = out.setdefault(name, {})
            if not isinstance(prev, dict):
                raise ModelError(f"--op {item!r}: {name} already given for all nodes")
            prev[node] = value
    return out


@app.command()
@handle_errors
def export(
    model_path: Path = typer.Argument(..., metavar="MODEL", help="model.json from `thermctl identify`."),
    statespace: Path = typer.Option(None, "--statespace", help="Write the linearized StateSpace (.npz)."),
    casadi_path: Path = typer.Option(None, "--casadi", help="Write CasADi f(x,u) (Function.save); "
                                     "also FILE.step with F(x,u,dt) and FILE.json with the names."),
    op: list[str] = typer.Option([], "--op", help="Operating point: NAME=VALUE or NAME\\[node]=VALUE, "
                                 "NAME in ms (kg/s), Ts (°C), T (°C, boundary), Q (W). Repeatable. "
                                 "The state is the steady state for these inputs."),
    dt: float = typer.Option(None, "--dt", help="Discretise the StateSpace by ZOH with this step (s)."),
    substeps: int = typer.Option(5, "--substeps", help="Sub-steps of the CasADi discrete step."),
):
    """Export an identified model for control design.

    Example:  thermctl export out/model.json --statespace ss.npz --op ms=0.05 --op Ts=14 --op T=5 --casadi f.casadi
    """
    model = load_model(model_path)
    if statespace is None and casadi_path is None:
        raise ModelError("nothing to export: give --statespace FILE and/or --casadi FILE")
    if statespace is not None:
        point = model.operating_point(**parse_operating_point(op))
        sys = model.to_statespace(point, dt=dt)
        save_statespace(sys, statespace, op=point)
        kind = f"discrete, dt={dt:g} s" if dt else "continuous"
        console.print(f"wrote {statespace}: {sys.nstates} states, {sys.ninputs} inputs, "
                      f"{sys.noutputs} outputs ({kind}); load with thermctl.io.load_statespace")
    if casadi_path is not None:
        cm = model.to_casadi(substeps=substeps)
        x, u = ca.SX.sym("x", len(cm.state_names)), ca.SX.sym("u", len(cm.input_names))
        f = ca.Function("f", [x, u], [cm.f(x, u, cm.p_value)], ["x", "u"], ["xdot"])
        xm, um, dtm = ca.MX.sym("x", x.numel()), ca.MX.sym("u", u.numel()), ca.MX.sym("dt")
        F = ca.Function("F", [xm, um, dtm], [cm.F(xm, um, cm.p_value, dtm)], ["x", "u", "dt"], ["x_next"])
        casadi_path.parent.mkdir(parents=True, exist_ok=True)
        f.save(str(casadi_path))
        F.save(str(casadi_path) + ".step")
        atomic_write_text(str(casadi_path) + ".json", json.dumps(
            {"states": cm.state_names, "inputs": cm.input_names, "parameters": cm.param_names,
             "p": cm.p_value.tolist(), "substeps": substeps}, indent=2))
        console.print(f"wrote {casadi_path} (f(x,u)), {casadi_path}.step (F(x,u,dt)) and "
                      f"{casadi_path}.json; load with casadi.Function.load")
