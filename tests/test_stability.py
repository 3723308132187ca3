"""Stability selection (issue 20): resampled blocks of days, selection frequencies."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from thermctl.errors import DataError, EstimationError
from thermctl.stability import (STABILITY_THRESHOLD, StabilityResample, StabilityResult,
                                mask_days, resample_days)


def _frame(days=12, step="1h"):
    idx = pd.date_range("2011-01-21", periods=int(days * 24), freq=step, tz="US/Eastern",
                        name="time")
    return pd.DataFrame({"T:a": np.arange(len(idx), dtype=float), "ms:a": 1.0,
                         "solar:s": 100.0}, index=idx)


def test_resampling_is_seeded_and_keeps_whole_blocks():
    fr = _frame(12)
    a = resample_days(fr, 6, fraction=0.5, block_days=2, seed=3)
    b = resample_days(fr, 6, fraction=0.5, block_days=2, seed=3)
    c = resample_days(fr, 6, fraction=0.5, block_days=2, seed=4)
    assert a == b and a != c
    # resample b does not depend on how many follow it
    assert resample_days(fr, 2, fraction=0.5, block_days=2, seed=3) == a[:2]
    days = sorted(set(fr.index.date))
    blocks = [tuple(days[i:i + 2]) for i in range(0, 12, 2)]
    for kept in a:
        assert len(kept) == 6                      # 3 of 6 blocks of 2 days
        got = [tuple(kept[i:i + 2]) for i in range(0, len(kept), 2)]
        assert all(g in blocks for g in got)
    assert len({tuple(k) for k in a}) > 1          # not the same subset every time


def test_mask_days_blanks_other_days_but_not_solar():
    fr = _frame(4)
    keep = sorted(set(fr.index.date))[1:3]
    m = mask_days(fr, keep)
    on = np.isin(fr.index.date, keep)
    assert np.isfinite(m.loc[on, "T:a"]).all() and m.loc[~on, ["T:a", "ms:a"]].isna().all().all()
    assert (m["solar:s"] == 100.0).all()
    assert (m.loc[on, "T:a"] == fr.loc[on, "T:a"]).all()


def test_bad_arguments_are_one_line_errors():
    fr = _frame(2)
    with pytest.raises(DataError, match="at least 2"):
        resample_days(fr, 3, block_days=2)
    with pytest.raises(EstimationError, match="fraction"):
        resample_days(_frame(6), 3, fraction=1.0)


def test_frequencies_and_below():
    rs = [StabilityResample(0, [], ["air:a-b"]), StabilityResample(1, [], ["air:a-b", "air:b-c"]),
          StabilityResample(2, [], [], error="DataError: x")]
    from thermctl.stability import _frequencies
    f = _frequencies({"air:a-b", "air:b-c", "air:a-c"}, rs)
    assert f == {"air:a-b": 1.0, "air:a-c": 0.0, "air:b-c": 0.5}
    res = StabilityResult(f, rs, 0.5, 2, 0, 1.0, 1.0)
    assert res.n_ok == 2 and res.below([("a", "b"), "air:b-c"]) == ["air:b-c"]
    assert STABILITY_THRESHOLD == 0.6 and "below threshold" in res.summary()
