"""`thermctl spec from-brick | map-columns`: building specs and column maps from Brick models."""

from __future__ import annotations

from pathlib import Path

import typer
import yaml
from rich.markup import escape

from ..errors import DataError
from . import app
from ._common import console, handle_errors, read_options

spec_app = typer.Typer(help="Building specs from Brick models, and the column maps that go "
                            "with them.", no_args_is_help=True)
app.add_typer(spec_app, name="spec")


@spec_app.command("from-brick")
@handle_errors
def from_brick(
    model: Path = typer.Argument(..., metavar="MODEL.ttl", help="Brick model (Turtle), with REC "
                                 "or BOT adjacency (see docs/brick.md)."),
    out: Path = typer.Option(..., "--out", "-o", help="Building spec to write (YAML or JSON)."),
    columns_out: Path = typer.Option(None, "--columns-out", help="Column map to write (BAS "
                                     "column: thermctl column; default columns.yaml beside --out)."),
    boundary: list[str] = typer.Option([], "--boundary", help="A space to take as a boundary "
                                       "node (measured neighbour, not modelled), beside those "
                                       "typed tc:Boundary. Repeatable."),
    height: float = typer.Option(3.0, min=0.5, help="Room height (m) for volumes from floor "
                                 "areas and estimated wall areas."),
    capacity_multiplier: float = typer.Option(None, "--capacity-multiplier", min=0.1,
                                              help="Zone capacitance over air capacitance "
                                                   "(default: the model's "
                                                   "tc:capacityMultiplier, else 1)."),
):
    """Write a building spec and a column map from a Brick model.

    Zones are the HVAC zones and rooms, walls the REC/BOT elements between them (a
    construction class where the model gives no U-value), the column map the zones'
    Brick points (zone air temperature, supply air flow and temperature, outside air
    temperature) by their time-series ids.

    Example:
      thermctl spec from-brick building.ttl --out building.yaml --columns-out map.yaml
      thermctl identify bas-export.csv -b building.yaml --columns map.yaml
    """
    from ..brick import read_brick, write_column_map

    imp = read_brick(model, boundary=boundary, height=height,
                     capacity_multiplier=capacity_multiplier)
    columns_out = columns_out or out.with_name("columns.yaml")
    out.parent.mkdir(parents=True, exist_ok=True)
    head = f"# building spec from {model} (thermctl spec from-brick)\n"
    if out.suffix.lower() in (".yaml", ".yml"):
        out.write_text(head + yaml.safe_dump(imp.spec_dict, sort_keys=False, allow_unicode=True))
    else:
        imp.spec.dump(out)
    write_column_map(imp.columns, columns_out, source=str(model), units=imp.units)
    spec = imp.spec
    console.print(escape(f"{spec.name}: {len(spec.zones)} zones ({len(spec.measured_zones)} "
                         f"measured), boundary {list(spec.boundary)}, {len(spec.walls)} walls, "
                         f"{len(spec.distances)} air-path lengths"), highlight=False)
    for note in imp.notes:
        console.print(escape(f"  note: {note}"), highlight=False, soft_wrap=True)
    units = f" --units {imp.units}" if imp.units == "imperial" else ""
    console.print(escape(f"wrote {out} and {columns_out} ({len(imp.columns)} columns); next: "
                         f"thermctl identify DATA -b {out} --columns {columns_out}{units}"),
                  highlight=False, soft_wrap=True)


@spec_app.command("map-columns")
@handle_errors
def map_columns(
    data: Path = typer.Argument(..., help="BAS export (CSV or parquet)."),
    columns: Path = typer.Option(..., "--columns", help="Column map (from `thermctl spec "
                                 "from-brick`)."),
    out: Path = typer.Option(..., "--out", "-o", help="CSV to write, with thermctl's column names."),
):
    """Rename the columns of a BAS export by a column map, for any command that reads data.

    Example:  thermctl spec map-columns bas-export.csv --columns map.yaml --out data.csv
    """
    from ..brick import load_column_map, read_mapped_table

    if out.resolve() == data.resolve():
        raise DataError(f"{out}: --out would overwrite the data file; give another name")
    df = read_mapped_table(data, load_column_map(columns), sep=read_options.sep)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out, index=False, lineterminator="\n")
    console.print(escape(f"wrote {out}: {len(df)} rows, {len(df.columns)} columns"),
                  highlight=False)
