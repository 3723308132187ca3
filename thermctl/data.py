"""Measured data: CSV/parquet ingest, units, resampling, gaps, splits, day × time-of-day arrays.

The exchange format (DESIGN.md, "Data exchange formats") is a wide table, one row per
time stamp:

=================  ==========================  =============================================
column             SI (``units="si"``)         imperial (``units="imperial"``)
=================  ==========================  =============================================
``time``           ISO 8601, UTC offset optional (``2011-01-21T00:05:00-05:00``)
``T:<node>``       °C                          °F
``Ts:<zone>``      °C                          °F
``ms:<zone>``      kg/s                        CFM (read as volume flow, like ``vs:``)
``vs:<zone>``      m³/s                        CFM
``Q:<zone>``       W                           W
``solar:<name>``   W/m²                        W/m²
=================  ==========================  =============================================

Choices this module makes (the user guide repeats them):

* Imperial means what a BAS export holds: temperatures in °F and air flows in CFM. A BAS
  logs no mass flow, so in imperial data an ``ms:`` column is a CFM column too. Flows
  become mass flows with ρ = 1.2 kg/m³ (:data:`thermctl.spec.RHO_AIR`, standard air).
  Heat inputs stay in W and irradiance in W/m² (metered power is logged in W; nobody's
  BAS logs BTU/h of heater power).
* Columns with any other prefix (``aux:``, ``wind:``, ``rh:`` ...) or no prefix are
  ignored and listed. A ``T:`` column of an unmeasured zone (``measured: false``) is
  ignored with a :class:`~thermctl.errors.DataWarning`.
* Time stamps with UTC offsets keep them: with one offset throughout, the data's time zone
  is that fixed offset; with several (daylight saving) it is the smallest offset, i.e.
  standard time, so every day has the same number of samples. Stamps without an offset
  are local time in ``tz`` (default UTC). Days, time-of-day indices and date splits are
  taken in that time zone.
* The model grid has step ``step`` (default: the data's median spacing snapped to a
  whole number of minutes that divides a day), aligned to local midnight, from the
  first to the last stamp. A grid point with a sample within 1 s takes that sample;
  otherwise the value is linearly interpolated in time between the valid samples before
  and after it. The time between those two samples is the *gap*: up to 1.5 data steps it
  is plain resampling of irregular stamps, up to ``gap_limit`` a short gap (interpolated
  and counted), longer a long gap (left NaN, reported, excluded). Down-sampling takes the
  value at each grid instant; it does not average.
* Duplicated time stamps are merged (rows with conflicting values are averaged and
  counted); rows out of order are sorted; negative flows are set to 0 and counted.

Nothing here writes a file.
"""

from __future__ import annotations

import csv
import datetime as dt
import logging
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from .errors import DataError, DataWarning
from .spec import RHO_AIR, BuildingSpec

__all__ = [
    "read_measurements", "Measurements", "QualityReport", "Gap", "DayArray",
    "CFM", "PAPER_CALIBRATION", "PAPER_VALIDATION_START",
]

logger = logging.getLogger(__name__)

CFM = 0.3048 ** 3 / 60.0
"""One cubic foot per minute [m³/s]."""

PAPER_CALIBRATION = ("2011-01-21", "2011-02-09")
"""Calibration days of Goyal et al. (inclusive); the rest of their data validates."""

PAPER_VALIDATION_START = "2011-02-10"
"""First validation day of Goyal et al. (their 48-h traces start at its midnight)."""

_PREFIXES = ("T", "Ts", "ms", "vs", "Q", "solar")
_ZONE_PREFIXES = ("Ts", "ms", "vs", "Q")
_ON_GRID_TOL = 1_000_000_000          # [ns]: a sample within 1 s of a grid point is on it
_DAY_NS = 86_400 * 1_000_000_000
_OFFSET_RE = re.compile(r"(Z|[+-]\d{2}:?\d{2})$")
_HAS_OFFSET_RE = re.compile(r"(?:Z|[+-]\d{2}:?\d{2})$")
_DATE_RE = re.compile(r"\d{4}-\d{2}-\d{2}")
# resampling codes per grid point and column
_EXACT, _RESAMPLED, _FILLED, _EXCLUDED = 0, 1, 2, 3


# ---------------------------------------------------------------------------- results
@dataclass(frozen=True)
class Gap:
    """A run of ``n`` grid samples of ``column`` (file name) left NaN, ``start``..``end``."""

    column: str
    start: pd.Timestamp
    end: pd.Timestamp
    n: int

    def to_dict(self) -> dict:
        return {"column": self.column, "start": self.start.isoformat(),
                "end": self.end.isoformat(), "n": self.n}


