"""Identification at building scale: local problems on corridor buildings of 7 to 200 zones.

For every building (``thermctl.testbed.generate("corridor", zones=Z)``, 5-min data; with
7 zones also Pugh Hall's 7-zone section as a second row) and every worker count this
script runs what ``thermctl identify --scale local --workers N --intervals none`` runs::

    identify(meas, IdentifyOptions(estimation=EstimationOptions(intervals="none"),
                                   split=SplitOptions(scale="local", workers=N)))

on the calibration days (thermctl's default split: the last quarter of the whole days is
held back) and prints one markdown row per (building, workers) as soon as it is done.

Columns:

* ``zones`` / ``meas``: zones of the building (unmeasured corridors included) / measured
  zones;
* ``probs``, ``st med``, ``st max``: local problems (one per measured zone) and the median
  and largest state count of one local model with every candidate air path
  (:attr:`thermctl.local.LocalProblem.n_states`): the largest dense matrices of the run;
* ``model st``: states of the selected whole-building model (above
  ``refit_max_states`` = 150 it is not refitted as a whole and keeps the local R̄_v);
* ``wall s``: wall time of ``identify``;
* ``CPU s``: CPU of ``identify``: this process's ``time.process_time()`` plus, when the
  local problems ran on worker processes, ``LocalIdentification.cpu`` (the tasks'
  ``process_time`` summed: the fits only, not the workers' start-up or pickling);
  ``local s`` / ``tasks CPU s``: wall time of the local problems (split, fits, combination:
  ``LocalIdentification.time``) and their tasks' CPU (``LocalIdentification.cpu``); the
  rest of ``wall s`` is mostly the whole-building refit (models of at most 150 states);
  ``CPU all s``: this process's plus every reaped child's CPU (``getrusage``
  ``RUSAGE_CHILDREN``), which includes that overhead;
* ``RSS MB``: peak resident memory of this process during ``identify``
  (``ru_maxrss``, its high-water mark reset before each run through
  ``/proc/self/clear_refs``; marked ``*`` where that was not possible: then it is the
  peak so far, testbed generation included); ``child MB``: largest peak of any reaped
  worker process so far (``RUSAGE_CHILDREN``, cannot be reset; ``—`` with no child yet).
  Workers are forked: their peak counts the pages they share with this process;
* ``recall``: true air paths found / true air paths; ``false``: air paths found that are
  not true; ``f/10z``: false air paths per 10 zones (``zones`` column);
* ``R̄v err``: median over the true air paths found of |R̄_v(model) / R̄_v(truth) − 1|,
  the model's per-edge value (or its shared value after a whole-building refit);
  ``loc R̄v err``: the same for the local problems' combined per-edge R̄_v
  (``LocalIdentification.rbar_v``, before any whole-building refit);
* ``out R̄v``: air paths both ends kept that the R̄_v window put out
  (:func:`thermctl.local.rbar_consensus`), and how many of them are true;
* ``note``: failed local problems, or the exception of a failed run.

With ``--global-too`` buildings of at most 13 zones also get a ``scale="global"`` row
(the whole-building selection: SIN candidates, backward BIC on the whole building's
Kalman likelihood), the reference the local rows compare with.

The machine's load (``os.getloadavg``) at start and end and its core count are printed
under the table: on a shared machine the times are only comparable within one run.

Usage::

    python benchmarks/scale.py --quick                 # 9 zones, 4 days, workers 1 and 2 (~1-2 min)
    python benchmarks/scale.py --zones 7 25 50 --global-too
    python benchmarks/scale.py --zones 49 196 --workers 2 --seed 0 1 2 3   # + pooled lines
    OMP_NUM_THREADS=1 nice python benchmarks/scale.py --save   # 7…200 zones → results/scale.txt

Progress (timestamps, per-row summaries, local problems done) goes to stderr, the table to
stdout (and, with ``--save``, to ``benchmarks/results/scale.txt`` line by line, so a long
run that is stopped keeps the rows it finished).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import resource
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from thermctl.data import read_measurements
from thermctl.identify import EstimationOptions, IdentifyOptions, SplitOptions, identify
from thermctl.testbed import generate

RESULTS = Path(__file__).resolve().parent / "results"
GLOBAL_MAX_ZONES = 13          # --global-too: buildings with at most this many zones
LOCAL_CANDIDATES = SplitOptions().candidates   # --local-candidates (the default of identify)
GAIN_SCHEDULE = SplitOptions().gain_schedule    # --gain-schedule
JOINT = SplitOptions().joint                    # --joint
LOOP_GAIN = EstimationOptions().loop_gain        # --loop-gain
LOCAL_ROWS = SplitOptions().rows                 # --local-rows
MIN_T_DAYS = SplitOptions().min_t_days           # --local-min-t-days
ONE_SIDED = SplitOptions().one_sided             # --local-one-sided
ZONES = [7, 25, 50, 100, 200]


def say(msg: str) -> None:
    """Progress on stderr (the table is stdout)."""
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


@dataclass
class Row:
    """One identify run; NaN / None where a measure does not apply."""

    building: str
    zones: int
    measured: int
    scale: str
    workers: int | None
    problems: int | None = None
    states_med: float = math.nan
    states_max: float = math.nan
    model_states: int | None = None
    wall: float = math.nan
    local_wall: float = math.nan
    tasks_cpu: float = math.nan
    cpu: float = math.nan
    cpu_all: float = math.nan
    rss_mb: float = math.nan
    rss_reset: bool = True
    child_mb: float = math.nan
    n_true: int = 0
    n_hit: int = 0
    n_false: int = 0
    rbar_err: float = math.nan
    rbar_err_local: float = math.nan
    edges: list = field(default_factory=list)
    true_paths: list = field(default_factory=list)
    group: str = ""
    failed_problems: int = 0
    out_rbar: int | None = None
    out_rbar_true: int = 0
    note: str = ""

    @property
    def recall(self) -> float:
        return self.n_hit / self.n_true if self.n_true else math.nan

    @property
    def false_per_10(self) -> float:
        return 10.0 * self.n_false / self.zones if self.zones else math.nan

    @property
    def ok(self) -> bool:
        return not self.note.startswith("failed")


@dataclass
class Result:
    rows: list
    text: str
    seconds: float
    load_start: tuple
    load_end: tuple


# ---------------------------------------------------------------------------- measures
def _pair(a, b):
    return tuple(sorted((str(a), str(b))))


def per_edge(values, edges) -> dict:
    """Edge pair → value, from a shared value (scalar) or one value per edge (in order)."""
    v = np.atleast_1d(np.asarray(values, dtype=float))
    if v.size == 1:
        v = np.full(len(edges), float(v[0]))
    if v.size != len(edges):
        raise ValueError(f"{v.size} values for {len(edges)} edges")
    return {_pair(e[0], e[1]): float(x) for e, x in zip(edges, v)}


def score(model, truth_edges, truth_rbar_v) -> dict:
    """Structure and R̄_v of ``model`` against the truth.

    Parameters
    ----------
    model : ThermalModel
    truth_edges : list of (a, b, d)
    truth_rbar_v : float or list of float
        Shared or one per true edge (in ``truth_edges`` order).

    Returns
    -------
    dict
        ``n_true``, ``n_hit``, ``n_false``, ``rbar_err`` (median relative error over the
        true edges found, NaN if none), ``edges`` (pairs found, sorted).
    """
    conv = model.network.convection_edges
    found = {_pair(e.a, e.b) for e in conv}
    true = per_edge(truth_rbar_v, truth_edges)
    hits = sorted(found & set(true))
    errs = []
    if hits:
        mine = per_edge(model.rbar_v, [(e.a, e.b) for e in conv])
        errs = [abs(mine[p] / true[p] - 1.0) for p in hits]
    return {"n_true": len(true), "n_hit": len(hits), "n_false": len(found - set(true)),
            "rbar_err": float(np.median(errs)) if errs else math.nan,
            "edges": sorted(found)}


# ---------------------------------------------------------------------------- memory
def _reset_peak_rss() -> bool:
    """Reset this process's resident-memory high-water mark (Linux ``clear_refs``)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _mb(kb) -> float:
    # ru_maxrss is in kB on Linux, bytes on macOS
    return kb / (1024.0 * 1024.0) if sys.platform == "darwin" else kb / 1024.0


