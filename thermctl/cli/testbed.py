"""`thermctl testbed`: generate a synthetic building with known air paths and BAS-like data."""

from __future__ import annotations

import time
from enum import Enum
from pathlib import Path

import typer
from rich.table import Table

from ..testbed import SensorNoise, generate
from . import app
from ._common import console, handle_errors, progress


class _Building(str, Enum):
    pugh_hall = "pugh-hall"
    corridor = "corridor"
    ring = "ring"
    ring_office = "ring-office"
    ring_equipment = "ring-equipment"
    l_shape = "l-shape"
    open_plan = "open-plan"


class _Plant(str, Enum):
    rc = "rc"
    rc_exact = "rc-exact"
    fd = "fd"


class _Walls(str, Enum):
    types = "types"
    random = "random"


class _WallSpec(str, Enum):
    u_value = "u_value"
    plant = "plant"


class _Gains(str, Enum):
    arrivals = "arrivals"
    hourly = "hourly"


class _Units(str, Enum):
    si = "si"
    imperial = "imperial"


@app.command()
@handle_errors
def testbed(
    out: Path = typer.Option(..., "--out", "-o", help="Output directory (created if needed)."),
    building: _Building = typer.Option(_Building.pugh_hall, help="Layout: the paper's Pugh Hall "
                                       "section (7 zones), a corridor office floor, offices in a "
                                       "ring around an unmeasured core (a hall, a conditioned "
                                       "space or a copy room), an L-shaped floor with two "
                                       "corridors and a lobby, or an open plan."),
    zones: int | None = typer.Option(None, min=5, help="Number of zones of the corridor building "
                              "(about; default 50; several floors above 51) or of the ring "
                              "(odd, >= 7; default 9)."),
    days: float = typer.Option(26.0, min=0.01, help="Days of data."),
    step: float = typer.Option(5.0, min=0.1, help="Data step (minutes)."),
    start: str = typer.Option("2011-01-21", help="First time stamp (local time, America/New_York)."),
    seed: int = typer.Option(0, help="Seed of everything random."),
    units: _Units = typer.Option(_Units.si, help="data.csv units: si (°C, kg/s) or imperial "
                                 "(°F, CFM as 'vs:' columns), as a BAS exports."),
    missing: float = typer.Option(0.0, min=0.0, max=0.99, help="Fraction of missing samples."),
    control: float = typer.Option(1.0, min=0.01, help="Control and integration step "
                                  "(minutes); must divide --step."),
    rbar_v: float = typer.Option(3.36e-4, "--rbar-v", help="True convection resistance per "
                                 "unit distance, K/(W m) (paper: 3.36e-4)."),
    c_v: float = typer.Option(1.19e3, "--c-v", help="True convection capacitance, J/K "
                              "(paper: 1.19e3)."),
    no_noise: bool = typer.Option(False, "--no-noise", help="Perfect sensors: log the plant's "
                                  "true values (no noise, offsets, rounding)."),
    plant: _Plant = typer.Option(_Plant.rc, help="rc: the 3R2C model (Radau step); rc-exact: "
                                 "the same with exact zero-order hold per control step; fd: "
                                 "walls of many finite volumes and an independent stiff "
                                 "integrator (a plant that is not the identified model)."),
    walls: _Walls = typer.Option(_Walls.types, help="Wall constructions: the layout's types, or "
                                 "random per wall (area, U-value, capacity; 25/50/25 % split)."),
    wall_spec: _WallSpec = typer.Option(_WallSpec.u_value, "--wall-spec", help="With random "
                                        "walls, building.yaml gets each wall's U-value and "
                                        "capacity (u_value) or the plant's own R/C (plant)."),
    gains: _Gains = typer.Option(_Gains.arrivals, help="Occupancy: random arrivals/lunch/"
                                 "departures, or a daily level with presence redrawn hourly "
                                 "plus white noise."),
    gain_noise: float | None = typer.Option(None, "--gain-noise", min=0.0, help="White noise on "
                                            "office gains per control step, W (default 30 with "
                                            "--gains hourly, else 0)."),
    neighbour_noise: float = typer.Option(0.0, "--neighbour-noise", min=0.0, help="White noise "
                                          "on conditioned neighbours' temperatures, K."),
    hide: int = typer.Option(0, min=0, help="Offices whose thermostat is not logged (they keep "
                             "their VAV box)."),
    floor_above: bool = typer.Option(False, "--floor-above", help="A measured floor above "
                                     "(a slab from every zone to the space above it)."),
):
    """Generate a synthetic building with known air paths and BAS-like data.

    Writes building.yaml (walls and distances, what a user would write),
    data.csv (wide: time, T:<node>, Ts:<zone>, ms:<zone> or vs:<zone>),
    truth.json (true air paths, rbar_v, c_v, alpha, seed, all settings)
    and gains.csv (true unmeasured heat gains Q:<zone>, W). The defaults
    are the paper's case: 26 days of 5-min data from 2011-01-21.

    Example:  thermctl testbed --out testbed --days 26 --units imperial
    """
    noise = None if no_noise else SensorNoise()
    t0 = time.perf_counter()
    with progress() as bar:
        task = bar.add_task("simulating", total=None)

        def report(done, total):
            bar.update(task, completed=done, total=total)

        tb = generate(building.value, days=days, step_minutes=step, start=start, seed=seed,
                      zones=zones, control_minutes=control, missing=missing, rbar_v=rbar_v,
                      c_v=c_v, noise=noise, plant=plant.value, walls=walls.value,
                      wall_spec=wall_spec.value, gains=gains.value, gain_noise=gain_noise,
                      neighbour_noise=neighbour_noise, hide=hide, floor_above=floor_above,
                      progress=report)
    paths = tb.write(out, units=units.value)
    elapsed = time.perf_counter() - t0
    net = tb.network
    console.print(f"[bold]{tb.spec.name}[/]: {net.n_zones} zones ({len(tb.spec.measured_zones)} "
                  f"measured), {net.n_states} states, {len(tb.data)} samples of "
                  f"{step:g} min from {tb.data.index[0]} ({elapsed:.1f} s)")
    t = Table("true air path", "d (m)")
    for a, b, d in tb.truth.edges[:20]:
        t.add_row(f"{a} - {b}", f"{d:g}")
    if len(tb.truth.edges) > 20:
        t.add_row(f"... {len(tb.truth.edges) - 20} more", "")
    console.print(t)
    for role, p in paths.items():
        console.print(f"  {role:9s} {p}")
