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
