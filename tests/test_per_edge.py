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


def test_per_path_intervals_take_in_the_shared_models():
    """Where the misfit chose one R̄_v per path, each path's interval is widened to take in
    the shared model's, and its verdict recomputed: the finite-volume factor case (all
    factors, seed 1) had r240–r243 at 2.52e-4 [2.06e-4, 3.15e-4] "identified (within
    ±25 %)" for a truth of 3.36e-4; the shared interval was [1.73e-4, 6.9e-4]."""
    from thermctl.estimate.likelihood.uncertainty import (IdentifiabilityReport,
                                                          ParameterInterval, _verdict)
    from thermctl.identify import _per_path_widen

    def iv(name, v, lo, hi):
        return ParameterInterval(name, v, lo, hi, 0.9, "profile", "K/(W m)")
    ints = {"rbar_v[air:r240-r243]": iv("rbar_v[air:r240-r243]", 2.52e-4, 2.06e-4, 3.15e-4),
            "rbar_v[air:r241-r244]": iv("rbar_v[air:r241-r244]", 9.87e-4, 3.03e-4, 1e-2),
            "tau0": ParameterInterval("tau0", 2.03, 0.416, 2.03, 0.9, "profile", "s/m")}
    ida = IdentifiabilityReport(ints, {}, [], {k: _verdict(v, None) for k, v in ints.items()},
                                0.9)
    assert ida.verdicts["rbar_v[air:r240-r243]"].endswith("identified (within ±25 %).")
    tau_verdict = ida.verdicts["tau0"]
    notes = []
    _per_path_widen(ida, iv("rbar_v", 3.45e-4, 1.73e-4, 6.9e-4), notes)
    a = ida.intervals["rbar_v[air:r240-r243]"]
    assert (a.lower, a.upper, a.value) == (1.73e-4, 6.9e-4, 2.52e-4) and a.covers(3.36e-4)
    v = ida.verdicts["rbar_v[air:r240-r243]"]
    assert "within a factor 4.0: not identified to a useful precision" in v
    assert "shared R̄_v's interval [0.000173, 0.00069]" in v and v.endswith(".")
    b = ida.intervals["rbar_v[air:r241-r244]"]
    assert (b.lower, b.upper) == (1.73e-4, 1e-2)           # only ever widened
    assert ida.verdicts["tau0"] == tau_verdict and ida.intervals["tau0"].lower == 0.416
    assert len(notes) == 1 and "far from white" in notes[0]
    _per_path_widen(None, ints["tau0"], notes)              # no intervals: nothing to do
    assert len(notes) == 1


def test_widening_keeps_what_the_calibration_length_and_the_bounds_say():
    """A widened interval keeps a short-calibration verdict, and a side that moves out to a
    search bound (open) is open: "bounded ... only", not "identified"."""
    from thermctl.estimate.likelihood.uncertainty import (IdentifiabilityReport,
                                                          ParameterInterval, _verdict)
    iv = ParameterInterval("rbar_v[air:a-b]", 3e-4, 2.7e-4, 3.3e-4, 0.9, "profile", "K/(W m)")
    short = IdentifiabilityReport({iv.name: iv}, {}, [], {iv.name: "not identified — 1.5 "
                                                          "calibration day(s)"}, 0.9)
    short.short_calibration_days = 1.5
    short.widen(iv.name, 2.5e-4, 3.5e-4, "widened")
    assert short.verdicts[iv.name].startswith("not identified — 1.5")
    iv = ParameterInterval("rbar_v[air:a-b]", 3e-4, 2.7e-4, 3.3e-4, 0.9, "profile", "K/(W m)")
    rep = IdentifiabilityReport({iv.name: iv}, {}, [], {iv.name: _verdict(iv, None)}, 0.9)
    rep.widen(iv.name, 1e-6, 3.2e-4, "widened", closed=(False, True))
    assert (iv.lower, iv.upper, iv.closed_lower, iv.closed_upper) == (1e-6, 3.3e-4, False, True)
    assert "bounded above only" in rep.verdicts[iv.name]