# ---------------------------------------------------------------------------- one run
def run_one(label, tb, meas, scale, workers, zones) -> Row:
    """``identify`` of one building at one scale / worker count, measured and scored."""
    spec = meas.spec
    row = Row(label, zones, len(spec.measured_zones), scale, workers if scale == "local" else None)
    opt = IdentifyOptions(estimation=EstimationOptions(intervals="none", loop_gain=LOOP_GAIN),
                          split=SplitOptions(scale=scale, workers=workers,
                                             candidates=LOCAL_CANDIDATES,
                                             gain_schedule=GAIN_SCHEDULE, joint=JOINT,
                                             rows=LOCAL_ROWS, min_t_days=MIN_T_DAYS,
                                             one_sided=ONE_SIDED))
    last = {"t": 0.0}
    t_start = time.perf_counter()

    def progress(stage, done, total):
        now = time.perf_counter()
        if (total and done == total) or now - last["t"] > 30.0:
            last["t"] = now
            say(f"  {label} {scale} w={workers}: {stage} {done}/{total or '?'} "
                f"({now - t_start:.0f} s)")

    reset = _reset_peak_rss()
    ch0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    c0, t0 = time.process_time(), time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ident = identify(meas, opt, progress=progress)
    except Exception as exc:        # a failing run is a result, not a crash
        row.wall = time.perf_counter() - t0
        row.note = f"failed: {type(exc).__name__}: {str(exc)[:100]}"
        return row
    row.wall = time.perf_counter() - t0
    cpu_self = time.process_time() - c0
    ch1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    me = resource.getrusage(resource.RUSAGE_SELF)
    row.rss_mb, row.rss_reset = _mb(me.ru_maxrss), reset
    row.child_mb = _mb(ch1.ru_maxrss) if ch1.ru_maxrss else math.nan
    row.cpu_all = cpu_self + (ch1.ru_utime + ch1.ru_stime) - (ch0.ru_utime + ch0.ru_stime)
    row.cpu = cpu_self
    li = ident.local
    if li is not None:
        st = [p.n_states for p in li.problems]
        row.problems = len(st)
        row.local_wall, row.tasks_cpu = li.time, li.cpu
        row.states_med = float(np.median(st)) if st else math.nan
        row.states_max = float(max(st)) if st else math.nan
        # tasks ran here (workers=1, or one problem): their CPU is in process_time already
        in_process = (workers or os.cpu_count() or 1) == 1 or len(li.problems) == 1
        if not in_process:
            row.cpu += li.cpu
        true = per_edge(tb.truth.rbar_v, tb.truth.edges)
        errs = [abs(li.rbar_v[f"air:{p[0]}-{p[1]}"] / true[p] - 1.0)
                for p in (_pair(a, b) for a, b, _ in li.edges)
                if p in true and math.isfinite(li.rbar_v.get(f"air:{p[0]}-{p[1]}", math.nan))]
        row.rbar_err_local = float(np.median(errs)) if errs else math.nan
        out = [v for v in li.verdicts if v.out_by_rbar]
        row.out_rbar = len(out)
        row.out_rbar_true = sum(1 for v in out if _pair(v.a, v.b) in true)
        row.failed_problems = sum(1 for r in li.results if r.error)
        if row.failed_problems:
            row.note = f"{row.failed_problems} local problem(s) failed"
    row.model_states = ident.model.network.n_states
    s = score(ident.model, tb.truth.edges, tb.truth.rbar_v)
    row.n_true, row.n_hit, row.n_false = s["n_true"], s["n_hit"], s["n_false"]
    row.rbar_err, row.edges = s["rbar_err"], s["edges"]
    found = {tuple(p) for p in row.edges}
    row.true_paths = [(float(d), _pair(a, b) in found) for a, b, d in tb.truth.edges]
    return row


