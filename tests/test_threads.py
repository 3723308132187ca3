"""Trial fits side by side in threads give the serial selection, number for number."""

import warnings

import numpy as np
import pytest

from thermctl.selection import select_air_paths


@pytest.fixture(scope="module")
def floor():
    from thermctl.data import read_measurements
    from thermctl.testbed import generate
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate(days=5, seed=3)
    return tb.spec, read_measurements(tb.data, tb.spec)


def test_threaded_backward_search_equals_serial(floor):
    spec, meas = floor
    cands = [("r240", "r243"), ("r241", "r247"), ("r242", "r244"), ("r241", "r242")]
    show, filters = warnings.showwarning, list(warnings.filters)
    out = [select_air_paths(spec, meas, candidates=cands, direction="backward", workers=w,
                            max_iter=60) for w in (1, 2)]
    s1, s2 = out
    assert s1.edges == s2.edges
    assert [(st.action, st.edge) for st in s1.path] == [(st.action, st.edge) for st in s2.path]
    np.testing.assert_allclose([st.value for st in s1.path], [st.value for st in s2.path],
                               rtol=1e-12)
    assert s1.n_fits == s2.n_fits
    for k, v in s1.estimator.params_.items():
        assert s2.estimator.params_[k] == pytest.approx(v, rel=1e-10), k
    # the threads left the process-wide warnings machinery as they found it
    assert warnings.showwarning is show and warnings.filters == filters


