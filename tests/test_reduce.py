"""Model reduction: balanced (truncation / DC-matching), structure-preserving, Kron, lumped.

Reference values are independent of the code under test: python-control/slycot for
Hankel singular values and singular perturbation, the CasADi Jacobian for the
linearization, hand-built conductance matrices for the lumped model, the analytical
slow subsystem for the two-time-scale limit.
"""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from thermctl.errors import ModelError, SpecWarning
from thermctl.model import OperatingPoint, ThermalModel
from thermctl.network import ThermalNetwork
from thermctl.reduce import (Reference, balanced_reduction, error_vs_order, flow_sweep,
                             hankel_singular_values, kron, load_reduction, lumped, structured)
from thermctl.reduce._lti import balance, prepare, symmetrizer
from thermctl.reduce.balanced import default_scales
from thermctl.reduce.network import linearize
from thermctl.spec import spec_from_dict

H = 3600.0


def corridor_spec(n_per_side: int, wall_c_scale: float = 1.0, name: str = "corridor"):
    """An office floor: ``n`` offices per side of an unmeasured corridor ``c``.

    Offices have a heavy exterior wall, a light wall to the corridor and partitions to
    their neighbours; the corridor has glazed end walls. Every other office on each side
    has an air path (door) to the corridor. ``wall_c_scale`` multiplies every wall's heat
    capacity (→ 0: walls become fast, the two-time-scale limit).
    """
    k = wall_c_scale
    zones = {"c": {"volume": 24.0 * n_per_side, "measured": False}}
    walls = [{"between": ["c", "outside"], "area": 9.0, "u_value": 1.2, "heat_capacity": 2e4 * k,
              "name": f"c-end{i}"} for i in (1, 2)]
    dist, conv = [], []
    for side in "NS":
        for i in range(n_per_side):
            z = f"{side}{i}"
            zones[z] = {"volume": 45.0}
            walls.append({"between": [z, "outside"], "area": 12.0, "u_value": 0.35,
                          "heat_capacity": 1.5e5 * k})
            walls.append({"between": [z, "c"], "area": 10.0, "u_value": 1.8, "heat_capacity": 2.5e4 * k})
            if i:
                walls.append({"between": [f"{side}{i - 1}", z], "area": 12.0, "u_value": 0.6,
                              "heat_capacity": 3e4 * k})
            dist.append({"between": [z, "c"], "d": 4.0})
            if i % 2 == 0:
                conv.append((z, "c"))
    spec = spec_from_dict({"name": name, "capacity_multiplier": 3, "zones": zones,
                           "boundary": ["outside"], "walls": walls, "distances": dist})
    return spec, conv


def corridor_model(n_per_side=3, **kw):
    spec, conv = corridor_spec(n_per_side, **kw)
    return ThermalModel(ThermalNetwork(spec, conv))


@pytest.fixture(scope="module")
def floor():
    """7 zones (3 offices per side + corridor), 51 states, design flow 0.05 kg/s per zone."""
    model = corridor_model(3)
    op = model.operating_point(ms=0.05, Ts=16.0, T=5.0, Q=200.0)
    return model, op


@pytest.fixture(scope="module")
def floor_ref(floor):
    model, op = floor
    return Reference(linearize(model, op), capacitances=model.capacitances())


def scaled(sys):
    su, sy = default_scales(sys.input_labels, sys.output_labels)
    return ct.ss(sys.A, sys.B * su, sys.C / sy[:, None], sys.D * su / sy[:, None])


def hinf_on_grid(G, Gr, omegas):
    """max σ_max(G(jω) - Gr(jω)) by python-control's own frequency response."""
    E = G.frequency_response(omegas).frdata - Gr.frequency_response(omegas).frdata  # (p, m, w)
    return max(np.linalg.norm(E[:, :, k], 2) for k in range(len(omegas)))


OMEGAS = np.concatenate([[0.0], np.logspace(-8, 0, 120)])


# ---- linearization and symmetric coordinates --------------------------------------------

def test_linearize_equals_casadi_jacobian(floor):
    model, op = floor
    a, b = linearize(model, op), model.to_statespace(op)
    np.testing.assert_allclose(a.A, b.A, rtol=0, atol=1e-12 * np.abs(b.A).max())
    np.testing.assert_allclose(a.B, b.B, rtol=0, atol=1e-12 * np.abs(b.B).max())
    assert a.state_labels == b.state_labels and a.input_labels == b.input_labels


