"""Results of reading measured data: the gridded :class:`Measurements` and its reports.

:class:`Measurements` holds SI data on a regular grid matched to a building spec and
gives what the rest of thermctl needs from it: model inputs, time windows, the
calibration/validation split and the day × time-of-day array for structure
identification. :class:`QualityReport` counts everything reading did to the data.
"""

from __future__ import annotations

import datetime as dt
import logging
import re
import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..errors import DataError, DataWarning
from ..spec import BuildingSpec
from ._grid import _DAY_NS, _fmt_step, _parse, _runs, _timedelta
from .days import DayArray, day_array
from .inputs import network_inputs

__all__ = ["Measurements", "QualityReport", "Gap", "PAPER_CALIBRATION", "PAPER_VALIDATION_START",
           "MIN_CALIBRATION_DAYS", "SPLIT_DAY_SLACK"]

logger = logging.getLogger(__name__)

PAPER_CALIBRATION = ("2011-01-21", "2011-02-09")
"""Calibration days of Goyal et al. (inclusive); the rest of their data validates."""

PAPER_VALIDATION_START = "2011-02-10"
"""First validation day of Goyal et al. (their 48-h traces start at its midnight)."""

_DATE_RE = re.compile(r"\d{4}-\d{2}-\d{2}")

MIN_CALIBRATION_DAYS = 3.0
"""Calibration data shorter than this [days] get a :class:`~thermctl.errors.DataWarning`
from :meth:`Measurements.split`: one day holds one weather pattern and one occupancy
cycle, too little to tell an air path from the gains, and interval estimates from it are
far too narrow (a 2-day file gave a model from 1 calibration day with an edge
"identified ±35 %")."""


SPLIT_DAY_SLACK = pd.Timedelta(hours=1)
"""Grid time a first or last date may lack and still count as a whole day for the default
:meth:`Measurements.split` (rows lost or stamps jittered at the ends of a log)."""


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
        Distinct stamps more than ``snap`` off the grid (used only through interpolation;
        unused when the grid is coarser than the data).
    snapped_stamps : int
        Distinct stamps more than 1 s but at most ``snap`` off a grid point, taken as
        that point's sample.
    snap : float
        Distance from a grid point within which a stamp is its sample [s] (1 unless
        ``read_measurements(snap=)``).
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
    snapped_stamps: int = 0
    snap: float = 1.0
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
            f"{self.rows_out_of_order} rows out of order; {self.off_grid_stamps} off-grid stamps"
            + (f", {self.snapped_stamps} snapped to their grid point (within {self.snap:g} s)"
               if self.snapped_stamps else ""),
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


