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



@app.callback()
def _root():
    """thermctl: building thermal network identification for MPC."""


# Command modules register themselves on `app` when imported.
from . import export, info, pipeline, reduce  # noqa: E402,F401

try:  # optional command modules, added as the features land
    from . import testbed  # noqa: F401
except ImportError:  # pragma: no cover
    pass


def main():  # pragma: no cover - console entry point
    app()
