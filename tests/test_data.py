"""Measured-data ingestion: formats, units, time zones, resampling, gaps, splits, bad input.

The synthetic data use signals that are *linear in time*, so linear interpolation onto
the grid must reproduce them to rounding: every resampled or filled value has an exact
reference. The real twin house file checks ingest on data nobody simulated.
"""

from __future__ import annotations

import datetime as dt
import json
import warnings

import numpy as np
import pandas as pd
import pytest

from thermctl.data import CFM, Measurements, QualityReport, day_array, read_measurements
from thermctl.errors import DataError, DataWarning
from thermctl.network import ThermalNetwork
from thermctl.spec import load_spec

FT3 = 0.3048 ** 3           # m³ per cubic foot, written out here (not from the module)
T0 = pd.Timestamp("2011-03-01T00:00:00", tz="UTC")


def linear_frame(n=288 * 2, step="5min", start=T0, supply=True, q=True):
    """SI data for the small spec; every column is linear in time (t in hours).

    r1 gets supply air (ms/Ts), r1 and r2 a heat input; the hallway is unmeasured.
    """
    t = pd.date_range(start, periods=n, freq=step)
    h = (t - t[0]).total_seconds().to_numpy() / 3600.0
    cols = {
        "time": [s.isoformat() for s in t],
        "T:r1": 20.0 + 0.01 * h,
        "T:r2": 21.0 - 0.02 * h,
        "T:r3": 22.0 + 0.005 * h,
        "T:outside": 5.0 + 0.1 * h,
        "T:ground": 10.0 + 0.0 * h,
    }
    if supply:
        cols["Ts:r1"] = 14.0 + 0.03 * h
        cols["ms:r1"] = 0.2 + 0.001 * h
    if q:
        cols["Q:r1"] = 100.0 + 2.0 * h
        cols["Q:r2"] = 50.0 + 0.0 * h
    cols["solar:south"] = 10.0 * h
    cols["aux:fan"] = 1.0
    return pd.DataFrame(cols)


def truth(col, times):
    """The linear signal of ``linear_frame`` at the given instants."""
    h = (pd.DatetimeIndex(times) - T0).total_seconds().to_numpy() / 3600.0
    a, b = {"T:r1": (20.0, 0.01), "T:r2": (21.0, -0.02), "T:r3": (22.0, 0.005),
            "T:outside": (5.0, 0.1), "T:ground": (10.0, 0.0), "Ts:r1": (14.0, 0.03),
            "ms:r1": (0.2, 0.001), "Q:r1": (100.0, 2.0), "Q:r2": (50.0, 0.0),
            "solar:south": (0.0, 10.0)}[col]
    return a + b * h


