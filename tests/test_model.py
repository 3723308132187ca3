"""ThermalModel against analytical answers and independent reference computations.

References are built here without the code under test: state matrices assembled by hand
from the edges (``reference_linear_system`` in conftest), ``scipy.linalg.expm`` of the
augmented affine system, steady states solved by hand, ``control.c2d``.
"""

from __future__ import annotations

import control as ct
import numpy as np
import pytest
import scipy.linalg as sla

from thermctl import rc
from thermctl.errors import ModelError, SpecWarning
from thermctl.model import (C_V_PAPER, RBAR_V_PAPER, OperatingPoint, ThermalModel, make_stepper,
                            zoh)
from thermctl.network import ThermalNetwork
from thermctl.spec import load_spec, spec_from_dict

CP = 1006.0 + 1860.0 * 0.0074  # [J/(kg K)], the paper's supply humidity ratio
T_BOUNDARY = {"outside": -5.0, "ground": 8.0}


# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------
def _one_zone_spec(wall, boundary=("outside",), volume=40.0):
    return spec_from_dict({"zones": {"z": {"volume": volume}}, "boundary": list(boundary),
                           "walls": wall}, source="one-zone.yaml")


def _closed_spec():
    """Three zones, walls only between zones, no boundary node (energy is conserved)."""
    data = {"zones": {"a": {"volume": 30.0}, "b": {"volume": 50.0, "capacitance": 2.0e5},
                      "c": {"volume": 20.0}},
            "boundary": [],
            "walls": [{"between": ["a", "b"], "R": [0.02, 0.05, 0.03], "C": [3e5, 2e5]},
                      {"between": ["b", "c"], "area": 9.0, "u_value": 1.5,
                       "heat_capacity": 6e4}],
            "distances": [{"between": ["a", "c"], "d": 6.0}]}
    with pytest.warns(SpecWarning, match="no wall path to any boundary node"):
        return spec_from_dict(data, source="closed.yaml")


def _affine_reference(A, Bt, cap, u, net):
    """Constant term b of xdot = A x + b for input u, by hand (A already includes the flow)."""
    sl = net.input_slices()
    nz = net.n_zones
    b = Bt @ u[sl["T"]]
    b[:nz] += (u[sl["ms"]] * CP * u[sl["Ts"]] + u[sl["Q"]]) / cap[:nz]
    return b


def _expm_trajectory(A, b, x0, times):
    """x(t) of xdot = A x + b (b constant) by the exponential of the augmented matrix."""
    n = len(x0)
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n] = A, b
    return np.array([(sla.expm(M * t) @ np.r_[x0, 1.0])[:n] for t in times])


@pytest.fixture
def constant_flow_case(small_model, reference_linear_system):
    """Small building, constant supply flow, zones off equilibrium: (model, U, x0, dt, X_ref)."""
    net = small_model.network
    ms = np.array([0.05, 0.03, 0.04, 0.0])
    u = net.input_vector(ms=dict(zip(net.zones, ms)), Ts=14.0, T=T_BOUNDARY, Q={"r2": 300.0})
    A, Bt, cap = reference_linear_system(net, RBAR_V_PAPER, C_V_PAPER, ms)
    b = _affine_reference(A, Bt, cap, u, net)
    x0 = small_model.initial_state([21.0, 22.0, 20.0, np.nan], [-5.0, 8.0])
    x0[:3] += [2.0, -1.0, 3.0]  # zones off their walls' mean: excites the fast modes
    dt, n_steps = 300.0, 12
    X_ref = _expm_trajectory(A, b, x0, dt * np.arange(n_steps + 1))
    scale = np.ptp(np.r_[x0, 14.0, -5.0, 8.0])  # the temperature differences at play [K]
    return small_model, np.tile(u, (n_steps, 1)), x0, dt, X_ref, scale


# ---------------------------------------------------------------------------------------------
# parameters and matrices
# ---------------------------------------------------------------------------------------------
def test_parameter_vector_layout(small_spec):
    net = ThermalNetwork(small_spec, [("r1", "r3"), ("r2", "r3")])
    model = ThermalModel(net, rbar_v=[3e-4, 5e-4], c_v=2000.0)
    np.testing.assert_array_equal(model.p, [3e-4, 5e-4, 2000.0, 2000.0])
    np.testing.assert_array_equal(model.expand(1e-4, [10.0, 20.0]), [1e-4, 1e-4, 10.0, 20.0])
    assert model.to_casadi().param_names == ["rbar_v[air:r1-r3]", "rbar_v[air:r2-r3]",
                                             "c_v[air:r1-r3]", "c_v[air:r2-r3]"]
    assert ThermalModel(net.conduction_only()).p.shape == (0,)