def test_profiles_in_threads_equal_serial(floor):
    from thermctl.estimate.likelihood import LikelihoodEstimator, identifiability
    from thermctl.network import ThermalNetwork
    spec, meas = floor
    net = ThermalNetwork(spec, [("r240", "r243", 2.8), ("r241", "r247", 5.8)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = LikelihoodEstimator(net, max_iter=80).fit(meas)
    show, filters = warnings.showwarning, list(warnings.filters)
    reps = [identifiability(est, threads=t) for t in (1, 2)]
    assert warnings.showwarning is show and warnings.filters == filters
    for name in ("rbar_v", "tau0"):
        a, b = reps[0].intervals[name], reps[1].intervals[name]
        assert a.method == b.method == "profile"
        assert (a.lower, a.upper) == pytest.approx((b.lower, b.upper), rel=1e-12)
        # the sides of each profile run as tasks of their own: the same interval as the
        # public one-parameter profile, both sides in turn
        from thermctl.estimate.likelihood.uncertainty import profile_likelihood
        c = profile_likelihood(est.problem_, est.eta_, name, nll_hat=est.nll_,
                               inflation=reps[1].wald[name].inflation)
        assert (c.lower, c.upper, c.closed_lower, c.closed_upper) == pytest.approx(
            (b.lower, b.upper, b.closed_lower, b.closed_upper), rel=1e-12)
    assert reps[0].verdicts == reps[1].verdicts
    # the Wald step: Hessian columns and day-block scores side by side
    for name, a in reps[0].wald.items():
        b = reps[1].wald[name]
        assert (a.lower, a.upper, a.inflation) == pytest.approx((b.lower, b.upper, b.inflation),
                                                                rel=1e-12), name


def test_first_fit_started_ahead_gives_the_serial_search(floor):
    """The search's first fit, started in a thread before the search (what identify does
    while it decides the gain model), is taken by the search: same selection, same count,
    and no second fit of that structure."""
    from thermctl._blas import ignore_warnings, single_thread_blas
    from thermctl.errors import BoundWarning, ConvergenceWarning, EstimationError
    from thermctl.estimate.likelihood.scoring import LikelihoodScorer
    from thermctl.structure.search import as_candidates
    spec, meas = floor
    cands = [("r240", "r243"), ("r241", "r247"), ("r242", "r244")]
    kw = dict(candidates=cands, direction="backward", max_iter=60, fast_gain=True)
    fits0 = []
    serial = select_air_paths(spec, meas, on_fit=fits0.append, **kw)
    ahead = LikelihoodScorer(spec, meas, max_iter=60, fast_gain=True)
    show, filters = warnings.showwarning, list(warnings.filters)
    with single_thread_blas(), ignore_warnings(BoundWarning, ConvergenceWarning):
        fut = ahead.speculate(as_candidates(spec, cands))
        fut.result()
    assert warnings.showwarning is show and warnings.filters == filters
    assert ahead.n_fits == 0            # counted by the search that takes it, once
    fits = []
    got = select_air_paths(spec, meas, ahead=ahead, on_fit=fits.append, **kw)
    assert got.edges == serial.edges and got.n_fits == serial.n_fits and fits == fits0
    np.testing.assert_allclose([st.value for st in got.path], [st.value for st in serial.path],
                               rtol=1e-12)
    # the search's first fit is the very object fitted ahead: it was not refitted
    assert got.path[0].value == fut.result()[1]
    for k, v in serial.estimator.params_.items():
        assert got.estimator.params_[k] == pytest.approx(v, rel=1e-10), k
    # fits started with other options are refused, not silently used
    other = LikelihoodScorer(spec, meas, max_iter=60)           # no fast gain
    with single_thread_blas(), ignore_warnings(BoundWarning, ConvergenceWarning):
        other.speculate(as_candidates(spec, cands[:1])).result()
    with pytest.raises(EstimationError, match="other options"):
        select_air_paths(spec, meas, ahead=other, **kw)


def test_a_fit_started_ahead_stops_when_cancelled(floor):
    """A wrong guess does not hold a core: the fit ends at its next likelihood evaluation,
    is not counted, and the search fits afresh (the serial result)."""
    import time

    from thermctl._blas import ignore_warnings, single_thread_blas
    from thermctl.errors import BoundWarning, ConvergenceWarning
    from thermctl.estimate.likelihood.scoring import LikelihoodScorer, _Stopped
    from thermctl.structure.search import as_candidates
    spec, meas = floor
    cands = [("r240", "r243"), ("r241", "r247"), ("r242", "r244")]
    ahead = LikelihoodScorer(spec, meas, max_iter=60, fast_gain=True)
    cs = as_candidates(spec, cands)
    with single_thread_blas(), ignore_warnings(BoundWarning, ConvergenceWarning):
        fut = ahead.speculate(cs)
        time.sleep(0.5)                       # the fit is under way
        t0 = time.perf_counter()
        ahead.cancel_ahead()
        waited = time.perf_counter() - t0
    assert fut.done() and isinstance(fut.exception(), _Stopped)
    assert waited < 2.0                       # one evaluation, not the rest of the fit
    assert ahead.n_fits == 0
    # nothing is left to adopt: the search fits that structure itself
    kw = dict(candidates=cands, direction="backward", max_iter=60, fast_gain=True)
    got = select_air_paths(spec, meas, ahead=ahead, **kw)
    serial = select_air_paths(spec, meas, **kw)
    assert got.edges == serial.edges and got.n_fits == serial.n_fits
    assert got.path[0].value == pytest.approx(serial.path[0].value, rel=1e-12)


def test_swap_stage_in_threads_equals_serial(floor):
    """The swap stage screens each kept edge's replacements in its own problem; with two
    workers those screenings (and the refits) run side by side: the same screening values,
    path and fit as one after the other."""
    spec, meas = floor
    cands = [("r240", "r243"), ("r241", "r244"), ("r242", "r244")]
    swaps = [("r241", "r247"), ("r240", "r241"), ("r243", "r244")]
    out = [select_air_paths(spec, meas, candidates=cands, direction="backward", workers=w,
                            max_iter=60, swaps=swaps) for w in (1, 2)]
    s1, s2 = out
    assert s1.edges == s2.edges
    assert [(st.action, st.edge) for st in s1.path] == [(st.action, st.edge) for st in s2.path]
    np.testing.assert_allclose([st.value for st in s1.path], [st.value for st in s2.path],
                               rtol=1e-12)
    # the alternatives the screening tried, with their values, are in both
    tried = {k: v for k, v in s1.reasons.items() if "tried in place" in v}
    assert tried and tried == {k: s2.reasons[k] for k in tried}
    assert s1.n_fits == s2.n_fits


@pytest.mark.parametrize("gains, kept", [("hourly", True), ("arrivals", False)])
def test_first_fit_beside_the_gain_decision_follows_the_decision(gains, kept, caplog):
    """``identify`` fits the search's first structure beside the gain-model decision, without
    the fast gain until the decision's running fit is better by more than the margin, then
    with it. Either way the fit handed to the search has the decided gain model and is the
    fit the search would have made (hourly occupancy, seed 1: kept, BIC −270; the default
    testbed: left out, +17.5)."""
    import logging

    from thermctl.data import read_measurements
    from thermctl.estimate.likelihood.scoring import LikelihoodScorer
    from thermctl.identify import IdentifyOptions, _gain_model_and_first_fit, _scorer_options
    from thermctl.structure.search import as_candidates
    from thermctl.testbed import generate
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate("pugh-hall", days=14, seed=1, gains=gains)
        meas = read_measurements(tb.data, tb.spec, name=gains)
    cal, _ = meas.split()
    first = [e[:2] for e in tb.truth.edges]
    opt = IdentifyOptions()
    opt.split.workers = 2
    notes = []
    with caplog.at_level(logging.INFO, logger="thermctl.identify"):
        got, ahead = _gain_model_and_first_fit(tb.spec, cal, opt, notes, None, first)
    assert got.estimation.fast_gain is kept
    switched = [r for r in caplog.records if "beside it now has it" in r.getMessage()]
    assert len(switched) == (1 if kept else 0)
    # the fit started ahead is the search's own cold fit of that structure, with the
    # decided gain model
    ref = LikelihoodScorer(tb.spec, cal, **_scorer_options(got))
    assert ahead is not None and ahead.kw == ref.kw
    fut = ahead._ahead[frozenset(c.name for c in as_candidates(tb.spec, first))]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est, val = ref.fit(as_candidates(tb.spec, first))
    assert fut.result()[1] == pytest.approx(val, rel=1e-12)


def test_a_switch_the_gain_decision_then_overturns_is_undone(floor, monkeypatch):
    """When an evaluation of the decision's fit passes the margin but the fit ends below it,
    the first fit started with the fast gain is stopped, and the search is left to fit that
    structure itself (no scorer adopted); no fit keeps running."""
    import dataclasses
    import threading
    import time

    import thermctl.identify as ident
    spec, meas = floor
    cands = [("r240", "r243"), ("r241", "r247"), ("r242", "r244")]

    def decide(spec, edges, cal, opt, notes, progress=None, off=None, watch=None):
        watch(opt.selection.margin + 1.0)       # the running fit passes the margin ...
        time.sleep(0.5)                         # (the fit beside it is under way)
        return dataclasses.replace(opt, estimation=dataclasses.replace(
            opt.estimation, fast_gain=False))   # ... and ends below it: left out

    monkeypatch.setattr(ident, "_resolve_fast_gain", decide)
    opt = ident.IdentifyOptions()
    opt.split.workers = 2
    before = threading.active_count()
    got, ahead = ident._gain_model_and_first_fit(spec, meas, opt, [], None, cands)
    assert got.estimation.fast_gain is False and ahead is None
    assert threading.active_count() == before


def test_grid_screening_on_threads_equals_serial(floor):
    """The grid screening evaluates every candidate of every job on the threads (one job
    alone too: the additions' screening); the values are the serial ones, digit for digit,
    and each job counts as one fit, as in the serial loop."""
    from thermctl.estimate.likelihood.scoring import LikelihoodScorer
    from thermctl.structure.search import as_candidates
    spec, meas = floor
    cs = as_candidates(spec, [("r240", "r243"), ("r241", "r247"), ("r242", "r244"),
                              ("r241", "r242")])
    scorer = LikelihoodScorer(spec, meas, max_iter=60)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f0, _ = scorer.fit([])
        f1, _ = scorer.fit(cs[:1], warm=f0)
    jobs = [(cs[:1], cs[1:], f1), ([], cs, f0)]
    n0 = scorer.n_fits
    serial = [scorer.screen(*j) for j in jobs]
    n1 = scorer.n_fits
    both = scorer.screen_many(jobs, workers=2)
    n2 = scorer.n_fits
    one = scorer.screen_many(jobs[1:], workers=2)
    assert both == serial and one == serial[1:]
    assert list(both[1]) == [c.name for c in cs]           # in the candidates' order
    assert n1 - n0 == n2 - n1 == 2
