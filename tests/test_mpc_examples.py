"""MPC examples: energy model, comfort KPI, the two MPC formulations, the filter, fast runs.

The unit tests use the small 4-zone building of ``conftest.py`` (boxes on r1, r2, r3; an
unmeasured hallway without supply); the last two run both examples end to end on the
testbed in fast mode, as subprocesses, so the command lines never rot.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import casadi as ca
import numpy as np
import pandas as pd
import pytest

from conftest import REPO
from mpc_examples.common import ComfortBand, Forecast, HVACModel, kpis, ClosedLoopResult
from mpc_examples.economic_mpc import EconomicMPC
from mpc_examples.linear_mpc import LinearMPC
from mpc_examples.model import GainKalmanFilter, logged_steps

CP = 1006.0 + 1860.0 * 0.0074
DT = 900.0


@pytest.fixture
def hvac():
    # boxes on the three offices, none in the hallway (zone order r1, r2, r3, hallway)
    ms_max = np.array([0.15, 0.12, 0.12, 0.0])
    return HVACModel(cp=CP, ms_min=0.3 * ms_max, ms_max=ms_max, Ts_max=32.0)


def _forecast(model, N, T_out=5.0, gains=80.0, start_hour=4.0, on_hours=(6, 19),
              comfort=(7, 19)):
    """Constant weather, constant gains, a morning schedule starting at ``start_hour``."""
    nz = model.network.n_zones
    h0 = start_hour + np.arange(N) * DT / 3600.0
    h1 = h0 + DT / 3600.0
    in_c = (h1 >= comfort[0]) & (h1 < comfort[1])
    Tb = np.column_stack([np.full(N, T_out), np.full(N, 12.0)])  # outside, ground
    return Forecast(T_boundary=Tb, gains=np.full((N, nz), gains), T_out=Tb[:, 0],
                    T_c=np.full(N, 12.8), hvac_on=(h0 >= on_hours[0]) & (h0 < on_hours[1]),
                    lo=np.where(in_c, 21.0, 16.0), hi=np.where(in_c, 24.0, 28.0))


def _x0(model, T=17.0):
    u = model.network.input_vector(ms=0.0, T={"outside": 5.0, "ground": 12.0}, Q=0.0)
    x = model.steady_state(u)
    return x + (T - x[: model.network.n_zones].mean())  # a cool night-time start


# ---- energy model and comfort KPI ---------------------------------------------------
def test_hvac_powers_by_hand(hvac):
    # two steps: design flow everywhere at 18 °C supply; nothing
    ms = np.array([hvac.ms_max, np.zeros(4)])
    Ts = np.full((2, 4), 18.0)
    Tz = np.full((2, 4), 22.0)
    p = hvac.powers(ms, Ts, Tz, T_out=np.array([2.0, 2.0]), T_c=np.array([12.8, 12.8]))
    m = hvac.ms_max.sum()
    np.testing.assert_allclose(p["fan"], [1500.0 * m / 1.2, 0.0], rtol=1e-12)
    mix = 0.3 * 2.0 + 0.7 * 22.0                        # 16.0 °C: the coil cools
    np.testing.assert_allclose(p["cooling"], [m * CP * (mix - 12.8), 0.0], rtol=1e-12)
    np.testing.assert_allclose(p["heating"], [m * CP * (18.0 - 12.8), 0.0], rtol=1e-12)
    # colder outside: the mixed air is below the cold deck, the coil preheats
    p = hvac.powers(ms[:1], Ts[:1], Tz[:1], T_out=np.array([-20.0]), T_c=np.array([12.8]))
    mix = 0.3 * -20.0 + 0.7 * 22.0
    np.testing.assert_allclose(p["cooling"], [0.0])
    np.testing.assert_allclose(p["heating"], [m * CP * ((18.0 - 12.8) + (12.8 - mix))], rtol=1e-12)


def test_hvac_casadi_matches_numpy(hvac):
    rng = np.random.default_rng(0)
    ms, Ts, Tz = rng.uniform(0, 0.1, 4), rng.uniform(13, 30, 4), rng.uniform(18, 25, 4)
    num = [hvac.fan_power(ms[None])[0], hvac.coil_duty(ms[None], Tz[None], np.array([3.0]),
                                                        np.array([12.8]))[0],
           hvac.reheat(ms[None], Ts[None], np.array([12.8]))[0]]
    sym = [hvac.fan_power(ca.DM(ms)), hvac.coil_duty(ca.DM(ms), ca.DM(Tz), 3.0, 12.8),
           hvac.reheat(ca.DM(ms), ca.DM(Ts), 12.8)]
    np.testing.assert_allclose([float(s) for s in sym], num, rtol=1e-12)


def test_discomfort_kpi_by_hand(hvac):
    # 2 h at 1-min steps on a Monday from 06:00: comfort starts at 07:00; zone r1 sits at
    # 20 °C (1 K below 21 for the hour 07:00-08:00 → 1 K·h), r2 at 25 (1 K·h), r3 at 22.
    time_ = pd.date_range("2011-02-07 06:00", periods=121, freq="min", tz="America/New_York")
    T = np.tile([20.0, 25.0, 22.0, 15.0], (121, 1))
    n = 120
    res = ClosedLoopResult("x", time_, ["r1", "r2", "r3", "hallway"], T, np.zeros((n, 4)),
                           np.full((n, 4), 12.8), np.full(n, 5.0), np.full(n, 12.8))
    k = kpis(res, hvac, ComfortBand(), ["r1", "r2", "r3"])
    assert k["discomfort [K·h]"] == pytest.approx(2.0, abs=1e-12)
    assert k["max violation [K]"] == pytest.approx(1.0)
    assert k["site energy [kWh]"] == 0.0


# ---- economic MPC -------------------------------------------------------------------
@pytest.fixture
def comfort_zones():
    return ["r1", "r2", "r3"]


def test_economic_transcriptions_agree(small_model, hvac, comfort_zones):
    """Implicit (sparse) and explicit (F.map) shooting gaps define the same NLP."""
    N = 16
    fc, x0 = _forecast(small_model, N), _x0(small_model)
    sols = [EconomicMPC(small_model, hvac, comfort_zones, dt=DT, horizon=N,
                        transcription=t).solve(x0, fc) for t in ("implicit", "explicit")]
    assert all(s.success for s in sols)
    # IPOPT stops at tol 1e-6 on its scaled KKT error, from differently conditioned
    # Jacobians: the optima agree to ~1e-5 relative, far below anything physical
    np.testing.assert_allclose(sols[0].cost, sols[1].cost, rtol=1e-4)
    # flows are unique only where they matter; the states they produce must agree
    np.testing.assert_allclose(sols[0].X, sols[1].X, atol=1e-3)


def test_economic_prediction_matches_model(small_model, hvac, comfort_zones):
    """The plan, simulated exactly by the model, reaches the band when comfort starts."""
    N = 16
    fc, x0 = _forecast(small_model, N), _x0(small_model)
    # this building's zones hold only their air (capacity multiplier 1): time constants of
    # minutes at full flow, so three Radau sub-steps per 15 min (3rd order, L-stable)
    mpc = EconomicMPC(small_model, hvac, comfort_zones, dt=DT, horizon=N, substeps=3)
    sol = mpc.solve(x0, fc)
    assert sol.success
    U = np.column_stack([sol.ms, sol.Ts, fc.T_boundary, fc.gains])
    X = small_model.simulate(U, DT, x0, method="exact")
    np.testing.assert_allclose(sol.X, X, atol=0.03)  # below the 0.05 K sensor noise
    c = [small_model.network.zones.index(z) for z in comfort_zones]
    occupied = fc.lo == 21.0
    # start cool (17 °C), comfort from 07:00 (step 12): it pre-heats in time
    assert X[1:][occupied][:, c].min() > 21.0 - 0.02
    # and nothing runs before occupancy that is not needed: no supply before 04:45
    assert np.all(sol.ms[:3] < 1e-4)


def test_economic_idle_when_nothing_to_do(small_model, hvac, comfort_zones):
    """Unoccupied, inside the setback band: the cheapest plan is to do nothing."""
    N = 8
    fc = _forecast(small_model, N, start_hour=0.0)
    sol = EconomicMPC(small_model, hvac, comfort_zones, dt=DT, horizon=N).solve(_x0(small_model, 20.0), fc)
    assert sol.success
    # interior point: bounds are approached to ~1e-6, i.e. a thousandth of a g/s
    np.testing.assert_allclose(sol.ms, 0.0, atol=1e-5)
    assert abs(sol.cost) < 1e-4  # [kWh]: 0.1 Wh over two hours


def test_economic_warm_start_is_cheaper(small_model, hvac, comfort_zones):
    N = 16
    fc, x0 = _forecast(small_model, N), _x0(small_model)
    mpc = EconomicMPC(small_model, hvac, comfort_zones, dt=DT, horizon=N)
    cold = mpc.solve(x0, fc)
    shifted = Forecast(*(np.concatenate([a[1:], a[-1:]]) for a in
                         (fc.T_boundary, fc.gains, fc.T_out, fc.T_c, fc.hvac_on, fc.lo, fc.hi)))
    warm = mpc.solve(cold.X[1], shifted)
    assert warm.success and warm.iterations < cold.iterations


@pytest.mark.parametrize("cls, bad, match", [
    (EconomicMPC, dict(transcription="collocation"), "transcription"),
    (EconomicMPC, dict(substeps=0), "substeps"),
    (EconomicMPC, dict(horizon=0), "horizon"),
    (EconomicMPC, dict(comfort_zones=["nowhere"]), "comfort zones"),
    (LinearMPC, dict(iterations=0), "iterations"),
    (LinearMPC, dict(horizon=2.5), "horizon"),
    (LinearMPC, dict(dt=0.0), "dt"),
    (LinearMPC, dict(comfort_zones=["nowhere"]), "comfort zones"),
    (LinearMPC, dict(transcription="rk4"), "transcription must be one of"),
], ids=["transcription", "substeps", "horizon", "zone", "iterations", "lin-horizon", "dt",
        "lin-zone", "lin-transcription"])
def test_bad_arguments(small_model, hvac, comfort_zones, cls, bad, match):
    kw = dict(comfort_zones=comfort_zones, dt=DT, horizon=4)
    kw.update(bad)
    with pytest.raises(ValueError, match=match):
        cls(small_model, hvac, **kw)


@pytest.mark.parametrize("cls", [EconomicMPC, LinearMPC], ids=["economic", "linear"])
def test_short_forecast_and_hvac_mismatch(small_model, hvac, comfort_zones, cls):
    mpc = cls(small_model, hvac, comfort_zones, dt=DT, horizon=8)
    with pytest.raises(ValueError, match="forecast covers 4 steps, the horizon needs 8"):
        mpc.solve(_x0(small_model), _forecast(small_model, 4))
    three = HVACModel(cp=CP, ms_min=hvac.ms_min[:3], ms_max=hvac.ms_max[:3])
    with pytest.raises(ValueError, match="the model has 4 zones"):
        cls(small_model, three, comfort_zones, dt=DT, horizon=4)


# ---- linear MPC ---------------------------------------------------------------------
def test_linear_export_exact_at_base_flow(small_model, hvac, comfort_zones):
    """At the mode's base flow the exported (A, B) is exact, not an approximation.

    Reheat r at minimum flow enters as heat through Q[z]; the nonlinear model with
    ms = ms_min and Ts = T_c + r/(ms_min cp) must give the same trajectory.
    """
    N = 6
    mpc = LinearMPC(small_model, hvac, comfort_zones, dt=DT, horizon=N, transcription="zoh")
    net = small_model.network
    rng = np.random.default_rng(1)
    x0 = _x0(small_model, 19.0)
    r = rng.uniform(0, 800.0, (N, 3))            # reheat per box [W]
    Tb = np.column_stack([rng.uniform(0, 10, N), np.full(N, 12.0)])
    s = mpc.systems[True]
    x = x0.copy()
    U = np.zeros((N, net.n_inputs))
    for k in range(N):
        q = np.zeros(net.n_zones)
        q[:3] = r[k]
        x = s["A"] @ x + s["B_Ts"] @ np.full(net.n_zones, 12.8) + s["B_T"] @ Tb[k] + s["B_Q"] @ q + s["c"]
        ms = hvac.ms_min.copy()
        Ts = np.full(net.n_zones, 12.8)
        Ts[:3] += r[k] / (ms[:3] * CP)
        U[k] = np.concatenate([ms, Ts, Tb[k], np.zeros(net.n_zones)])
    X = small_model.simulate(U, DT, x0, method="exact")
    np.testing.assert_allclose(x, X[-1], atol=1e-8)


def test_linear_matches_economic(small_model, hvac, comfort_zones):
    """Same task, two formulations: the same plan within a few percent of energy.

    Both plans are replayed on the exact nonlinear model (the linear MPC's inputs are
    recovered from its virtual heats).
    """
    N = 16
    fc, x0 = _forecast(small_model, N), _x0(small_model)
    e = EconomicMPC(small_model, hvac, comfort_zones, dt=DT, horizon=N, substeps=3).solve(x0, fc)
    # the exact (ZOH) export: these air-only zones need sub-steps for Radau at 15 min
    s = LinearMPC(small_model, hvac, comfort_zones, dt=DT, horizon=N, iterations=3,
                  transcription="zoh").solve(x0, fc)
    assert e.success and s.success
    energy = []
    for sol in (e, s):
        U = np.column_stack([sol.ms, sol.Ts, fc.T_boundary, fc.gains])
        X = small_model.simulate(U, DT, x0, method="exact")
        p = hvac.powers(sol.ms, sol.Ts, X[:-1, :4], fc.T_out, fc.T_c)
        energy.append(hvac.site_power(p).sum() * DT / 3.6e6)
        occupied = fc.lo == 21.0
        # 0.2 K: the QP converts heat to flow at the predicted mid-step temperature, and the
        # warm-up step of these air-only zones is 4.5 K in 15 min
        assert X[1:][occupied][:, :3].min() > 21.0 - 0.2
    # the QP prices flow at predicted temperatures and the fan by a Taylor model
    np.testing.assert_allclose(energy[1], energy[0], rtol=0.05)


# ---- Kalman filter ------------------------------------------------------------------
def test_kalman_recovers_unknown_gain(small_model):
    """True model, constant unmeasured gains, noisy sensors: the filter finds the gains."""
    net = small_model.network
    dt = 300.0
    gains_true = np.array([300.0, 0.0, 150.0, 0.0])
    measured = ["r1", "r2", "r3"]
    # a slow random walk (50 W/√h) for a constant gain; the examples use 150 to track people
    kf = GainKalmanFilter(small_model, dt, measured, sd_gain=50.0, sd_meas=0.05)
    rng = np.random.default_rng(3)
    u = net.input_vector(ms={"r1": 0.05, "r2": 0.05, "r3": 0.05}, Ts=18.0,
                         T={"outside": 5.0, "ground": 12.0}, Q=0.0)
    x = small_model.steady_state(u)
    kf.reset(x[:3] + rng.normal(0, 0.05, 3), u[net.input_slices()["T"]])
    u_true = u.copy()
    u_true[net.input_slices()["Q"]] = gains_true
    X = small_model.simulate(np.tile(u_true, (576, 1)), dt, x, method="exact")  # 48 h
    for k in range(1, len(X)):
        kf.predict(u)
        kf.update(X[k, :3] + rng.normal(0, 0.05, 3))
    # the estimate wanders by about 7 W (1 sd) at this noise level: 15 W is 2 sd
    np.testing.assert_allclose(kf.gains, gains_true[:3], atol=15.0)
    np.testing.assert_allclose(kf.x[:3], X[-1, :3], atol=0.1)


def _logged_frame(model, u, gains, hours, step=300.0, seed=5):
    """BAS-like log of the small building: constant inputs and gains, noisy zone sensors."""
    net = model.network
    n = int(hours * 3600 / step)
    u_true = u.copy()
    u_true[net.input_slices()["Q"]] = gains
    x0 = model.steady_state(u)
    X = model.simulate(np.tile(u_true, (n, 1)), step, x0, method="exact")
    rng = np.random.default_rng(seed)
    time_ = pd.date_range("2011-02-07", periods=n + 1, freq=f"{int(step)}s",
                          tz="America/New_York")
    sl = net.input_slices()
    cols = {f"T:{z}": X[:, i] + rng.normal(0, 0.05, n + 1) for i, z in enumerate(net.zones)
            if z in net.measured_zones}
    cols.update({f"T:{b}": np.full(n + 1, u[sl["T"]][j]) for j, b in enumerate(net.boundary)})
    for i, z in enumerate(net.zones[:3]):
        cols[f"ms:{z}"] = np.full(n + 1, u[sl["ms"]][i])
        cols[f"Ts:{z}"] = np.full(n + 1, u[sl["Ts"]][i])
    return pd.DataFrame(cols, index=time_), X


def test_logged_steps_by_hand(small_model):
    """Inputs are averaged over each step [t, t + dt); temperatures are read at t."""
    net = small_model.network
    t = pd.date_range("2011-02-07", periods=6, freq="5min")
    df = pd.DataFrame({"T:r1": [20.0, 21, 22, 23, 24, 25], "T:r2": 21.0, "T:r3": 22.0,
                       "T:outside": [0.0, 3, 6, 9, 12, 15], "T:ground": 10.0,
                       "ms:r1": [0.0, 0.03, 0.06, 0.0, 0.0, 0.09], "Ts:r1": 30.0}, index=t)
    times, U, Y = logged_steps(net, df, 900.0, ["r1", "r2", "r3"])
    sl = net.input_slices()
    assert list(times) == [t[0], t[3]]
    np.testing.assert_allclose(U[:, sl["ms"].start], [0.03, 0.03])        # (0 + .03 + .06)/3
    np.testing.assert_allclose(U[:, sl["T"].start], [3.0, 12.0])          # outside
    np.testing.assert_allclose(U[:, sl["ms"].start + 1], 0.0)              # r2: no supply
    np.testing.assert_allclose(Y[:, 0], [20.0, 23.0])


def test_kalman_replay_recovers_gains_and_state(small_model):
    """Replaying 48 h of logged data leaves the filter at the true gains and state at the
    end of the data (what the closed loop starts from)."""
    net = small_model.network
    u = net.input_vector(ms={"r1": 0.05, "r2": 0.05, "r3": 0.05}, Ts=18.0,
                         T={"outside": 5.0, "ground": 12.0}, Q=0.0)
    gains = np.array([300.0, 0.0, 150.0, 0.0])
    df, X = _logged_frame(small_model, u, gains, hours=48.0)
    kf = GainKalmanFilter(small_model, 900.0, ["r1", "r2", "r3"], sd_gain=50.0, sd_meas=0.05)
    G = kf.run(df.iloc[:-1])                  # the log ends 5 min before the last sample
    assert len(G) == 192 and G.iloc[-1].isna().all() and G.iloc[-2].notna().all()
    # about 7 W (1 sd) of wander at this noise level (test_kalman_recovers_unknown_gain)
    np.testing.assert_allclose(kf.gains, gains[:3], atol=15.0)
    # the state at the end of the last step (predicted there, not yet corrected)
    np.testing.assert_allclose(kf.x[:3], X[-1, :3], atol=0.1)


# ---- the examples, end to end, fast mode -------------------------------------------
def _run_example(module, tmp_path, *extra):
    env = dict(os.environ, OMP_NUM_THREADS="1", MPLBACKEND="Agg")
    cmd = [sys.executable, "-m", module, "--hours", "3", "--start-day", "10", "--start-hour", "5",
           "--horizon", "4", "--out", str(tmp_path), *extra]
    out = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout


@pytest.mark.slow   # identification in a subprocess: 1-3 min each on a shared machine
@pytest.mark.parametrize("module, stem, extra", [
    ("mpc_examples.economic_mpc", "economic_mpc", ("--no-figure", "--no-band-baseline")),
    ("mpc_examples.linear_mpc", "linear_mpc", ()),
], ids=["economic", "linear"])
def test_example_fast_mode(tmp_path, module, stem, extra):
    """Identify on the 10 days before, control Monday 05:00-08:00 (warm-up, occupancy).

    Measured (seed 0): baseline 14.2 kWh and 0.013 K·h, band baseline 13.8 kWh; both MPCs
    12.4 kWh and 0.00 K·h: they start the warm-up at 06:00 with the minimum flow at full
    reheat and add flow at 06:30 just as needed, where the baseline overshoots its set
    points. The bounds below leave room for a different identified model, not for a
    controller that stops planning the warm-up.
    """
    stdout = _run_example(module, tmp_path, *extra)
    table = pd.read_csv(tmp_path / f"{stem}.csv", index_col=0)
    assert "baseline (testbed BAS)" in table.index
    mpc = [i for i in table.index if "identified model" in i]
    assert len(mpc) == 1 and mpc[0] in stdout
    row, base = table.loc[mpc[0]], table.loc["baseline (testbed BAS)"]
    assert row["failures"] == 0
    e, e_base = row["site energy [kWh]"], base["site energy [kWh]"]
    assert 0.5 * e_base < e < 0.95 * e_base
    # comfort from 07:00: the MPC plans the warm-up, the baseline reacts (0.013 K·h, 0.18 K)
    assert row["discomfort [K·h]"] < 0.05
    assert row["max violation [K]"] < 0.15
    assert row["CPU median [s]"] < 1.0   # CPU, not wall: the test machine may be loaded
    if "--no-band-baseline" not in extra:
        band = table.loc["baseline (band set points)"]
        assert row["site energy [kWh]"] < band["site energy [kWh]"]
    assert (tmp_path / f"{stem}.txt").read_text().startswith("controller")
    meta = json.loads((tmp_path / f"{stem}.json").read_text())
    assert len(meta["models"]["identified"]["edges"]) >= 1
    if "--no-figure" not in extra:
        assert (tmp_path / f"{stem}.png").stat().st_size > 10_000


@pytest.mark.slow   # 12 closed-loop QPs on the testbed: about a minute
def test_minimal_linear_example():
    """The copyable example (mpc_examples/linear_mpc_minimal.py), fast mode: true model inside,
    Monday 06:00-09:00 (12 QPs of 15 min: the warm-up from 06:00, comfort from 07:00).

    The first QP (the warm-up plan: minimum flow, reheat at its cap, one box above minimum
    flow) re-solved by HiGHS (active set, an independent code) gives the same first input to
    1e-7.
    """
    from mpc_examples.linear_mpc_minimal import run

    res = run(fast=True, hours=3.0, start_hour=6.0, verbose=False)
    assert res["steps"] == 12 and res["failures"] == 0          # every QP solved
    assert res["discomfort"] < 0.05 and res["max_violation"] < 0.15   # on the true plant
    assert np.isfinite(res["energy"]) and res["energy"] > 0 and res["heating"] > 0
    first, qp = res["first"], res["qp"]
    other = ca.conic("check", "highs", {"h": qp["h"].sparsity(), "a": qp["a"].sparsity()},
                     {"highs": {"output_flag": False}})
    u = np.asarray(other(**first["args"])["x"]).ravel()[:first["u"].size]
    assert other.stats()["success"]
    m = u.size // 2                                             # [flow kg/s, reheat kW] per box
    assert first["u"][m:].min() > 0.1                           # a real plan: the warm-up
    np.testing.assert_allclose(u[:m], first["u"][:m], atol=1e-5)   # box flows ~0.03-0.16 kg/s
    np.testing.assert_allclose(u[m:], first["u"][m:], atol=1e-4)   # reheat 0-3 kW


# ---- sparse transcriptions (mpc_examples.sparse) -------------------------------------
def _op_small(model, hvac):
    return model.operating_point(ms=dict(zip(model.network.zones, hvac.ms_min)), Ts=13.0,
                                 T={"outside": 5.0, "ground": 12.0})


def test_sparse_and_dense_transcriptions_same_optimum(small_model, hvac, comfort_zones):
    """The implicit Radau rows (collocation form, sparse) and the same step solved for x⁺
    (dense blocks) are one problem: the same optimum, cost and plan."""
    N = 16
    fc, x0 = _forecast(small_model, N), _x0(small_model)
    sols = [LinearMPC(small_model, hvac, comfort_zones, dt=DT, horizon=N, transcription=t)
            .solve(x0, fc) for t in ("radau", "radau-dense")]
    assert all(s.success for s in sols)
    # PIQP stops at 1e-8 (its default) on both: agreement well inside 1e-6
    np.testing.assert_allclose(sols[0].cost, sols[1].cost, rtol=1e-6)
    np.testing.assert_allclose(sols[0].X, sols[1].X, atol=1e-6)
    np.testing.assert_allclose(sols[0].ms, sols[1].ms, atol=1e-6)


@pytest.mark.parametrize("transcription", ["euler", "radau"])
def test_two_qp_solvers_agree(small_model, hvac, comfort_zones, transcription):
    """PIQP (interior point) and HiGHS (active set) on the same sparse QP."""
    N = 12
    fc, x0 = _forecast(small_model, N), _x0(small_model)
    sols = [LinearMPC(small_model, hvac, comfort_zones, dt=DT, horizon=N, solver=s,
                      transcription=transcription).solve(x0, fc) for s in ("piqp", "highs")]
    assert all(s.success for s in sols)
    np.testing.assert_allclose(sols[0].cost, sols[1].cost, rtol=1e-6)
    # the first applied input: flows [kg/s] to 1e-6, supply temperatures [°C] where it flows
    np.testing.assert_allclose(sols[0].ms[0], sols[1].ms[0], atol=1e-6)
    # and the state it leads to (later steps can trade flow for reheat at equal cost: the
    # optimum is not unique there, 5 mK apart was seen)
    np.testing.assert_allclose(sols[0].X[1], sols[1].X[1], atol=1e-5)


def test_implicit_steps_converge_to_zoh_at_their_order(small_model, hvac):
    """On the linear model at a fixed flow, the implicit steps approach the exact (ZOH) step
    at their order: halving h divides Radau's error by about 2³ and Euler's by 2."""
    from mpc_examples.sparse import at_flow, step_rows

    dyn = at_flow(small_model, hvac.ms_min)
    net = small_model.network
    rng = np.random.default_rng(0)
    x0 = 20.0 + rng.normal(0.0, 1.0, net.n_states)
    u = (np.full(net.n_zones, 30.0), np.array([5.0, 12.0]), np.full(net.n_zones, 200.0))

    def error(method, h, T=3600.0):
        ex, ap = step_rows(dyn, h, "zoh"), step_rows(dyn, h, method)
        xe, xa = x0.copy(), x0.copy()
        for _ in range(int(round(T / h))):
            b = lambda s: s.B_Ts @ u[0] + s.B_T @ u[1] + s.B_Q @ u[2]  # noqa: E731
            xe = ex.N @ xe + b(ex)
            rhs = ap.N @ xa + b(ap)
            xa = np.linalg.solve(ap.L.toarray(), rhs)[-net.n_states:]
        return np.abs(xa - xe).max()

    e_r = [error("radau", h) for h in (120.0, 60.0)]
    e_e = [error("euler", h) for h in (120.0, 60.0)]
    assert e_r[0] < 0.05 * e_e[0]                 # third order beats first by far
    assert 5.0 < e_r[0] / e_r[1] < 11.0           # ~2³ (the fast edges are not asymptotic yet)
    assert 1.7 < e_e[0] / e_e[1] < 2.3            # ~2
    # at the MPC's 10-min step (far from asymptotic for the fast states) still the better
    assert error("radau", 600.0) < 0.5 * error("euler", 600.0)


def test_eliminating_convection_edges_keeps_sparsity(small_model, hvac):
    """Singular perturbation of the r1–r3 air path: two states fewer, no fill-in, zone and
    wall states unchanged, exact at steady state, small step error."""
    from mpc_examples.sparse import eliminate_fast_edges

    op = _op_small(small_model, hvac)
    rnet, info = eliminate_fast_edges(small_model, op)
    net = small_model.network
    assert rnet.n_states == net.n_states - 2 and info["eliminated"] == 2
    assert rnet.state_names == [n for n in net.state_names if not n.startswith("x[air:r1-r3")]
    # the Schur complement couples r1 and r3 directly and fills in nothing else
    A, _ = small_model.matrices()
    K = np.asarray(rnet.K)
    keep = [net.state_names.index(n) for n in rnet.state_names]
    outside = (K != 0) & (np.asarray(A.toarray())[np.ix_(keep, keep)] == 0)
    assert {tuple(sorted(ij)) for ij in zip(*np.nonzero(outside))} == {(0, 2)}   # r1–r3
    assert info["nnz"][1] < info["nnz"][0]
    x_r = rnet.steady_state(op.u)
    np.testing.assert_allclose(x_r[: net.n_zones], op.x[: net.n_zones], atol=1e-9)
    assert max(info["step error"].values()) < 0.01


def test_economic_on_reduced_network(small_model, hvac, comfort_zones):
    """The economic NMPC on the model without convection states (sparse symbolic rows from
    the ReducedNetwork): solves, and plans within 1 % of the full model's energy."""
    from mpc_examples.sparse import eliminate_fast_edges

    N = 12
    fc, x0 = _forecast(small_model, N, start_hour=5.0), _x0(small_model)
    rnet, _ = eliminate_fast_edges(small_model, _op_small(small_model, hvac), error=False)
    full = EconomicMPC(small_model, hvac, comfort_zones, dt=DT, horizon=N, substeps=3)
    red = EconomicMPC(rnet, hvac, comfort_zones, dt=DT, horizon=N, substeps=3)
    a, b = full.solve(x0, fc), red.solve(rnet.from_full_state(x0), fc)
    assert a.success and b.success
    np.testing.assert_allclose(b.cost, a.cost, rtol=0.01)
    assert red.n_nonzeros < full.n_nonzeros