def test_symmetrizer_recovers_capacitances(floor):
    model, op = floor
    s = symmetrizer(linearize(model, op).A)
    cap = model.capacitances()
    np.testing.assert_allclose(s ** 2 / (s ** 2).max(), cap / cap.max(), rtol=1e-9)
    assert symmetrizer(np.array([[-1.0, 2.0], [-1.0, -3.0]])) is None  # A_ij A_ji < 0


# ---- balanced: HSVs, DC matching, bound, full order, slycot, two time scales, c2d --------

def test_hsv_agree_with_python_control_and_general_path(floor):
    model, op = floor
    sys = linearize(model, op)
    ours = hankel_singular_values(model, op)
    # python-control's tail is sqrt of eigenvalues at rounding level: on some installs
    # slightly negative, so NaN (measured on a fresh venv: 2 of 51) — those are zeros
    theirs = np.sort(np.nan_to_num(np.real(ct.hankel_singular_values(scaled(sys))), nan=0.0))[::-1]
    big = theirs > 1e-4 * theirs[0]
    np.testing.assert_allclose(ours[big], theirs[big], rtol=1e-6)
    # python-control takes sqrt(eig(Wc·Wo)) of a non-symmetric product: small values only
    # agree in absolute terms, and its tail is rounding noise (measured: two values of
    # 1.5e-9·σ1 where ours are 0, with this machine's numpy/OpenBLAS)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-8 * theirs[0])
    # a similarity transform destroys the symmetric structure: the scipy Bartels-Stewart
    # path must give the same (similarity-invariant) values
    T = np.linalg.qr(np.random.default_rng(0).standard_normal((sys.nstates,) * 2))[0]
    rot = ct.ss(T @ sys.A @ T.T, T @ sys.B, sys.C @ T.T, sys.D, inputs=sys.input_labels,
                outputs=sys.output_labels)
    assert symmetrizer(rot.A) is None
    general = hankel_singular_values(rot)
    np.testing.assert_allclose(general[big], ours[big], rtol=1e-6)


def test_fast_eigen_path_matches_svd_path(floor):
    model, op = floor
    sys = scaled(linearize(model, op))
    lti = prepare(sys.A, sys.B, sys.C, sys.D, s=np.sqrt(model.capacitances()))
    acc, fast = balance(lti, accurate=True), balance(lti, accurate=False)
    k = fast.n_min
    np.testing.assert_allclose(fast.hsv[:k], acc.hsv[:k], rtol=1e-6)
    for r in (5, 13):  # orders that do not split a pair of equal HSVs (the floor is mirror-symmetric)
        a = ct.ss(*acc.reduce(r)[:4])
        f = ct.ss(*fast.reduce(r)[:4])
        assert hinf_on_grid(a, f, OMEGAS) < 1e-6 * hinf_on_grid(a, 0 * a, OMEGAS)


@pytest.mark.parametrize("r", [1, 7, 14], ids=["r1", "r7", "r14"])
def test_matchdc_keeps_dc_gain(floor, r):
    model, op = floor
    full = linearize(model, op)
    red = balanced_reduction(model, op, order=r)
    np.testing.assert_allclose(red.sys.dcgain(), full.dcgain(), rtol=1e-9,
                               atol=1e-9 * np.abs(full.dcgain()).max())
    trunc = balanced_reduction(model, op, order=r, method="truncate")
    assert np.abs(trunc.sys.dcgain() - full.dcgain()).max() > 1e-4 * np.abs(full.dcgain()).max()


@pytest.mark.parametrize("method", ["matchdc", "truncate"])
@pytest.mark.parametrize("r", [1, 4, 7, 14, 21], ids=lambda r: f"r{r}")
def test_hinf_error_below_a_priori_bound(floor, method, r):
    model, op = floor
    full = scaled(linearize(model, op))
    red = balanced_reduction(model, op, order=r, method=method)
    err = hinf_on_grid(full, scaled(red.sys), OMEGAS)
    assert err <= red.error_bound * (1 + 1e-9)
    assert red.error_bound == pytest.approx(2 * red.hsv[r:].sum(), rel=1e-12)
    # the bound is not vacuous: the error is within a factor 30 of it
    assert err > red.error_bound / 30


