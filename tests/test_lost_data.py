"""Edges whose verdict rests on the samples that survived a data loss (issue 20)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from thermctl.data import read_measurements
from thermctl.estimate.likelihood.scoring import LikelihoodScorer
from thermctl.testbed import generate


@pytest.fixture(scope="module")
def pugh(tmp_path_factory):
    out = tmp_path_factory.mktemp("pugh")
    tb = generate("pugh-hall", days=5, seed=1)
    tb.write(out)
    return out, tb


def _scorer(out, tb, blank_hours=0.0):
    df = pd.read_csv(out / "data.csv")
    if blank_hours:
        t = pd.to_datetime(df["time"])
        t0 = t.iloc[0] + pd.Timedelta(days=1)
        df = df[~((t >= t0) & (t < t0 + pd.Timedelta(hours=blank_hours))).values]
    meas = read_measurements(df, tb.spec, name="test")
    return LikelihoodScorer(tb.spec, meas)


def test_lost_days_count_the_missing_samples(pugh):
    out, tb = pugh
    assert _scorer(out, tb).lost_days == 0.0
    # 6 h blanked in the file: the rows on either side are kept, the gap stays NaN
    # (longer than the reader's 30-min interpolation limit)
    lost = _scorer(out, tb, blank_hours=6.0).lost_days
    assert lost == pytest.approx(0.25, abs=2 * 300 / 86400)


def test_verdict_turns_when_the_lost_days_could_have_gone_like_the_worst(pugh, monkeypatch):
    out, tb = pugh
    sc = _scorer(out, tb)
    g = np.array([9.0, 8.0, 10.0, 7.0, 11.0, 9.0, 8.0, 10.0, 9.0, -6.0])   # q10 = 5.7
    monkeypatch.setattr(sc, "_daily_gains", lambda small, big: g)
    q10, q90 = np.quantile(g, 0.1), np.quantile(g, 0.9)
    assert q10 > 0
    sc._lost = 2.0
    # every tenth of days gains: losing days cannot remove a kept path
    assert sc.lost_data(None, None, cost=12.0, margin=10.0) == ""
    g[:] = [9.0, 8.0, -30.0, 7.0, 11.0, 9.0, 8.0, 10.0, 9.0, -6.0]
    q10 = float(np.quantile(g, 0.1))
    assert q10 < 0
    # kept with cost 12 > margin 10; 2 lost days like the worst tenth: 12 + 4·q10 < 10
    note = sc.lost_data(None, None, cost=12.0, margin=10.0)
    assert note.startswith("uncertain (data lost)") and f"{12.0 + 4 * q10:+.1f}" in note
    # a clear path is not uncertain (12 + 4·q10 >= 10 once the cost is large enough)
    assert sc.lost_data(None, None, cost=10.0 - 4 * q10 + 0.1, margin=10.0) == ""
    # left out with gain 8 < 10: its best tenth of days (q90 = 9.9) over 2 days could bring it in
    q90 = float(np.quantile(g, 0.9))
    assert "adding it would gain" in sc.lost_data(None, None, cost=8.0, margin=10.0)
    assert sc.lost_data(None, None, cost=10.0 - 4 * q90 - 0.1, margin=10.0) == ""
    sc._lost = 0.0
    assert sc.lost_data(None, None, cost=8.0, margin=10.0) == ""


def test_search_puts_the_verdict_in_the_reasons():
    from thermctl.structure.search import Candidate, search_edges

    class Stub:
        """A (BIC -100, kept) and B (BIC -8 when added, left out); data lost flags A."""

        name = "bic"
        VALUE = {(): 0.0, ("A",): -100.0, ("B",): -8.0, ("A", "B"): -108.0}

        def fit(self, edges, warm=None):
            key = tuple(sorted(c.a for c in edges))
            return key, self.VALUE[key]

        def screen(self, edges, rest, fitted):
            return {c.name: self.VALUE[tuple(sorted(fitted + (c.a,)))] - self.VALUE[fitted]
                    for c in rest}

        def lost_data(self, small, big, cost, margin):
            extra = sorted(set(big) - set(small))
            return f"uncertain (data lost): {extra} {cost:+.0f}" if extra == ["A"] else ""

    res = search_edges([Candidate("A", "z", 1.0), Candidate("B", "z", 1.0)], Stub(),
                       direction="both", margin=10.0)
    assert [c.a for c in res.edges] == ["A"]
    a = [v for k, v in res.reasons.items() if k.startswith("air:A")][0]
    b = [v for k, v in res.reasons.items() if k.startswith("air:B")][0]
    assert "uncertain (data lost): ['A'] +100" in a
    assert "data lost" not in b