def test_tariff_event_cap_and_peak(small_model, hvac, comfort_zones):
    """With a tariff: the planned electric power respects a feasible event cap (the MPC
    pre-cools instead), and the peak variable is the plan's largest electric power."""
    from mpc_examples.common import Tariff

    N = 16
    fc = _forecast(small_model, N, T_out=30.0, gains=600.0, start_hour=8.0)
    x0 = _x0(small_model, 22.5)
    el = np.full(N, 0.1)
    cap = np.where((np.arange(N) >= 8) & (np.arange(N) < 12), 0.0, np.inf)
    plans = {}
    for name, c in (("free", np.full(N, np.inf)), ("event", cap)):
        fc.tariff = Tariff(elec=el, heat=np.full(N, 0.04), demand=1.0, elec_cap=c,
                           cap_penalty=50.0)
        mpc = LinearMPC(small_model, hvac, comfort_zones, dt=DT, horizon=N, tariff=True,
                        transcription="zoh")
        sol = mpc.solve(x0, fc)
        assert sol.success
        p = hvac.powers(sol.ms, sol.Ts, sol.X[:-1, :4], fc.T_out, fc.T_c)
        plans[name] = (p["fan"] + p["cooling"] / hvac.cop_cool) / 1e3, sol
    free, event = plans["free"][0], plans["event"][0]
    on = cap == 0.0
    # the cap 0 is infeasible (fan and coil at the ventilation minimum): the event plan sheds
    # the extra cooling flow, what it can (measured 0.45 against 0.56 kW at most)
    assert event[on].max() < 0.9 * free[on].max()
    # and cools earlier (pre-cooling): more electric power before the event than without it
    assert event[:8].sum() > free[:8].sum()