@dataclass
class QualityReport:
    """What reading the data did: every dropped, merged or filled sample is counted.

    Per-column counts are keyed by the file's column name; over the grid they add up,
    ``n_samples = exact + resampled + interpolated + excluded``.

    Attributes
    ----------
    source, units : str
        File read (or ``<DataFrame>``); ``"si"`` or ``"imperial"``.
    rows_read : int
        Data rows in the file.
    columns_used : dict
        Frame column → file column (``vs:`` becomes ``ms:``).
    ignored_columns, unmeasured_zone_columns : list of str
        Columns with other prefixes; ``T:`` columns of ``measured: false`` zones.
    zones_without_supply : list of str
        Zones with no supply columns: they get no supply air.
    conversions, notes : list of str
        Unit conversions applied; anything else worth knowing (time zone, unit sanity).
    time_zone : str
        Time zone of the index (days and date splits are taken in it).
    step, data_step : float
        Grid step and median spacing of the file's stamps [s].
    step_inferred : bool
    start, end : pandas.Timestamp
        First and last grid stamp.
    n_samples : int
        Grid length.
    rows_out_of_order, duplicates_removed, duplicate_conflicts : int
        Rows sorted into place; rows dropped as repeated stamps; repeated stamps whose
        rows disagreed (averaged).
    off_grid_stamps : int
        Distinct stamps more than 1 s off the grid (used only through interpolation;
        unused when the grid is coarser than the data).
    missing_cells : dict
        Column → empty/NaN cells in the file.
    exact, resampled, interpolated, excluded : dict
        Column → grid samples taken as is / interpolated between neighbouring stamps /
        filled across a short gap / left NaN in a long gap.
    long_gaps : list of Gap
    clipped_flows : dict
        Column → negative flows set to 0.
    """

    source: str
    units: str
    rows_read: int
    columns_used: dict
    ignored_columns: list
    unmeasured_zone_columns: list
    zones_without_supply: list
    conversions: list
    time_zone: str
    step: float
    step_inferred: bool
    data_step: float
    start: pd.Timestamp
    end: pd.Timestamp
    n_samples: int
    rows_out_of_order: int = 0
    duplicates_removed: int = 0
    duplicate_conflicts: int = 0
    off_grid_stamps: int = 0
    missing_cells: dict = field(default_factory=dict)
    exact: dict = field(default_factory=dict)
    resampled: dict = field(default_factory=dict)
    interpolated: dict = field(default_factory=dict)
    excluded: dict = field(default_factory=dict)
    long_gaps: list = field(default_factory=list)
    clipped_flows: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    def to_dict(self) -> dict:
        """Plain JSON-serialisable dict (stamps as ISO 8601 strings, steps in seconds)."""
        out = {}
        for key, val in self.__dict__.items():
            if isinstance(val, pd.Timestamp):
                val = val.isoformat()
            elif key == "long_gaps":
                val = [g.to_dict() for g in val]
            elif isinstance(val, (dict, list)):
                val = type(val)(val)
            out[key] = val
        return out

    def summary(self) -> str:
        """A few lines of plain text for people."""
        def total(d):
            return sum(d.values())

        lines = [
            f"{self.source}: {self.rows_read} rows, {self.start:%Y-%m-%d %H:%M} to "
            f"{self.end:%Y-%m-%d %H:%M} ({self.time_zone}), step {_fmt_step(self.step)}"
            f"{' (inferred)' if self.step_inferred else ''}, units {self.units}",
            f"grid: {self.n_samples} samples × {len(self.columns_used)} columns; "
            f"{self.duplicates_removed} duplicate rows removed "
            f"({self.duplicate_conflicts} conflicting, averaged); "
            f"{self.rows_out_of_order} rows out of order; {self.off_grid_stamps} off-grid stamps",
            f"samples: {total(self.resampled)} resampled between stamps, "
            f"{total(self.interpolated)} interpolated across short gaps, "
            f"{total(self.excluded)} excluded in {len(self.long_gaps)} long gap(s); "
            f"{total(self.missing_cells)} empty cells in the file",
        ]
        for g in self.long_gaps[:5]:
            lines.append(f"  long gap {g.column}: {g.start:%Y-%m-%d %H:%M} to "
                         f"{g.end:%Y-%m-%d %H:%M} ({g.n} samples)")
        if len(self.long_gaps) > 5:
            lines.append(f"  ... and {len(self.long_gaps) - 5} more long gaps")
        if self.conversions:
            lines.append("converted: " + "; ".join(self.conversions))
        if self.clipped_flows:
            lines.append(f"negative flows set to 0: {self.clipped_flows}")
        if self.zones_without_supply:
            lines.append("no supply air (no Ts:/ms: columns): "
                         + ", ".join(self.zones_without_supply))
        if self.unmeasured_zone_columns:
            lines.append("ignored (zone not measured in the spec): "
                         + ", ".join(self.unmeasured_zone_columns))
        if self.ignored_columns:
            lines.append(f"ignored {len(self.ignored_columns)} other column(s): "
                         + _short_list(self.ignored_columns))
        lines += self.notes
        return "\n".join(lines)


class DayArray(NamedTuple):
    """Zone temperatures arranged day × time of day, for structure identification.

    Attributes
    ----------
    X : ndarray, shape (n_days, K, n_zones)
        Temperature [°C]; ``K = 1 day / step``.
    days_used : list of datetime.date
    days_dropped : list of (datetime.date, str)
        Days left out and why (incomplete day, or a gap in a named column).
    """

    X: np.ndarray
    days_used: list
    days_dropped: list


