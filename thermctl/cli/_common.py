"""Shared pieces of the command line: console, error handling, progress bars."""

from __future__ import annotations

import functools
import logging
import warnings

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from ..errors import ThermctlError

console = Console(stderr=False)
err_console = Console(stderr=True)


def handle_errors(func):
    """Turn thermctl's errors into one red line on stderr and exit code 2 (no traceback)."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            warnings.showwarning = _show_warning
            try:
                return func(*args, **kwargs)
            except ThermctlError as exc:
                err_console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
                raise typer.Exit(2) from None
            except (OSError, PermissionError) as exc:
                err_console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
                raise typer.Exit(2) from None
    return wrapper


def _show_warning(message, category, filename, lineno, file=None, line=None):
    err_console.print(f"[yellow]warning ({category.__name__}):[/] {message}", highlight=False,
                      soft_wrap=True)


def progress() -> Progress:
    """A rich progress bar for long work (goes to stderr, quiet when not a terminal)."""
    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), console=err_console, transient=True)
