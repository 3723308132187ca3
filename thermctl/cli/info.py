"""`thermctl info`: what a spec builds (states, edges, alpha, time constants)."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from .. import rc
from ..model import ThermalModel
from ..network import ThermalNetwork
from ..spec import load_spec
from . import app
from ._common import console, handle_errors


@app.command()
@handle_errors
def info(
    building: Path = typer.Argument(..., help="Building spec (YAML or JSON)."),
):
    """Summarise a building spec: zones, edges, state count, alpha and wall time constants.

    Example:  thermctl info building.yaml
    """
    spec = load_spec(building)
    net = ThermalNetwork(spec)
    model = ThermalModel(net)
    console.print(f"[bold]{spec.name}[/]: {net}")
    t = Table("wall", "between", "R_tot (K/W)", "C_tot (kJ/K)", "tau (h)", "alpha (-)")
    for label, w in zip(spec.alphas(), spec.walls):
        t.add_row(label, f"{w.a} - {w.b}", f"{sum(w.R):.4g}", f"{sum(w.C) / 1e3:.4g}",
                  f"{rc.time_constant(w.R, w.C) / 3600:.3g}", f"{w.alpha:.4f}")
    console.print(t)
    console.print(f"alpha used for the convection bounds (median over walls): {spec.alpha():.4f}")
    caps = model.capacitances()[: net.n_zones]
    console.print("zone capacitances (kJ/K): "
                  + ", ".join(f"{z}={c / 1e3:.4g}" for z, c in zip(net.zones, caps)))