@pytest.mark.slow
def test_scaling_benchmark_small(tmp_path):
    """The scaling benchmark's command line on the 7-zone building: every sparse form and
    model runs, solves succeed, the sparse QP carries fewer nonzeros than the dense one."""
    env = dict(os.environ, OMP_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "mpc_examples.scaling", "--zones", "7", "--solves", "2",
           "--forms", "zoh", "euler", "radau", "--solvers", "piqp", "--models", "full", "no-conv",
           "--per-zone", "--out", str(tmp_path)]
    out = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    df = pd.read_csv(tmp_path / "scaling.csv")
    assert (df["failures"] == 0).all() and (df["solves"] == 2).all()
    lin = df[(df["MPC"] == "linear") & (df["model"] == "full")].set_index("form")
    assert lin.loc["euler", "nonzeros"] < 0.2 * lin.loc["zoh", "nonzeros"]
    assert "no-conv: 55 -> 49 states" in (tmp_path / "scaling.txt").read_text()


@pytest.mark.slow
def test_demand_response_example(tmp_path):
    """The DR day, true and conduction-only models, 12:00-17:00 (the event at 14-16 h, its cap
    binding at 0.8 × the ventilation-only power): the MPC exceeds the cap less than the
    band-set-point BAS, at a lower cost."""
    env = dict(os.environ, OMP_NUM_THREADS="1", MPLBACKEND="Agg")
    cmd = [sys.executable, "-m", "mpc_examples.demand_response", "--model", "true,conduction-only",
           "--start-hour", "12", "--hours", "5", "--warmup", "24", "--cap-factor", "0.8",
           "--out", str(tmp_path)]
    out = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    t = pd.read_csv(tmp_path / "demand_response.csv", index_col=0)
    base, true = t.loc["baseline (band set points)"], t.loc["linear MPC (true model)"]
    assert true["failures"] == 0
    assert true["event excess [kWh]"] < base["event excess [kWh]"]
    assert true["cost [$]"] < base["cost [$]"]


