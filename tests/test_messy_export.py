"""A messy export of a testbed building (issue 20): what reading repairs, and the structure.

The messy copy is made by ``benchmarks/messy.py`` (:func:`make_messy`): a 6-hour outage,
1 % of the rows lost, 8 empty cells, every stamp jittered by up to 20 s, 20 rows written
twice and 60 pairs of rows swapped, the header and cell formatting kept. The fast tests
check the reader with exact counts on 4 days of the Pugh Hall testbed; the slow one
identifies 16 days clean and messy and compares the air paths.
"""

from __future__ import annotations

import importlib.util
import io
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from thermctl.data import read_measurements
from thermctl.errors import DataError
from thermctl.testbed import generate
from thermctl.testbed.output import write_data_csv

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "messy.py"
STEP = pd.Timedelta("5min")


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_messy", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _export(days, seed=0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate("pugh-hall", days=days, seed=seed)
    buf = io.StringIO()
    write_data_csv(tb.data, buf)
    return tb, buf.getvalue()


def _read(text, tmp_path, name, spec, **kw):
    path = tmp_path / f"{name}.csv"
    path.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_measurements(path, spec, **kw)


@pytest.fixture(scope="module")
def four_days(bench, tmp_path_factory):
    tb, clean = _export(4)
    messy, log = bench.make_messy(clean, 20)
    tmp = tmp_path_factory.mktemp("messy")
    return dict(tb=tb, clean_text=clean, messy_text=messy, log=log,
                clean=_read(clean, tmp, "clean", tb.spec),
                messy=_read(messy, tmp, "messy", tb.spec, snap=None),
                snapped=_read(messy, tmp, "messy_snap", tb.spec, snap="30s"))


def _stamps(text):
    return pd.DatetimeIndex([pd.Timestamp(line.split(",", 1)[0])
                             for line in text.rstrip("\n").split("\n")[1:]])


def test_the_mess_is_what_it_says(four_days, bench):
    """The copy holds exactly the six messes, and the header as exported."""
    clean, messy, log = four_days["clean_text"], four_days["messy_text"], four_days["log"]
    assert messy.split("\n", 1)[0] == clean.split("\n", 1)[0]
    n_clean = len(clean.rstrip("\n").split("\n")) - 1
    n_messy = len(messy.rstrip("\n").split("\n")) - 1
    assert log["outage"][2] == 72                      # 6 h of 5-min rows
    assert n_messy == n_clean - 72 - log["missing"] + 20
    # 8 cells drawn; one falling on a lost row or an empty cell is not emptied again
    assert log["missing"] == round(0.01 * (n_clean - 72)) and 1 <= log["empty"] <= 8
    t = _stamps(messy)
    grid = t.round("5min")
    assert np.abs((t - grid).total_seconds()).max() <= 20
    assert (np.diff(t.asi8) < 0).any()


def test_duplicates_disorder_and_outage_repaired(four_days):
    """20 duplicates dropped, rows sorted, the 6-h outage left a gap, not interpolated."""
    q, meas = four_days["messy"].quality, four_days["messy"]
    assert q.duplicates_removed == 20 and q.duplicate_conflicts == 0
    assert q.rows_out_of_order > 0
    idx = meas.frame.index
    assert (np.diff(idx.asi8) == STEP.value).all()
    first, last = (pd.Timestamp(s) for s in four_days["log"]["outage"][:2])
    zone_cols = [f"T:{z}" for z in four_days["tb"].spec.measured_zones]
    for col in zone_cols:
        gaps = [g for g in q.long_gaps if g.column == col]
        assert len(gaps) == 1
        g = gaps[0]
        # the outage's 72 slots, plus at most the slot on each side whose own row was
        # jittered off it (read without snap, that slot has no sample within 1 s)
        assert g.start <= first and g.end >= last and 72 <= g.n <= 74
        assert meas.frame.loc[first:last, col].isna().all()
    # the default split is the clean export's, though a stamp at an end is jittered (the
    # first stamp here is 00:00:xx, so without snap the grid starts at 00:05)
    cal_c, val_c = four_days["clean"].split()
    cal_m, val_m = meas.split()
    assert (cal_m.end, val_m.start) == (cal_c.end, val_c.start)