# ---------------------------------------------------------------------------- table
def _f(v, spec="{:.0f}"):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—"
    return spec.format(v)


COLUMNS = [  # header, width, cell(row)
    ("building", 14, lambda r: r.building),
    ("zones", 5, lambda r: str(r.zones)),
    ("meas", 4, lambda r: str(r.measured)),
    ("scale", 6, lambda r: r.scale),
    ("workers", 7, lambda r: _f(r.workers, "{:d}")),
    ("probs", 5, lambda r: _f(r.problems, "{:d}")),
    ("st med", 6, lambda r: _f(r.states_med, "{:g}")),
    ("st max", 6, lambda r: _f(r.states_max, "{:g}")),
    ("model st", 8, lambda r: _f(r.model_states, "{:d}")),
    ("wall s", 7, lambda r: _f(r.wall, "{:.1f}")),
    ("CPU s", 7, lambda r: _f(r.cpu, "{:.1f}")),
    ("local s", 7, lambda r: _f(r.local_wall, "{:.1f}")),
    ("tasks CPU s", 11, lambda r: _f(r.tasks_cpu, "{:.1f}")),
    ("CPU all s", 9, lambda r: _f(r.cpu_all, "{:.1f}")),
    ("RSS MB", 7, lambda r: _f(r.rss_mb) + ("" if r.rss_reset or not r.ok else "*")),
    ("child MB", 8, lambda r: _f(r.child_mb)),
    ("recall", 6, lambda r: (f"{r.n_hit}/{r.n_true}" if r.n_true else "—") if r.ok else "—"),
    ("false", 5, lambda r: str(r.n_false) if r.ok else "—"),
    ("f/10z", 5, lambda r: _f(r.false_per_10, "{:.2f}") if r.ok else "—"),
    ("R̄v err", 7, lambda r: _f(100 * r.rbar_err, "{:.1f}%")),
    ("loc R̄v err", 11, lambda r: _f(100 * r.rbar_err_local, "{:.1f}%")),
    ("out R̄v", 6, lambda r: "—" if r.out_rbar is None else
     f"{r.out_rbar}" + (f" ({r.out_rbar_true} true)" if r.out_rbar_true else "")),
    ("note", 4, lambda r: r.note),
]