# ---------------------------------------------------------------------------- Measurements
@dataclass
class Measurements:
    """Measured data on a regular grid, in SI units, matched to a building spec.

    Build with :func:`read_measurements`.

    Attributes
    ----------
    frame : pandas.DataFrame
        Tz-aware regular ``DatetimeIndex`` named ``time``; columns ``T:<node>`` [°C],
        ``Ts:<zone>`` [°C], ``ms:<zone>`` [kg/s], ``Q:<zone>`` [W], ``solar:<name>`` [W/m²];
        NaN inside long gaps.
    step : pandas.Timedelta
        Grid step.
    spec : BuildingSpec
    units : {"si", "imperial"}
        Units of the source data (use :meth:`to_data_units` to report in them).
    source : str
    quality : QualityReport
        The data-quality report of the whole read (shared by windows and splits).
    """

    frame: pd.DataFrame
    step: pd.Timedelta
    spec: BuildingSpec
    units: str
    source: str
    quality: QualityReport

    def __repr__(self):
        return (f"Measurements({self.source!r}: {len(self.frame)} samples × "
                f"{self.frame.shape[1]} columns, {self.start} to {self.end}, "
                f"step {_fmt_step(self.step.total_seconds())})")

    def __len__(self):
        return len(self.frame)

    # ---- basic facts ---------------------------------------------------------
    @property
    def tz(self):
        """Time zone of the index."""
        return self.frame.index.tz

    @property
    def start(self) -> pd.Timestamp:
        return self.frame.index[0]

    @property
    def end(self) -> pd.Timestamp:
        """Last stamp (inclusive)."""
        return self.frame.index[-1]

    @property
    def temperature_unit(self) -> str:
        """``"°C"`` or ``"°F"``: the source data's temperature unit."""
        return "°F" if self.units == "imperial" else "°C"

    def to_data_units(self, delta):
        """Convert a temperature *difference* [K] to the data's unit (K or °F).

        Parameters
        ----------
        delta : float or array_like
            Temperature difference, e.g. an RMSE [K].
        """
        return np.asarray(delta) * (1.8 if self.units == "imperial" else 1.0)

    @property
    def valid(self) -> np.ndarray:
        """Rows where every ``T:``, ``Ts:``, ``ms:`` and ``Q:`` column is finite (solar aside)."""
        cols = [c for c in self.frame.columns if not c.startswith("solar:")]
        return np.isfinite(self.frame[cols].to_numpy()).all(axis=1)

    def segments(self) -> list[tuple[pd.Timestamp, pd.Timestamp, int]]:
        """Maximal runs of :attr:`valid` rows: (first stamp, last stamp, number of rows)."""
        ok = np.r_[False, self.valid, False].astype(np.int8)
        edges = np.flatnonzero(np.diff(ok))
        idx = self.frame.index
        return [(idx[a], idx[b - 1], int(b - a)) for a, b in zip(edges[::2], edges[1::2])]

    # ---- columns for the model -----------------------------------------------
    def zone_temperatures(self, zones=None) -> pd.DataFrame:
        """Measured zone temperatures [°C], one column per zone (named by the zone).

        Parameters
        ----------
        zones : list of str, optional
            Default: the spec's measured zones, in spec order.
        """
        zones = list(self.spec.measured_zones if zones is None else zones)
        bad = [z for z in zones if f"T:{z}" not in self.frame or z not in self.spec.zone_names]
        if bad:
            raise DataError(f"{self.source}: no measured temperature for zone(s) {bad}; "
                            f"measured zones are {self.spec.measured_zones}")
        out = self.frame[[f"T:{z}" for z in zones]].copy()
        out.columns = zones
        return out

    def inputs(self, network) -> np.ndarray:
        """Model inputs in ``network.input_names`` order.

        A zone without supply columns gets ``ms = 0`` and ``Ts`` = its own temperature
        (or, for an unmeasured zone or inside a gap, the mean of the measured zones,
        so that ``0·Ts`` never turns into NaN); a zone without ``Q:`` gets ``Q = 0``.

        Parameters
        ----------
        network : ThermalNetwork
            Must have the zones and boundary nodes of this data's spec.

        Returns
        -------
        ndarray, shape (n_samples, network.n_inputs)
            ``ms`` [kg/s], ``Ts`` [°C], ``T`` of boundary nodes [°C], ``Q`` [W].
        """
        zones, bnd = list(network.zones), list(network.boundary)
        if set(zones) != set(self.spec.zone_names) or set(bnd) != set(self.spec.boundary):
            raise DataError(
                f"{self.source}: network nodes do not match the data's spec "
                f"{self.spec.source}: zones {sorted(zones)} vs {sorted(self.spec.zone_names)}, "
                f"boundary {sorted(bnd)} vs {sorted(self.spec.boundary)}")
        f = self.frame
        n = len(f)
        measured = [f[f"T:{z}"].to_numpy() for z in self.spec.measured_zones]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)   # all-NaN rows inside gaps
            mean_t = np.nanmean(np.vstack(measured), axis=0) if measured else np.full(n, np.nan)
        mean_t = np.where(np.isfinite(mean_t), mean_t, 20.0)    # no zone measured: any value
        ms, ts, q = [], [], []
        for z in zones:
            if f"ms:{z}" in f:
                ms.append(f[f"ms:{z}"].to_numpy())
                ts.append(f[f"Ts:{z}"].to_numpy())
            else:
                own = f[f"T:{z}"].to_numpy() if f"T:{z}" in f else mean_t
                ms.append(np.zeros(n))
                ts.append(np.where(np.isfinite(own), own, mean_t))
            q.append(f[f"Q:{z}"].to_numpy() if f"Q:{z}" in f else np.zeros(n))
        tb = [f[f"T:{b}"].to_numpy() for b in bnd]
        return np.column_stack(ms + ts + tb + q).astype(float)

    # ---- time windows and splits ---------------------------------------------
    def window(self, start=None, end=None, duration=None) -> "Measurements":
        """The samples in ``[start, end)`` (exact instants; a date means its midnight).

        Parameters
        ----------
        start, end : str, datetime or Timestamp, optional
            Naive values are local time of :attr:`tz`. Default: data start / end.
        duration : str or Timedelta, optional
            Instead of ``end``: ``end = start + duration``.
        """
        t0 = self.start if start is None else self._instant(start, "start")
        if duration is not None:
            t1 = t0 + _timedelta(duration, "duration")
        else:
            t1 = self.end + self.step if end is None else self._instant(end, "end")
        return self._slice(t0, t1, "window")

    def split(self, calibration=None, validation=None) -> tuple["Measurements", "Measurements"]:
        """Split into calibration and validation data by date.

        Parameters
        ----------
        calibration, validation : (start, end), optional
            Each bound is a date (``"2011-02-09"``: an end date is *inclusive*, the whole
            day) or an instant with a time (an end instant is exclusive). Given one, the
            other is the rest of the data (after it, or else before it). Default: the
            paper's split (calibration 2011-01-21..02-09, validation from 2011-02-10 on)
            when the data covers 2011-01-21..2011-02-12; otherwise the last quarter of the
            whole days (rounded, at least one) validates and the days before calibrate.

        Returns
        -------
        calibration, validation : Measurements

        Raises
        ------
        DataError
            A window outside the data, an empty calibration set, or data too short to split.
        """
        if calibration is None and validation is None:
            first, last = self.start.date(), self.end.date()
            if first <= dt.date(2011, 1, 21) and last >= dt.date(2011, 2, 12):
                calibration = PAPER_CALIBRATION
                validation = (PAPER_VALIDATION_START, None)
                logger.info("%s: paper's calibration/validation split", self.source)
            else:
                days = self._whole_days()
                if len(days) < 2:
                    raise DataError(f"{self.source}: {len(days)} whole day(s) of data "
                                    f"({self.start} to {self.end}); cannot split into "
                                    "calibration and validation days")
                n_val = max(1, int(len(days) / 4 + 0.5))
                validation = (pd.Timestamp(days[-n_val]), None)   # exclusive end for cal
                calibration = (None, validation[0])
                logger.info("%s: last %d of %d whole days validate", self.source, n_val,
                            len(days))
        # explicit windows first, so an error names the window at fault
        v = self._slice(*self._range(validation, "validation"), "validation") \
            if validation is not None else None
        c = self._slice(*self._range(calibration, "calibration"), "calibration") \
            if calibration is not None else None
        end = self.end + self.step
        if c is None:
            c = (self._slice(self.start, v.start, "calibration (before validation)")
                 if v.start > self.start else
                 self._slice(v.end + self.step, end, "calibration (after validation)"))
        if v is None:
            v = (self._slice(c.end + self.step, end, "validation (after calibration)")
                 if c.end < self.end else
                 self._slice(self.start, c.start, "validation (before calibration)"))
        if c.start <= v.end and v.start <= c.end:
            warnings.warn(f"{self.source}: calibration ({c.start} to {c.end}) and validation "
                          f"({v.start} to {v.end}) overlap", DataWarning, stacklevel=2)
        return c, v

    def require_days(self, n: int, why: str) -> int:
        """Check that at least ``n`` whole days without gaps are available.

        Parameters
        ----------
        n : int
            Days needed.
        why : str
            What needs them, for the message (e.g. ``"structure identification (sin, 7
            zones)"``).

        Returns
        -------
        int
            The number of usable days.
        """
        arr = self.day_time_array()
        if len(arr.days_used) < n:
            gaps = sum(1 for _, r in arr.days_dropped if not r.startswith("incomplete"))
            raise DataError(
                f"{self.source}: {why} needs at least {n} whole days without gaps, found "
                f"{len(arr.days_used)} ({len(arr.days_dropped)} dropped: {gaps} with gaps, "
                f"{len(arr.days_dropped) - gaps} incomplete)")
        return len(arr.days_used)

    def day_time_array(self, zones=None) -> DayArray:
        """Zone temperatures as days × time-of-day, whole days without gaps only.

        Parameters
        ----------
        zones : list of str, optional
            Default: the spec's measured zones, in spec order.

        Returns
        -------
        DayArray
            ``(X, days_used, days_dropped)``; ``X`` has shape (days, K, zones) [°C] with
            ``K = 1 day / step``. Days are local calendar days of :attr:`tz`; a day is
            dropped when it lacks any of its K stamps (data start/end, a daylight-saving
            change) or a zone temperature is NaN in it.
        """
        temps = self.zone_temperatures(zones)
        step_ns = int(self.step.value)
        if _DAY_NS % step_ns:
            raise DataError(f"{self.source}: step {self.step} does not divide a day; "
                            "no time-of-day index")
        K = _DAY_NS // step_ns
        idx = self.frame.index
        tod = (idx - idx.normalize()).as_unit("ns").asi8
        k = tod // step_ns
        dates = np.asarray(idx.date)
        vals = temps.to_numpy()
        used, dropped, X = [], [], []
        bounds = np.flatnonzero(np.r_[True, dates[1:] != dates[:-1], True])
        for a, b in zip(bounds[:-1], bounds[1:]):
            day = dates[a]
            kk = k[a:b]
            if b - a != K or not np.array_equal(kk, np.arange(K)) or (tod[a:b] % step_ns).any():
                dropped.append((day, f"incomplete ({b - a} of {K} samples)"))
                continue
            bad = ~np.isfinite(vals[a:b]).all(axis=0)
            if bad.any():
                cols = [f"T:{z}" for z, m in zip(temps.columns, bad) if m]
                dropped.append((day, "gap in " + ", ".join(cols)))
                continue
            used.append(day)
            X.append(vals[a:b])
        X = np.stack(X) if X else np.empty((0, K, vals.shape[1]))
        if dropped:
            logger.info("%s: %d day(s) used, %d dropped", self.source, len(used), len(dropped))
        return DayArray(X, used, dropped)

    # ---- helpers ---------------------------------------------------------------
    def _instant(self, x, what) -> pd.Timestamp:
        try:
            ts = pd.Timestamp(x)
        except (ValueError, TypeError):
            raise DataError(f"{self.source}: {what} {x!r} is not a date or time") from None
        if ts is pd.NaT:
            raise DataError(f"{self.source}: {what} {x!r} is not a date or time")
        return ts.tz_localize(self.tz) if ts.tzinfo is None else ts.tz_convert(self.tz)

    def _range(self, rng, what):
        try:
            a, b = rng
        except (TypeError, ValueError):
            raise DataError(f"{self.source}: {what} must be (start, end), found {rng!r}") from None
        t0 = self.start if a is None else self._instant(a, f"{what} start")
        if b is None:
            t1 = self.end + self.step
        else:
            t1 = self._instant(b, f"{what} end")
            is_date = ((isinstance(b, str) and _DATE_RE.fullmatch(b.strip()))
                       or (isinstance(b, dt.date) and not isinstance(b, dt.datetime)))
            if is_date:
                t1 = t1 + pd.Timedelta(days=1)
        if t1 <= t0:
            raise DataError(f"{self.source}: {what} window {rng!r} ends before it starts")
        return t0, t1

    def _slice(self, t0, t1, what) -> "Measurements":
        data_end = self.end + self.step
        if t1 <= self.start or t0 >= data_end:
            raise DataError(f"{self.source}: {what} window {t0} to {t1} is outside the data "
                            f"({self.start} to {self.end})")
        if t0 < self.start or t1 > data_end:
            warnings.warn(f"{self.source}: {what} window {t0} to {t1} reaches beyond the data "
                          f"({self.start} to {self.end}); cut to the data", DataWarning,
                          stacklevel=3)
        idx = self.frame.index
        sub = self.frame[(idx >= t0) & (idx < t1)]
        if sub.empty:
            raise DataError(f"{self.source}: {what} window {t0} to {t1} holds no samples")
        return Measurements(sub, self.step, self.spec, self.units, self.source, self.quality)

    def _whole_days(self) -> list:
        """Dates with all their grid stamps present (NaN or not)."""
        K = _DAY_NS // int(self.step.value)
        dates = pd.Series(self.frame.index.date)
        counts = dates.value_counts()
        return sorted(d for d, c in counts.items() if c == K)


