"""thermctl's command line (typer). Each command lives in its own module of this package."""

from __future__ import annotations

import typer

app = typer.Typer(
    name="thermctl",
    help="Identify multi-zone building thermal network models from BAS data and export "
         "them for MPC (python-control StateSpace, CasADi).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)



def _version(value: bool):
    if value:
        from .. import __version__
        typer.echo(f"thermctl {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
    sep: str = typer.Option(",", "--sep", envvar="THERMCTL_SEP",
                            help="Data files: CSV field separator, e.g. ';' (then decimal "
                                 "commas are read too)."),
    time_format: str = typer.Option(None, "--time-format", envvar="THERMCTL_TIME_FORMAT",
                                    help="Data files: how 'time' is written: iso (default), "
                                         "excel (serial days), unix (seconds) or a strptime "
                                         "format such as '%d.%m.%Y %H:%M'."),
    allow_odd_units: bool = typer.Option(False, "--allow-odd-units",
                                         help="Data files: read a zone temperature column "
                                              "whose level does not fit --units (e.g. °F "
                                              "read as °C) as given, with a warning, instead "
                                              "of stopping."),
    average_conflicts: bool = typer.Option(False, "--average-conflicts",
                                           help="Data files: average rows that repeat a time "
                                                "stamp with different values (a clock set "
                                                "back) instead of stopping."),
    snap: str = typer.Option("auto", "--snap", envvar="THERMCTL_SNAP",
                             help="Data files: a time stamp this close to the grid is that "
                                  "grid point's sample, taken as is (a BAS stamping rows a "
                                  "few seconds late): auto (a tenth of the step), a duration "
                                  "such as 20s, or none (1 s; stamps further off are "
                                  "interpolated in time, which blends rows)."),
):
    """thermctl: building thermal network identification for MPC.

    Options before the command say how data files are read, for every command:
      thermctl --sep ';' --time-format excel identify data.csv -b building.yaml
      thermctl --snap none identify data.csv -b building.yaml
    """
    from ._common import read_options
    read_options.sep = sep
    read_options.time_format = time_format
    read_options.allow_odd_units = allow_odd_units
    read_options.average_conflicts = average_conflicts
    read_options.snap = None if snap.strip().lower() in ("none", "off", "no") else snap


# Command modules register themselves on `app` when imported.
from . import export, info, pipeline, reduce, spec  # noqa: E402,F401

try:  # optional command modules, added as the features land
    from . import testbed  # noqa: F401
except ImportError:  # pragma: no cover
    pass


def main():  # pragma: no cover - console entry point
    from .._blas import keep_heap
    keep_heap()
    app()