def test_full_order_gives_back_the_full_model():
    rng = np.random.default_rng(1)
    n = 6  # a random minimal stable system (continuous)
    A = -np.diag(rng.uniform(0.1, 3.0, n)) + 0.2 * rng.standard_normal((n, n))
    sys = ct.ss(A, rng.standard_normal((n, 2)), rng.standard_normal((3, n)), 0,
                inputs=["u1", "u2"], outputs=["y1", "y2", "y3"])
    for method in ("matchdc", "truncate"):
        red = balanced_reduction(sys, order=n, method=method)
        assert red.order == n and red.error_bound == 0.0
        scale = hinf_on_grid(sys, 0 * sys, OMEGAS)
        assert hinf_on_grid(sys, red.sys, OMEGAS) < 1e-10 * scale
        assert red.sys.input_labels == ["u1", "u2"]


def test_full_order_thermal_model_is_exact_to_rounding(floor):
    model, op = floor
    full = linearize(model, op)
    red = balanced_reduction(model, op, order=full.nstates)  # capped at the minimal order
    scale = hinf_on_grid(scaled(full), 0 * scaled(full), OMEGAS)
    assert hinf_on_grid(scaled(full), scaled(red.sys), OMEGAS) < 1e-7 * scale


@pytest.mark.parametrize("r", [3, 10], ids=["r3", "r10"])
def test_matchdc_equals_slycot_ab09nd(floor, r):
    model, op = floor
    full = scaled(linearize(model, op))
    ours = scaled(balanced_reduction(model, op, order=r).sys)
    theirs = ct.balanced_reduction(full, r, method="matchdc")
    assert theirs.nstates == r
    scale = hinf_on_grid(full, 0 * full, OMEGAS)
    assert hinf_on_grid(ours, theirs, OMEGAS) < 1e-6 * scale


def _slow_subsystem(model, op):
    """Zones only, each wall replaced by its series conductance (the ε → 0 limit), by hand."""
    net = model.network
    nz = net.n_zones
    zi = {z: i for i, z in enumerate(net.zones)}
    cp = net.spec.cp
    Kz = np.zeros((nz, nz))
    gb = np.zeros(nz)
    m = len(net.convection_edges)
    for e in net.edges:
        R = sum(e.R) if e.kind == "conduction" else 3 * model.rbar_v * e.d
        g = 1.0 / R
        ia, ib = zi.get(e.a), zi.get(e.b)
        for i in (ia, ib):
            if i is not None:
                Kz[i, i] += g
        if ia is not None and ib is not None:
            Kz[ia, ib] -= g
            Kz[ib, ia] -= g
        else:
            gb[ia if ia is not None else ib] += g
    Cz = model.capacitances()[:nz]
    sl = net.input_slices()
    ms, Ts, Tz = op.u[sl["ms"]], op.u[sl["Ts"]], op.x[:nz]
    A = -(Kz + np.diag(cp * ms)) / Cz[:, None]
    B = np.zeros((nz, net.n_inputs))
    i = np.arange(nz)
    B[i, sl["ms"].start + i] = cp * (Ts - Tz) / Cz
    B[i, sl["Ts"].start + i] = cp * ms / Cz
    B[:, sl["T"].start] = gb / Cz
    B[i, sl["Q"].start + i] = 1.0 / Cz
    assert m > 0
    return ct.ss(A, B, np.eye(nz), 0, inputs=net.input_names, outputs=net.output_names)


def test_two_time_scales_reduce_to_the_slow_part():
    """Walls (and air paths) ε times lighter: reductions to n_zones states → the slow model."""
    errs = {}
    for eps in (1e-2, 1e-3, 1e-4):
        model = corridor_model(2, wall_c_scale=eps)
        model.c_v = 1.19e3 * eps
        op = model.operating_point(ms=0.05, Ts=16.0, T=5.0, Q=200.0)
        nz = model.network.n_zones
        slow = scaled(_slow_subsystem(model, op))
        scale = hinf_on_grid(slow, 0 * slow, OMEGAS)
        hsv = hankel_singular_values(model, op)
        errs[eps] = {
            "balanced": hinf_on_grid(scaled(balanced_reduction(model, op, order=nz).sys), slow, OMEGAS) / scale,
            "structured": hinf_on_grid(scaled(structured(model, op, order=nz).sys), slow, OMEGAS) / scale,
            "lumped": hinf_on_grid(scaled(lumped(model, op).sys), slow, OMEGAS) / scale,
            "hsv_gap": hsv[nz] / hsv[0],
        }
    # structured with no edge mode is the Kron reduction of all edge states: the slow model
    # itself, for every ε
    assert max(e["structured"] for e in errs.values()) < 1e-12
    for key in ("balanced", "lumped", "hsv_gap"):
        assert errs[1e-4][key] < 2e-3, key
        # first order in ε: two decades of ε give (nearly) two decades of error
        assert errs[1e-2][key] / errs[1e-4][key] > 30, key