def test_jittered_stamps_snap_to_their_slot(four_days):
    """With snap="30s" every surviving row is its slot's sample, value for value."""
    clean, snapped = four_days["clean"], four_days["snapped"]
    q = snapped.quality
    assert snapped.frame.index.equals(clean.frame.index)
    t = _stamps(four_days["messy_text"]).unique()
    off = np.abs((t - t.round("5min")).total_seconds())
    assert q.snapped_stamps == int((off > 1).sum()) and q.off_grid_stamps == 0
    # slots with a row in the messy file and a non-empty cell hold the clean value exactly
    raw = pd.read_csv(io.StringIO(four_days["messy_text"]))
    raw.index = pd.DatetimeIndex([pd.Timestamp(s) for s in raw.pop("time")]).round("5min")
    raw = raw[~raw.index.duplicated()].tz_convert(clean.tz)[list(clean.frame.columns)]
    have = raw.index
    fc, fm = clean.frame.loc[have].to_numpy(), snapped.frame.loc[have].to_numpy()
    cell = np.isfinite(raw.to_numpy())
    np.testing.assert_array_equal(fm[cell], fc[cell])
    assert (~cell).sum() == four_days["log"]["empty"] and np.isfinite(fm[~cell]).all()
    # the outage is exactly its 72 slots; a lost row or empty cell is one filled slot
    zone = f"T:{four_days['tb'].spec.measured_zones[0]}"
    assert [g.n for g in q.long_gaps if g.column == zone] == [72]
    lost = clean.frame.index.difference(have)
    n_cols = clean.frame.shape[1]
    assert sum(q.interpolated.values()) == (len(lost) - 72) * n_cols + four_days["log"]["empty"]
    assert "snapped to their grid point (within 30 s)" in q.summary()


def test_one_jittered_row_maps_to_its_slot(tmp_path, bench):
    """A row stamped 00:05:17 is the 00:05 sample with snap (the default: a tenth of the
    step), a blend of rows with the 1-s tolerance (``snap=None``)."""
    tb, clean = _export(1)
    lines = clean.split("\n")
    stamp = pd.Timestamp(lines[2].split(",", 1)[0])
    assert stamp.minute == 5
    lines[2] = (stamp + pd.Timedelta(seconds=17)).isoformat() + "," + lines[2].split(",", 1)[1]
    text = "\n".join(lines)
    col = f"T:{tb.spec.measured_zones[0]}"
    want = float(lines[2].split(",")[lines[0].split(",").index(col)])
    snapped = _read(text, tmp_path, "snap", tb.spec, snap="30s")
    assert snapped.frame.loc[stamp, col] == want and snapped.quality.snapped_stamps == 1
    assert _read(text, tmp_path, "default", tb.spec).frame.loc[stamp, col] == want
    plain = _read(text, tmp_path, "plain", tb.spec, snap=None)
    assert plain.quality.off_grid_stamps == 1 and plain.quality.resampled[col] == 1
    with pytest.raises(DataError, match="snap must be less than half the step"):
        _read(text, tmp_path, "bad", tb.spec, snap="150s")


@pytest.mark.slow
def test_messy_structure_matches_clean(bench, tmp_path):
    """Issue 20's target on 16 days of Pugh Hall: at most one air path differs."""
    tb, clean = _export(16)
    messy, _ = bench.make_messy(clean, 20)
    a = bench._run(_write(tmp_path, "clean", clean), tb.spec, "clean")
    b = bench._run(_write(tmp_path, "messy", messy), tb.spec, "messy")
    assert len(a["edges"] ^ b["edges"]) <= 1, (sorted(a["edges"]), sorted(b["edges"]))
    s = bench._run(_write(tmp_path, "snap", messy), tb.spec, "messy", snap="30s")
    assert s["edges"] == a["edges"], (sorted(a["edges"]), sorted(s["edges"]))


def _write(tmp_path, name, text):
    path = tmp_path / f"{name}.csv"
    path.write_text(text)
    return path
