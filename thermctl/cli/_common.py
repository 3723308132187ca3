"""Shared pieces of the command line: console, error handling, progress, data-reading options."""

from __future__ import annotations

import functools
import logging
import sys
import threading
import time
import warnings
from dataclasses import dataclass

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from ..errors import ThermctlError

console = Console(stderr=False)
err_console = Console(stderr=True)
logger = logging.getLogger("thermctl")


@dataclass
class ReadOptions:
    """How data files are read, set by the root options (``thermctl --sep ';' identify ...``).

    Root options rather than per-command ones: one place for what a data file looks like,
    the same for identify, validate and simulate.
    """

    sep: str = ","
    time_format: str | None = None
    allow_odd_units: bool = False
    average_conflicts: bool = False
    snap: str | None = "auto"

    def kwargs(self) -> dict:
        return {"sep": self.sep, "time_format": self.time_format,
                "allow_odd_units": self.allow_odd_units,
                "average_conflicts": self.average_conflicts, "snap": self.snap}


read_options = ReadOptions()


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
            except RuntimeError as exc:
                # Ctrl-C inside a CasADi callback arrives as CasADi's RuntimeError: the
                # user's stop, as anywhere else (no traceback, exit status 130)
                if "KeyboardInterrupt" in str(exc):
                    raise KeyboardInterrupt from None
                raise
    return wrapper


def _show_warning(message, category, filename, lineno, file=None, line=None):
    err_console.print(f"[yellow]warning ({category.__name__}):[/] {message}", highlight=False,
                      soft_wrap=True)