def test_matrices_match_hand_assembly(small_model, reference_linear_system):
    A, Bt = small_model.matrices()
    A_ref, Bt_ref, cap = reference_linear_system(small_model.network, RBAR_V_PAPER, C_V_PAPER)
    np.testing.assert_allclose(A.toarray(), A_ref, rtol=1e-13, atol=1e-18)
    np.testing.assert_allclose(Bt.toarray(), Bt_ref, rtol=1e-13, atol=1e-18)
    np.testing.assert_allclose(small_model.capacitances(), cap, rtol=1e-14)
    # and at other parameters, passed as p
    p = small_model.expand(1e-3, 4e3)
    A2, _ = small_model.matrices(p)
    np.testing.assert_allclose(A2.toarray(), reference_linear_system(small_model.network, 1e-3,
                                                                     4e3)[0], rtol=1e-13)


def test_affine_matches_hand_assembly(small_model, reference_linear_system):
    net = small_model.network
    ms = np.array([0.1, 0.0, 0.02, 0.05])
    u = net.input_vector(ms=dict(zip(net.zones, ms)), Ts={"r1": 30.0, "r3": 12.0},
                         T=T_BOUNDARY, Q={"r1": 100.0, "hallway": -40.0})
    A_u, b_u = small_model.affine(u)
    A_ref, Bt, cap = reference_linear_system(net, RBAR_V_PAPER, C_V_PAPER, ms)
    np.testing.assert_allclose(A_u.toarray(), A_ref, rtol=1e-13, atol=1e-18)
    np.testing.assert_allclose(b_u, _affine_reference(A_ref, Bt, cap, u, net), rtol=1e-13)


def test_capacity_multiplier_default_is_air_only(small_model):
    cap = small_model.capacitances()
    np.testing.assert_allclose(cap[[0, 1, 3]], 1.2 * CP * np.array([60.0, 45.0, 120.0]),
                               rtol=1e-14)
    assert cap[2] == 5.0e5


@pytest.mark.parametrize("rbar_v, c_v", [((RBAR_V_PAPER, RBAR_V_PAPER), (C_V_PAPER, C_V_PAPER)),
                                         ((3e-4, 2e-3), (1e3, 250.0))],
                         ids=["paper-shared", "per-edge"])
def test_convection_edge_time_constant(small_spec, rbar_v, c_v):
    net = ThermalNetwork(small_spec, [("r1", "r3"), ("r2", "r3")])
    model = ThermalModel(net, rbar_v=list(rbar_v), c_v=list(c_v))
    A = model.matrices()[0].toarray()
    for k, e in enumerate(net.convection_edges):
        i = net.state_names.index(f"x[{e.name},1]")
        # with both end zones held fixed the edge is a 3R2C element, R = rbar_v d, C = c_v:
        R, C = rbar_v[k] * e.d, c_v[k]
        lam = np.sort(np.linalg.eigvals(A[i:i + 2, i:i + 2]).real)[::-1]
        np.testing.assert_allclose(lam, [-1 / (R * C), -3 / (R * C)], rtol=1e-12)
        tau = rc.time_constant([R] * 3, [C] * 2)
        np.testing.assert_allclose(tau, rbar_v[k] * e.d * c_v[k], rtol=1e-12)
        # time constant per metre is rbar_v c_v itself (what the paper bounds by t/alpha)
        np.testing.assert_allclose(tau / e.d, rbar_v[k] * c_v[k], rtol=1e-12)
        assert rc.alpha([R] * 3, [C] * 2) == pytest.approx(6.0, rel=1e-12)