# ---------------------------------------------------------------------------- reading
def read_measurements(source, spec: BuildingSpec, units: str = "si", step=None,
                      gap_limit="30min", tz=None, name: str | None = None) -> Measurements:
    """Read measured data (CSV, parquet or a DataFrame) onto a regular SI grid.

    Parameters
    ----------
    source : str, Path or pandas.DataFrame
        ``.csv`` (any other suffix is read as CSV) or ``.parquet``/``.pq`` file, or a
        DataFrame with a ``time`` column (or a ``DatetimeIndex``).
    spec : BuildingSpec
        Gives the zones (``T:`` needed for every measured zone) and boundary nodes
        (``T:`` needed for each).
    units : {"si", "imperial"}, default "si"
        ``si``: °C, kg/s, m³/s, W, W/m². ``imperial``: °F for ``T:``/``Ts:``, CFM for
        ``ms:`` and ``vs:`` (ρ = 1.2 kg/m³); W and W/m² unchanged.
    step : str or Timedelta, optional
        Model grid step (must divide a day). Default: the data's median spacing, snapped
        to a whole number of minutes (seconds below one minute) dividing a day.
    gap_limit : str or Timedelta, default "30min"
        Longest gap (time between the valid samples around it) that is linearly
        interpolated; longer gaps stay NaN and are reported. ``0`` fills nothing.
    tz : str, optional
        Time zone of the result (IANA name, ``"UTC"`` or ``"+01:00"``); also the zone of
        stamps without a UTC offset. Default: the data's own offset (UTC for naive stamps).
    name : str, optional
        Name used in messages for a DataFrame source.

    Returns
    -------
    Measurements

    Raises
    ------
    DataError
        One line naming the file and the column, zone or line at fault.

    Examples
    --------
    >>> spec = load_spec("building.yaml")                      # doctest: +SKIP
    >>> meas = read_measurements("data.csv", spec, units="imperial")  # doctest: +SKIP
    >>> cal, val = meas.split()                                 # doctest: +SKIP
    >>> print(meas.quality.summary())                           # doctest: +SKIP
    """
    if units not in ("si", "imperial"):
        raise DataError(f"units must be 'si' or 'imperial', found {units!r}")
    df, src, row_label = _load_table(source, name)
    cols = _classify(df.columns, spec, src)
    t_ns, tzinfo, notes = _parse_time(df["time"], src, tz, row_label)
    gap_ns = _timedelta(gap_limit, "gap_limit").value
    if gap_ns < 0:
        raise DataError(f"gap_limit must be >= 0, found {gap_limit!r}")

    # numbers, unit conversion, flow clipping (per file column, before any regridding)
    values, missing, conversions, clipped = {}, {}, [], {}
    for fcol, scol in cols["used"].items():
        v = _numeric(df[scol], src, scol, row_label)
        missing[scol] = int(np.isnan(v).sum())
        v, conv = _to_si(v, scol, units)
        if conv:
            conversions.append(conv)
        if fcol.startswith("ms:"):
            neg = v < 0
            if neg.any():
                clipped[scol] = int(neg.sum())
                v = np.where(neg, 0.0, v)
        values[fcol] = v
    if clipped:
        warnings.warn(f"{src}: negative flows set to 0: {clipped}", DataWarning, stacklevel=2)

    # order, duplicates
    raw = pd.DataFrame(values, index=pd.Index(t_ns, name="time"))
    out_of_order = int((np.diff(t_ns) < 0).sum())
    raw = raw.sort_index(kind="stable")
    dup = raw.index.duplicated(keep=False)
    n_dups, conflicts = 0, 0
    if dup.any():
        grp = raw[dup].groupby(level=0)
        n_dups = int(dup.sum() - grp.ngroups)
        conflicts = int((grp.nunique(dropna=False) > 1).any(axis=1).sum())
        raw = raw.groupby(level=0, sort=True).mean()
        logger.info("%s: %d duplicate rows removed (%d conflicting)", src, n_dups, conflicts)
    t = raw.index.to_numpy(dtype=np.int64)
    if len(t) < 2:
        raise DataError(f"{src}: need at least 2 distinct time stamps, found {len(t)}")

    # grid
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
    off = int(pd.Timestamp(t[0], tz="UTC").tz_convert(tzinfo).utcoffset().total_seconds() * 1e9)
    g0 = -((-(t[0] + off - _ON_GRID_TOL)) // step_ns) * step_ns - off     # ceil
    g1 = ((t[-1] + off + _ON_GRID_TOL) // step_ns) * step_ns - off        # floor
    if g1 < g0:
        raise DataError(f"{src}: data span {pd.Timedelta(int(t[-1] - t[0]))} is shorter "
                        f"than one step {pd.Timedelta(step_ns)}")
    grid = np.arange(g0, g1 + 1, step_ns, dtype=np.int64)
    r = (t - g0) % step_ns
    off_grid = int((np.minimum(r, step_ns - r) > _ON_GRID_TOL).sum())
    bridge = 1.5 * max(step_ns, data_step)

    frame, counts, gaps = {}, {c: {} for c in range(4)}, []
    index = pd.DatetimeIndex(pd.to_datetime(grid, unit="ns", utc=True)).tz_convert(tzinfo)
    index.name = "time"
    for fcol, v in raw.items():
        scol = cols["used"][fcol]
        vals, code = _regrid(t, v.to_numpy(), grid, bridge, gap_ns)
        frame[fcol] = vals
        for c in range(4):
            counts[c][scol] = int((code == c).sum())
        gaps += _gap_runs(scol, code == _EXCLUDED, index)
    frame = pd.DataFrame(frame, index=index)

    notes += _sanity(frame, spec, units)
    quality = QualityReport(
        source=src, units=units, rows_read=len(df), columns_used=dict(cols["used"]),
        ignored_columns=cols["ignored"], unmeasured_zone_columns=cols["unmeasured"],
        zones_without_supply=cols["no_supply"], conversions=conversions,
        time_zone=str(tzinfo), step=step_ns / 1e9, step_inferred=step is None,
        data_step=data_step / 1e9, start=index[0], end=index[-1], n_samples=len(index),
        rows_out_of_order=out_of_order, duplicates_removed=n_dups,
        duplicate_conflicts=conflicts, off_grid_stamps=off_grid, missing_cells=missing,
        exact=counts[_EXACT], resampled=counts[_RESAMPLED], interpolated=counts[_FILLED],
        excluded=counts[_EXCLUDED], long_gaps=gaps, clipped_flows=clipped, notes=notes)
    if gaps:
        warnings.warn(f"{src}: {sum(g.n for g in gaps)} samples excluded in {len(gaps)} long "
                      f"gap(s) over {len({g.column for g in gaps})} column(s), e.g. "
                      f"{gaps[0].column} {gaps[0].start} to {gaps[0].end}", DataWarning,
                      stacklevel=2)
    for note in notes:
        logger.info("%s: %s", src, note)
    return Measurements(frame, pd.Timedelta(step_ns), spec, units, src, quality)


# ---------------------------------------------------------------------------- internals
def _load_table(source, name):
    """Read the table; returns (DataFrame with a 'time' column, source name, row labeller)."""
    if isinstance(source, pd.DataFrame):
        src = name or "<DataFrame>"
        df = source.copy()
        df.columns = [str(c).strip() for c in df.columns]
        if "time" not in df.columns and isinstance(df.index, pd.DatetimeIndex):
            df = df.rename_axis("time").reset_index()
        dupes = sorted({c for c in df.columns if list(df.columns).count(c) > 1})
        _check_table(df, src, dupes)
        df = df.reset_index(drop=True)
        return df, src, (lambda i: f"row {i}")
    path = Path(source)
    src = str(path)
    if not path.exists():
        raise DataError(f"{src}: data file not found")
    if not path.is_file():
        raise DataError(f"{src}: not a file")
    if path.stat().st_size == 0:
        raise DataError(f"{src}: data file is empty")
    parquet = path.suffix.lower() in (".parquet", ".pq")
    try:
        if parquet:
            df = pd.read_parquet(path)
            if "time" not in df.columns and df.index.name == "time":
                df = df.reset_index()
            df.columns = [str(c).strip() for c in df.columns]
            dupes = sorted({c for c in df.columns if list(df.columns).count(c) > 1})
        else:
            with open(path, newline="", encoding="utf-8-sig") as fh:
                header = next(csv.reader(fh), [])
            header = [h.strip() for h in header]
            dupes = sorted({h for h in header if header.count(h) > 1})
            if not any(h for h in header):
                raise DataError(f"{src}: data file is empty (no header line)")
            df = pd.read_csv(path, encoding="utf-8-sig", skipinitialspace=True)
            df.columns = [str(c).strip() for c in df.columns]
    except DataError:
        raise
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, OSError,
            ValueError) as exc:
        kind = "parquet" if parquet else "CSV"
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise DataError(f"{src}: not a readable {kind} file: {msg}") from None
    _check_table(df, src, dupes)
    # CSV line of data row i: line 1 is the header
    return df, src, ((lambda i: f"row {i}") if parquet else (lambda i: f"line {i + 2}"))


def _check_table(df, src, dupes):
    if dupes:
        raise DataError(f"{src}: column(s) {dupes} appear more than once")
    if "time" not in df.columns:
        hint = ""
        if len(df.columns) == 1 and any(s in str(df.columns[0]) for s in ";\t"):
            hint = " (the file looks ';'- or tab-separated; expected commas)"
        raise DataError(f"{src}: no 'time' column{hint}; found columns "
                        f"{_short_list([str(c) for c in df.columns])}")
    if len(df) == 0:
        raise DataError(f"{src}: data file has a header but no data rows")


def _classify(columns, spec: BuildingSpec, src):
    """Map file columns to frame columns; check them against the spec."""
    zones, bnd = spec.zone_names, list(spec.boundary)
    measured = set(spec.measured_zones)
    t_cols, zone_cols, solar, ignored, unmeasured = {}, {}, [], [], []
    unknown_t, unknown_z = [], []
    for col in columns:
        if col == "time":
            continue
        prefix, sep, node = col.partition(":")
        if not sep or prefix not in _PREFIXES or not node:
            ignored.append(col)
        elif prefix == "T":
            if node in measured or node in bnd:
                t_cols[node] = col
            elif node in zones:
                unmeasured.append(col)
            else:
                unknown_t.append(node)
        elif prefix == "solar":
            solar.append(col)
        elif node in zones:
            zone_cols[(prefix, node)] = col
        else:
            unknown_z.append(col)
    need = [n for n in list(spec.measured_zones) + bnd if n not in t_cols]
    if unknown_t or need:
        parts = []
        if unknown_t:
            parts.append(f"T: column(s) for node(s) not in the spec: {unknown_t}")
        if need:
            parts.append(f"measured zone(s)/boundary node(s) with no T: column: {need}")
        raise DataError(f"{src}: columns do not match {spec.source}: " + "; ".join(parts)
                        + f" (spec zones {zones}, boundary {bnd})")
    if unknown_z:
        raise DataError(f"{src}: column(s) {unknown_z} name no zone of {spec.source} "
                        f"(zones {zones}; boundary nodes take only T: columns)")
    used, no_supply = {}, []
    for node in list(spec.measured_zones) + bnd:
        used[f"T:{node}"] = t_cols[node]
    for z in zones:
        ms, vs, ts = (zone_cols.get((p, z)) for p in ("ms", "vs", "Ts"))
        if ms and vs:
            raise DataError(f"{src}: zone {z!r} has both {ms} and {vs}; give one supply flow")
        flow = ms or vs
        if flow and not ts:
            raise DataError(f"{src}: zone {z!r} has supply flow {flow} but no Ts:{z} column")
        if ts and not flow:
            raise DataError(f"{src}: zone {z!r} has {ts} but no supply flow (ms:{z} or vs:{z})")
        if flow:
            used[f"Ts:{z}"] = ts
            used[f"ms:{z}"] = flow
        else:
            no_supply.append(z)
    for z in zones:
        if ("Q", z) in zone_cols:
            used[f"Q:{z}"] = zone_cols[("Q", z)]
    for col in solar:
        used[col] = col
    if unmeasured:
        warnings.warn(f"{src}: {unmeasured} belong to zone(s) the spec marks 'measured: false'; "
                      "ignored (set measured: true to use them)", DataWarning, stacklevel=3)
    return {"used": used, "ignored": ignored, "unmeasured": unmeasured, "no_supply": no_supply}


def _parse_time(col: pd.Series, src, tz, row_label):
    """Time stamps → (int64 ns UTC array, tzinfo of the result, notes)."""
    notes = []
    target = _tzinfo(tz) if tz is not None else None
    empty = col.isna()
    if empty.any():
        raise DataError(f"{src}: column 'time' is empty at {row_label(int(np.argmax(empty)))}")
    if pd.api.types.is_datetime64_any_dtype(col):
        idx = pd.DatetimeIndex(col)
        native = idx.tz
        if native is None:
            idx, native = _localize(idx, target, src, notes)
        utc = idx.tz_convert("UTC")
        out_tz = target or native
    else:
        s = col.astype(str).str.strip()
        # naive stamps parse as UTC wall clock here; they are localized below
        parsed = pd.to_datetime(s, format="ISO8601", utc=True, errors="coerce")
        bad = parsed.isna().to_numpy()
        if bad.any():
            i = int(np.argmax(bad))
            raise DataError(f"{src}: column 'time': cannot parse {s.iloc[i]!r} at {row_label(i)} "
                            f"({int(bad.sum())} unparsable); expected ISO 8601 such as "
                            "2011-01-21T00:05:00-05:00")
        has_off = s.str.contains(_HAS_OFFSET_RE)
        if has_off.any() and not has_off.all():
            i = int(np.argmax(~has_off.to_numpy() if has_off.iloc[0] else has_off.to_numpy()))
            raise DataError(f"{src}: column 'time' mixes stamps with and without a UTC offset "
                            f"(first different: {s.iloc[i]!r} at {row_label(i)})")
        idx = pd.DatetimeIndex(parsed)
        if has_off.all():
            offsets = sorted({_offset_minutes(m) for m in s.str.extract(_OFFSET_RE)[0].unique()})
            native = _fixed(offsets[0])
            if len(offsets) > 1 and target is None:
                notes.append(f"time stamps carry UTC offsets {offsets} min; days are taken in "
                             f"standard time {native}")
            utc = idx
            out_tz = target or native
        else:
            idx, out_tz = _localize(idx.tz_localize(None), target, src, notes)
            utc = idx.tz_convert("UTC")
    t_ns = utc.as_unit("ns").asi8.copy()
    return t_ns, out_tz, notes


def _localize(idx, target, src, notes):
    if target is None:
        notes.append("time stamps have no UTC offset; taken as UTC")
        return idx.tz_localize("UTC"), dt.timezone.utc
    try:
        return idx.tz_localize(target, ambiguous="infer", nonexistent="raise"), target
    except Exception as exc:        # pytz/zoneinfo raise several types for DST problems
        why = str(exc).splitlines()[0].split(". Try")[0] if str(exc) else type(exc).__name__
        raise DataError(f"{src}: column 'time': local stamps do not fit time zone {target} "
                        f"({why}); export stamps with a UTC offset") from None


def _offset_minutes(text) -> int:
    if text == "Z":
        return 0
    sign = -1 if text[0] == "-" else 1
    digits = text[1:].replace(":", "")
    return sign * (int(digits[:2]) * 60 + int(digits[2:]))


def _fixed(minutes: int):
    """Fixed-offset tzinfo (``UTC`` for 0, else ``UTC±hh:mm``)."""
    return dt.timezone(dt.timedelta(minutes=minutes)) if minutes else dt.timezone.utc


def _tzinfo(tz):
    if isinstance(tz, dt.tzinfo):
        return tz
    text = str(tz).strip()
    m = re.fullmatch(r"(?:UTC)?([+-]\d{2}:?\d{2})", text)
    if m:
        return _fixed(_offset_minutes(m.group(1)))
    try:
        return pd.Timestamp("2000-01-01", tz=text).tzinfo
    except Exception:               # the tz libraries raise several exception types
        raise DataError(f"tz: unknown time zone {tz!r} (use an IANA name such as "
                        "'America/New_York', 'UTC' or an offset '+01:00')") from None


def _timedelta(value, what) -> pd.Timedelta:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return pd.Timedelta(seconds=value)
    try:
        td = pd.Timedelta(value)
    except (ValueError, TypeError):
        raise DataError(f"{what}: expected a duration such as '5min', found {value!r}") from None
    if td is pd.NaT:
        raise DataError(f"{what}: expected a duration such as '5min', found {value!r}")
    return td


def _numeric(col: pd.Series, src, name, row_label) -> np.ndarray:
    num = pd.to_numeric(col, errors="coerce")
    bad = (col.notna() & num.isna()).to_numpy()
    inf = np.isinf(num.to_numpy(dtype=float))
    if bad.any() or inf.any():
        i = int(np.argmax(bad | inf))
        raise DataError(f"{src}: column {name}: non-numeric value {col.iloc[i]!r} at "
                        f"{row_label(i)} ({int((bad | inf).sum())} such cells)")
    v = num.to_numpy(dtype=float)
    if np.isnan(v).all():
        raise DataError(f"{src}: column {name} has no values (all empty/NaN)")
    return v


def _to_si(v, col, units):
    prefix = col.partition(":")[0]
    if units == "imperial":
        if prefix in ("T", "Ts"):
            return (v - 32.0) / 1.8, f"{col} °F → °C"
        if prefix in ("ms", "vs"):
            return v * CFM * RHO_AIR, f"{col} CFM → kg/s (ρ = {RHO_AIR} kg/m³)"
    elif prefix == "vs":
        return v * RHO_AIR, f"{col} m³/s → kg/s (ρ = {RHO_AIR} kg/m³)"
    return v, None


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


def _regrid(t, v, grid, bridge, gap_ns):
    """Values of one column on the grid and how each was obtained (``_EXACT``...)."""
    ok = np.isfinite(v)
    tv, vv = t[ok], v[ok]
    n = len(tv)
    j = np.searchsorted(tv, grid, side="right")        # tv[j-1] <= g < tv[j]
    has_p, has_n = j > 0, j < n
    jp, jn = np.clip(j - 1, 0, n - 1), np.clip(j, 0, n - 1)
    dp = np.where(has_p, (grid - tv[jp]).astype(float), np.inf)
    dn = np.where(has_n, (tv[jn] - grid).astype(float), np.inf)
    span = dp + dn
    exact = np.minimum(dp, dn) <= _ON_GRID_TOL
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


def _gap_runs(col, mask, index) -> list[Gap]:
    m = np.r_[False, mask, False].astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    return [Gap(col, index[a], index[b - 1], int(b - a)) for a, b in zip(edges[::2], edges[1::2])]


def _sanity(frame, spec, units) -> list[str]:
    """Warn when zone temperatures look like the other unit system."""
    cols = [f"T:{z}" for z in spec.measured_zones if f"T:{z}" in frame]
    if not cols:
        return []
    med = float(np.nanmedian(frame[cols].to_numpy()))
    msg = None
    if units == "si" and med > 45:
        msg = (f"median zone temperature {med:.1f} °C looks like °F; "
               "read with units='imperial' (--units imperial)?")
    elif units == "imperial" and med < 5:
        msg = (f"median zone temperature {med * 1.8 + 32:.1f} °F looks like °C; "
               "read with units='si'?")
    if msg:
        warnings.warn(msg, DataWarning, stacklevel=3)
        return [msg]
    return []


def _fmt_step(seconds: float) -> str:
    if seconds % 60 == 0:
        return f"{int(seconds // 60)} min"
    return f"{seconds:g} s"


def _short_list(items, k=8) -> str:
    items = list(items)
    return ", ".join(items[:k]) + (f", ... ({len(items) - k} more)" if len(items) > k else "")