def test_reduce_then_c2d_matches_c2d_then_reduce(floor):
    model, op = floor
    nz = model.network.n_zones
    dt = 300.0
    full = linearize(model, op)
    r = 2 * nz + 1  # 14 would split a pair of equal HSVs
    a = balanced_reduction(model, op, order=r).to_statespace(dt=dt)    # reduce, then c2d
    b = balanced_reduction(linearize(model, op, dt=dt), order=r)      # c2d, then reduce
    assert b.sys.dt == dt and b.sys.input_labels == full.input_labels
    # both DC-matching, ZOH keeps DC: same static gain as the full model to rounding
    np.testing.assert_allclose(b.sys.dcgain(), full.dcgain(), rtol=1e-8, atol=1e-8 * np.abs(full.dcgain()).max())
    np.testing.assert_allclose(a.dcgain(), full.dcgain(), rtol=1e-8, atol=1e-8 * np.abs(full.dcgain()).max())
    su, _ = default_scales(full.input_labels, full.output_labels)
    T = np.arange(0, 24 * H + dt, dt)
    w = su[None, :, None]
    yf, ya, yb = (ct.step_response(s, T=T).outputs * w for s in (linearize(model, op, dt=dt), a, b.sys))
    for t in (1 * H, 6 * H, 24 * H):
        k = int(round(t / dt))
        big = np.abs(yf[:, :, k]).max()
        err_a, err_b = (np.abs(y[:, :, k] - yf[:, :, k]).max() / big for y in (ya, yb))
        diff = np.abs(ya[:, :, k] - yb[:, :, k]).max() / big
        # measured at 1/6/24 h: errors 1.1/0.49/0.10 % and 1.3/0.51/0.10 %, difference
        # 0.19/0.02/0.01 %: the order of c2d and reduction matters far less than the reduction
        assert max(err_a, err_b) < 0.02
        assert diff < 0.5 * min(err_a, err_b)


# ---- tolerance, errors, names, file format ---------------------------------------------

def test_order_from_tolerance(floor):
    model, op = floor
    for tol in (2.0, 0.3, 0.05):
        red = balanced_reduction(model, op, tol=tol)
        assert red.error_bound <= tol
        assert 2 * red.hsv[red.order - 1:].sum() > tol  # one state fewer would not do


@pytest.mark.parametrize("kwargs, match", [
    ({"order": 0}, "order must be an integer in \\[1, 51\\]"),
    ({"order": 52}, "order must be an integer in \\[1, 51\\]"),
    ({"order": 2.5}, "order must be an integer"),
    ({"order": 3, "tol": 0.1}, "exactly one of order"),
    ({}, "exactly one of order"),
    ({"tol": -1.0}, "tol must be > 0"),
    ({"order": 3, "method": "modal"}, "method must be 'matchdc' or 'truncate'"),
    ({"order": 3, "input_scale": [1.0, 2.0]}, "input_scale: expected 22 positive values"),
], ids=["zero", "too-big", "fraction", "both", "neither", "negative-tol", "bad-method", "bad-scale"])
def test_balanced_argument_errors(floor, kwargs, match):
    model, op = floor
    with pytest.raises(ModelError, match=match):
        balanced_reduction(model, op, **kwargs)


def test_structured_argument_errors(floor):
    model, op = floor
    with pytest.raises(ModelError, match="order must be an integer in \\[7, 51\\].*keeps all 7 zone"):
        structured(model, op, order=5)
    with pytest.raises(ModelError, match="operating point"):
        structured(model, None, order=10)
    with pytest.raises(ModelError, match="expected a ThermalModel"):
        lumped(linearize(model, op), op)
    with pytest.raises(ModelError, match="design_ms: supply flows must be ≥ 0"):
        structured(model, op, order=10, design_ms=[-0.1])


def test_unstable_system_names_the_floating_zones():
    with pytest.warns(SpecWarning, match="no wall path"):
        spec = _floating_spec()
    model = ThermalModel(ThermalNetwork(spec))
    op = OperatingPoint(x=np.full(model.network.n_states, 20.0), u=model.network.input_vector(T=5.0))
    with pytest.raises(ModelError, match=r"not asymptotically stable.*T\[b\].*T\[c\]"):
        balanced_reduction(model, op, order=2)


