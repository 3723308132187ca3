"""do-mpc models out: the do-mpc model's right-hand side is thermctl's, the linear model is
the exported state space, and a do-mpc MPC on the testbed building keeps the zones in their
band where the open loop leaves it."""

from __future__ import annotations

import sys
import warnings

import casadi as ca
import numpy as np
import pytest

do_mpc = pytest.importorskip("do_mpc")

from thermctl.errors import ModelError  # noqa: E402
from thermctl.export import disturbances, export_point, statespace, to_do_mpc  # noqa: E402
from thermctl.model import ThermalModel  # noqa: E402
from thermctl.network import ThermalNetwork  # noqa: E402
from thermctl.testbed.buildings import pugh_hall_spec  # noqa: E402

GREYBOX = {"params": {"aperture[r240,south]": 2.0, "gain[r241,const]": 150.0,
                      "gain[r243,occupied]": 80.0}}
OP = {"ms": {"*": 0.06, "hallway": 0.0}, "Ts": 28.0, "T": {"*": 21.0, "outside": -5.0}}


@pytest.fixture(scope="module")
def pugh():
    spec, edges = pugh_hall_spec()
    model = ThermalModel(ThermalNetwork(spec, edges), 3.36e-4, 1.19e3, meta={"greybox": GREYBOX})
    point = export_point(model, OP)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)    # do-mpc's numpy notice
        dm = to_do_mpc(model, point)
    return model, point, dm


def _random_point(rng, dm):
    x = rng.uniform(10.0, 30.0, len(dm.states))
    u = {n: rng.uniform(0.0, 0.3) if n.startswith("ms") else rng.uniform(12.0, 35.0)
         for n in dm.inputs}
    w = {}
    for n in dm.tvp:
        lo, hi = {"T": (-5.0, 30.0), "Q": (-200.0, 500.0), "solar": (0.0, 800.0),
                  "gain": (0.0, 1.0)}[n.partition("[")[0]]
        w[n] = rng.uniform(lo, hi)
    return x, u, w


def _rhs(m, x, u, w, names_u, names_w):
    return np.asarray(m._rhs_fun(x, [u[n] for n in names_u], m._z(0), [w[n] for n in names_w],
                                 m._p(0), m._w(0))).ravel()


def test_names_and_variables(pugh):
    model, _, dm = pugh
    net = model.network
    assert dm.states == net.state_names and dm.model.n_x == net.n_states == 55
    assert dm.inputs == [f"ms[{z}]" for z in net.spec.measured_zones] + \
        [f"Ts[{z}]" for z in net.spec.measured_zones]           # no supply to the hallway
    assert dm.tvp[:6] == ["T[outside]", "T[r200]", "T[r210]", "T[r230]", "T[r248]", "T[corridor]"]
    assert dm.tvp[-3:] == ["solar[south]", "gain[const]", "gain[occupied]"]
    named = lambda struct: [k for k in struct.keys() if k != "default"]  # noqa: E731 (do-mpc's size-0 slot)
    assert named(dm.model.x) == dm.states and named(dm.model.u) == dm.inputs
    assert named(dm.model.tvp) == dm.tvp and dm.model.n_u == 12 and dm.model.n_tvp == 16


def test_bilinear_rhs_is_thermctls(pugh):
    """At random states, flows, temperatures, gains: do-mpc's f = thermctl's affine form
    (sparse numeric matrices, a separate code path from the CasADi one) + E d."""
    model, _, dm = pugh
    net = model.network
    E = disturbances(model).E
    rng = np.random.default_rng(0)
    for _ in range(5):
        x, u, w = _random_point(rng, dm)
        full = {**{n: 0.0 for n in net.input_names}, **u, **{n: w[n] for n in net.input_names
                                                              if n in w}}
        A_u, b_u = model.affine(np.array([full[n] for n in net.input_names]))
        d = np.array([w[n] for n in disturbances(model).names])
        ref = A_u @ x + b_u + E @ d
        got = _rhs(dm.model, x, u, w, dm.inputs, dm.tvp)
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_linear_model_is_the_exported_statespace(pugh):
    """The LinearModel's rhs at random deviations = the python-control export's A, B."""
    model, point, dm = pugh
    sys_, _ = statespace(model, point.op)
    rng = np.random.default_rng(1)
    x, u, w = _random_point(rng, dm)
    col = {n: i for i, n in enumerate(sys_.input_labels)}
    du = np.zeros(sys_.ninputs)
    for n, v in {**u, **w}.items():
        du[col[n]] = v
    ref = sys_.A @ x + sys_.B @ du
    got = _rhs(dm.linear, x, u, w, dm.inputs, dm.tvp)
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    np.testing.assert_allclose(dm.linear.sys_A, sys_.A, rtol=1e-12, atol=0)
    assert dm.x_op["T[r240]"] == pytest.approx(point.op.x[0], rel=1e-15)
    assert dm.u_op["ms[r240]"] == 0.06 and dm.tvp_op["T[outside]"] == -5.0


