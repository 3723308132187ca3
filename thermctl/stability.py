"""Stability selection of air paths: how often the selection picks an edge on resampled days.

The likelihood's evidence for an air path is inflated when the model is only approximately
right (issue 20: BIC differences of 10²–10⁴ for spurious couplings on the twin house). A
frequency is a different kind of evidence: refit the same selection on many random halves
of the calibration days and count how often each candidate is chosen (Meinshausen &
Bühlmann, "Stability selection", J. R. Stat. Soc. B 72, 2010). An edge that a few days
alone bring into the model is chosen on the halves holding those days only.

Days are resampled in **blocks of consecutive days** (weather and occupancy run over days,
so single days are not independent samples) and without replacement. A resample keeps the
rows of its blocks and sets every other row to NaN: the likelihood splits the data at NaN
rows into segments, each with its own burn-in
(:class:`~thermctl.estimate.likelihood.LikelihoodOptions` ``burn_in``), so a resample is
a gappy log of the same building, not a shorter one glued together.

Each resample runs the same selection as the full data (:func:`stability_selection`:
:func:`thermctl.selection.select_air_paths` with the same candidates and options;
:func:`stability_local`: the local problems and their combination rule). The candidates
are fixed by the full data: SIN, which proposes them, needs ``zones + 2`` complete days and
half of the days are often fewer.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from ._parallel import run_tasks
from .errors import DataError, EstimationError
from .local import ONE_SIDED

__all__ = ["StabilityResult", "StabilityResample", "resample_days", "stability_selection",
           "stability_local", "STABILITY_THRESHOLD"]

log = logging.getLogger(__name__)

STABILITY_THRESHOLD = 0.6
"""Frequency below which a selected edge is dropped [-]. Meinshausen & Bühlmann (2010)
bound the expected number of false selections for thresholds in 0.6–0.9 and find the
results insensitive within that range; 0.6, the low end, drops an edge only when the
selection leaves it out on at least 40 % of the half-data resamples. Measured on the 7-zone
testbed with B = 10 (docs/identification.md, "Stability selection"): true paths 0.7–1.0 on
14–16 days (0.8 would have dropped one), 0.3 for the weakest on 12 days; a spurious path
1.0 on 16 days, 0.2 on 12."""


@dataclass
class StabilityResample:
    """One resample: the days it kept and what the selection chose on them.

    Attributes
    ----------
    index : int
    kept_days : list of str
        ISO dates kept (local calendar days of the data).
    edges : list of str
        Air paths selected, ``air:a-b``.
    cpu : float
        CPU time of the process that ran it [s].
    time : float
        Wall time [s].
    error : str or None
        Why the selection failed on this resample (it then counts for no edge and is left
        out of the frequencies' denominator).
    """

    index: int
    kept_days: list
    edges: list = field(default_factory=list)
    cpu: float = 0.0
    time: float = 0.0
    error: str | None = None


@dataclass
class StabilityResult:
    """Outcome of :func:`stability_selection` / :func:`stability_local`.

    Attributes
    ----------
    frequency : dict
        Candidate air path ``air:a-b`` → fraction of the successful resamples that selected
        it [-] (every candidate, 0 included).
    resamples : list of StabilityResample
    fraction : float
        Fraction of the day blocks each resample keeps [-].
    block_days : int
        Days per block [d].
    seed : int
    time : float
        Wall time of all resamples [s].
    cpu : float
        CPU time summed over the resamples' processes [s].
    """

    frequency: dict
    resamples: list
    fraction: float
    block_days: int
    seed: int
    time: float
    cpu: float

    @property
    def kept_days(self) -> list:
        """Per resample, the ISO dates it kept."""
        return [r.kept_days for r in self.resamples]

    @property
    def n_ok(self) -> int:
        """Resamples whose selection ran."""
        return sum(r.error is None for r in self.resamples)

    def below(self, edges, threshold: float = STABILITY_THRESHOLD) -> list:
        """Names of ``edges`` (names or ``(a, b[, d])``) selected on fewer than
        ``threshold`` of the resamples [-]."""
        from .network import air_path_name
        names = [e if isinstance(e, str) else air_path_name(e[0], e[1]) for e in edges]
        return [n for n in names if self.frequency.get(n, 0.0) < threshold]

    def to_dict(self) -> dict:
        """Plain numbers for ``identification.json``."""
        return {"frequency": dict(self.frequency), "resamples": len(self.resamples),
                "ok": self.n_ok, "fraction": self.fraction, "block_days": self.block_days,
                "seed": self.seed, "time_s": self.time, "cpu_s": self.cpu,
                "kept_days": self.kept_days, "selected": [r.edges for r in self.resamples],
                "errors": [r.error for r in self.resamples if r.error]}

    def summary(self, threshold: float = STABILITY_THRESHOLD) -> str:
        lines = [f"stability selection: {self.n_ok}/{len(self.resamples)} resamples of "
                 f"{self.fraction:g} of the {self.block_days}-day blocks, {self.cpu:.0f} s CPU"]
        for nm, f in sorted(self.frequency.items(), key=lambda kv: (-kv[1], kv[0])):
            lines.append(f"  {nm:28s} {f:5.2f}{'  (below threshold)' if f < threshold else ''}")
        return "\n".join(lines)


# ---------------------------------------------------------------------------- resampling
def _days(frame):
    """Local calendar days of the index, in order, and each row's day number."""
    dates = np.asarray(frame.index.date)
    uniq, inv = np.unique(dates, return_inverse=True)
    return list(uniq), inv


def resample_days(frame, resamples: int, *, fraction: float = 0.5, block_days: int = 2,
                  seed: int = 0) -> list:
    """The days each resample keeps: a seeded random subset of blocks of consecutive days.

    Parameters
    ----------
    frame : pandas.DataFrame
        Calibration data with a ``DatetimeIndex``.
    resamples : int
        Number of resamples, >= 1.
    fraction : float
        Fraction of the blocks kept, in (0, 1) [-]: ``round(fraction × blocks)`` of them
        (half of 5 blocks: 2), at least one kept and at least one left out. Meinshausen &
        Bühlmann subsample half the data.
    block_days : int
        Consecutive calendar days per block [d] (the last block may be shorter).
    seed : int
        Resample ``b`` draws from ``numpy.random.default_rng([seed, b])``: the same seed gives
        the same days, and resample ``b`` does not depend on how many follow it.

    Returns
    -------
    list of list of datetime.date
        Per resample, the kept days in order.
    """
    if int(resamples) < 1:
        raise EstimationError(f"stability resamples must be >= 1, found {resamples}")
    if not 0.0 < fraction < 1.0:
        raise EstimationError(f"stability fraction must be in (0, 1), found {fraction}")
    if int(block_days) < 1:
        raise EstimationError(f"stability block_days must be >= 1, found {block_days}")
    days, _ = _days(frame)
    blocks = [days[i:i + int(block_days)] for i in range(0, len(days), int(block_days))]
    if len(blocks) < 2:
        raise DataError(f"stability selection: {len(days)} calibration day(s) make "
                        f"{len(blocks)} block(s) of {block_days} days; at least 2 are needed")
    k = min(len(blocks) - 1, max(1, int(round(fraction * len(blocks)))))
    out = []
    for b in range(int(resamples)):
        rng = np.random.default_rng([int(seed), b])
        pick = np.sort(rng.choice(len(blocks), size=k, replace=False))
        out.append([d for i in pick for d in blocks[i]])
    return out


def mask_days(frame, keep):
    """``frame`` with every row outside the days ``keep`` set to NaN (``solar:`` columns
    aside: irradiance is an input the data reader fills; a row is left out of the likelihood
    when any temperature or supply value is NaN)."""
    days, inv = _days(frame)
    keep = set(keep)
    drop = ~np.array([d in keep for d in days], dtype=bool)[inv]
    out = frame.copy()
    cols = [c for c in out.columns if not c.startswith("solar:")]
    out.loc[drop, cols] = np.nan
    return out


# ---------------------------------------------------------------------------- run
def _select_task(index, spec, meas, kwargs):
    """One resample of the whole-building selection; errors returned, not raised (as
    :func:`thermctl.local._fit_task`)."""
    import warnings

    from ._blas import single_thread_blas
    from .errors import BoundWarning, ConvergenceWarning
    from .network import air_path_name
    from .selection import select_air_paths
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        with single_thread_blas(), warnings.catch_warnings():
            warnings.simplefilter("ignore", BoundWarning)
            warnings.simplefilter("ignore", ConvergenceWarning)
            sel = select_air_paths(spec, meas, **kwargs)
        edges, err = [air_path_name(a, b) for a, b, _ in sel.edges], None
    except Exception as exc:            # noqa: BLE001 - one resample must not stop the rest
        log.warning("stability resample %d failed: %s", index, exc)
        edges, err = [], f"{type(exc).__name__}: {exc}"
    return index, edges, time.process_time() - c0, time.perf_counter() - t0, err


def _candidate_names(spec, candidates) -> list:
    from .structure.search import as_candidates
    return [c.name for c in as_candidates(spec, candidates)]


def _measurements(cal, frame):
    """``cal`` with its frame replaced (same spec, step, units, quality, input timing)."""
    from .data import Measurements
    return Measurements(frame, cal.step, cal.spec, cal.units, cal.source, cal.quality,
                        cal.input_timing)


def _frequencies(names, resamples):
    ok = [r for r in resamples if r.error is None]
    if not ok:
        raise EstimationError("stability selection: the selection failed on every resample: "
                              + (resamples[0].error if resamples else "no resample"))
    return {n: sum(n in r.edges for r in ok) / len(ok) for n in sorted(names)}


def stability_selection(spec, cal, *, resamples: int = 10, fraction: float = 0.5,
                        block_days: int = 2, seed: int = 0, workers: int | None = None,
                        progress=None, **selection_kwargs) -> StabilityResult:
    """Selection frequency of every candidate air path over resampled blocks of days.

    Parameters
    ----------
    spec : BuildingSpec
    cal : thermctl.data.Measurements
        Calibration data.
    resamples : int
        B, the number of resamples; the cost is about B selections on half the data.
    fraction, block_days, seed
        See :func:`resample_days`.
    workers : int, optional
        Processes (default: every core); 1 runs in this process. One resample is one task,
        with one-threaded BLAS (as :func:`thermctl.local.run_local`).
    progress : callable, optional
        ``progress(stage, done, total)`` after each resample.
    **selection_kwargs
        Passed to :func:`thermctl.selection.select_air_paths` (give ``candidates`` as a
        list: the full data's). Its final fit is skipped (``final_per_edge=True`` with the
        likelihood: the search's last fit is kept): only the edges are used.

    Returns
    -------
    StabilityResult
    """
    t0 = time.perf_counter()
    kw = {k: v for k, v in selection_kwargs.items() if k not in ("progress", "on_fit")}
    kw.update(final_per_edge=True, final_criterion="likelihood")
    cands = kw.get("candidates", "all")
    if isinstance(cands, str):
        raise EstimationError("stability_selection: give the candidates as a list (the full "
                              f"data's), not {cands!r}: SIN on half the days may not run")
    names = _candidate_names(spec, cands)
    days = resample_days(cal.frame, resamples, fraction=fraction, block_days=block_days,
                         seed=seed)
    out = [StabilityResample(b, [str(d) for d in ks]) for b, ks in enumerate(days)]
    say = progress or (lambda *a: None)
    n = len(days)

    def meas(b):
        return _measurements(cal, mask_days(cal.frame, days[b]))

    finished = []

    def done(res):
        b, edges, cpu, wall, err = res
        out[b].edges, out[b].cpu, out[b].time, out[b].error = edges, cpu, wall, err
        finished.append(b)
        k = len(finished)
        log.info("stability resample %d/%d: %s (%.0f s CPU)", k, n, ", ".join(edges) or "none",
                 cpu)
        say("stability resamples", k, n)

    say("stability resamples", 0, n)
    run_tasks(_select_task, [(b, spec, meas(b), kw) for b in range(n)], workers=workers,
              on_done=lambda i, res: done(res))
    names = set(names) | {e for r in out for e in r.edges}
    return StabilityResult(_frequencies(names, out), out, fraction, int(block_days), int(seed),
                           time.perf_counter() - t0, float(sum(r.cpu for r in out)))


def stability_local(problems, frame, *, resamples: int = 10, fraction: float = 0.5,
                    block_days: int = 2, seed: int = 0, rule: str = "both",
                    margin: float = 10.0, workers: int | None = None, client=None,
                    progress=None, confirm: bool = False, one_sided: float | None = ONE_SIDED,
                    **fit_kwargs) -> StabilityResult:
    """Selection frequency of every candidate air path of the local problems.

    Every resample runs every local problem (:func:`thermctl.local.run_local`: the
    problems of all resamples are one set of tasks) and combines their verdicts by
    ``rule`` (:func:`thermctl.local.combine`), as :func:`thermctl.local.identify_local`.

    Parameters
    ----------
    problems : list of LocalProblem
        As the full data's identification made them (with SIN proposals, if any).
    frame : pandas.DataFrame
        Calibration data.
    resamples, fraction, block_days, seed
        See :func:`resample_days`.
    rule : {"both", "sum", "either"}
    margin : float
        [-]
    workers, client, progress
        As :func:`thermctl.local.run_local`.
    confirm : bool
        With ``rule="both"``, one-sided paths are tested at their other end on each
        resample (:func:`thermctl.local.confirm_local`), as on the full data.
    one_sided : float or None
        :func:`thermctl.local.combine`'s, as on the full data (default
        :data:`thermctl.local.ONE_SIDED`, as :func:`thermctl.local.identify_local`'s) [-].
    **fit_kwargs
        Passed to :func:`thermctl.local.fit_local`.

    Returns
    -------
    StabilityResult
        ``cpu`` sums the local tasks' CPU time.
    """
    from .local import combine, confirm_local, run_local
    from .network import air_path_name

    t0 = time.perf_counter()
    days = resample_days(frame, resamples, fraction=fraction, block_days=block_days, seed=seed)
    frames = [mask_days(frame, ks) for ks in days]
    n = len(problems)
    every = list(problems) * len(days)          # every problem on every resample
    tables = [f for f in frames for _ in range(n)]
    results = run_local(every, tables, workers=workers, client=client, progress=progress,
                        margin=margin, **fit_kwargs)
    if confirm and rule == "both":
        results = confirm_local(every, results, tables, workers=workers, client=client,
                                progress=progress,
                                groups=[b for b in range(len(days)) for _ in range(n)],
                                margin=margin, **fit_kwargs)
    out = []
    names = {air_path_name(a, b) for p in problems for a, b, _ in p.candidates}
    for b, ks in enumerate(days):
        res = results[b * n:(b + 1) * n]
        failed = [r for r in res if r.error]
        err = None if len(failed) < n else failed[0].error
        edges = [] if err else [v.name for v in combine(problems, res, rule, margin, one_sided)
                                if v.kept]
        out.append(StabilityResample(b, [str(d) for d in ks], edges,
                                     float(sum(r.cpu for r in res)),
                                     float(sum(r.time for r in res)), err))
    return StabilityResult(_frequencies(names, out), out, fraction, int(block_days), int(seed),
                           time.perf_counter() - t0, float(sum(r.cpu for r in out)))
