"""The model's regular time grid: step, alignment, resampling onto it, gap runs.

All times here are int64 nanoseconds since the epoch (UTC); durations are ns too.

* The step is given (it must divide a day) or inferred from the data's median spacing,
  snapped to the nearest whole-minute divisor of a day (whole-second divisor of a minute
  below one minute).
* The grid is aligned to local midnight of the data's time zone and runs from the first
  grid point at or after the first stamp to the last one at or before the last stamp
  (each with 1 s tolerance, or ``snap``).
* A grid point with a valid sample within 1 s (within ``snap``, when the reader is given
  one: a trend log polled with jitter) takes that sample; otherwise the value is
  interpolated linearly between the valid samples before and after it. The time between
  those two samples is the gap: up to ``bridge`` (1.5 × the larger of step and data
  spacing) the point is plain resampling, up to ``gap_limit`` a filled short gap, longer
  (or with no sample on one side) it stays NaN.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..errors import DataError

_ON_GRID_TOL = 1_000_000_000          # [ns]: a sample within 1 s of a grid point is on it
_DAY_NS = 86_400 * 1_000_000_000
# resampling codes per grid point and column
_EXACT, _RESAMPLED, _FILLED, _EXCLUDED = 0, 1, 2, 3


class _Grid(NamedTuple):
    """The model grid of one read (all times and durations in ns)."""

    times: np.ndarray          # int64 UTC instants of the grid points
    index: pd.DatetimeIndex    # the same instants in the data's time zone, named "time"
    step_ns: int
    data_step: int             # median spacing of the distinct stamps
    off_grid: int              # distinct stamps more than ``snap`` off the grid
    bridge: float              # longest span between samples that is plain resampling
    snapped: int = 0           # distinct stamps more than 1 s but at most ``snap`` off it
    snap: int = _ON_GRID_TOL   # a sample this close to a grid point is its sample


def _timedelta(value, what) -> pd.Timedelta:
    """A duration from seconds (int/float) or anything :class:`pandas.Timedelta` parses."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return pd.Timedelta(seconds=value)
    return _parse(pd.Timedelta, value,
                  f"{what}: expected a duration such as '5min', found {value!r}")


def _parse(parse, value, message: str):
    """``parse(value)`` (``pd.Timedelta``, ``pd.Timestamp``), or :class:`DataError` (``message``).

    pandas reports an unreadable value either by raising or by returning ``NaT`` (for
    ``None``, ``"nat"``, ``""``), so both count as failure.
    """
    try:
        out = parse(value)
    except (ValueError, TypeError):
        out = pd.NaT
    if out is pd.NaT:
        raise DataError(message)
    return out


def _fmt_step(seconds: float) -> str:
    if seconds % 60 == 0:
        return f"{int(seconds // 60)} min"
    return f"{seconds:g} s"


def _infer_step(data_step: int, src) -> int:
    """Median spacing → the nearest whole-minute (or whole-second) divisor of a day [ns]."""
    if data_step <= 0:
        raise DataError(f"{src}: cannot infer the time step; pass step=")
    if data_step > _DAY_NS:
        raise DataError(f"{src}: time stamps are {pd.Timedelta(data_step)} apart; "
                        "need at least one sample a day")
    if data_step >= 60e9:
        cands = [m * 60 for m in range(1, 1441) if 1440 % m == 0]
    else:
        cands = [s for s in range(1, 61) if 60 % s == 0]
    best = min(cands, key=lambda c: abs(math.log(data_step / (c * 1e9))))
    return int(best * 1_000_000_000)


