"""The daily-gain t test asks the same effect of a longer record: t ≥ min_t·√(D / min_t_days)."""

from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pytest

from thermctl.errors import DataError, EstimationError
from thermctl.estimate.likelihood.scoring import LikelihoodScorer, required_t
from thermctl.identify import IdentifyOptions, SplitOptions
from thermctl.local import fit_local, local_problems
from thermctl.testbed import generate


@pytest.fixture(scope="module")
def corridor():
    """A 9-zone corridor floor (4 offices a side, unmeasured hallway), 8 days."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate("corridor", zones=9, days=8, seed=2)
    frame = tb.data
    probs = local_problems(tb.spec, frame.columns)
    return tb, frame, probs


def test_required_t_keeps_the_effect_size_of_the_reference_record():
    assert required_t(2.0, 10, 10.0) == 2.0
    assert required_t(2.0, 4, 10.0) == 2.0          # never below min_t on a short record
    assert required_t(2.0, 40, 10.0) == pytest.approx(4.0, rel=1e-15)
    assert required_t(2.0, 40, None) == 2.0
    assert required_t(0.0, 40, 10.0) == 0.0          # off stays off
    # t = mean/sd·√D: a gain of mean/sd = 2/√10 (what min_t 2 asks of 10 days) reaches the
    # requirement on every longer record, and exactly
    for D in (11, 21, 28, 60):
        assert (2.0 / math.sqrt(10.0)) * math.sqrt(D) == pytest.approx(required_t(2.0, D, 10.0))


def _gains(ratio, days, seed=0):
    """Daily gains whose mean is exactly ``ratio`` sample standard deviations."""
    g = np.random.default_rng(seed).normal(size=days)
    g = (g - g.mean()) / g.std(ddof=1)
    return g + ratio


def test_consistent_asks_more_of_a_longer_record(corridor, monkeypatch):
    """A gain of 0.55 sd a day: t = 0.55·√21 = 2.52 on 21 days passes min_t 2 but not the
    2.90 that min_t 2 on 10 days asks of 21; on 10 days (t 1.74) it fails both."""
    _, frame, probs = corridor
    p = probs[0]
    data = p.data(frame)
    fixed = LikelihoodScorer(p.spec, data, min_t=2.0)
    scaled = LikelihoodScorer(p.spec, data, min_t=2.0, min_t_days=10.0)
    for days, ok_fixed, ok_scaled in ((21, True, False), (10, False, False), (60, True, False)):
        g = _gains(0.55, days)
        for sc in (fixed, scaled):
            monkeypatch.setattr(sc, "_daily_gains", lambda small, big, g=g: g)
        t = 0.55 * math.sqrt(days)
        ok, t1, note = fixed.consistent(None, None)
        assert (ok, t1) == (ok_fixed, pytest.approx(t, rel=1e-12)) and "(needs 2)" in note
        ok, t2, note = scaled.consistent(None, None)
        need = required_t(2.0, days, 10.0)
        assert (ok, t2) == (ok_scaled, pytest.approx(t, rel=1e-12))
        assert f"(needs {need:g})" in note
    # a gain of 0.7 sd a day passes both on any record from 10 days on (0.7 > 2/√10 = 0.63)
    for days in (10, 21, 60):
        g = _gains(0.7, days, seed=days)
        monkeypatch.setattr(scaled, "_daily_gains", lambda small, big, g=g: g)
        assert scaled.consistent(None, None)[0]


def test_bad_values_are_refused(corridor):
    _, frame, probs = corridor
    p = probs[0]
    with pytest.raises(EstimationError, match="min_t_days must be > 0"):
        LikelihoodScorer(p.spec, p.data(frame), min_t=2.0, min_t_days=0.0)
    with pytest.raises(DataError, match="split.min_t_days must be > 0"):
        IdentifyOptions(split=SplitOptions(min_t_days=-1.0)).check()
    assert IdentifyOptions().local_fit_options()["min_t_days"] == SplitOptions().min_t_days == 10


def test_a_local_search_asks_the_scaled_t_of_every_path_it_keeps(corridor):
    """fit_local hands min_t_days to its search: with min_t_days 1 on 8 days every daily
    test asks t ≥ 2·√(D/1), and every path kept reaches it; the default record (10 days)
    leaves the 8-day search as it was (the same paths and evidence)."""
    _, frame, probs = corridor
    p = max(probs, key=lambda q: len(q.candidates))
    kw = dict(min_t=2.0, max_iter=100)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = fit_local(p, frame, **kw)
        same = fit_local(p, frame, min_t_days=10.0, **kw)
        strict = fit_local(p, frame, min_t_days=1.0, **kw)
    assert same.edges == plain.edges and same.evidence == plain.evidence
    texts = " ".join(strict.reasons.values())
    days = {int(m) for m in re.findall(r"better on \d+ of (\d+) days", texts)}
    assert len(days) == 1, texts
    # the result's own count of the days the test compared is the one its reasons give
    assert strict.days == plain.days == next(iter(days)) == 8, (strict.days, days)
    need = required_t(2.0, days.pop(), 1.0)
    assert need > 4.5
    assert f"(needs {need:g})" in texts
    for e in strict.edges:
        ts = [float(t) for t in re.findall(r"daily gain t ([-\d.]+)", strict.reasons[e])]
        assert ts and ts[-1] >= round(need, 1) - 0.05, strict.reasons[e]
    # and it asked something: a path the plain search kept at 2 <= t < need is out
    weak = [e for e in plain.edges
            if float(re.findall(r"daily gain t ([-\d.]+)", plain.reasons[e])[-1]) < need]
    assert weak and not set(weak) & set(strict.edges), (plain.reasons, strict.reasons)


@pytest.mark.parametrize("args, days", [([], 10.0), (["--local-min-t-days", "21"], 21.0),
                                        (["--local-min-t-days", "0"], None)])
def test_cli_option_reaches_the_split_options(identify_split, args, days):
    """``thermctl identify --local-min-t-days D`` (0: off) sets ``split.min_t_days``."""
    assert identify_split(*args).min_t_days == days


def test_identify_says_what_t_a_long_record_asked():
    """The note gives the t the local problems asked (2·√(21/10) = 2.90 on 21 days), and is
    not written on the record min_t is for, or with the scaling off."""
    from types import SimpleNamespace

    from thermctl.identify import _min_t_days_note
    from thermctl.local import LocalResult

    def li(days):
        # a problem without candidates (no search: days 0) does not count
        return SimpleNamespace(results=[
            LocalResult("a", ["air:a-b"], {}, {}, 1.0, 10, days=days),
            LocalResult("b", ["air:a-b"], {}, {}, 1.0, 10, days=days),
            LocalResult("c", [], {}, {}, float("nan"), 10)])
    notes = []
    _min_t_days_note(li(21), SplitOptions(), notes)
    assert len(notes) == 1 and "on 21 calibration days" in notes[0] and "t 2.90" in notes[0]
    for days, split in ((10, SplitOptions()), (21, SplitOptions(min_t_days=None)),
                        (21, SplitOptions(min_t=0.0))):
        notes = []
        _min_t_days_note(li(days), split, notes)
        assert notes == []