# ---------------------------------------------------------------------------------------------
# steady states
# ---------------------------------------------------------------------------------------------
def test_single_wall_steady_heat_flow():
    R, C = (0.1, 0.3, 0.1), (1e5, 2e5)
    model = ThermalModel(ThermalNetwork(_one_zone_spec([{"between": ["z", "outside"],
                                                         "R": list(R), "C": list(C)}])))
    net = model.network
    Q, To = 40.0, 5.0
    u = net.input_vector(T=To, Q=Q)
    x = model.steady_state(u)
    Tz, s1, s2 = x
    # the heat input leaves through the wall: q = (Tz - To)/sum(R), linear profile
    np.testing.assert_allclose((Tz - To) / sum(R), Q, rtol=1e-12)
    np.testing.assert_allclose([Tz - s1, s1 - s2, s2 - To] / np.array(R), Q, rtol=1e-12)
    # the same from a long simulation (60 days, slowest time constant ~1.4 days)
    X = model.simulate(np.tile(u, (60, 1)), 86400.0, np.full(3, To))
    np.testing.assert_allclose(X[-1], x, rtol=1e-10)


def test_wall_chain_between_two_fixed_temperatures():
    Ra, Ca = (0.05, 0.2, 0.05), (4e5, 4e5)
    spec = _one_zone_spec([{"between": ["inside", "z"], "R": list(Ra), "C": list(Ca)},
                           {"between": ["z", "outside"], "area": 10.0, "u_value": 0.5,
                            "heat_capacity": 1e5}], boundary=("inside", "outside"))
    model = ThermalModel(ThermalNetwork(spec))
    Tin, Tout = 20.0, -10.0
    x = model.steady_state(model.network.input_vector(T={"inside": Tin, "outside": Tout}))
    R_sum = sum(Ra) + 1 / (0.5 * 10.0)
    q = (Tin - Tout) / R_sum  # one heat flow through all six resistors in series
    Rb = spec.walls[1].R
    nodes = [Tin, x[1], x[2], x[0], x[3], x[4], Tout]
    np.testing.assert_allclose(-np.diff(nodes) / np.r_[Ra, Rb], q, rtol=1e-12)
    np.testing.assert_allclose(x[0], Tin - q * sum(Ra), rtol=1e-12)


@pytest.mark.parametrize("ms, Ts, To, Q", [(0.0, 30.0, 0.0, 500.0), (0.02, 30.0, 0.0, 0.0),
                                           (0.2, 14.0, -8.0, 1500.0), (0.05, 35.0, 30.0, -200.0)],
                         ids=["no-supply", "heating", "cooling-with-gains", "hot-outside"])
def test_zone_steady_state_with_supply_air(ms, Ts, To, Q):
    spec = _one_zone_spec([{"between": ["z", "outside"], "area": 10.0, "u_value": 0.8,
                            "heat_capacity": 2e5}])
    model = ThermalModel(ThermalNetwork(spec))
    UA = 0.8 * 10.0  # [W/K]
    op = model.operating_point(ms=ms, Ts=Ts, T=To, Q=Q)
    expected = (ms * CP * Ts + UA * To + Q) / (ms * CP + UA)
    np.testing.assert_allclose(op.x[0], expected, rtol=1e-12)
    np.testing.assert_allclose(model.sym.f(op.x, op.u, model.p), 0.0, atol=1e-14)


def test_supply_air_pins_a_closed_network():
    model = ThermalModel(ThermalNetwork(_closed_spec(), [("a", "c")]))
    # supply air into one zone is the only link to a fixed temperature: everything goes to Ts
    x = model.steady_state(model.network.input_vector(ms={"b": 0.01}, Ts=17.0))
    np.testing.assert_allclose(x, 17.0, rtol=1e-12)


@pytest.mark.parametrize("Q", [0.0, 100.0], ids=["no-gain", "with-gain"])
def test_steady_state_needs_a_boundary_or_supply(Q):
    model = ThermalModel(ThermalNetwork(_closed_spec(), [("a", "c")]))
    u = model.network.input_vector(ms=0.0, Q={"a": Q})
    with pytest.raises(ModelError, match="no unique steady state"):
        model.steady_state(u)


# ---------------------------------------------------------------------------------------------
# energy conservation
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def closed_model():
    return ThermalModel(ThermalNetwork(_closed_spec(), [("a", "c")]))


@pytest.mark.parametrize("method, tol", [("exact", 1e-11), ("radau", 1e-12), ("cvodes", 1e-8)],
                         ids=["exact", "radau", "cvodes"])