def _make_grid(t, step, tzinfo, src, notes, snap=None) -> _Grid:
    """The grid for sorted distinct stamps ``t`` [ns]; appends a note if the step is rounded.

    ``snap`` [ns or anything :func:`_timedelta` reads; ``"auto"``: a tenth of the step;
    None: 1 s] widens the 1 s within which a stamp is on a grid point (also for the first and last grid point: a first stamp 10 s late
    still starts the grid at its slot); it must be less than half the step, so that no
    sample can belong to two grid points.
    """
    data_step = int(np.median(np.diff(t)))
    if step is None:
        step_ns = _infer_step(data_step, src)
        if abs(step_ns - data_step) > 0.05 * step_ns:
            notes.append(f"data spacing {data_step / 1e9:g} s rounded to step "
                         f"{_fmt_step(step_ns / 1e9)}")
    else:
        step_ns = _timedelta(step, "step").value
        if step_ns <= 0 or _DAY_NS % step_ns:
            raise DataError(f"step must be > 0 and divide a day (e.g. '5min', '10min'), "
                            f"found {step!r}")
    tol = _ON_GRID_TOL
    if isinstance(snap, str) and snap == "auto":
        # a tenth of the step (30 s at 5 min): a polled log's jitter, far from the next slot
        tol = max(_ON_GRID_TOL, step_ns // 10)
    elif snap is not None:
        tol = max(_ON_GRID_TOL, _timedelta(snap, "snap").value)
        if 2 * tol >= step_ns:
            raise DataError(f"snap must be less than half the step "
                            f"({pd.Timedelta(step_ns // 2)}), found {snap!r}")
    # grid points sit on multiples of the step counted from local midnight
    off = int(pd.Timestamp(t[0], tz="UTC").tz_convert(tzinfo).utcoffset().total_seconds() * 1e9)
    g0 = -((-(t[0] + off - tol)) // step_ns) * step_ns - off     # ceil
    g1 = ((t[-1] + off + tol) // step_ns) * step_ns - off        # floor
    if g1 < g0:
        raise DataError(f"{src}: data span {pd.Timedelta(int(t[-1] - t[0]))} is shorter "
                        f"than one step {pd.Timedelta(step_ns)}")
    grid = np.arange(g0, g1 + 1, step_ns, dtype=np.int64)
    r = (t - g0) % step_ns
    dist = np.minimum(r, step_ns - r)
    off_grid = int((dist > tol).sum())
    snapped = int(((dist > _ON_GRID_TOL) & (dist <= tol)).sum())
    index = pd.DatetimeIndex(pd.to_datetime(grid, unit="ns", utc=True)).tz_convert(tzinfo)
    index.name = "time"
    return _Grid(grid, index, step_ns, data_step, off_grid, 1.5 * max(step_ns, data_step),
                 snapped, tol)


def _regrid(t, v, grid, bridge, gap_ns, snap=_ON_GRID_TOL):
    """Values of one column on the grid and how each was obtained (``_EXACT``...).

    A grid point with a valid sample within ``snap`` [ns] takes the nearest such sample.
    """
    ok = np.isfinite(v)
    tv, vv = t[ok], v[ok]
    n = len(tv)
    j = np.searchsorted(tv, grid, side="right")        # tv[j-1] <= g < tv[j]
    has_p, has_n = j > 0, j < n
    jp, jn = np.clip(j - 1, 0, n - 1), np.clip(j, 0, n - 1)
    dp = np.where(has_p, (grid - tv[jp]).astype(float), np.inf)
    dn = np.where(has_n, (tv[jn] - grid).astype(float), np.inf)
    span = dp + dn
    exact = np.minimum(dp, dn) <= snap
    with np.errstate(invalid="ignore", divide="ignore"):
        lin = vv[jp] + (vv[jn] - vv[jp]) * (dp / span)
    out = np.where(exact, np.where(dp <= dn, vv[jp], vv[jn]), lin)
    code = np.full(len(grid), _EXCLUDED, dtype=np.int8)
    code[exact] = _EXACT
    inner = ~exact & has_p & has_n
    code[inner & (span <= bridge)] = _RESAMPLED
    code[inner & (span > bridge) & (span <= gap_ns)] = _FILLED
    out[code == _EXCLUDED] = np.nan
    return out, code


def _runs(mask) -> list[tuple[int, int]]:
    """Maximal runs of True in a 1-D boolean array, as half-open ``(first, stop)`` indices."""
    m = np.r_[False, mask, False].astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]
