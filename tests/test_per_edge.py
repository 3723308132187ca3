"""`identify` with one R̄_v per air path (``EstimationOptions.per_edge``, ``--per-edge``).

The model takes the selection's per-path fit as it is (τ0 shared), with no refit: the same
edges as the shared default, its values those of the selection's per-path fit.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from thermctl.data import read_measurements
from thermctl.errors import DataError
from thermctl.identify import EstimationOptions, IdentifyOptions, identify
from thermctl.testbed import generate


@pytest.fixture(scope="module")
def runs():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate(days=10, seed=0)
        meas = read_measurements(tb.data, tb.spec, name="pe")
        out = {}
        for pe in (False, True):
            opt = IdentifyOptions(estimation=EstimationOptions(per_edge=pe, intervals="wald"))
            out[pe] = identify(meas, opt)
    return out


def test_the_model_carries_the_selections_per_path_values(runs):
    shared, per = runs[False], runs[True]
    edges = [e.name for e in per.model.network.convection_edges]
    assert edges == [e.name for e in shared.model.network.convection_edges] and edges
    rb = np.atleast_1d(per.model.rbar_v)
    assert rb.shape == (len(edges),)
    assert np.allclose(rb, [per.selection.per_edge[e] for e in edges], rtol=1e-12, atol=0)
    assert np.ndim(shared.model.rbar_v) == 0
    # C_v per path from one shared τ0 = R̄_v·C_v
    tau = rb * np.atleast_1d(per.model.c_v)
    assert np.allclose(tau, tau[0], rtol=1e-9)
    # the same search, without the shared refit at its end
    assert [st.edge for st in per.selection.path] == [st.edge for st in shared.selection.path]
    assert per.selection.n_fits == shared.selection.n_fits - 1
    # a per-path interval for every path, and no "shared value is a compromise" note
    assert {f"rbar_v[{e}]" for e in edges} <= set(per.intervals.intervals)
    assert not any("shared R̄_v is a compromise" in n for n in per.notes)


@pytest.mark.parametrize("est, match", [
    (EstimationOptions(per_edge="yes"), "estimation.per_edge"),
    (EstimationOptions(per_edge=None), "estimation.per_edge"),
    (EstimationOptions(per_edge=True, criterion="simulation"), "per_edge needs a Kalman"),
])
def test_per_edge_option_checks(est, match):
    with pytest.raises(DataError, match=match):
        IdentifyOptions(estimation=est).check()