def test_energy_conserved_without_boundary_or_supply(closed_model, method, tol):
    net = closed_model.network
    x0 = np.random.default_rng(3).uniform(10.0, 30.0, net.n_states)
    U = np.tile(net.input_vector(ms=0.0, Ts=50.0, Q=0.0), (24, 1))  # Ts must not leak in
    X = closed_model.simulate(U, 600.0, x0, method=method)
    cap = closed_model.capacitances()
    E = X @ cap
    assert np.ptp(X[-1]) < 0.5 * np.ptp(x0)  # heat did move
    # exact and radau conserve C^T x to rounding (C^T A = 0 and the rational step keeps every
    # linear invariant; measured 5e-13 for expm, 1e-14 for radau); cvodes to its 1e-10
    # tolerances (measured 3e-15)
    np.testing.assert_allclose(E, E[0], rtol=0, atol=tol * cap.sum() * np.ptp(x0))


@pytest.mark.parametrize("method", ["exact", "radau", "cvodes"])
def test_heat_input_adds_energy_at_rate_sum_q(closed_model, method):
    net = closed_model.network
    Q = {"a": 300.0, "b": -120.0, "c": 50.0}
    U = np.tile(net.input_vector(ms=0.0, Q=Q), (10, 1))
    x0 = np.full(net.n_states, 20.0)
    X = closed_model.simulate(U, 900.0, x0, method=method)
    cap = closed_model.capacitances()
    t = 900.0 * np.arange(11)
    np.testing.assert_allclose(X @ cap, x0 @ cap + 230.0 * t, rtol=1e-9)


def test_closed_network_relaxes_to_capacitance_weighted_mean(closed_model):
    net = closed_model.network
    x0 = np.random.default_rng(5).uniform(0.0, 40.0, net.n_states)
    cap = closed_model.capacitances()
    X = closed_model.simulate(np.tile(net.input_vector(), (20, 1)), 1e6, x0)
    np.testing.assert_allclose(X[-1], x0 @ cap / cap.sum(), rtol=1e-10)


# ---------------------------------------------------------------------------------------------
# simulation vs the matrix exponential
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("method, kw", [("exact", {}), ("cvodes", {}),
                                        ("radau", {"substeps": 64})],
                         ids=["exact", "cvodes", "radau-64"])
def test_constant_flow_simulation_vs_expm(constant_flow_case, method, kw):
    model, U, x0, dt, X_ref, scale = constant_flow_case
    X = model.simulate(U, dt, x0, method=method, **kw)
    assert np.max(np.abs(X - X_ref)) < 1e-6 * scale
    assert np.ptp(X[:, 0]) > 0.1  # something happened


def test_radau_converges_at_third_order(constant_flow_case):
    model, U, x0, dt, X_ref, scale = constant_flow_case
    substeps = [16, 32, 64, 128]
    err = [np.max(np.abs(model.simulate(U, dt, x0, method="radau", substeps=s) - X_ref))
           for s in substeps]
    order = np.log2(np.divide(err[:-1], err[1:]))
    # Radau IIA (2 stages) is order 3; h = 19 s ... 2.3 s against edge time constants of 1-5 s
    # is already in the asymptotic range here (measured orders 2.97-3.00).
    np.testing.assert_allclose(order, 3.0, atol=0.1)
    assert err[-1] < 1e-8 * scale


def test_time_varying_flow_vs_stepwise_expm(small_model, reference_linear_system):
    """Several flow patterns interleaved: checks the per-pattern stepper cache."""
    net = small_model.network
    rng = np.random.default_rng(11)
    patterns = [np.array([0.05, 0.0, 0.02, 0.0]), np.zeros(4), np.array([0.0, 0.1, 0.0, 0.03])]
    U, refs = [], []
    for k in range(15):
        ms = patterns[[0, 1, 2, 0, 2][k % 5]]
        u = net.input_vector(ms=dict(zip(net.zones, ms)), Ts=rng.uniform(12, 35),
                             T={"outside": rng.uniform(-10, 10), "ground": 8.0},
                             Q=dict(zip(net.zones, rng.uniform(0, 400, 4))))
        U.append(u)
    U = np.array(U)
    x = small_model.initial_state([21.0, 22.0, 20.0, np.nan], [0.0, 8.0])
    X_ref = [x]
    for u in U:
        A, Bt, cap = reference_linear_system(net, RBAR_V_PAPER, C_V_PAPER, u[:4])
        x = _expm_trajectory(A, _affine_reference(A, Bt, cap, u, net), x, [600.0])[0]
        X_ref.append(x)
    X_ref = np.array(X_ref)
    scale = np.ptp(np.r_[X_ref.ravel(), U[:, 4:10].ravel()])
    np.testing.assert_allclose(small_model.simulate(U, 600.0, X_ref[0]), X_ref, rtol=0,
                               atol=1e-9 * scale)
    np.testing.assert_allclose(small_model.simulate(U, 600.0, X_ref[0], method="cvodes"), X_ref,
                               rtol=0, atol=1e-6 * scale)
    np.testing.assert_allclose(small_model.simulate(U, 600.0, X_ref[0], method="radau",
                                                    substeps=100), X_ref, rtol=0,
                               atol=1e-6 * scale)
    # the default ("auto") is the exponential for a small model, Radau above the limit
    import thermctl.model as M
    exact = small_model.simulate(U, 600.0, X_ref[0], method="exact")
    assert np.array_equal(small_model.simulate(U, 600.0, X_ref[0]), exact)
    M.SIMULATE_EXACT_STATES, keep = small_model.network.n_states - 1, M.SIMULATE_EXACT_STATES
    try:
        auto = small_model.simulate(U, 600.0, X_ref[0])
    finally:
        M.SIMULATE_EXACT_STATES = keep
    assert np.array_equal(auto, small_model.simulate(U, 600.0, X_ref[0], method="radau"))
    assert not np.array_equal(auto, exact)