def _line(cells):
    out = []
    for (_, w, _), c in zip(COLUMNS, cells):
        out.append(c.ljust(w) if out == [] else c.rjust(w))
    return "| " + " | ".join(out) + " |"


def header() -> list[str]:
    head = _line([h for h, _, _ in COLUMNS])
    rule = "|" + "|".join(("-" * (w + 1) + ":") if k else ("-" * (w + 2))
                          for k, (_, w, _) in enumerate(COLUMNS)) + "|"
    return [head, rule]


def format_row(r: Row) -> str:
    return _line([fn(r) for _, _, fn in COLUMNS])


def table(rows) -> str:
    return "\n".join(header() + [format_row(r) for r in rows])


# ---------------------------------------------------------------------------- output
class Out:
    """Lines to stdout and (``--save``) to the results file, flushed line by line."""

    def __init__(self, path=None):
        self.lines = []
        self.f = open(path, "w", encoding="utf-8") if path else None

    def __call__(self, line=""):
        self.lines.append(line)
        print(line, flush=True)
        if self.f:
            self.f.write(line + "\n")
            self.f.flush()

    def close(self):
        if self.f:
            self.f.close()


def _git_head() -> str:
    """The checkout's commit, read from ``.git`` (no subprocess: a forked child would
    count in ``RUSAGE_CHILDREN``'s peak memory)."""
    try:
        git = Path(__file__).resolve().parents[1] / ".git"
        head = (git / "HEAD").read_text().strip()
        if not head.startswith("ref: "):
            return head[:7]
        ref = head[5:]
        if (git / ref).exists():
            return (git / ref).read_text().strip()[:7]
        for line in (git / "packed-refs").read_text().splitlines():
            if line.endswith(" " + ref):
                return line[:7]
    except OSError:
        pass
    return "?"


def buildings(zones, pugh: bool, control_minutes: float | None = None):
    """(label, generate() arguments, zones asked) in run order."""
    out = []
    ctrl = {} if control_minutes is None else {"control_minutes": control_minutes}
    tag = "" if control_minutes is None else f" ctrl {control_minutes:g}"
    for z in zones:
        out.append((f"corridor {z}{tag}", dict(building="corridor", zones=z, **ctrl), z))
        if z == 7 and pugh:
            out.append((f"pugh-hall 7{tag}", dict(building="pugh-hall", **ctrl), 7))
    return out


LENGTH_BINS = (0.0, 3.0, 5.0, 7.0, math.inf)
"""Air path lengths [m] the pooled lines count true paths found in: a path's conductance
is 1/(R̄_v·d), and the long ones are the ones lost."""