def read_quiet(source, spec, **kw):
    """read_measurements, failing on any warning (tests that expect one use pytest.warns)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return read_measurements(source, spec, **kw)


def write_csv(df, tmp_path, name="data.csv"):
    path = tmp_path / name
    df.to_csv(path, index=False)
    return path


def assert_counts_add_up(q: QualityReport):
    for col in q.columns_used.values():
        total = q.exact[col] + q.resampled[col] + q.interpolated[col] + q.excluded[col]
        assert total == q.n_samples, col


# ---------------------------------------------------------------------------------------------
# the real house
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def twin(twinhouse_spec_path):
    spec = load_spec(twinhouse_spec_path)
    path = twinhouse_spec_path.parent / "data.csv"
    return spec, path, read_quiet(path, spec)


def test_twinhouse_ingest(twin):
    spec, path, meas = twin
    q = meas.quality
    assert q.rows_read == 5905 and q.n_samples == 5905 and len(meas) == 5905
    assert meas.step == pd.Timedelta(seconds=600) and q.step == 600 and q.step_inferred
    assert q.time_zone == "UTC+01:00"
    assert meas.start == pd.Timestamp("2013-08-21T00:00:00+01:00")
    assert meas.end == pd.Timestamp("2013-10-01T00:00:00+01:00")
    assert meas.start.utcoffset() == dt.timedelta(hours=1)
    assert not q.long_gaps and sum(q.interpolated.values()) == 0
    assert sum(q.resampled.values()) == 0 and q.off_grid_stamps == 0
    assert q.duplicates_removed == 0 and sum(q.missing_cells.values()) == 0
    assert_counts_add_up(q)
    # every extra column ignored and listed, none used
    raw = pd.read_csv(path)
    extra = [c for c in raw.columns if c.split(":")[0] in ("aux", "wind", "longwave", "rh")]
    assert len(extra) == 29 and sorted(q.ignored_columns) == sorted(extra)
    assert not any(c in meas.frame for c in extra)
    assert q.zones_without_supply == ["corridor", "bath", "child", "kitchen", "doorway",
                                      "bedroom"]
    # on-grid data pass through unchanged
    for col in ("T:living", "T:attic", "Q:kitchen", "ms:living", "solar:south_vertical"):
        np.testing.assert_array_equal(meas.frame[col].to_numpy(), raw[col].to_numpy())
    assert meas.valid.all() and len(meas.segments()) == 1
    json.dumps(q.to_dict())
    assert "5905 rows" in q.summary() and "ignored 29 other column(s)" in q.summary()


def test_twinhouse_inputs_days_and_split(twin):
    spec, _, meas = twin
    net = ThermalNetwork(spec)
    U = meas.inputs(net)
    assert U.shape == (5905, net.n_inputs) and np.isfinite(U).all()
    col = {n: i for i, n in enumerate(net.input_names)}
    f = meas.frame
    np.testing.assert_array_equal(U[:, col["ms[living]"]], f["ms:living"])
    np.testing.assert_array_equal(U[:, col["Ts[living]"]], f["Ts:living"])
    np.testing.assert_array_equal(U[:, col["ms[bath]"]], 0.0)
    np.testing.assert_array_equal(U[:, col["Ts[bath]"]], f["T:bath"])   # no supply: Ts = T
    np.testing.assert_array_equal(U[:, col["T[cellar]"]], f["T:cellar"])
    np.testing.assert_array_equal(U[:, col["Q[kitchen]"]], f["Q:kitchen"])
    days = meas.day_time_array()
    assert days.values.shape == (41, 144, 7)
    assert days.days[0] == dt.date(2013, 8, 21) and days.days[-1] == dt.date(2013, 9, 30)
    assert days.dropped == [(dt.date(2013, 10, 1), "incomplete (1 of 144 samples)")]
    np.testing.assert_array_equal(days.values[1, 6, 0], f["T:living"].iloc[144 + 6])
    assert days.zones == list(spec.measured_zones) and days.step == 600.0 and days.n_times == 144
    # the same shaping of the zone-named frame, step inferred from the index: identical
    plain = day_array(meas.zone_temperatures(), days.zones)
    np.testing.assert_array_equal(plain.values, days.values)
    assert (plain.days, plain.dropped, plain.step) == (days.days, days.dropped, days.step)
    # one sample: the step comes from the grid, not the index; the day is incomplete
    one = meas.window(meas.start, duration="10min").day_time_array()
    assert one.values.shape == (0, 144, 7)
    assert one.dropped == [(dt.date(2013, 8, 21), "incomplete (1 of 144 samples)")]
    assert meas.require_days(9, "SIN with 7 zones") == 41
    cal, val = meas.split()      # not the paper's dates: the last quarter (10 of 41 days)
    assert cal.start == meas.start and cal.end == pd.Timestamp("2013-09-20T23:50+01:00")
    assert val.start == pd.Timestamp("2013-09-21T00:00+01:00") and val.end == meas.end
    assert len(cal) + len(val) == len(meas)


# ---------------------------------------------------------------------------------------------
# regular, irregular, duplicated, gappy synthetic data
# ---------------------------------------------------------------------------------------------
def test_regular_frame_passes_through(small_spec, tmp_path):
    df = linear_frame()
    meas = read_quiet(write_csv(df, tmp_path), small_spec)
    q = meas.quality
    assert meas.step == pd.Timedelta("5min") and q.n_samples == len(df)
    assert list(meas.frame.columns) == ["T:r1", "T:r2", "T:r3", "T:outside", "T:ground",
                                        "Ts:r1", "ms:r1", "Q:r1", "Q:r2", "solar:south"]
    for col in meas.frame:
        np.testing.assert_allclose(meas.frame[col], df[col], rtol=0, atol=1e-12)
    assert q.ignored_columns == ["aux:fan"]
    assert q.zones_without_supply == ["r2", "r3", "hallway"]
    assert set(q.exact.values()) == {len(df)}
    assert str(meas.tz) == "UTC"


def test_irregular_stamps_resampled(small_spec):
    rng = np.random.default_rng(7)
    df = linear_frame()
    t = pd.to_datetime(df["time"])
    jitter = rng.integers(-40, 41, size=len(df))          # seconds, a polling BAS
    jitter[np.abs(jitter) == 1] = 2                        # ±1 s counts as on the grid
    jitter[::3] = 0                                        # a third land on the grid
    t = t + pd.to_timedelta(jitter, unit="s")
    df["time"] = [s.isoformat() for s in t]
    for col in df.columns[1:-1]:
        df[col] = truth(col, t)
    meas = read_quiet(df, small_spec, snap=None)     # 1 s: interpolate every jittered stamp
    q = meas.quality
    assert meas.step == pd.Timedelta("5min")
    n_off = int((jitter != 0).sum())
    assert q.off_grid_stamps == n_off
    # a grid point between two jittered samples is resampled, never a gap
    assert not q.long_gaps and sum(q.interpolated.values()) == 0
    assert q.resampled["T:r1"] + q.exact["T:r1"] == q.n_samples
    assert q.resampled["T:r1"] > 0.5 * n_off
    for col in meas.frame:
        # linear signal: linear interpolation is exact up to rounding
        np.testing.assert_allclose(meas.frame[col], truth(col, meas.frame.index),
                                   rtol=1e-12, atol=1e-9)
    assert_counts_add_up(q)


def test_duplicates_and_disorder(small_spec):
    df = linear_frame(n=100)
    dup_same = df.iloc[[10, 11, 12]]
    dup_diff = df.iloc[[20, 21]].copy()
    dup_diff["T:r1"] += 1.0                               # conflicting values
    mixed = pd.concat([df, dup_same, dup_diff]).sample(frac=1.0, random_state=3)
    # conflicting repeated stamps are an error by default (issue 22); averaged on request
    with pytest.raises(DataError, match="2 time stamp.*appear more than once with different"):
        read_quiet(mixed, small_spec)
    with pytest.warns(DataWarning, match="averaged"):
        meas = read_measurements(mixed, small_spec, average_conflicts=True)
    q = meas.quality
    assert q.rows_read == 105 and q.n_samples == 100
    assert q.duplicates_removed == 5 and q.duplicate_conflicts == 2
    assert q.rows_out_of_order > 0
    expected = df["T:r1"].to_numpy().copy()
    expected[[20, 21]] += 0.5                             # conflicts averaged
    np.testing.assert_allclose(meas.frame["T:r1"], expected, atol=1e-12)
    np.testing.assert_allclose(meas.frame["Q:r1"], df["Q:r1"], atol=1e-12)


def test_short_and_long_gaps(small_spec):
    df = linear_frame()
    short = np.arange(100, 103)               # 3 missing: 20 min between valid samples
    long_ = np.arange(300, 312)               # 12 missing: 65 min
    df = df.drop(index=np.r_[short, long_])
    df.loc[400:401, "T:r2"] = np.nan          # 2 empty cells in one column only
    with pytest.warns(DataWarning, match=r"120 samples excluded in 10 long gap\(s\) over 10"):
        meas = read_measurements(df, small_spec, gap_limit="30min")
    q = meas.quality
    assert q.n_samples == 576 and q.step == 300
    assert q.interpolated["T:r1"] == 3 and q.interpolated["T:r2"] == 5
    assert q.excluded["T:r1"] == 12 and q.missing_cells["T:r2"] == 2
    assert len(q.long_gaps) == len(meas.frame.columns)       # the 12-sample hole, per column
    g = q.long_gaps[0]
    assert (g.column, g.n) == ("T:r1", 12)
    assert g.start == T0 + 300 * pd.Timedelta("5min") and g.end == T0 + 311 * pd.Timedelta("5min")
    f = meas.frame
    assert f["T:r1"].iloc[long_].isna().all() and f["T:r1"].notna().sum() == 576 - 12
    np.testing.assert_allclose(f["T:r1"].iloc[short], truth("T:r1", f.index[short]), atol=1e-12)
    np.testing.assert_allclose(f["T:r2"].iloc[[400, 401]], truth("T:r2", f.index[[400, 401]]),
                               atol=1e-12)
    assert_counts_add_up(q)
    # validity and segments follow the long gap
    assert (~meas.valid).sum() == 12
    seg = meas.segments()
    assert [s[2] for s in seg] == [300, 576 - 312]
    assert seg[1][0] == f.index[312]
    # the day holding the long gap leaves the day × time array, named
    days = meas.day_time_array()
    assert days.values.shape == (1, 288, 3)
    assert days.dropped[0][0] == dt.date(2011, 3, 2)
    assert days.dropped[0][1].startswith("gap in T:r1, T:r2, T:r3")


@pytest.mark.parametrize("gap_limit, filled, excluded", [
    (0, 0, 15), ("30min", 3, 12), ("2h", 15, 0)], ids=["none", "30min", "2h"])
def test_gap_limit_is_configurable(small_spec, gap_limit, filled, excluded):
    df = linear_frame().drop(index=np.r_[100:103, 300:312])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        q = read_measurements(df, small_spec, gap_limit=gap_limit).quality
    assert q.interpolated["T:r3"] == filled and q.excluded["T:r3"] == excluded


def test_explicit_step_and_upsampling(small_spec):
    df = linear_frame(step="10min", n=144)
    up = read_quiet(df, small_spec, step="5min", gap_limit=0)
    assert up.step == pd.Timedelta("5min") and len(up) == 287
    q = up.quality
    # halfway points between 10-min samples are resampling, not gap filling
    assert q.resampled["T:r1"] == 143 and q.interpolated["T:r1"] == 0 and not q.long_gaps
    np.testing.assert_allclose(up.frame["T:r1"], truth("T:r1", up.frame.index), atol=1e-12)
    down = read_quiet(linear_frame(), small_spec, step="15min")
    assert len(down) == 192 and set(down.quality.exact.values()) == {192}
    np.testing.assert_allclose(down.frame["T:r2"], truth("T:r2", down.frame.index), atol=1e-12)


def test_step_inferred_from_jittery_median(small_spec):
    df = linear_frame(n=60)
    t = pd.to_datetime(df["time"]) + pd.to_timedelta(np.arange(60) * 2, unit="s")  # 302 s
    df["time"] = [s.isoformat() for s in t]
    meas = read_quiet(df, small_spec)
    assert meas.step == pd.Timedelta("5min")


# ---------------------------------------------------------------------------------------------
# units and flows
# ---------------------------------------------------------------------------------------------
def test_imperial_equals_si(small_spec, tmp_path):
    si = linear_frame()
    imp = si.copy()
    for col in ("T:r1", "T:r2", "T:r3", "T:outside", "T:ground", "Ts:r1"):
        imp[col] = si[col] * 9.0 / 5.0 + 32.0
    imp["ms:r1"] = si["ms:r1"] / 1.2 / (FT3 / 60.0)      # kg/s → CFM of standard air
    a = read_quiet(write_csv(si, tmp_path, "si.csv"), small_spec)
    b = read_quiet(write_csv(imp, tmp_path, "imp.csv"), small_spec, units="imperial")
    for col in a.frame:
        np.testing.assert_allclose(b.frame[col], a.frame[col], rtol=1e-12, atol=1e-12)
    assert b.units == "imperial" and b.temperature_unit == "°F"
    assert float(b.to_data_units(2.0)) == pytest.approx(3.6)
    assert any("°F → °C" in c for c in b.quality.conversions)
    assert any("ms:r1 CFM → kg/s" in c for c in b.quality.conversions)


def test_imperial_reference_values(small_spec):
    df = linear_frame(n=10)
    df["T:r1"] = 68.0                 # °F
    df["T:r2"] = df["T:r3"] = 70.0
    df = df.drop(columns=["ms:r1"]).assign(**{"vs:r1": 1000.0})  # CFM
    meas = read_quiet(df, small_spec, units="imperial")
    np.testing.assert_allclose(meas.frame["T:r1"], 20.0, rtol=1e-14)
    # 1000 ft³/min = 0.4719474 m³/s; times 1.2 kg/m³
    np.testing.assert_allclose(meas.frame["ms:r1"], 0.566336932, rtol=1e-8)
    np.testing.assert_allclose(meas.frame["Q:r1"], df["Q:r1"])   # W in both systems
    assert CFM == pytest.approx(4.719474432e-4, rel=1e-12)


def test_si_volume_flow_and_negative_flow(small_spec):
    df = linear_frame(n=10).drop(columns=["ms:r1"])
    df["vs:r1"] = [0.1] * 9 + [-0.002]
    with pytest.warns(DataWarning, match="negative flows"):
        meas = read_measurements(df, small_spec)
    np.testing.assert_allclose(meas.frame["ms:r1"], [0.12] * 9 + [0.0])
    assert meas.quality.clipped_flows == {"vs:r1": 1}
    assert meas.quality.columns_used["ms:r1"] == "vs:r1"


def test_fahrenheit_read_as_si_warns(small_spec):
    df = linear_frame(n=10)
    for col in ("T:r1", "T:r2", "T:r3"):
        df[col] = 72.0
    # an error naming the columns since issue 22; allow_odd_units reads as given, warning
    with pytest.raises(DataError, match=r"T:r1 \(median 72.0 °C\).*like °F.*--units imperial"):
        read_measurements(df, small_spec)
    with pytest.warns(DataWarning, match="like °F"):
        meas = read_measurements(df, small_spec, allow_odd_units=True)
    assert any("like °F" in n for n in meas.quality.notes)


# ---------------------------------------------------------------------------------------------
# time zones, parquet, unmeasured zones
# ---------------------------------------------------------------------------------------------
def test_utc_offset_days_are_local(small_spec):
    # 2 local days at -05:00, starting at local midnight
    df = linear_frame(start=pd.Timestamp("2011-03-01T05:00", tz="UTC"))
    df["time"] = [s.tz_convert("-05:00").isoformat() for s in pd.to_datetime(df["time"])]
    assert df["time"].iloc[0] == "2011-03-01T00:00:00-05:00"
    meas = read_quiet(df, small_spec)
    assert meas.quality.time_zone == "UTC-05:00"
    assert meas.start.hour == 0 and meas.start.utcoffset() == dt.timedelta(hours=-5)
    days = meas.day_time_array()
    assert days.days == [dt.date(2011, 3, 1), dt.date(2011, 3, 2)] and not days.dropped
    # the same data read in UTC has its days cut at UTC midnight: 3 partial days
    utc = read_quiet(df, small_spec, tz="UTC")
    assert utc.start == meas.start and str(utc.tz) == "UTC"
    d = utc.day_time_array()
    assert len(d.days) == 1 and len(d.dropped) == 2


def test_daylight_saving_offsets_use_standard_time(small_spec):
    df = linear_frame(n=48, step="1h", start=pd.Timestamp("2011-03-12T06:00", tz="UTC"))
    ny = pd.to_datetime(df["time"]).dt.tz_convert("America/New_York")   # DST starts 03-13
    df["time"] = [s.isoformat() for s in ny]
    assert df["time"].str[-6:].nunique() == 2
    meas = read_quiet(df, small_spec)
    assert meas.quality.time_zone == "UTC-05:00"
    assert any("standard time" in n for n in meas.quality.notes)
    np.testing.assert_allclose(meas.frame["T:r1"], df["T:r1"], atol=1e-12)


def test_naive_stamps_and_tz(small_spec):
    df = linear_frame(n=20)
    df["time"] = [s[:19] for s in df["time"]]                 # drop "+00:00"
    meas = read_quiet(df, small_spec)
    assert str(meas.tz) == "UTC" and any("taken as UTC" in n for n in meas.quality.notes)
    local = read_quiet(df, small_spec, tz="+01:00")
    assert local.start == pd.Timestamp("2011-03-01T00:00+01:00")
    assert local.start.utcoffset() == dt.timedelta(hours=1)


def test_naive_local_stamps_in_a_dst_zone(small_spec, tmp_path):
    # hourly wall-clock stamps across the 2011-11-06 fall-back in New York: 01:00 twice
    utc = pd.date_range("2011-11-05T04:00Z", periods=73, freq="1h")
    df = linear_frame(n=73, step="1h", start=utc[0])
    df["time"] = [s.tz_convert("America/New_York").strftime("%Y-%m-%dT%H:%M:%S") for s in utc]
    assert df["time"].duplicated().sum() == 1
    meas = read_quiet(df, small_spec, tz="America/New_York")
    assert len(meas) == 73 and meas.quality.duplicates_removed == 0
    np.testing.assert_allclose(meas.frame["T:r1"], df["T:r1"], atol=1e-12)
    days = meas.day_time_array()
    assert days.days == [dt.date(2011, 11, 5), dt.date(2011, 11, 7)]
    assert days.dropped == [(dt.date(2011, 11, 6),
                             "repeated time of day (clock change, 25 of 24 samples)")]
    # a wall-clock time that does not exist (spring forward) cannot be placed
    df.loc[70:, "time"] = ["2012-03-11T01:00:00", "2012-03-11T02:00:00", "2012-03-11T03:00:00"]
    with pytest.raises(DataError, match=r"data\.csv: column 'time': local stamps do not fit"):
        read_measurements(write_csv(df, tmp_path), small_spec, tz="America/New_York")


def test_parquet_matches_csv(small_spec, tmp_path):
    df = linear_frame()
    pq = df.assign(time=pd.to_datetime(df["time"]))            # a real datetime column
    pq.to_parquet(tmp_path / "data.parquet", index=False)
    a = read_quiet(tmp_path / "data.parquet", small_spec)
    b = read_quiet(write_csv(df, tmp_path), small_spec)
    pd.testing.assert_frame_equal(a.frame, b.frame)
    # a DataFrame with a DatetimeIndex works too
    c = read_quiet(pq.set_index("time"), small_spec)
    pd.testing.assert_frame_equal(c.frame, b.frame)


def test_unmeasured_zone_column_ignored(small_spec):
    df = linear_frame(n=10).assign(**{"T:hallway": 19.0})
    with pytest.warns(DataWarning, match="measured: false"):
        meas = read_measurements(df, small_spec)
    assert "T:hallway" not in meas.frame
    assert meas.quality.unmeasured_zone_columns == ["T:hallway"]


# ---------------------------------------------------------------------------------------------
# inputs, zone temperatures
# ---------------------------------------------------------------------------------------------
def test_inputs_follow_network_order(small_spec, small_network):
    meas = read_quiet(linear_frame(n=50), small_spec)
    U = meas.inputs(small_network)
    names = small_network.input_names
    assert U.shape == (50, len(names))
    f = meas.frame
    col = {n: U[:, i] for i, n in enumerate(names)}
    np.testing.assert_array_equal(col["ms[r1]"], f["ms:r1"])
    np.testing.assert_array_equal(col["Ts[r1]"], f["Ts:r1"])
    np.testing.assert_array_equal(col["ms[r2]"], 0.0)
    np.testing.assert_array_equal(col["Ts[r2]"], f["T:r2"])
    # unmeasured hallway without supply: Ts = mean of the measured zones (irrelevant at ms=0)
    np.testing.assert_allclose(col["Ts[hallway]"], f[["T:r1", "T:r2", "T:r3"]].mean(axis=1))
    np.testing.assert_array_equal(col["T[ground]"], f["T:ground"])
    np.testing.assert_array_equal(col["Q[r2]"], f["Q:r2"])
    np.testing.assert_array_equal(col["Q[r3]"], 0.0)
    np.testing.assert_array_equal(col["Q[hallway]"], 0.0)
    # agrees with the network's own input_vector for one row
    row = small_network.input_vector(
        ms={"r1": f["ms:r1"].iloc[7]},
        Ts={"r1": f["Ts:r1"].iloc[7], "r2": f["T:r2"].iloc[7], "r3": f["T:r3"].iloc[7],
            "hallway": col["Ts[hallway]"][7]},
        T={"outside": f["T:outside"].iloc[7], "ground": f["T:ground"].iloc[7]},
        Q={"r1": f["Q:r1"].iloc[7], "r2": f["Q:r2"].iloc[7]})
    np.testing.assert_array_equal(U[7], row)
    temps = meas.zone_temperatures()
    assert list(temps.columns) == ["r1", "r2", "r3"]
    np.testing.assert_array_equal(temps["r3"], f["T:r3"])
    with pytest.raises(DataError, match=r"zone\(s\) \['hallway'\]"):
        meas.zone_temperatures(["r1", "hallway"])


def test_inputs_reject_other_spec(small_spec, twinhouse_spec_path):
    meas = read_quiet(linear_frame(n=10), small_spec)
    with pytest.raises(DataError, match="network nodes do not match"):
        meas.inputs(ThermalNetwork(load_spec(twinhouse_spec_path)))


# ---------------------------------------------------------------------------------------------
# splits
# ---------------------------------------------------------------------------------------------
def hourly(start, days, small_spec):
    n = 24 * days
    return read_quiet(linear_frame(n=n, step="1h", start=pd.Timestamp(start, tz="UTC")),
                      small_spec)


def test_split_paper_dates(small_spec):
    meas = hourly("2011-01-21", 26, small_spec)           # the paper's 26 days
    cal, val = meas.split()
    assert cal.start == pd.Timestamp("2011-01-21T00:00Z")
    assert cal.end == pd.Timestamp("2011-02-09T23:00Z")
    assert val.start == pd.Timestamp("2011-02-10T00:00Z") and val.end == meas.end
    assert len(cal) == 20 * 24 and len(val) == 6 * 24


def test_split_default_last_quarter_and_options(small_spec):
    meas = hourly("2012-05-01", 8, small_spec)
    cal, val = meas.split()
    assert len(cal) == 6 * 24 and len(val) == 2 * 24
    assert val.start == pd.Timestamp("2012-05-07T00:00Z")
    # explicit both; date ends are inclusive
    cal, val = meas.split(calibration=("2012-05-02", "2012-05-03"),
                          validation=("2012-05-05", "2012-05-05"))
    assert (cal.start, len(cal)) == (pd.Timestamp("2012-05-02T00:00Z"), 48)
    assert (val.start, len(val)) == (pd.Timestamp("2012-05-05T00:00Z"), 24)
    # only calibration: validation is the rest after it; an instant end is exclusive
    cal, val = meas.split(calibration=("2012-05-01", "2012-05-04T12:00"))
    assert cal.end == pd.Timestamp("2012-05-04T11:00Z")
    assert val.start == pd.Timestamp("2012-05-04T12:00Z") and val.end == meas.end
    # only validation at the start: calibration is the rest after it
    cal, val = meas.split(validation=(dt.date(2012, 5, 1), dt.date(2012, 5, 1)))
    assert len(val) == 24 and cal.start == pd.Timestamp("2012-05-02T00:00Z")
    w = meas.window("2012-05-03", duration="48h")
    assert len(w) == 48 and w.end == pd.Timestamp("2012-05-04T23:00Z")


def test_split_window_partly_outside_warns(small_spec):
    meas = hourly("2012-05-01", 8, small_spec)
    with pytest.warns(DataWarning, match="beyond the data"):
        _, val = meas.split(validation=("2012-05-07", "2012-05-20"))
    assert len(val) == 48


# ---------------------------------------------------------------------------------------------
# bad input: one-line DataError naming the file and the column/zone at fault
# ---------------------------------------------------------------------------------------------
def _csv(text):
    def make(tmp_path, df):
        (tmp_path / "data.csv").write_text(text)
        return tmp_path / "data.csv"
    return make


def _edit(fn):
    def make(tmp_path, df):
        df = fn(df.copy())
        return write_csv(df, tmp_path)
    return make


def _set(col, row, value):
    def fn(df):
        df[col] = df[col].astype(object)
        df.loc[row, col] = value
        return df
    return fn


BAD = [
    ("missing file", lambda tmp_path, df: tmp_path / "nope.csv", {},
     r"nope\.csv: data file not found"),
    ("empty file", _csv(""), {}, r"data\.csv: data file is empty"),
    ("header only", _csv("time,T:r1\n"), {}, "header but no data rows"),
    ("no time column", _edit(lambda df: df.drop(columns=["time"])), {}, r"no 'time' column"),
    ("semicolons", _csv("time;T:r1\n2011-01-01T00:00;20\n"), {}, r"looks ';'-separated; pass sep=';'"),
    ("unparsable time", _edit(_set("time", 2, "yesterday")), {},
     r"column 'time': cannot parse 'yesterday' at line 4"),
    ("empty time", _edit(_set("time", 5, None)), {}, r"column 'time' is empty at line 7"),
    ("mixed offsets", _edit(_set("time", 3, "2011-03-01T00:15:00")), {},
     "mixes stamps with and without a UTC offset"),
    ("non-numeric cell", _edit(_set("T:r2", 3, "21,5")), {},
     r"column T:r2: non-numeric value '21,5' at line 5"),
    ("infinite cell", _edit(_set("Q:r1", 3, "inf")), {}, r"column Q:r1: non-numeric value"),
    ("all-NaN column", _edit(_set("T:r3", slice(None), np.nan)), {},
     r"column T:r3 has no values"),
    ("unknown node", _edit(lambda df: df.assign(**{"T:r9": 1.0})), {},
     r"not in the spec: \['r9'\]"),
    ("zone with no data", _edit(lambda df: df.drop(columns=["T:r2"])), {},
     r"no T: column: \['r2'\]"),
    ("boundary with no data", _edit(lambda df: df.drop(columns=["T:ground"])), {},
     r"no T: column: \['ground'\]"),
    ("Q for a boundary node", _edit(lambda df: df.assign(**{"Q:outside": 1.0})), {},
     r"\['Q:outside'\] name no zone"),
    ("flow without Ts", _edit(lambda df: df.drop(columns=["Ts:r1"])), {},
     r"zone 'r1' has supply flow ms:r1 but no Ts:r1"),
    ("ms and vs", _edit(lambda df: df.assign(**{"vs:r1": 0.1})), {}, "both ms:r1 and vs:r1"),
    ("duplicate column", _csv("time,T:r1,T:r1\n2011-01-01T00:00,1,2\n"), {},
     r"\['T:r1'\] appear more than once"),
    ("one stamp", _edit(lambda df: df.iloc[:1]), {}, "at least 2 distinct time stamps"),
    ("bad step", _edit(lambda df: df), {"step": "7min"}, "divide a day"),
    ("bad units", _edit(lambda df: df), {"units": "kelvin"}, "units must be"),
    ("bad tz", _edit(lambda df: df), {"tz": "Mars/Olympus"}, "unknown time zone"),
]


@pytest.mark.parametrize("make, kwargs, match", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input(small_spec, tmp_path, make, kwargs, match):
    path = make(tmp_path, linear_frame(n=20))
    with pytest.raises(DataError, match=match) as info:
        read_measurements(path, small_spec, **kwargs)
    msg = str(info.value)
    assert "\n" not in msg
    if "units" not in kwargs and "tz" not in kwargs and "step" not in kwargs:
        assert msg.startswith(str(path))


def test_bad_windows_and_too_few_days(small_spec):
    meas = hourly("2012-05-01", 8, small_spec)
    with pytest.raises(DataError, match=r"validation window .* is outside the data"):
        meas.split(validation=("2013-01-01", "2013-01-02"))
    with pytest.raises(DataError, match="calibration window .* ends before it starts"):
        meas.split(calibration=("2012-05-05", "2012-05-02"))
    with pytest.raises(DataError, match=r"SIN \(3 zones\) needs at least 10 whole days without "
                                        r"gaps, found 8"):
        meas.require_days(10, "SIN (3 zones)")
    short = hourly("2012-05-01", 1, small_spec)
    with pytest.raises(DataError, match="cannot split"):
        short.split()


def test_quality_report_serialises(small_spec):
    df = linear_frame().drop(index=np.r_[300:312])
    with pytest.warns(DataWarning):
        meas = read_measurements(df, small_spec)
    d = json.loads(json.dumps(meas.quality.to_dict()))
    assert d["long_gaps"][0] == {"column": "T:r1", "start": "2011-03-02T01:00:00+00:00",
                                 "end": "2011-03-02T01:55:00+00:00", "n": 12}
    assert d["step"] == 300.0 and d["ignored_columns"] == ["aux:fan"]
    text = meas.quality.summary()
    assert "120 excluded in 10 long gap(s)" in text and "long gap T:r1" in text
    assert isinstance(meas, Measurements) and "576 samples" in repr(meas)


def test_default_snap_takes_a_jittered_stamp_as_its_grid_sample(small_spec):
    """By default a stamp within a tenth of the step (30 s at 5 min) is its grid point's
    sample as is; one further off is still interpolated."""
    df = linear_frame()
    t = pd.to_datetime(df["time"])
    jitter = np.zeros(len(df), dtype=int)
    jitter[5], jitter[9] = 20, -29          # snapped
    jitter[13] = 40                         # > 30 s: interpolated
    t = t + pd.to_timedelta(jitter, unit="s")
    df["time"] = [s.isoformat() for s in t]
    for col in df.columns[1:-1]:
        df[col] = truth(col, t)
    meas = read_quiet(df, small_spec)
    q = meas.quality
    assert q.snapped_stamps == 2 and q.off_grid_stamps == 1 and q.snap == 30.0
    col = meas.frame.columns[0]
    # the snapped slots hold the jittered samples' own values
    for k in (5, 9):
        assert meas.frame[col].iloc[k] == pytest.approx(truth(col, t[k:k + 1])[0], rel=1e-12)
        assert meas.frame[col].iloc[k] != pytest.approx(truth(col, meas.frame.index[k:k + 1])[0],
                                                        rel=1e-9)