def test_make_stepper_and_zoh(small_model):
    A_u, b = small_model.affine(small_model.network.input_vector(ms=0.05, Ts=16.0, T=0.0))
    Phi, Gamma = zoh(A_u, 300.0)
    Ad = A_u.toarray()
    np.testing.assert_allclose(Phi, sla.expm(Ad * 300.0), rtol=1e-12, atol=1e-15)
    # Gamma = A^-1 (Phi - I) for invertible A
    np.testing.assert_allclose(Gamma, np.linalg.solve(Ad, Phi - np.eye(len(b))), rtol=1e-8,
                               atol=1e-10)
    x = np.linspace(5.0, 25.0, len(b))
    exact = make_stepper(A_u, 300.0, "exact")(x, b)
    rad = make_stepper(A_u, 300.0, "radau", substeps=300)(x, b)
    np.testing.assert_allclose(rad, exact, atol=1e-7)


@pytest.mark.parametrize("m", [3, 40])      # fewer inputs than states, and more
def test_zoh_with_an_input_matrix_is_gamma_times_b(small_model, m):
    A_u, _ = small_model.affine(small_model.network.input_vector(ms=0.05, Ts=16.0, T=0.0))
    n = A_u.shape[0]
    B = np.random.default_rng(m).normal(size=(n, m))
    Phi, Gamma = zoh(A_u, 900.0)
    Phi_b, GB = zoh(A_u, 900.0, B)
    assert GB.shape == (n, m)
    np.testing.assert_allclose(Phi_b, Phi, rtol=1e-11, atol=1e-12)      # measured 1.6e-13
    np.testing.assert_allclose(GB, Gamma @ B, rtol=1e-9, atol=1e-11 * np.abs(Gamma @ B).max())


# ---------------------------------------------------------------------------------------------
# CasADi exports
# ---------------------------------------------------------------------------------------------
def _op(model, seed=0):
    """A non-equilibrium point with supply air everywhere (so the bilinear terms matter)."""
    net = model.network
    rng = np.random.default_rng(seed)
    u = net.input_vector(ms=dict(zip(net.zones, rng.uniform(0.01, 0.2, net.n_zones))),
                         Ts=dict(zip(net.zones, rng.uniform(12, 35, net.n_zones))),
                         T=dict(zip(net.boundary, rng.uniform(-10, 15, len(net.boundary)))),
                         Q=dict(zip(net.zones, rng.uniform(0, 500, net.n_zones))))
    return OperatingPoint(x=rng.uniform(10, 30, net.n_states), u=u)


def test_f_matches_hand_assembly(small_model, reference_linear_system):
    op = _op(small_model, seed=1)
    net = small_model.network
    A, Bt, cap = reference_linear_system(net, RBAR_V_PAPER, C_V_PAPER, op.u[:4])
    f = small_model.to_casadi().f
    np.testing.assert_allclose(np.asarray(f(op.x, op.u, small_model.p)).ravel(),
                               A @ op.x + _affine_reference(A, Bt, cap, op.u, net),
                               rtol=1e-12, atol=1e-15)