def pooled(rows) -> list[str]:
    """One line per (size, scale, workers) over the seeds' rows: true paths found of all
    true paths, false paths per 10 zones, mean CPU; then the mean-CPU ratio of each size
    to the smallest with the same scale and workers (the linear-growth target compares
    200 zones with 50), and under it the true paths found by length (:data:`LENGTH_BINS`)."""
    groups = {}
    for r in rows:
        groups.setdefault((r.group or r.building, r.zones, r.scale, r.workers), []).append(r)
    lines, first = [], {}
    for (size, zones, scale, w), rs in groups.items():
        ok = [r for r in rs if not math.isnan(r.cpu)]
        hit, true = sum(r.n_hit for r in ok), sum(r.n_true for r in ok)
        false = sum(r.n_false for r in ok)
        cpu = float(np.mean([r.cpu for r in ok])) if ok else math.nan
        wall = float(np.mean([r.wall for r in ok])) if ok else math.nan
        text = (f"pooled {size} {scale} w={w}: {len(ok)} seed(s), recall {hit}/{true} = "
                f"{hit / max(true, 1):.2f}, {false} false = "
                f"{10 * false / max(zones * len(ok), 1):.2f} per 10 zones; mean "
                f"{wall:.1f} s wall, {cpu:.1f} s CPU")
        base = first.setdefault((scale, w), (zones, cpu, wall))
        if base[0] != zones:
            text += (f"; ×{cpu / base[1]:.2f} CPU, ×{wall / base[2]:.2f} wall of {base[0]} "
                     f"zones for ×{zones / base[0]:.2f} the zones")
        lines.append(text)
        paths = [p for r in ok for p in r.true_paths]
        if paths:
            d = np.array([p[0] for p in paths])
            found = np.array([p[1] for p in paths], dtype=bool)
            parts = []
            for lo, hi in zip(LENGTH_BINS, LENGTH_BINS[1:]):
                m = (d >= lo) & (d < hi)
                name = f"< {hi:g} m" if lo == 0 else (f">= {lo:g} m" if math.isinf(hi)
                                                        else f"{lo:g}-{hi:g} m")
                parts.append(f"{name} {int(found[m].sum())}/{int(m.sum())}")
            lines.append(f"  true paths found by length (median {np.median(d):.1f} m): "
                         + ", ".join(parts))
    return lines