def _clock(seconds: float) -> str:
    """``1:23`` or ``1:02:03`` (whole seconds)."""
    s = int(round(max(seconds, 0.0)))
    h, rem = divmod(s, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


LIMIT_STAGES = frozenset({"ipopt"})
"""Stages whose ``total`` is an iteration limit (no ETA: they usually stop far before it)."""


class ProgressReporter:
    """Progress of long work: a rich bar on a terminal, plain lines otherwise, and log lines.

    Use as a context manager; :meth:`callback` gives the ``cb(stage, done, total)`` that
    :func:`thermctl.identify.identify` (and anything else with a ``progress=`` argument)
    calls. Lines such as ``"identify: selection 3/9, elapsed 1:23, ETA ~2:10"`` go to the
    ``thermctl`` logger at INFO and, when stderr is not a terminal (a CI log, ``nohup``, a
    pipe), to stderr as plain text: the first and last call of each stage, and changes of
    the count at most every ``min_interval`` seconds. The ETA extrapolates the mean time
    per step of the stage once one step is done. One long step (a stage sitting at 0/1 for
    minutes) would look frozen, so while a stage is unfinished a heartbeat line with the
    elapsed time follows every ``heartbeat`` seconds without news; on a terminal the bar's
    own clock ticks instead.

    Parameters
    ----------
    name : str
        Prefix of the lines (e.g. ``"identify"``).
    terminal : bool, optional
        Force the rich bar (True) or plain lines (False); default: whether stderr is a
        terminal.
    min_interval : float
        Shortest time between two lines of the same stage [s] (first and last excepted).
    heartbeat : float
        Time without a line after which an unfinished stage is reported again [s].
    """

    def __init__(self, name: str = "thermctl", terminal: bool | None = None,
                 min_interval: float = 5.0, heartbeat: float = 30.0):
        self.name = name
        self.terminal = err_console.is_terminal if terminal is None else terminal
        self.min_interval = min_interval
        self.heartbeat = heartbeat
        self._bar = None
        self._tasks = {}
        self._stages = {}          # stage -> [t_start, t_last_line, (done, total) last seen]
        self._current = None       # the stage of the latest call
        self._last_line = time.perf_counter()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = None

    def __enter__(self):
        if self.terminal:
            self._bar = Progress(TextColumn("{task.description}"), BarColumn(),
                                 MofNCompleteColumn(), TimeElapsedColumn(),
                                 TextColumn("{task.fields[eta]}"), console=err_console,
                                 transient=True)
            self._bar.__enter__()
        elif self.heartbeat > 0:
            self._thread = threading.Thread(target=self._beat, daemon=True,
                                            name="thermctl-progress")
            self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        if self._bar is not None:
            self._bar.__exit__(*exc)
        return False

    def line(self, stage: str, done: int, total: int, now: float | None = None) -> str:
        """The text of one progress line (also what the log gets)."""
        now = time.perf_counter() if now is None else now
        t_start = self._stages.get(stage, [now])[0]
        elapsed = now - t_start
        if stage in LIMIT_STAGES:
            # an iteration limit, not a count of work: IPOPT stops at 13 of 500 on the
            # 49-zone paper pipeline, so an ETA from the limit said "~13 min" for 20 s
            return (f"{self.name}: {stage} iteration {done} (limit {total}), "
                    f"elapsed {_clock(elapsed)}")
        count = f"{done}/{total}" if total else f"{done}"
        text = f"{self.name}: {stage} {count}, elapsed {_clock(elapsed)}"
        if total and done >= total:
            text += ", done"
        elif total and done > 0:
            text += f", ETA ~{_clock(elapsed / done * (total - done))}"
        return text

    def callback(self):
        """``cb(stage: str, done: int, total: int)`` for ``progress=`` arguments."""
        return self.report

    # rich.Progress-style use (``task = p.add_task(name); p.update(task, completed=k)``)
    def add_task(self, description: str, total=None, **_) -> str:
        """A stage named ``description``; returns its id for :meth:`update`."""
        self.report(description, 0, total)
        return description

    def update(self, task: str, *, completed=None, total=None, **_) -> None:
        """Like :meth:`rich.progress.Progress.update` for a task from :meth:`add_task`."""
        st = self._stages.get(task)
        last = st[2] if st is not None and st[2] is not None else (0, None)
        self.report(task, last[0] if completed is None else int(completed),
                    last[1] if total is None else total)

    def report(self, stage: str, done: int, total) -> None:
        """One progress call: ``done`` of ``total`` steps of ``stage`` (total None: unknown)."""
        now = time.perf_counter()
        with self._lock:
            st = self._stages.get(stage)
            first = st is None
            if first:
                st = self._stages[stage] = [now, -float("inf"), None]
            changed = st[2] != (done, total)
            st[2] = (done, total)
            self._current = stage
            finished = bool(total) and done >= total
            if changed and (first or finished or now - st[1] >= self.min_interval):
                st[1] = now
                self._emit(self.line(stage, done, total, now), now)
            self._update_bar(stage, done, total, now)

    def _emit(self, text: str, now: float) -> None:
        self._last_line = now
        logger.info(text)
        if not self.terminal:
            print(text, file=sys.stderr, flush=True)

    def _beat(self):
        """Heartbeat thread: repeat an unfinished stage after ``heartbeat`` s of silence."""
        while not self._stop.wait(min(1.0, self.heartbeat)):
            now = time.perf_counter()
            with self._lock:
                stage = self._current
                if stage is None or now - self._last_line < self.heartbeat:
                    continue
                done, total = self._stages[stage][2]
                if total and done >= total:
                    continue
                self._emit(self.line(stage, done, total, now) + " (working)", now)

    def _update_bar(self, stage, done, total, now):
        if self._bar is None:
            return
        elapsed = now - self._stages[stage][0]
        eta = f"ETA ~{_clock(elapsed / done * (total - done))}" if total and 0 < done < total else ""
        if stage not in self._tasks:
            self._tasks[stage] = self._bar.add_task(stage, total=total, eta=eta)
        self._bar.update(self._tasks[stage], completed=done, total=total, eta=eta)


def progress(name: str = "thermctl", **kwargs) -> ProgressReporter:
    """Progress for long work: a bar on a terminal, plain stderr lines otherwise, log lines.

    ``with progress("identify") as p: run(..., progress=p.callback())``.
    """
    return ProgressReporter(name, **kwargs)