def test_jacobian_vs_central_differences(small_model):
    op = _op(small_model, seed=2)
    f = small_model.to_casadi().f
    p = small_model.p

    def fx(x, u):
        return np.asarray(f(x, u, p)).ravel()

    def central(fun, v, h):
        cols = []
        for i in range(len(v)):
            e = np.zeros_like(v)
            e[i] = h * max(1.0, abs(v[i]))
            cols.append((fun(v + e) - fun(v - e)) / (2 * e[i]))
        return np.array(cols).T

    Jx_fd = central(lambda x: fx(x, op.u), op.x, 1e-4)
    Ju_fd = central(lambda u: fx(op.x, u), op.u, 1e-4)
    sys = small_model.to_statespace(op)
    # f is affine in each single coordinate (bilinear only across ms and T, Ts), so central
    # differences have no truncation error: only rounding (~1e-12 of the entries).
    # Measured: 4e-13 and 1e-12 of the largest entry.
    np.testing.assert_allclose(sys.A, Jx_fd, rtol=1e-7, atol=1e-10 * np.abs(Jx_fd).max())
    np.testing.assert_allclose(sys.B, Ju_fd, rtol=1e-7, atol=1e-10 * np.abs(Ju_fd).max())


def test_statespace_analytic_linearization(small_model, reference_linear_system):
    op = _op(small_model, seed=4)
    net = small_model.network
    sys = small_model.to_statespace(op)
    nz, sl = net.n_zones, net.input_slices()
    ms, Ts, Q = op.u[sl["ms"]], op.u[sl["Ts"]], op.u[sl["Q"]]
    A, Bt, cap = reference_linear_system(net, RBAR_V_PAPER, C_V_PAPER, ms)
    np.testing.assert_allclose(sys.A, A, rtol=1e-12, atol=1e-18)
    Cz = cap[:nz]
    B = np.zeros((net.n_states, net.n_inputs))
    B[:nz, sl["ms"]] = np.diag(CP * (Ts - op.x[:nz]) / Cz)  # d/dms of ms cp (Ts - T) / C
    B[:nz, sl["Ts"]] = np.diag(ms * CP / Cz)
    B[:, sl["T"]] = Bt
    B[:nz, sl["Q"]] = np.diag(1 / Cz)
    np.testing.assert_allclose(sys.B, B, rtol=1e-12, atol=1e-18)
    np.testing.assert_array_equal(sys.C, np.eye(net.n_states)[:nz])
    np.testing.assert_array_equal(sys.D, 0.0)
    assert sys.dt == 0 and sys.name == "small"


def test_statespace_signal_names(small_model):
    sys = small_model.to_statespace(small_model.operating_point(ms=0.05, Ts=14.0, T=T_BOUNDARY))
    zones = ["r1", "r2", "r3", "hallway"]
    edges = ["r1-ext", "r1-window", "r2-outside", "r3-outside", "r1-hallway", "r2-hallway",
             "r3-hallway", "r1-r2", "hallway-ground", "air:r1-r3"]
    assert sys.state_labels == [f"T[{z}]" for z in zones] + [
        f"x[{e},{k}]" for e in edges for k in (1, 2)]
    assert sys.input_labels == ([f"ms[{z}]" for z in zones] + [f"Ts[{z}]" for z in zones]
                                + ["T[outside]", "T[ground]"] + [f"Q[{z}]" for z in zones])
    assert sys.output_labels == [f"T[{z}]" for z in zones]
    assert (sys.nstates, sys.ninputs, sys.noutputs) == (24, 14, 4)
    cm = small_model.to_casadi()
    assert cm.state_names == sys.state_labels and cm.input_names == sys.input_labels
    assert cm.f.name_in() == ["x", "u", "p"] and cm.F.name_in() == ["x", "u", "p", "dt"]


SPEC_CASES = ["small-conduction-only", "small-one-edge", "small-all-distances",
              "small-x5-capacity", "twinhouse-conduction-only", "twinhouse-all-distances"]
OP_CASES = {"no-flow": dict(ms=0.0, Ts=20.0, T=5.0),
            "ventilated": dict(ms=0.05, Ts=14.0, T=-5.0, Q=200.0),
            "strong-hot-supply": dict(ms=0.5, Ts=40.0, T=30.0, Q=1000.0)}


