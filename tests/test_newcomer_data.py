"""Issue 22, items 2 and 9: bad data caught at read time, per column, with an override.

One column in °F while reading °C, a clock that jumps back, too few calibration days,
Excel serial dates, ';'-separated files and a building spec given as data.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

from thermctl.data import read_measurements
from thermctl.errors import DataError, DataWarning


def frame(days=4, step="5min", start="2011-01-21T00:00:00"):
    n = int(days * pd.Timedelta("1D") / pd.Timedelta(step))
    t = pd.date_range(start, periods=n, freq=step)
    h = np.arange(len(t)) * pd.Timedelta(step).total_seconds() / 3600.0
    return pd.DataFrame({
        "time": [s.isoformat() for s in t],
        "T:r1": 21.0 + np.sin(h / 3.0), "T:r2": 22.0 + 0.5 * np.cos(h / 5.0), "T:r3": 20.5 + 0 * h,
        "T:outside": 2.0 + 3 * np.sin(h / 4.0), "T:ground": 8.0 + 0 * h,
    })


def quiet(source, spec, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return read_measurements(source, spec, **kw)


# ---- one column in °F while --units si -------------------------------------------------
def test_one_fahrenheit_column_is_an_error_naming_it(small_spec):
    df = frame(days=1)
    df["T:r2"] = df["T:r2"] * 1.8 + 32.0          # this zone's sensor exports °F
    with pytest.raises(DataError) as info:
        read_measurements(df, small_spec)
    msg = str(info.value)
    assert "T:r2" in msg and "T:r1" not in msg and "°F" in msg
    assert "--allow-odd-units" in msg and "\n" not in msg
    # the documented override reads it as given, with a warning naming the column
    with pytest.warns(DataWarning, match="T:r2"):
        meas = read_measurements(df, small_spec, allow_odd_units=True)
    assert meas.frame["T:r2"].median() > 60


def test_whole_file_in_fahrenheit_points_to_units_imperial(small_spec):
    df = frame(days=1)
    for c in ("T:r1", "T:r2", "T:r3", "T:outside", "T:ground"):
        df[c] = df[c] * 1.8 + 32.0
    with pytest.raises(DataError, match=r"read the file with units='imperial' \(--units imperial\)"):
        read_measurements(df, small_spec)
    quiet(df, small_spec, units="imperial")        # read right, no complaint


# ---- a clock that jumps back -------------------------------------------------------------
def test_clock_jumping_back_is_an_error_with_the_range(small_spec):
    df = frame(days=2)
    # after 2011-01-21 18:00 the logger's clock is set back 6 h: 72 stamps come again
    i = int(18 * 12)
    again = df.iloc[i - 72:i].copy()
    again[["T:r1", "T:r2", "T:r3"]] += 1.5
    bad = pd.concat([df.iloc[:i], again, df.iloc[i:]], ignore_index=True)
    with pytest.raises(DataError) as info:
        read_measurements(bad, small_spec)
    msg = str(info.value)
    assert "72 time stamp(s) from 2011-01-21 12:00 to 2011-01-21 17:55" in msg
    assert "jumps back from 2011-01-21 17:55 to 2011-01-21 12:00 at row 216" in msg
    assert "--average-conflicts" in msg
    # the override keeps the old behaviour (averaged), now with a warning
    with pytest.warns(DataWarning, match="72 time stamp"):
        meas = read_measurements(bad, small_spec, average_conflicts=True)
    assert meas.quality.duplicate_conflicts == 72
    # identical repeated rows are still merged quietly
    same = pd.concat([df.iloc[:i], df.iloc[i - 72:i], df.iloc[i:]], ignore_index=True)
    assert quiet(same, small_spec).quality.duplicates_removed == 72


# ---- two days of data ------------------------------------------------------------------
def test_two_days_warn_at_the_split(small_spec):
    meas = quiet(frame(days=2), small_spec)
    with pytest.warns(DataWarning, match=r"only 1\.0 day\(s\) of calibration data"):
        cal, val = meas.split()
    assert len(cal) == 288
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        quiet(frame(days=5), small_spec).split()     # 4 calibration days: no warning


# ---- time formats and separators (item 9) -----------------------------------------------
def test_excel_serial_dates(small_spec, tmp_path):
    df = frame(days=1)
    t = pd.to_datetime(df["time"])
    df["time"] = (t - pd.Timestamp("1899-12-30")) / pd.Timedelta(days=1)   # 40564.0, ...
    path = tmp_path / "excel.csv"
    df.to_csv(path, index=False)
    with pytest.raises(DataError, match=r"spreadsheet serial date.*--time-format excel"):
        read_measurements(path, small_spec)
    meas = read_measurements(path, small_spec, time_format="excel")
    assert meas.start == pd.Timestamp("2011-01-21T00:00Z") and len(meas) == 288
    assert meas.quality.off_grid_stamps == 0


def test_strptime_format_and_semicolons(small_spec, tmp_path):
    df = frame(days=1)
    df["time"] = pd.to_datetime(df["time"]).dt.strftime("%d.%m.%Y %H:%M")
    path = tmp_path / "eu.csv"
    # a European spreadsheet export: ';' between fields, decimal commas
    df.to_csv(path, index=False, sep=";", decimal=",")
    with pytest.raises(DataError, match=r"pass sep=';'.*--sep"):
        read_measurements(path, small_spec)
    with pytest.raises(DataError, match=r"--time-format '%d\.%m\.%Y %H:%M'"):
        read_measurements(path, small_spec, sep=";")
    meas = read_measurements(path, small_spec, sep=";", time_format="%d.%m.%Y %H:%M")
    assert meas.start == pd.Timestamp("2011-01-21T00:00Z")
    np.testing.assert_allclose(meas.frame["T:r1"], df["T:r1"], atol=1e-9)


def test_spec_given_as_data(small_spec, write_spec, small_spec_dict):
    path = write_spec(small_spec_dict, "building.yaml")
    with pytest.raises(DataError, match="did you swap DATA and --building"):
        read_measurements(path, small_spec)
    txt = path.with_name("spec.txt")
    txt.write_text(path.read_text())               # the content says so too
    with pytest.raises(DataError, match="did you swap"):
        read_measurements(txt, small_spec)