# ---------------------------------------------------------------------------- main
def main(argv=None) -> Result:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--zones", type=int, nargs="+", default=ZONES,
                    help=f"corridor sizes (default {' '.join(map(str, ZONES))})")
    ap.add_argument("--workers", type=int, nargs="*", default=[1, 2],
                    help="worker processes of the local problems (default 1 2; none: "
                         "no local row, e.g. with --global-too)")
    ap.add_argument("--days", type=float, default=14.0, help="generated days (default 14)")
    ap.add_argument("--seed", type=int, nargs="+", default=[0],
                    help="testbed seed(s); with several, every building is drawn once per seed "
                         "and a pooled line per size follows the table (default 0)")
    ap.add_argument("--quick", action="store_true",
                    help="one 9-zone corridor, 4 days, workers 1 and 2 (~1-2 min)")
    ap.add_argument("--global-too", action="store_true",
                    help=f"also scale='global' for buildings of at most {GLOBAL_MAX_ZONES} zones")
    ap.add_argument("--no-pugh", action="store_true", help="no pugh-hall row with 7 zones")
    ap.add_argument("--local-candidates", choices=("all", "sin"), default=LOCAL_CANDIDATES,
                    help="what each local search starts from (as identify --local-candidates)")
    ap.add_argument("--control-minutes", type=float, default=None, metavar="M",
                    help="the testbed's control step [min] (default 1: the VAV boxes act "
                         "between the 5-min samples; 5: at the data step, the logged inputs "
                         "are what the plant got; labels get ' ctrl M')")
    ap.add_argument("--gain-schedule", choices=("occupied",), default=None,
                    help="split.gain_schedule: the local fits' gains wander faster in "
                         "occupied hours")
    ap.add_argument("--joint", action="store_true",
                    help="split.joint: every kept path tested again in a joint problem of "
                         "both ends")
    ap.add_argument("--loop-gain", action="store_true",
                    help="estimation.loop_gain: a fitted gain per zone with supply air for its "
                         "loop acting between samples")
    ap.add_argument("--local-rows", choices=("all", "auto", "supply_off"), default=LOCAL_ROWS,
                    help="split.rows: the samples whose innovations count in the local "
                         f"likelihoods (default {LOCAL_ROWS})")
    ap.add_argument("--save", action="store_true", help=f"write {RESULTS.name}/scale.txt")
    ap.add_argument("--local-min-t-days", type=float, default=MIN_T_DAYS, metavar="D",
                    help="split.min_t_days: the calibration days the local daily-gain t test "
                         f"is for, longer records ask t·√(days/D) (default {MIN_T_DAYS:g}; "
                         "0: the same t on any record)")
    ap.add_argument("--local-one-sided", type=float, default=ONE_SIDED, metavar="T",
                    help="split.one_sided: a path one end keeps is kept when the ends' BIC "
                         f"changes sum below -T (default {ONE_SIDED}; a negative T: none)")
    args = ap.parse_args(argv)
    globals()["ONE_SIDED"] = (None if args.local_one_sided is None or args.local_one_sided < 0
                              else args.local_one_sided)
    globals()["LOCAL_ROWS"] = args.local_rows
    globals()["MIN_T_DAYS"] = args.local_min_t_days or None
    globals()["JOINT"] = args.joint
    globals()["LOOP_GAIN"] = args.loop_gain
    globals()["LOCAL_CANDIDATES"] = args.local_candidates
    globals()["GAIN_SCHEDULE"] = args.gain_schedule
    if args.quick:
        args.zones, args.days, args.workers = [9], 4.0, [1, 2]
    # the library's log lines (one per local problem) would interleave with the table
    logging.getLogger("thermctl").setLevel(logging.ERROR)

    cores = os.cpu_count() or 1
    try:
        avail = len(os.sched_getaffinity(0))
    except AttributeError:
        avail = cores
    load0 = os.getloadavg()
    T0 = time.perf_counter()
    out = Out(RESULTS / "scale.txt" if args.save else None)
    cmd = "python benchmarks/scale.py " + " ".join(argv if argv is not None else sys.argv[1:])
    out(f"# Identification at building scale ({cmd.strip()})")
    out()
    seeds = list(dict.fromkeys(args.seed))
    out(f"thermctl @ {_git_head()}, {time.strftime('%Y-%m-%d %H:%M')}, "
        f"seed{'s' if len(seeds) > 1 else ''} {' '.join(map(str, seeds))}, "
        f"{args.days:g} generated days (last quarter held back), 5-min data; "
        f"identify(scale=..., workers=N, intervals='none', split.min_t_days={MIN_T_DAYS}, "
        f"split.one_sided={ONE_SIDED}); "
        f"OMP_NUM_THREADS="
        f"{os.environ.get('OMP_NUM_THREADS', 'unset')}")
    out()
    rows = []
    started = False
    try:
        for group, label, kw, z, seed in [(lb, lb + (f" s{sd}" if len(seeds) > 1 else ""), kw,
                                           z, sd)
                                          for lb, kw, z in buildings(args.zones, not args.no_pugh,
                                                                     args.control_minutes)
                                          for sd in seeds]:
            t = time.perf_counter()
            say(f"{label}: generating {args.days:g} days")
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    tb = generate(days=args.days, seed=seed, **kw)
                    meas = read_measurements(tb.data, tb.spec, name=label)
            except Exception as exc:    # noqa: BLE001 - a building that fails is a result
                say(f"{label}: generation failed: {type(exc).__name__}: {exc}")
                continue
            n_zones = len(tb.spec.zones)
            say(f"{label}: {n_zones} zones ({len(tb.spec.measured_zones)} measured), "
                f"{len(tb.truth.edges)} true air paths, {len(meas)} samples; generated in "
                f"{time.perf_counter() - t:.0f} s")
            runs = [("local", w) for w in args.workers]
            if args.global_too and n_zones <= GLOBAL_MAX_ZONES:
                runs.append(("global", None))
            for scale, w in runs:
                say(f"{label}: identify scale={scale}" + (f" workers={w}" if w else ""))
                r = run_one(label, tb, meas, scale, w, n_zones)
                r.group = group
                rows.append(r)
                if not started:
                    for ln in header():
                        out(ln)
                    started = True
                out(format_row(r))
                say(f"{label} {scale} w={w}: {r.wall:.0f} s wall, {r.cpu:.0f} s CPU; found "
                    f"{len(r.edges)} air path(s), {r.n_hit}/{r.n_true} true, {r.n_false} false"
                    + (f"; {r.note}" if r.note else ""))
            del tb, meas
    finally:
        load1 = os.getloadavg()
        seconds = time.perf_counter() - T0
        if not started:
            out("(no row)")
        if len(seeds) > 1 and rows:
            out()
            for ln in pooled(rows):
                out(ln)
        out()
        out(f"machine: {cores} cores ({avail} available to this process); load average "
            f"(1, 5, 15 min) at start {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, at end "
            f"{load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")
        out(f"{len(rows)} run(s), {seconds:.0f} s in all (testbed generation included)")
        out.close()
    return Result(rows, "\n".join(out.lines), seconds, load0, load1)


if __name__ == "__main__":
    main()