def _network(case, request):
    if case.startswith("twinhouse"):
        spec = load_spec(request.getfixturevalue("twinhouse_spec_path"))
    else:
        d = request.getfixturevalue("small_spec_dict")
        if case == "small-x5-capacity":
            d["capacity_multiplier"] = 5
        spec = spec_from_dict(d)
    pairs = {"conduction-only": [], "one-edge": [("r1", "r3")]}.get(
        case.split("-", 1)[1], [(dd.a, dd.b) for dd in spec.distances])
    return ThermalNetwork(spec, pairs)


@pytest.mark.parametrize("op_case", list(OP_CASES))
@pytest.mark.parametrize("case", SPEC_CASES)
def test_linearization_is_stable(case, op_case, request):
    net = _network(case, request)
    model = ThermalModel(net)
    sys = model.to_statespace(model.operating_point(**OP_CASES[op_case]))
    ev = np.linalg.eigvals(sys.A)
    assert ev.real.max() < 0
    # C^(1/2) A C^(-1/2) is symmetric (reciprocal conductances, diagonal supply term):
    # the spectrum is real
    assert np.abs(ev.imag).max() <= 1e-8 * np.abs(ev.real).max()
    cap = model.capacitances()
    S = np.sqrt(cap)[:, None] * sys.A / np.sqrt(cap)[None, :]
    np.testing.assert_allclose(S, S.T, rtol=1e-10, atol=1e-12 * np.abs(S).max())


