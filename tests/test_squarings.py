"""The likelihood's discretisation takes the squarings its own parameters need.

Oracles: scipy's matrix exponential and the modal formula of the process noise at
parameter values far apart, the graph made for the whole parameter box (what every
evaluation used before), and a fresh problem (the value at a point must not depend on
what was evaluated before it, or threads and serial runs would differ).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from thermctl.estimate.likelihood import LikelihoodOptions, LikelihoodProblem
from thermctl.estimate.likelihood import kalman
from thermctl.network import ThermalNetwork
from thermctl.spec import spec_from_dict

pytestmark = pytest.mark.filterwarnings("ignore::thermctl.errors.BoundWarning")


@pytest.fixture(scope="module")
def case():
    from conftest import SMALL_SPEC
    from test_greybox import simulate_self_consistent
    d = copy.deepcopy(SMALL_SPEC)
    d["capacity_multiplier"] = 5.0
    net = ThermalNetwork(spec_from_dict(d, source="small5.yaml"), convection=[("r2", "r3")])
    data, opts = simulate_self_consistent(net, days=2, seed=4)
    return net, data, opts


def _at(pb, rbar, tau=None):
    """``eta`` at R̄_v [K/(W m)] and τ0 (``"lower"``/``"upper"``: its bound; None: start)."""
    values = {"rbar_v": rbar}
    if tau is not None:
        p = pb.layout.params[pb.layout.index("tau0")]
        values["tau0"] = getattr(p, tau)
    return pb.layout.eta_from(values)


def _norm_dt(pb, eta):
    return np.abs(pb.matrices(eta)["A"]).sum(axis=0).max() * pb.data.dt


def test_squarings_follow_the_norm_of_A_not_the_box(case):
    net, data, opts = case
    pb = LikelihoodProblem(net, data, opts)
    eta = _at(pb, 3.36e-4)
    s = pb.squarings_at(eta)
    # the box's fastest corner (R̄_v at its lower bound) needs more than the paper's value
    assert s < pb.box_squarings
    # the fewest halvings that bring 1.1·‖A‖₁·dt to 1/4 or below
    nd = 1.1 * _norm_dt(pb, eta)
    assert nd / 2 ** s <= 0.25 < nd / 2 ** (s - 1)
    assert pb.squarings_at(_at(pb, 1e-6, "lower")) == pb.box_squarings
    # a shorter τ0 makes the convection edges' states faster: more halvings
    assert pb.squarings_at(_at(pb, 3.36e-4, "lower")) > pb.squarings_at(_at(pb, 3.36e-4, "upper"))


@pytest.mark.parametrize("rbar, tau", [(1e-6, "lower"), (3.36e-4, None), (3.36e-3, "upper")])
def test_discretisation_is_exact_at_its_own_squarings(case, rbar, tau):
    net, data, opts = case
    pb = LikelihoodProblem(net, data, opts)
    eta = _at(pb, rbar, tau)
    m = pb.matrices(eta)
    # scipy's expm of the input block and the modal formula of the process noise (the Van
    # Loan block at the whole step overflows: e^{+A dt} with edge states of seconds)
    Phi, Gam, Q = kalman.discretize_np(m["A"], m["B"], m["Sigma"], pb.data.dt)
    assert np.max(np.abs(m["Phi"] - Phi)) < 1e-12
    assert np.max(np.abs(m["Gamma"] - Gam)) < 1e-10 * np.max(np.abs(Gam))
    assert np.max(np.abs(m["Qd"] - Q)) < 1e-9 * np.max(np.abs(Q))


def test_value_and_gradient_match_the_box_graph_and_do_not_depend_on_history(case):
    net, data, opts = case
    pb = LikelihoodProblem(net, data, opts)
    eta = _at(pb, 3.36e-4)
    f, g = pb.nll_grad(eta)
    # the graph valid over the whole box, which IPOPT keeps using
    box = pb._graph()
    assert box.squarings == pb.box_squarings > pb.squarings_at(eta)
    fb, gb = box.nll_grad_buf(eta)
    assert abs(f - float(fb[0])) < 1e-10 * abs(f)
    assert np.max(np.abs(g - gb)) < 1e-7 * np.max(np.abs(g))
    # after points that take other graphs, the same point gives the same numbers, digit
    # for digit, as on a fresh problem that never left it
    for r, tau in ((1e-6, "lower"), (3.36e-3, "upper"), (3.36e-5, "lower")):
        pb.nll_grad(_at(pb, r, tau))
    f2, g2 = pb.nll_grad(eta)
    fresh = LikelihoodProblem(net, data, opts)
    f3, g3 = fresh.nll_grad(eta)
    assert f2 == f == f3
    assert np.array_equal(g2, g) and np.array_equal(g3, g)
    assert len(pb._graphs) >= 3
    # the blocks' contributions and their gradients come from the point's own graph too
    ids, parts = pb.block_nll(eta)
    assert abs(parts.sum() - f) < 1e-9 * abs(f)
    scores = pb.block_scores(eta)
    assert scores.shape == (len(ids), len(pb.layout))
    assert np.max(np.abs(scores.sum(axis=0) - g)) < 1e-8 * np.max(np.abs(g))
    pb.release_buffers()
    assert pb.nll(eta) == f


def test_threads_making_and_using_graphs_get_the_serial_numbers(case):
    # random points over the whole box, evaluated on three threads by a fresh problem that
    # makes its graphs as they are asked for: the serial problem's numbers, digit for digit
    from concurrent.futures import ThreadPoolExecutor
    net, data, opts = case
    pb = LikelihoodProblem(net, data, opts)
    lo, hi = pb.layout.bounds()
    rng = np.random.default_rng(0)
    etas = [lo + (hi - lo) * rng.uniform(size=len(lo)) for _ in range(24)]
    serial = [pb.nll_grad(e) for e in etas]
    assert len({pb.squarings_at(e) for e in etas}) >= 3
    other = LikelihoodProblem(net, data, opts)
    with ThreadPoolExecutor(3) as ex:
        threaded = list(ex.map(other.nll_grad, etas * 2))
    for (f, g), (f2, g2) in zip(serial * 2, threaded):
        assert f == f2 and np.array_equal(g, g2)
    assert sorted(other._graphs) == sorted(pb._graphs)
