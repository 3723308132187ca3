"""Measured data: CSV/parquet ingest, units, resampling, gaps, splits, day × time-of-day arrays.

The exchange format (docs/data-format.md) is a wide table, one row per
time stamp:

=================  ==========================  =============================================
column             SI (``units="si"``)         imperial (``units="imperial"``)
=================  ==========================  =============================================
``time``           ISO 8601, UTC offset optional (``2011-01-21T00:05:00-05:00``); other
                   forms with ``time_format`` (``excel``, ``unix``, ``%d.%m.%Y %H:%M``)
``T:<node>``       °C                          °F
``Ts:<zone>``      °C                          °F
``ms:<zone>``      kg/s                        CFM (read as volume flow, like ``vs:``)
``vs:<zone>``      m³/s                        CFM
``Q:<zone>``       W                           W
``solar:<name>``   W/m²                        W/m²
=================  ==========================  =============================================

Choices this package makes (``docs/data-format.md`` repeats them for users):

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
  whole number of minutes that divides a day, or of seconds that divides a minute below
  one minute), aligned to local midnight, from the first to the last stamp. A grid
  point with a sample within 1 s (within ``snap`` if given: a trend log polled with
  jitter, ``snap="30s"``) takes that sample; otherwise the value is linearly
  interpolated in time between the valid samples before and after it. The time between
  those two samples is the *gap*: up to 1.5 × the larger of grid step and data spacing
  it is plain resampling of irregular stamps, up to ``gap_limit`` a short gap
  (interpolated and counted), longer a long gap (left NaN, reported, excluded).
  Down-sampling takes the value at each grid instant; it does not average.
* Duplicated time stamps with identical rows are merged and counted; repeated stamps whose
  rows disagree (a clock set back) are an error naming the time range, unless
  ``average_conflicts=True`` (then averaged, with a warning). Rows out of order are
  sorted; negative flows are set to 0 and counted.
* A zone (``T:``) or supply (``Ts:``) temperature column whose median does not fit the
  units (above 40 °C / 50 °C for ``si``, below 41 °F / 32 °F for ``imperial``) is an error
  naming the column, unless ``allow_odd_units=True`` (then a warning). Checked per column:
  one column exported in °F among °C columns is caught.
* CSV files are comma-separated unless ``sep`` says otherwise (``sep=";"`` also reads
  decimal commas). A YAML/JSON file given as data is refused as a likely swap of data
  and spec.
* :meth:`Measurements.split` warns when fewer than :data:`MIN_CALIBRATION_DAYS` (3)
  days calibrate.

Nothing here writes a file.

Layout: :mod:`._read` (file, columns, time stamps, units; :func:`read_measurements`),
:mod:`._grid` (step, grid, resampling, gap runs), :mod:`.measurements` (the results),
:mod:`.days` (day × time-of-day arrays of any regular frame: :func:`day_array`).
"""

from .days import DayArray, day_array
from .measurements import (MIN_CALIBRATION_DAYS, PAPER_CALIBRATION, PAPER_VALIDATION_START, Gap,
                           Measurements, QualityReport)
from ._read import CFM, read_measurements
from .inputs import GAP_POLICIES, network_inputs

__all__ = [
    "network_inputs", "GAP_POLICIES",
    "read_measurements", "Measurements", "QualityReport", "Gap", "DayArray", "day_array",
    "CFM", "PAPER_CALIBRATION", "PAPER_VALIDATION_START", "MIN_CALIBRATION_DAYS",
]