def _floating_spec():
    return spec_from_dict({
        "name": "floating", "zones": {"a": {"volume": 30}, "b": {"volume": 30}, "c": {"volume": 30}},
        "boundary": ["outside"],
        "walls": [{"between": ["a", "outside"], "R": [0.1, 0.1, 0.1], "C": [1e5, 1e5]},
                  {"between": ["b", "c"], "R": [0.1, 0.1, 0.1], "C": [1e5, 1e5]}]})


def test_names_survive(floor):
    model, op = floor
    full = linearize(model, op)
    nz = model.network.n_zones
    reds = [balanced_reduction(model, op, order=9), structured(model, op, order=2 * nz),
            kron(model, op), lumped(model, op)]
    for red in reds:
        assert red.sys.input_labels == full.input_labels
        assert red.sys.output_labels == full.output_labels == [f"T[{z}]" for z in model.network.zones]
    assert reds[0].state_names == [f"xr[{k}]" for k in range(9)]
    assert reds[1].state_names[:nz] == full.state_labels[:nz]
    assert reds[1].state_names[nz:] == [f"xr[{k}]" for k in range(nz)]
    assert set(reds[2].state_names) == set(full.state_labels) - set(reds[2].info["eliminated"])
    assert reds[3].state_names == full.state_labels[:nz]


@pytest.mark.parametrize("which", ["balanced", "structured"])
def test_save_load_round_trip(floor, tmp_path, which):
    model, op = floor
    red = balanced_reduction(model, op, order=9) if which == "balanced" else structured(model, op, order=12)
    path = red.save(tmp_path / "red")
    assert path.suffix == ".npz"
    back = load_reduction(path)
    for m in "ABCD":
        np.testing.assert_array_equal(getattr(back.sys, m), getattr(red.sys, m))
    assert back.sys.state_labels == red.sys.state_labels
    assert back.sys.input_labels == red.sys.input_labels
    assert (back.method, back.order, back.error_bound) == (red.method, red.order, red.error_bound)
    np.testing.assert_array_equal(back.op.u, red.op.u)
    if which == "structured":
        u = model.network.input_vector(ms=0.3, Ts=14.0, T=-5.0, Q=50.0)
        op2 = back.operating_point(ms=0.3, Ts=14.0, T=-5.0, Q=50.0)
        np.testing.assert_allclose(back.to_statespace(op2).A, red.network.to_statespace(
            red.network.operating_point(ms=0.3, Ts=14.0, T=-5.0, Q=50.0)).A, rtol=0, atol=0)
        np.testing.assert_array_equal(op2.u, u)
    else:
        with pytest.raises(ModelError, match="design point"):
            back.operating_point(ms=0.3, T=5.0)
    # plain numpy can read it
    with np.load(path, allow_pickle=False) as z:
        assert z["A"].shape == (red.order, red.order)


def test_discrete_reduction_round_trip(floor, tmp_path):
    model, op = floor
    red = balanced_reduction(linearize(model, op, dt=600.0), order=10)
    back = load_reduction(red.save(tmp_path / "d.npz"))
    assert back.sys.dt == 600.0
    np.testing.assert_array_equal(back.sys.A, red.sys.A)
    assert back.to_statespace(dt=600.0) is back.sys
    with pytest.raises(ModelError, match="discrete"):
        back.to_statespace(dt=300.0)


def test_load_rejects_other_files(tmp_path):
    bad = tmp_path / "x.npz"
    np.savez(bad, A=np.eye(2))
    with pytest.raises(ModelError, match="no 'meta' entry"):
        load_reduction(bad)
    with pytest.raises(ModelError, match="not found"):
        load_reduction(tmp_path / "missing.npz")


# ---- structure-preserving, Kron, lumped ------------------------------------------------

def test_reduced_network_without_reduction_is_the_full_model():
    """No convection edge → Kron eliminates nothing: the ReducedNetwork is the model itself."""
    spec, _ = corridor_spec(2)
    model = ThermalModel(ThermalNetwork(spec))
    op = model.operating_point(ms=0.05, Ts=16.0, T=5.0, Q=200.0)
    red = kron(model, op)
    assert red.order == model.network.n_states
    for ms in (0.0, 0.05, 0.4):
        o = model.operating_point(ms=ms, Ts=15.0, T=-2.0, Q=100.0)
        a = red.network.to_statespace(red.network.operating_point(ms=ms, Ts=15.0, T=-2.0, Q=100.0))
        b = model.to_statespace(o)
        np.testing.assert_allclose(a.A, b.A, rtol=0, atol=1e-12 * np.abs(b.A).max())
        np.testing.assert_allclose(a.B, b.B, rtol=0, atol=1e-12 * np.abs(b.B).max())
    # simulation with a varying flow: same trajectories
    rng = np.random.default_rng(3)
    U = np.array([model.network.input_vector(ms=f, Ts=14.0, T=t, Q=q)
                  for f, t, q in zip(rng.uniform(0, 0.3, 12), rng.uniform(-5, 10, 12), rng.uniform(0, 500, 12))])
    x0 = model.steady_state(U[0])
    np.testing.assert_allclose(red.network.simulate(U, 600.0, x0), model.simulate(U, 600.0, x0),
                               rtol=0, atol=1e-9)