# ---------------------------------------------------------------------------- Measurements
@dataclass
class Measurements:
    """Measured data on a regular grid, in SI units, matched to a building spec.

    Build with :func:`thermctl.data.read_measurements`.

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
    input_timing : {"held", "centred"}
        How a row's inputs act on the step that starts at its stamp: ``held`` as logged
        (a sample the controller holds over the step), ``centred`` already replaced by the
        mean of the row and the next (:meth:`centred_inputs`).
    """

    frame: pd.DataFrame
    step: pd.Timedelta
    spec: BuildingSpec
    units: str
    source: str
    quality: QualityReport
    input_timing: str = "held"

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
        idx = self.frame.index
        return [(idx[a], idx[b - 1], b - a) for a, b in _runs(self.valid)]

    # ---- columns for the model -----------------------------------------------
    def zone_temperatures(self, zones=None) -> pd.DataFrame:
        """Measured zone temperatures [°C], one column per zone (named by the zone).

        Parameters
        ----------
        zones : list of str, optional
            Default: the spec's measured zones, in spec order.
        """
        zones = self._zone_list(zones)
        out = self.frame[[f"T:{z}" for z in zones]].copy()
        out.columns = zones
        return out

    def inputs(self, network) -> np.ndarray:
        """Model inputs in ``network.input_names`` order.

        A zone without supply columns gets ``ms = 0`` and ``Ts`` = its own temperature
        (or, for an unmeasured zone or inside a gap, the mean of the measured zones,
        so that ``0·Ts`` never turns into NaN); a zone without ``Q:`` gets ``Q = 0``
        (:func:`thermctl.data.network_inputs`, gaps kept as NaN).

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
        return network_inputs(self.frame, network)

    def centred_inputs(self) -> "Measurements":
        """The same data with every input column centred on the step.

        Each value of a column other than a zone temperature ``T:<zone>`` (heat ``Q:``,
        supply ``ms:``/``Ts:``, ``solar:``, boundary ``T:``...) becomes the mean of itself
        and the next row's, which the model then holds over the step between the two
        rows. That is the input of that step when every value is the mean over the
        interval that *ends* at its stamp, as meters and many trend logs export: the zone
        temperatures are then means too, centred half a step earlier, and the step between
        two of them spans half of each input interval. Holding the logged value instead
        applies every input half a step to a step late. The last row, and a row whose
        next value is missing, keep their own value.

        Returns
        -------
        Measurements
            ``input_timing="centred"``; ``self`` when it already is.
        """
        if self.input_timing == "centred":
            return self
        zones = {f"T:{z}" for z in self.spec.zone_names}
        frame = self.frame.copy()
        for c in frame.columns:
            if c in zones or not pd.api.types.is_numeric_dtype(frame[c]):
                continue
            x = frame[c].to_numpy(float)
            nxt = np.r_[x[1:], x[-1:]]
            frame[c] = np.where(np.isfinite(nxt), 0.5 * (x + nxt), x)
        return Measurements(frame, self.step, self.spec, self.units, self.source,
                            self.quality, "centred")

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
            whole days (rounded, at least one) validates and the days before calibrate; a
            first or last day short of at most :data:`SPLIT_DAY_SLACK` (1 h) counts as whole.

        Returns
        -------
        calibration, validation : Measurements

        Raises
        ------
        DataError
            A window outside the data, an empty calibration set, or data too short to split.

        Warns
        -----
        DataWarning
            Calibration data shorter than :data:`MIN_CALIBRATION_DAYS` (3 days), or
            calibration and validation overlapping.
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
        span = (c.end + self.step - c.start) / pd.Timedelta(days=1)
        if span < MIN_CALIBRATION_DAYS:
            warnings.warn(f"{self.source}: only {span:.1f} day(s) of calibration data "
                          f"({c.start:%Y-%m-%d %H:%M} to {c.end:%Y-%m-%d %H:%M}; "
                          f"{(v.end + self.step - v.start) / pd.Timedelta(days=1):.1f} validate)"
                          f": fewer than {MIN_CALIBRATION_DAYS:g} days cannot separate air paths "
                          "from unmeasured gains, and intervals from them are too narrow to "
                          "trust; treat every edge and interval as unidentified, or give "
                          "more days", DataWarning, stacklevel=2)
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
        if len(arr.days) < n:
            gaps = sum(1 for _, r in arr.dropped if r.startswith("gap in"))
            raise DataError(
                f"{self.source}: {why} needs at least {n} whole days without gaps, found "
                f"{len(arr.days)} ({len(arr.dropped)} dropped: {gaps} with gaps, "
                f"{len(arr.dropped) - gaps} incomplete or with a clock change)")
        return len(arr.days)

    def day_time_array(self, zones=None) -> DayArray:
        """Zone temperatures as days × time-of-day, whole days without gaps only.

        A thin call of :func:`thermctl.data.day_array` on the ``T:<zone>`` columns.

        Parameters
        ----------
        zones : list of str, optional
            Default: the spec's measured zones, in spec order.

        Returns
        -------
        DayArray
            ``values`` has shape (days, K, zones) [°C] with ``K = 1 day / step``. Days
            are local calendar days of :attr:`tz`; a day is dropped (and listed in
            ``dropped`` with the reason) when it lacks any of its K stamps (data
            start/end, a daylight-saving change) or a zone temperature is NaN in it.
        """
        zones = self._zone_list(zones)
        return day_array(self.frame[[f"T:{z}" for z in zones]], zones,
                         step=self.step.total_seconds())

    # ---- helpers ---------------------------------------------------------------
    def _zone_list(self, zones) -> list:
        """``zones`` (default: the spec's measured zones), checked to have ``T:`` columns."""
        zones = list(self.spec.measured_zones if zones is None else zones)
        bad = [z for z in zones if f"T:{z}" not in self.frame or z not in self.spec.zone_names]
        if bad:
            raise DataError(f"{self.source}: no measured temperature for zone(s) {bad}; "
                            f"measured zones are {self.spec.measured_zones}")
        return zones

    def _instant(self, x, what) -> pd.Timestamp:
        ts = _parse(pd.Timestamp, x, f"{self.source}: {what} {x!r} is not a date or time")
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
        return Measurements(sub, self.step, self.spec, self.units, self.source, self.quality,
                            self.input_timing)

    def _whole_days(self) -> list:
        """Dates the grid covers but for at most :data:`SPLIT_DAY_SLACK` (NaN or not).

        The grid runs from the first to the last stamp, so only the first and last dates
        can be short. A log whose last row is lost, or whose last stamp is jittered a few
        seconds early (23:54:50 for 23:55), still holds that day: counted strictly, the
        day would drop out and move the default split a whole day (a messy export of 16
        days calibrated on 11 days instead of the clean export's 12).
        """
        K = _DAY_NS // int(self.step.value)
        slack = int(SPLIT_DAY_SLACK / self.step)      # 12 samples at 5 min
        dates = pd.Series(self.frame.index.date)
        counts = dates.value_counts()
        return sorted(d for d, c in counts.items() if c >= K - slack)


def _short_list(items, k=8) -> str:
    items = list(items)
    return ", ".join(items[:k]) + (f", ... ({len(items) - k} more)" if len(items) > k else "")
