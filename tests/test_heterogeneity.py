"""The shared R̄_v's interval when the air paths' own values scatter beyond their intervals.

`random_effects_inflation` is DerSimonian & Laird's between-estimate variance: checked against
its closed form with equal variances and by the coverage of a pooled value's interval on
seeded draws; `identify` widens the shared R̄_v's interval by it (one testbed case, slow).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from thermctl.errors import EstimationError
from thermctl.estimate.likelihood.uncertainty import random_effects_inflation


def test_equal_variances_give_q_over_its_degrees_of_freedom():
    y = np.array([0.0, 0.3, -0.1, 0.5])
    v = 0.04
    q, tau2, ratio = random_effects_inflation(y, np.full(4, v))
    assert q == pytest.approx(np.sum((y - y.mean()) ** 2) / v)          # 4.4375
    assert ratio == pytest.approx(q / 3)
    assert tau2 == pytest.approx(v * (q / 3 - 1))
    # estimates closer than their variances say: no between-path variance, no widening
    q, tau2, ratio = random_effects_inflation([0.0, 0.05, -0.05], [0.04] * 3)
    assert q < 2 and tau2 == 0.0 and ratio == 1.0


def test_unequal_variances_match_the_textbook_formula():
    y = np.array([1.53, 1.09, 1.27])
    v = np.array([0.079, 0.067, 0.030]) ** 2
    w = 1 / v
    ybar = np.sum(w * y) / np.sum(w)
    q_ref = np.sum(w * (y - ybar) ** 2)
    tau2_ref = (q_ref - 2) / (w.sum() - (w ** 2).sum() / w.sum())
    q, tau2, ratio = random_effects_inflation(y, v)
    assert q == pytest.approx(q_ref) and tau2 == pytest.approx(tau2_ref)
    assert ratio == pytest.approx(w.sum() / np.sum(1 / (v + tau2_ref)))
    assert ratio > 2


@pytest.mark.parametrize("tau, lo, hi, gain", [(0.0, 0.88, 0.96, 0.0), (0.1, 0.72, 0.86, 0.12)])
def test_widened_interval_covers_a_scattered_mean_more_often(tau, lo, hi, gain):
    # three paths with their own errors of 5, 11 and 13 % (the Pugh Hall factor case) and a
    # true between-path spread tau: the 90 % interval of the inverse-variance mean, widened
    # by sqrt(ratio), covers the common mean about as often as asked when tau = 0 and far
    # more often than the unwidened one when the paths scatter
    rng = np.random.default_rng(0)
    v = np.array([0.05, 0.11, 0.13]) ** 2
    z = 1.6449
    n, plain, wide = 3000, 0, 0
    for _ in range(n):
        y = rng.normal(0.0, np.sqrt(v + tau ** 2))
        w = 1 / v
        ybar, se = np.sum(w * y) / w.sum(), math.sqrt(1 / w.sum())
        ratio = random_effects_inflation(y, v)[2]
        plain += abs(ybar) <= z * se
        wide += abs(ybar) <= z * se * math.sqrt(ratio)
    assert lo <= wide / n <= hi
    assert wide / n >= plain / n + gain


def test_bad_input_is_refused():
    with pytest.raises(EstimationError):
        random_effects_inflation([1.0], [0.1])
    with pytest.raises(EstimationError):
        random_effects_inflation([1.0, 2.0], [0.1, 0.0])


@pytest.mark.slow
def test_identify_widens_the_shared_interval_where_the_paths_disagree():
    """Pugh Hall, random walls with published U-values, 14 days, seed 1 (session 21): the
    shared R̄_v 3.19e-4 [3.05e-4, 3.34e-4] missed the truth 3.36e-4; the three paths'
    own values 3.06e-4, 3.17e-4, 3.51e-4 (± 4–6 %) scatter with Q 4.3 on 2 degrees of
    freedom, and the widened interval covers it."""
    from thermctl.data import read_measurements
    from thermctl.identify import identify
    from thermctl.testbed import generate
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate(days=14, seed=1, walls="random")
        ident = identify(read_measurements(tb.data, tb.spec, name="walls"))
    ida = ident.intervals
    het = ida.heterogeneity
    assert het is not None and len(het["paths"]) == 3
    assert het["Q"] > 2 and het["ratio"] > 1.5
    iv = ida.intervals["rbar_v"]
    assert iv.covers(tb.truth.rbar_v)
    assert "scatter beyond their intervals" in ida.verdicts["rbar_v"]
    assert any("scatter beyond their intervals" in n for n in ident.notes)
    meta = ident.model.meta["greybox"]["heterogeneity"]
    assert meta["ratio"] == pytest.approx(het["ratio"])


@pytest.mark.slow
def test_per_path_p_makes_the_model_per_path_where_the_paths_disagree():
    """The same case with ``estimation.per_path_p`` 0.2: Q 4.3 on 2 degrees of freedom is p
    0.12 (below 0.2, above 0.1), so the model takes the search's per-path fit (no refit), and each path's interval
    takes in the shared value's interval widened by the scatter, the one the shared model
    reports."""
    from thermctl.data import read_measurements
    from thermctl.identify import (EstimationOptions, IdentifyOptions, SelectionOptions,
                                   identify)
    from thermctl.testbed import generate
    # the selection's own model: with the gain-schedule check (default since session 41)
    # the paths' p is 0.026 on this case, below both limits
    sel = SelectionOptions(schedule_check=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate(days=14, seed=1, walls="random")
        meas = read_measurements(tb.data, tb.spec, name="walls")
        shared = identify(meas, IdentifyOptions(selection=sel))
        per = identify(meas, IdentifyOptions(selection=sel,
                                             estimation=EstimationOptions(per_path_p=0.2)))
        off = identify(meas, IdentifyOptions(selection=sel,
                                             estimation=EstimationOptions(per_path_p=0.1)))
    het = shared.intervals.heterogeneity
    assert 0.1 < het["p"] < 0.2
    assert het["p"] == pytest.approx(math.exp(-het["Q"] / 2), rel=1e-9)   # χ² on 2 dof
    edges = [e.name for e in per.model.network.convection_edges]
    assert edges == [e.name for e in shared.model.network.convection_edges] == sorted(het["paths"])
    rb = np.atleast_1d(per.model.rbar_v)
    assert np.allclose(rb, [het["rbar_v"][e] for e in edges], rtol=1e-9)
    # the shared model reports a profile interval; the per-path ones take in the robust Wald
    # interval the misfit check computed, widened alike (measured 0.13 % apart at the top)
    wide = shared.intervals.intervals["rbar_v"]
    for e in edges:
        iv = per.intervals.intervals[f"rbar_v[{e}]"]
        assert iv.lower <= wide.lower * 1.01 and iv.upper >= wide.upper * 0.99
    assert any("estimation.per_path_p 0.2" in n and "Cochran's Q" in n for n in per.notes)
    # below the threshold's p nothing changes
    assert np.ndim(off.model.rbar_v) == 0
    assert off.intervals.intervals["rbar_v"].upper == pytest.approx(wide.upper)