@pytest.mark.parametrize("which", ["structured", "kron", "lumped"])
def test_zone_temperatures_exact_at_steady_state_at_every_flow(floor, which):
    model, op = floor
    nz = model.network.n_zones
    red = {"structured": lambda: structured(model, op, order=2 * nz),
           "kron": lambda: kron(model, op), "lumped": lambda: lumped(model, op)}[which]()
    rng = np.random.default_rng(7)
    for _ in range(4):  # random per-zone flows, supply temperatures and heat, not the design point
        u = model.network.input_vector(
            ms=dict(zip(model.network.zones, rng.uniform(0, 0.5, nz))),
            Ts=dict(zip(model.network.zones, rng.uniform(12, 30, nz))), T=rng.uniform(-10, 30),
            Q=dict(zip(model.network.zones, rng.uniform(0, 800, nz))))
        np.testing.assert_allclose(red.network.steady_state(u)[:nz], model.steady_state(u)[:nz],
                                   rtol=1e-10)
        # the lift reconstructs the full steady state exactly (quasi-static edges are exact there)
        xr = red.network.steady_state(u)
        np.testing.assert_allclose(red.network.to_full_state(xr, u[model.network.input_slices()["T"]]),
                                   model.steady_state(u), rtol=1e-10)
    # and the design linearization has the full model's DC gain
    np.testing.assert_allclose(red.sys.dcgain(), linearize(model, op).dcgain(), rtol=1e-9,
                               atol=1e-9 * np.abs(red.sys.dcgain()).max())


def test_structured_is_stable_and_symmetric_for_all_flows(floor):
    model, op = floor
    red = structured(model, op, order=14)
    net = red.network
    np.testing.assert_allclose(net.K, net.K.T, rtol=0, atol=0)
    assert np.all(net.cap > 0)
    for ms in (0.0, 0.01, 1.0, 5.0):
        A, _ = net.affine(net.input_vector(ms=ms, T=5.0))
        assert np.linalg.eigvals(A).real.max() < 0