@pytest.mark.parametrize("tail", [[3] * 10, [6] * 5], ids=["30-min tail", "60-min tail"])
def test_coarse_tail_grid_same_first_input(tail):
    """The linear MPC on the 7-zone testbed (Pugh Hall, true model, euler rows, PIQP) with a
    non-uniform prediction grid — the first hour in 10-min steps, then 30- or 60-min steps
    to 6 h (16 or 11 steps) — against the uniform 36 × 10-min grid: two problems, not one,
    that must give the same applied input. Three state-feedback steps of the Monday warm-up
    from 06:00, where the boxes reheat (up to the 32 °C limit). Measured over eight steps:
    flows 1e-10 kg/s apart, supply temperatures 3e-5 K (30-min tail) and 5e-6 K (60-min),
    the predicted zone temperatures after 10 min 1e-6 K; the tolerances are 100× that or
    more. (Starting the 30-min steps after 30 min instead moves the 06:20 reheat by up to
    17 K: the first hour must stay fine.)"""
    from mpc_examples.simulator import make_scenario

    scn = make_scenario(7, 0, 0.5, 6.0, start_day=3, start_hour=6.0)
    nz, sup = len(scn.tb.network.zones), scn.hvac.supplied
    grid = [1] * 6 + tail
    mpcs = [LinearMPC(scn.tb.model, scn.hvac, scn.comfort_zones, dt=600.0, horizon=len(s),
                      transcription="euler", steps=s) for s in ([1] * 36, grid)]
    assert mpcs[1].n_variables < 0.5 * mpcs[0].n_variables
    plant = scn.plant()
    reheat = 0.0
    for j in range(3):
        meas = plant.measure()
        sols = [m.solve(plant.x, scn.forecast(10 * j, m.N, 10, np.zeros(nz), meas.T_ahu,
                                              steps=m.steps)) for m in mpcs]
        assert all(s.success for s in sols)
        np.testing.assert_allclose(sols[1].ms[0], sols[0].ms[0], atol=1e-6)       # [kg/s]
        np.testing.assert_allclose(sols[1].Ts[0][sup], sols[0].Ts[0][sup], atol=5e-3)  # [°C]
        np.testing.assert_allclose(sols[1].X[1][:nz], sols[0].X[1][:nz], atol=1e-4)    # [°C]
        reheat = max(reheat, float(np.max(sols[0].Ts[0][sup] - meas.T_ahu)))
        ms = np.zeros(nz)
        ms[sup] = sols[0].ms[0][sup]
        Ts = np.full(nz, meas.T_ahu)
        Ts[sup] = np.maximum(sols[0].Ts[0][sup], meas.T_ahu)
        for _ in range(10):
            plant.step(ms, Ts)
    assert reheat > 10.0   # not two idle plans agreeing at their bounds