def test_mpc_keeps_the_zones_in_their_band(pugh):
    """Six 10-min steps of a do-mpc MPC (bilinear model, collocation) on the do-mpc
    simulator, outside at −8 °C: every office stays at or above 21 °C, while with the boxes
    off the same start falls below it."""
    model, _, dm = pugh
    m = dm.model
    zones = model.network.spec.measured_zones
    fed = [n for n in dm.inputs if n.startswith("ms[")]
    weather = {"T[outside]": -8.0, "solar[south]": lambda t: 0.0, "gain[const]": 1.0}
    x0 = model.operating_point(ms={"*": 0.06, "hallway": 0.0}, Ts=26.5,
                               T={"*": 21.0, "outside": -5.0}).x
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        mpc = do_mpc.controller.MPC(m)
        mpc.set_param(n_horizon=6, t_step=600.0, store_full_solution=False,
                      nlpsol_opts={"ipopt.print_level": 0, "print_time": 0, "ipopt.sb": "yes"})
        comfort = sum((m.x[f"T[{z}]"] - 22.0) ** 2 for z in zones)
        mpc.set_objective(lterm=sum(m.u[n] for n in fed) + 1e-3 * comfort, mterm=ca.DM(0.0))
        mpc.set_rterm(**{n: 1e-2 for n in fed})
        for n in dm.inputs:
            lo, hi = (0.0, 0.3) if n.startswith("ms") else (12.0, 40.0)
            mpc.bounds["lower", "_u", n], mpc.bounds["upper", "_u", n] = lo, hi
        for z in zones:
            mpc.bounds["lower", "_x", f"T[{z}]"], mpc.bounds["upper", "_x", f"T[{z}]"] = 21.0, 25.0
        mpc.set_tvp_fun(dm.tvp_fun(mpc, weather))
        mpc.setup()
        sims = []
        for _ in range(2):
            sim = do_mpc.simulator.Simulator(m)
            sim.set_param(t_step=600.0)
            sim.set_tvp_fun(dm.tvp_fun(sim, weather))
            sim.setup()
            sim.x0 = x0
            sims.append(sim)
        mpc.x0 = x0
        mpc.u0 = np.array([dm.u_op[n] for n in dm.inputs])
        mpc.set_initial_guess()
        closed, opened, flows = [], [], []
        x = x0
        off = np.array([0.0] * len(fed) + [26.5] * len(fed))[:, None]
        for _ in range(6):
            u = mpc.make_step(x)
            assert mpc.solver_stats["success"], mpc.solver_stats["return_status"]
            x = sims[0].make_step(u)
            closed.append(x[:len(zones)].ravel())
            opened.append(sims[1].make_step(off)[:len(zones)].ravel())
            flows.append(u[:len(fed)].ravel())
    closed, opened = np.array(closed), np.array(opened)
    # 0.01 K: the MPC's collocation against the simulator's CVODES on the same model
    assert closed.min() >= 21.0 - 0.01 and closed.max() <= 25.0 + 0.01
    assert opened.min() < 20.6                    # the band binds: the boxes must heat
    assert np.max(flows) > 1e-3


def test_errors(pugh, monkeypatch):
    model, point, _ = pugh
    with pytest.raises(ModelError, match=r"supply_zones: \['r999'\] are not zones"):
        to_do_mpc(model, supply_zones=["r999"])
    with pytest.raises(ModelError, match=r"op: supply flow at zone\(s\) \['r241', .*'r247'\], "
                                         r"which are not supply_zones \['r240'\]"):
        to_do_mpc(model, point.op, supply_zones=["r240"])
    monkeypatch.setitem(sys.modules, "do_mpc", None)
    with pytest.raises(ImportError, match=r"needs do-mpc: pip install 'thermctl\[do-mpc\]'"):
        to_do_mpc(model)


def test_docs_snippet_runs(docs_snippets):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)    # do-mpc's numpy notice
        ns = docs_snippets("do-mpc.md")
    assert ns["x"][:6].min() > 21.0 - 0.01