def test_lumped_is_series_resistances_and_moved_capacitances(floor):
    model, op = floor
    net = model.network
    nz = net.n_zones
    red = lumped(model, op).network
    zi = {z: i for i, z in enumerate(net.zones)}
    K = np.zeros((nz, nz))
    G = np.zeros(nz)
    C = np.array([net.spec.zone_capacitance(z) for z in net.zones])
    for e in net.edges:
        R = sum(e.R) if e.kind == "conduction" else 3 * model.rbar_v * e.d
        C1, C2 = e.C if e.kind == "conduction" else (model.c_v, model.c_v)
        a, b = zi.get(e.a), zi.get(e.b)
        if a is not None:
            K[a, a] += 1 / R
            C[a] += C1
        if b is not None:
            K[b, b] += 1 / R
            C[b] += C2
        if a is not None and b is not None:
            K[a, b] -= 1 / R
            K[b, a] -= 1 / R
        else:
            G[a if a is not None else b] += 1 / R
    np.testing.assert_allclose(red.K, K, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(red.G[:, 0], G, rtol=1e-9)
    np.testing.assert_allclose(red.cap, C, rtol=1e-12)


def test_kron_tau_selects_edges_by_time_constant(floor):
    from thermctl import rc

    model, op = floor
    net = model.network
    nz = net.n_zones
    taus = {e.name: rc.time_constant(e.R, e.C) for e in net.conduction_edges}
    cut = sorted(taus.values())[len(taus) // 2]
    red = kron(model, op, tau=cut)
    fast = {e for e, t in taus.items() if t < cut} | {e.name for e in net.convection_edges}
    assert set(red.info["eliminated"]) == {f"x[{e},{k}]" for e in fast for k in (1, 2)}
    # everything eliminated: the conductances of the lumped model (both are Kron reductions)
    everything = kron(model, op, tau=1e12)
    assert everything.order == nz
    np.testing.assert_allclose(everything.network.K, lumped(model, op).network.K, rtol=1e-12, atol=1e-12)


def test_structured_full_order_is_the_full_model(floor):
    model, op = floor
    red = structured(model, op, order=model.network.n_states)
    for ms in (0.05, 0.5):
        u = model.network.input_vector(ms=ms, Ts=16.0, T=5.0, Q=200.0)
        full = scaled(linearize(model, OperatingPoint(model.steady_state(u), u)))
        r = scaled(red.network.to_statespace(OperatingPoint(red.network.steady_state(u), u)))
        assert hinf_on_grid(full, r, OMEGAS) < 1e-8 * hinf_on_grid(full, 0 * full, OMEGAS)


def test_structured_beats_lumped_and_kron_is_nearly_exact(floor, floor_ref):
    model, op = floor
    nz = model.network.n_zones
    e_lumped = floor_ref.step_error(lumped(model, op).sys).rel
    e_s2 = floor_ref.step_error(structured(model, op, order=2 * nz).sys).rel
    e_s3 = floor_ref.step_error(structured(model, op, order=3 * nz).sys).rel
    e_kron = floor_ref.step_error(kron(model, op).sys).rel
    # measured: lumped 65 % / 18 % / 2.1 % at 1/6/24 h (heavy walls moved into the air),
    # structured 2/zone 4.1 % / 0.73 % / 0.10 %, 3/zone 0.29 % / 0.10 % / 0.04 %,
    # Kron (convection edges only) 0.06 % / 0.014 % / 0.002 %
    assert np.all(e_s2 < e_lumped / 2)
    assert np.all(e_s3 < [0.005, 0.002, 0.001])
    assert np.all(e_s3 < e_s2)
    assert np.all(e_kron < 1e-3)
    assert e_lumped[0] > 0.3  # the baseline is really poor at 1 h on heavy walls


def test_structured_tolerance_and_balanced_comparison(floor, floor_ref):
    model, op = floor
    red = structured(model, op, tol=0.2, reference=floor_ref)
    assert floor_ref.hinf_error(red.sys) <= 0.2
    fewer = structured(model, op, order=red.order - 1)
    assert floor_ref.hinf_error(fewer.sys) > 0.2


def test_flow_sweep_structured_holds_and_multi_flow_design_helps(floor):
    model, op = floor
    nz = model.network.n_zones
    flows = [0.0, 0.05, 0.3]
    single = structured(model, op, order=2 * nz)
    multi = structured(model, op, order=2 * nz, design_ms=[0.0, 0.3])
    bal = balanced_reduction(model, op, order=2 * nz)
    df = flow_sweep(model, [single, multi, bal], flows)
    assert list(df.method) == ["structured", "structured", "balanced"] * len(flows)
    errs = df[["err_1h", "err_6h", "err_24h"]].to_numpy().reshape(len(flows), 3, 3)  # flow, model, t
    worst_single, worst_multi = errs[:, 0].max(), errs[:, 1].max()
    # the bilinear structured model stays within a few per cent at every flow
    assert worst_single < 0.1
    # Gramians at several flows choose modes that do at least as well over the sweep
    assert worst_multi <= worst_single * 1.05
    # a balanced model frozen at its design flow is badly off once the flow moves
    assert errs[flows.index(0.3), 2, 2] > 0.1
    assert errs[flows.index(0.05), 2].max() < 0.05  # ... but fine at its design point


def test_error_vs_order_table(floor, floor_ref):
    model, op = floor
    nz = model.network.n_zones
    df = error_vs_order(model, op, "balanced", [nz, 2 * nz, 3 * nz], reference=floor_ref, hinf=True)
    assert list(df.order) == [nz, 2 * nz, 3 * nz]
    assert np.all(df.hinf <= df.bound * (1 + 1e-9))
    assert np.all(np.diff(df.err_24h) < 0)
    lump = error_vs_order(model, op, "lumped", [99], reference=floor_ref)
    assert list(lump.order) == [nz]


def test_casadi_export_matches_affine(floor):
    model, op = floor
    net = structured(model, op, order=14).network
    f, F = net.to_casadi(substeps=20)
    rng = np.random.default_rng(5)
    x = rng.uniform(15, 25, net.n_states)
    u = net.input_vector(ms=0.2, Ts=14.0, T=3.0, Q=300.0)
    A, b = net.affine(u)
    np.testing.assert_allclose(np.asarray(f(x, u)).ravel(), A @ x + b, rtol=1e-12, atol=1e-12)
    exact = net.simulate(u[None, :], 600.0, x)[1]
    # Radau IIA with 20 sub-steps of 30 s: 3rd order, error ~1e-5 K on a 600 s step
    np.testing.assert_allclose(np.asarray(F(x, u, 600.0)).ravel(), exact, atol=1e-4)


def test_reduced_network_stands_in_for_the_model(floor):
    """The ThermalModel interface controllers use: matrices, affine, capacitances, initial_state."""
    model, op = floor
    net = structured(model, op, order=14).network
    assert net.network is net and net.measured_zones == model.network.measured_zones
    A0, Bt = net.matrices()
    u = net.input_vector(ms=0.1, Ts=15.0, T=2.0, Q=100.0)
    A_u, b = net.affine(u, mats=(A0, Bt))
    nz = net.n_zones
    kz = net.cp * 0.1 / net.capacitances()[:nz]
    np.testing.assert_allclose(A_u - A0.toarray(), -np.diag(np.r_[kz, np.zeros(net.n_states - nz)]),
                               atol=1e-15)
    # initial state: zones as given, modes at their steady state for those temperatures, so
    # that with the matching zone inputs nothing moves but the zones' own balance
    Tz = np.linspace(18.0, 22.0, nz)
    x0 = net.initial_state(Tz, [2.0])
    np.testing.assert_array_equal(x0[:nz], Tz)
    xdot = A0 @ x0 + Bt @ [2.0]
    np.testing.assert_allclose(xdot[nz:], 0.0, atol=1e-12)


def test_cli_reduce(floor, tmp_path):
    from typer.testing import CliRunner

    from thermctl.cli import app
    import thermctl.cli.reduce  # noqa: F401 (registers the command until cli/__init__ imports it)
    from thermctl.io import save_model

    model, _ = floor
    save_model(model, tmp_path / "model.json")
    runner = CliRunner()
    args = ["reduce", str(tmp_path / "model.json"), "--op", "ms=0.05", "--op", "Ts=16", "--op", "T=5",
            "--op", "Q=200"]
    res = runner.invoke(app, args + ["--method", "balanced", "--order", "9", "--out", str(tmp_path / "b.npz"),
                                     "--report", str(tmp_path / "rep"), "--sweep", "0,0.3"])
    assert res.exit_code == 0, res.output
    assert "balanced 9 states" in res.output and "flow sweep" in res.output
    red = load_reduction(tmp_path / "b.npz")
    assert red.order == 9 and red.method == "balanced"
    assert sorted(p.name for p in (tmp_path / "rep" / "figures").iterdir()) == [
        "reduction-error-vs-order.png", "reduction-hsv.png", "reduction-steps.png"]
    res = runner.invoke(app, args + ["--method", "kron", "--order", "9", "--out", str(tmp_path / "k.npz")])
    assert res.exit_code == 2 and "fixed order" in res.output
    res = runner.invoke(app, args + ["--method", "modal", "--out", str(tmp_path / "k.npz")])
    assert res.exit_code == 2 and "--method must be one of" in res.output


def test_plots_show_the_computed_responses(floor):
    from thermctl.plots.reduce import plot_error_vs_order, plot_hsv, plot_step_responses
    from thermctl.reduce import step_responses

    model, op = floor
    full = linearize(model, op)
    red = structured(model, op, order=14)
    fig = plot_step_responses(full, {"structured": red.sys}, channels=[("Q[N1]", "T[N1]")], t_end=10 * H,
                              n_points=11)
    lines = fig.axes[0].get_lines()
    t = np.linspace(0, 10 * H, 11)
    np.testing.assert_allclose(lines[0].get_ydata(), 1000 * step_responses(full, t, ["Q[N1]"], ["T[N1]"])[:, 0, 0])
    np.testing.assert_allclose(lines[1].get_ydata(), 1000 * step_responses(red.sys, t, ["Q[N1]"], ["T[N1]"])[:, 0, 0])
    hsv = hankel_singular_values(model, op)
    fig = plot_hsv(hsv, order=10, n_zones=7)
    np.testing.assert_allclose(fig.axes[0].get_lines()[1].get_ydata()[9], 2 * hsv[10:].sum())
    df = error_vs_order(model, op, "structured", [7, 14])
    assert len(plot_error_vs_order(df).axes[0].get_lines()) == 3 + 2  # 3 times + 2 reference lines
