"""The search's cold fits start from the conduction-only fit's solar apertures and gain
noises (:func:`thermctl.estimate.likelihood.scoring.cold_start_from`): the same optimum as
the default start, in fewer evaluations, and the same start whether the first fit runs
ahead in a thread or in the search."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from thermctl.data import read_measurements
from thermctl.estimate.likelihood.problem import LikelihoodProblem
from thermctl.estimate.likelihood.scoring import LikelihoodScorer, cold_start_from
from thermctl.identify import IdentifyOptions, _conduction_only_fit, _scorer_options, identify
from thermctl.structure.search import as_candidates
from thermctl.testbed import generate


@pytest.fixture(scope="module")
def pugh():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate(days=8, seed=0)
        meas = read_measurements(tb.data, tb.spec)
    cal, _ = meas.split()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        off = _conduction_only_fit(tb.spec, cal, IdentifyOptions())
    return tb, meas, cal, off


def test_the_start_takes_apertures_and_gain_noises_only(pugh):
    tb, _, _, off = pugh
    start = cold_start_from(off)
    names = set(off.params_)
    assert set(start) == {k for k in names if k.startswith(("aperture[", "sigma_phi["))}
    # the demo floor's apertures come from its spec (no aperture parameter): gain noises only
    assert {k for k in start if k.startswith("sigma_phi[")} == {
        f"sigma_phi[{z}]" for z in tb.spec.measured_zones}
    # sensor and heat noises keep the default start (their split has several modes)
    assert not any(k.startswith(("sigma_v[", "sigma_q[", "rbar_v")) for k in start)
    assert all(start[k] == off.params_[k] for k in start)


def test_a_cold_fit_started_there_reaches_the_default_optimum_sooner(pugh, monkeypatch):
    """The true paths of the demo floor (8 days): the same −log L as the default start
    (within 0.05 nat), the same R̄_v (0.5 %), and fewer likelihood evaluations; the fit's
    first evaluation is at the given values."""
    tb, _, cal, off = pugh
    start = cold_start_from(off)
    cs = as_candidates(tb.spec, [e[:2] for e in tb.truth.edges])
    counts, firsts = [], []
    orig = LikelihoodProblem.nll_grad

    def counted(self, eta):
        if counts[-1] == 0:
            firsts.append(self.layout.values(eta))
        counts[-1] += 1
        return orig(self, eta)

    monkeypatch.setattr(LikelihoodProblem, "nll_grad", counted)
    fits = []
    for cold in (None, start):
        counts.append(0)
        sc = LikelihoodScorer(tb.spec, cal, cold_start=cold, **_scorer_options(IdentifyOptions()))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fits.append(sc.fit(cs)[0])
    default, warm = fits
    assert warm.nll_ == pytest.approx(default.nll_, abs=0.05)
    for k, v in default.params_.items():
        if k.startswith("rbar_v"):
            assert warm.params_[k] == pytest.approx(v, rel=5e-3), k
    assert counts[1] < counts[0], counts
    for k, v in start.items():
        assert firsts[1][k] == pytest.approx(v, rel=1e-9), k
    assert firsts[0]["sigma_phi[r240]"] != pytest.approx(start["sigma_phi[r240]"], rel=1e-3)


def test_identify_starts_the_same_first_fit_ahead_and_in_the_search(pugh):
    """With two threads the first fit runs beside the gain decision; with one the search
    makes it. Both start from the conduction-only fit, so the selections are the same,
    step by step (1e-10)."""
    tb, meas, _, _ = pugh
    out = []
    for workers in (1, 2):
        opt = IdentifyOptions()
        opt.split.workers = workers
        opt.estimation.intervals = "none"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out.append(identify(meas, opt))
    a, b = (o.selection for o in out)
    assert a.edges == b.edges
    assert [st.action for st in a.path] == [st.action for st in b.path]
    np.testing.assert_allclose([st.value for st in a.path], [st.value for st in b.path],
                               rtol=1e-10)


class _Quadratic:
    """A stand-in problem: ½ Σ h_i (η_i − 1)², curvatures over four decades, no noise
    coordinate (L-BFGS-B moves η itself)."""

    def __init__(self, h):
        from types import SimpleNamespace
        self.h = np.asarray(h, float)
        n = len(self.h)
        ps = [SimpleNamespace(name=f"p{i}", group="x", log=False, fixed=False) for i in range(n)]
        self.layout = SimpleNamespace(params=ps, bounds=lambda: (np.full(n, -50.0),
                                                                 np.full(n, 50.0)),
                                      eta0=lambda: np.zeros(n), free=lambda: np.ones(n, bool))
        self.n_obs = 1
        self.n_eval = 0

    def nll_grad(self, eta):
        self.n_eval += 1
        r = np.asarray(eta) - 1.0
        return 0.5 * float(np.sum(self.h * r * r)), self.h * r


def test_a_fits_step_scales_give_the_next_fit_its_curvature():
    """``OptResult.step_scale`` is the square root of L-BFGS-B's last inverse-Hessian
    diagonal: on a diagonal quadratic with curvatures 1e-2…1e2 it is 1/√h (within ×2),
    and a second fit from the same start with those scales needs a fraction of the
    evaluations (12 against 56: the scaled problem is nearly the identity) and ends at the
    optimum."""
    from thermctl.estimate.likelihood.optimize import minimize_criterion
    h = np.logspace(-2, 2, 8)
    pb = _Quadratic(h)
    first = minimize_criterion(pb, tol=1e-14, max_iter=500)
    n_first = pb.n_eval
    np.testing.assert_allclose(first.eta, 1.0, atol=1e-4)
    got = np.array([first.step_scale[f"p{i}"] for i in range(len(h))])
    want = 1 / np.sqrt(h)
    # an approximation from the last 20 steps: each within a factor 2 of the truth, in order
    assert np.all(np.abs(np.log(got / np.median(got)) - np.log(want / np.median(want)))
                  < np.log(2.0)), got
    assert np.all(np.diff(got) < 0)
    pb2 = _Quadratic(h)
    second = minimize_criterion(pb2, tol=1e-14, max_iter=500, step_scale=first.step_scale)
    np.testing.assert_allclose(second.eta, 1.0, atol=1e-4)
    assert pb2.n_eval <= n_first / 2, (pb2.n_eval, n_first)


def test_trials_with_the_fits_curvature_end_as_low(pugh):
    """On the demo floor the removal trials from a fit of the true paths plus a false one,
    with that fit's step scales, end at the same optima or lower (within 0.05 nat) than
    from the identity. (There they take more evaluations, 131 against 82: the plain trials
    stop early on the criterion's relative change, the scaled ones go 0.004–0.22 nats
    lower; on the twin house the selection's trials took 2 325 instead of 3 428.)"""
    tb, _, cal, _ = pugh
    sc = LikelihoodScorer(tb.spec, cal, **_scorer_options(IdentifyOptions()))
    cs = as_candidates(tb.spec, [e[:2] for e in tb.truth.edges] + [("r243", "r244")])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        parent, _ = sc.fit(cs)
        free = [p.name for p in parent.problem_.layout.params if not p.fixed]
        assert set(parent.step_scale_) == set(free)
        assert all(np.isfinite(v) and v > 0 for v in parent.step_scale_.values())
        scaled = [sc.fit(cs[:k] + cs[k + 1:], warm=parent)[0].nll_ for k in range(len(cs))]
        parent.step_scale_ = None
        plain = [sc.fit(cs[:k] + cs[k + 1:], warm=parent)[0].nll_ for k in range(len(cs))]
    for v0, v1 in zip(plain, scaled):
        assert v1 <= v0 + 0.05


def test_equal_step_scales_are_the_identity():
    """Scales are relative (over their median): equal ones change nothing, a parameter the
    dict lacks gets 1, and each stays within [1e-3, 1e3]."""
    from types import SimpleNamespace

    from thermctl.estimate.likelihood.optimize import _step_scales
    pb = SimpleNamespace(layout=SimpleNamespace(params=[SimpleNamespace(name=n)
                                                        for n in "abcd"]))
    idx = np.arange(4)
    np.testing.assert_array_equal(_step_scales(pb, idx, {k: 5.0 for k in "abcd"}), np.ones(4))
    np.testing.assert_array_equal(_step_scales(pb, idx, None), np.ones(4))
    d = _step_scales(pb, idx, {"a": 2.0, "b": 4.0, "c": 8.0, "d": 1e9})
    np.testing.assert_allclose(d, [2 / 6, 4 / 6, 8 / 6, 1e3])
    np.testing.assert_allclose(_step_scales(pb, idx, {"a": 2.0, "b": 4.0}), [2 / 3, 4 / 3, 1, 1])