def test_forecast_on_a_grid_averages_the_fine_one():
    """Scenario.forecast on a non-uniform grid: boundary temperatures the mean of the 10-min
    forecast's over each long step, the band at each step's end, the mode at its start."""
    from mpc_examples.simulator import make_scenario

    scn = make_scenario(7, 0, 0.5, 6.0, start_day=3, start_hour=6.0)
    nz = len(scn.tb.network.zones)
    fine = scn.forecast(0, 36, 10, np.zeros(nz), 13.0)
    grid = [1] * 6 + [3] * 10
    coarse = scn.forecast(0, 16, 10, np.zeros(nz), 13.0, steps=grid)
    np.testing.assert_allclose(coarse.T_boundary[:6], fine.T_boundary[:6])
    np.testing.assert_allclose(coarse.T_boundary[6:],
                               fine.T_boundary[6:].reshape(10, 3, -1).mean(axis=1))
    np.testing.assert_array_equal(coarse.lo[6:], fine.lo[8::3])
    np.testing.assert_array_equal(coarse.hvac_on[6:], fine.hvac_on[6::3])


def test_small_load_makes_the_small_box_bind():
    """``make_dr_scenario(small_load=W)`` adds W to r240's gains in occupied hours from the
    control start only (the log before it is untouched), and with 1200 W the band-set-point
    BAS, whose r240 box is at 35 %, leaves r240 too warm (08:00-12:00: 1.76 K·h measured;
    0.006 K·h without the load)."""
    from mpc_examples.demand_response import (SMALL_BOX_ZONE, dr_kpis, make_dr_scenario,
                                              small_box_baseline)
    from mpc_examples.simulator import run_baseline

    out = {}
    for load in (0.0, 1200.0):
        scn = make_dr_scenario(0, 4.0, 6.0, None, 8.0, 0.35, small_load=load)
        out[load] = scn
    d0, d1 = out[0.0].tb.disturbances, out[1200.0].tb.disturbances
    diff = d1.gains - d0.gains
    j = list(d0.zones).index(SMALL_BOX_ZONE)
    k0 = out[0.0].k0
    on = np.asarray(d0.occupied, bool) & (np.arange(len(d0)) >= k0)
    np.testing.assert_array_equal(diff[:, j], np.where(on, 1200.0, 0.0))
    assert not np.any(np.delete(diff, j, axis=1))
    assert on.sum() > 0 and not np.any(diff[:k0])
    kp = {load: dr_kpis(run_baseline(scn, small_box_baseline(scn), "bas"), scn)
          for load, scn in out.items()}
    key = f"{SMALL_BOX_ZONE} discomfort [K·h]"
    assert kp[0.0][key] < 0.05 and kp[1200.0][key] > 1.0