def test_discrete_statespace_matches_c2d(small_model):
    op = small_model.operating_point(ms=0.05, Ts=14.0, T=T_BOUNDARY, Q=100.0)
    sys_c = small_model.to_statespace(op)
    sys_d = small_model.to_statespace(op, dt=300.0)
    ref = ct.c2d(sys_c, 300.0, method="zoh")
    assert sys_d.dt == 300.0
    np.testing.assert_allclose(sys_d.A, ref.A, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(sys_d.B, ref.B, rtol=1e-10, atol=1e-13)
    np.testing.assert_array_equal(sys_d.C, ref.C)
    np.testing.assert_array_equal(sys_d.D, ref.D)
    assert sys_d.state_labels == sys_c.state_labels and sys_d.input_labels == sys_c.input_labels
    # same DC gain: ZOH discretisation keeps the steady state
    np.testing.assert_allclose(ct.dcgain(sys_d), ct.dcgain(sys_c), rtol=1e-7, atol=1e-12)


def test_casadi_step_converges_to_exact_step(constant_flow_case):
    model, U, x0, dt, X_ref, scale = constant_flow_case
    p = model.p
    err = []
    for s in (1, 2, 4, 8, 16, 32):
        F = model.to_casadi(substeps=s).F
        err.append(np.max(np.abs(np.asarray(F(x0, U[0], p, dt)).ravel() - X_ref[1])))
    assert all(e1 > e2 for e1, e2 in zip(err[:-1], err[1:]))
    # third order once h is below the edge time constants
    np.testing.assert_allclose(np.log2(err[-2] / err[-1]), 3.0, atol=0.1)
    assert err[-1] < 1e-5 * scale
    # L-stable: one 300-s step over 1-s edge modes stays bounded
    assert err[0] < scale


def test_casadi_step_keeps_steady_state(small_model):
    u = small_model.network.input_vector(ms=0.08, Ts=15.0, T=T_BOUNDARY, Q=50.0)
    xs = small_model.steady_state(u)
    F = small_model.to_casadi(substeps=3).F
    np.testing.assert_allclose(np.asarray(F(xs, u, small_model.p, 300.0)).ravel(), xs,
                               rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# initial state
# ---------------------------------------------------------------------------------------------
def test_initial_state_rules(small_model):
    net = small_model.network
    Tz, Tb = np.array([21.0, 23.0, 19.0, np.nan]), np.array([-5.0, 8.0])
    x = small_model.initial_state(Tz, Tb)
    hall = (21.0 + 23.0 + 19.0) / 3  # its measured zone neighbours r1, r2, r3 (not ground)
    node = {"r1": 21.0, "r2": 23.0, "r3": 19.0, "hallway": hall, "outside": -5.0, "ground": 8.0}
    np.testing.assert_allclose(x[:4], [21.0, 23.0, 19.0, hall], rtol=1e-15)
    for k, e in enumerate(net.edges):
        np.testing.assert_allclose(x[4 + 2 * k:6 + 2 * k], 0.5 * (node[e.a] + node[e.b]),
                                   rtol=1e-15, err_msg=e.name)
    assert np.isnan(Tz[3])  # input not modified


def test_initial_state_unmeasured_without_measured_neighbour(small_spec_dict):
    small_spec_dict["zones"]["store"] = {"volume": 10.0, "measured": False}
    small_spec_dict["zones"]["r3"]["measured"] = False
    small_spec_dict["walls"].append({"between": ["store", "ground"], "R": [1, 1, 1],
                                     "C": [1e4, 1e4]})
    net = ThermalNetwork(spec_from_dict(small_spec_dict), [("r1", "r3")])
    x = ThermalModel(net).initial_state([20.0, 24.0, np.nan, np.nan, np.nan], [0.0, 10.0])
    # r3: measured neighbour r1 only (hallway is unmeasured); hallway: r1, r2;
    # store: none (only ground) -> mean of all measured zones
    np.testing.assert_allclose(x[:5], [20.0, 24.0, 20.0, 22.0, 22.0], rtol=1e-15)
    store_edge = net.state_names.index("x[store-ground,1]")
    np.testing.assert_allclose(x[store_edge:store_edge + 2], 16.0, rtol=1e-15)


# ---------------------------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------------------------
def _zeros(model, n=3):
    return np.zeros((n, model.network.n_inputs)), np.zeros(model.network.n_states)


MODEL_ERRORS = [
    ("U-width", lambda m: m.simulate(np.zeros((3, 13)), 60.0, _zeros(m)[1]),
     r"U: expected 14 input columns \(\['ms\[r1\]'.*\), found 13"),
    ("x0-shape", lambda m: m.simulate(_zeros(m)[0], 60.0, np.zeros(23)),
     r"x0: expected shape \(24,\), found \(23,\)"),
    ("x0-2d", lambda m: m.simulate(_zeros(m)[0], 60.0, np.zeros((1, 24))),
     r"x0: expected shape \(24,\), found \(1, 24\)"),
    ("dt-zero", lambda m: m.simulate(*_zeros(m)[:1], 0.0, _zeros(m)[1]),
     r"dt must be > 0 \[s\], found 0\.0"),
    ("bad-method", lambda m: m.simulate(_zeros(m)[0], 60.0, _zeros(m)[1], method="euler"),
     r"method must be 'auto', 'exact', 'radau' or 'cvodes', found 'euler'"),
    ("stepper-bad-method", lambda m: make_stepper(np.eye(2), 60.0, method="cvodes"),
     r"method must be 'exact' or 'radau', found 'cvodes'"),
    ("rbar_v-zero", lambda m: ThermalModel(m.network, rbar_v=0.0).p,
     r"rbar_v must be finite and > 0 \[K/\(W m\)\], found \[0\.0\]"),
    ("rbar_v-negative", lambda m: ThermalModel(m.network, rbar_v=-1e-4).simulate(
        *_zeros(m)[:1], 60.0, _zeros(m)[1]), r"rbar_v must be finite and > 0"),
    ("c_v-nan", lambda m: m.expand(1e-4, np.nan), r"c_v must be finite and > 0 \[J/K\]"),
    ("rbar_v-per-edge-length", lambda m: m.expand([1e-4, 2e-4], 1e3),
     r"rbar_v: expected a scalar or 1 values \(one per convection edge\), found shape \(2,\)"),
    ("c_v-per-edge-length", lambda m: ThermalModel(m.network, c_v=[[1e3]]).p,
     r"c_v: expected a scalar or 1 values \(one per convection edge\), found shape \(1, 1\)"),
    ("statespace-dt", lambda m: m.to_statespace(m.operating_point(T=T_BOUNDARY), dt=-1.0),
     r"dt must be > 0 \[s\], found -1\.0"),
    ("initial-state-shape", lambda m: m.initial_state([20.0, 20.0, 20.0], [0.0, 0.0]),
     r"initial_state: expected 4 zone and 2 boundary temperatures"),
    ("initial-state-all-nan", lambda m: m.initial_state([np.nan] * 4, [0.0, 0.0]),
     r"initial_state: no zone temperature is known"),
]


@pytest.mark.parametrize("call, match", [c[1:] for c in MODEL_ERRORS],
                         ids=[c[0] for c in MODEL_ERRORS])
def test_model_errors(small_model, call, match):
    with pytest.raises(ModelError, match=match):
        call(small_model)


def test_explicit_p_is_validated(small_model):
    U, x0 = _zeros(small_model)
    with pytest.raises(ModelError, match="p"):
        small_model.simulate(U, 60.0, x0, p=np.ones(3))
