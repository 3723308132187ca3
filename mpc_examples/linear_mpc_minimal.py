"""Linear MPC of a 7-zone building in one file: the example to copy.

    python -m mpc_examples.linear_mpc_minimal           # identifies the model first (minutes)
    python -m mpc_examples.linear_mpc_minimal --fast    # the testbed's true model instead

testbed logs -> identified ThermalModel -> control.StateSpace -> sparse QP built once
(casadi.conic) -> receding-horizon loop on the true building -> KPIs. Each VAV box has two
inputs: supply flow ms [kg/s] of cold-deck air (it cools) and reheat q [kW]. The rest of
mpc_examples/ is the comparison harness (economic vs linear MPC, baselines, figures); this
file shares no code with it.
"""
from __future__ import annotations

import argparse
import math
import time

import casadi as ca
import control as ct
import numpy as np
import scipy.sparse as sp

from thermctl.data import read_measurements
from thermctl.identify import EstimationOptions, IdentifyOptions, identify
from thermctl.testbed import generate

DT_MIN, HORIZON_H = 15, 6.0         # MPC step [min], prediction horizon [h]
T_C, TS_MAX, COP = 12.8, 32.0, 3.0  # cold deck, highest discharge temperature [°C]; chiller COP
DAY, NIGHT = (21.0, 24.0), (16.0, 28.0)  # comfort band 07-19 h on weekdays, else [°C]
RHO1, RHO2, LAM = 5.0, 50.0, 1e-3   # comfort [kWh per K·h, per K²·h]; move penalty [kWh/unit²]
BACKOFF = 0.3                       # aim this far inside the band: noise, model error [K]
ID_DAYS = 10                        # days of BAS logs to learn from (day 0 is a Friday)


def band(times):
    """Comfort band (lower, upper) at each time stamp [°C]."""
    h = times.hour + times.minute / 60.0
    day = np.asarray((h >= 7) & (h < 19) & (times.day_of_week < 5))
    return np.where(day, DAY[0], NIGHT[0]), np.where(day, DAY[1], NIGHT[1])


def run(fast=False, hours=72.0, start_hour=0.0, seed=0, solver="piqp", verbose=True):
    """Control ``hours`` from ``start_hour`` on the Monday after the logs; return the KPIs
    (energy and discomfort on the true plant, solve times) and the first QP's data."""
    # 1. Testbed: a building whose truth is known, logged by its own BAS, then handed to us.
    tb = generate("pugh-hall", days=ID_DAYS + math.ceil((start_hour + hours + HORIZON_H) / 24),
                  seed=seed)
    net, dist, cp = tb.network, tb.disturbances, tb.spec.cp   # disturbances: 1-min grid
    dt, N, every = DT_MIN * 60.0, int(HORIZON_H * 60 / DT_MIN), int(DT_MIN * 60 / dist.dt)
    k0 = int(round((ID_DAYS * 24 + start_hour) * 3600 / dist.dt))   # first control minute
    t0 = dist.time[k0]

    # 2. Model: identified from the logs before t0 only (--fast: the true model).
    if fast:
        model = tb.model
    else:
        meas = read_measurements(tb.data[tb.data.index < t0], tb.spec, name="testbed logs")
        opt = IdentifyOptions(estimation=EstimationOptions(intervals="none"))
        model = identify(meas, opt).model

    # 3. StateSpace. With the supply off the model is linear in state, boundary temperatures
    # and heat with no constant term, so A and those columns of B hold for absolute values;
    # only the flow column cp(Ts - Tz)/Cz depends on the point: take it at the cold deck and
    # at the 22 °C we hold. Reheat is heat, exactly: ms cp (Ts - Tz) = ms cp (T_C - Tz) + q.
    zones, bnd = net.zones, net.boundary
    boxes = [z for z in zones if f"ms:{z}" in tb.data]     # offices with a VAV box (and sensor)
    bi, ym = [zones.index(z) for z in boxes], [zones.index(z) for z in net.measured_zones]
    x22 = model.initial_state(np.full(len(zones), 22.0), np.full(len(bnd), 22.0))
    op = model.operating_point(x=x22, ms=0.0, Ts=T_C, T=22.0, Q=0.0)
    sysd = ct.sample_system(model.to_statespace(op), dt, method="zoh")   # inputs held: exact
    B = lambda names, scale=1.0: scale * sysd.B[:, [sysd.input_labels.index(s) for s in names]]
    A, n, m, p = sysd.A, sysd.nstates, len(boxes), len(ym)
    Bu = np.hstack([B([f"ms[{z}]" for z in boxes]), B([f"Q[{z}]" for z in boxes], 1e3)])
    BT, BQ = B([f"T[{b}]" for b in bnd]), B([f"Q[{z}]" for z in zones], 1e3)
    # u = [ms kg/s, q kW] of the boxes; disturbances: boundary T [°C], gains [kW] of all zones
    Cb = sysd.C[bi]
    ms_min, ms_max = tb.controller.ms_min, tb.controller.ms_max   # box sizes, zone order

    # 4. Kalman filter on the zone sensors. The unmeasured gains (people, sun, equipment) are
    # random-walk heat inputs of the measured zones: the prediction becomes offset-free.
    G = B([f"Q[{z}]" for z in net.measured_zones], 1e3)
    Aa = np.block([[A, G], [np.zeros((p, n)), np.eye(p)]])
    Ca = np.hstack([sysd.C[ym], np.zeros((p, p))])
    R = 0.05**2 * np.eye(p)                                 # sensor noise 0.05 K
    _, P, _ = ct.dlqe(Aa, np.eye(n + p), Ca, np.diag([1e-4] * n + [0.1**2] * p), R)
    K = P @ Ca.T @ np.linalg.inv(Ca @ P @ Ca.T + R)         # measurement-update gain

    # 5. The QP, built once: w = [u_0..u_N-1, x_1..x_N, s_1..s_N], one comfort slack per box
    # zone and step. Dynamics stay equality rows (sparse, linear in N); what changes from one
    # step to the next (state, forecasts, band, schedule) goes into bounds and g only.
    nu, I, Z = 2 * m, sp.identity, lambda r, c: sp.csc_matrix((r, c))
    dyn = sp.hstack([sp.kron(I(N), -Bu), sp.kron(I(N), I(n)) - sp.kron(sp.eye(N, k=-1), A),
                     Z(N * n, N * m)])                      # x_k+1 - A x_k - Bu u_k = BT T_k + ...
    band_rows = lambda sign: sp.hstack([Z(N * m, N * nu), sp.kron(I(N), Cb), sign * I(N * m)])
    reheat = sp.hstack([-cp * (TS_MAX - T_C) / 1e3 * I(m), I(m)])   # q <= ms cp (TS_MAX - T_C)
    Acon = sp.vstack([dyn, band_rows(1), band_rows(-1),
                      sp.hstack([sp.kron(I(N), reheat), Z(N * m, N * (n + m))])]).tocsc()
    S2 = np.concatenate([1 / ms_max**2, np.ones(m)])         # flow moves in fractions of max
    D = sp.csc_matrix(I(N) - sp.eye(N, k=-1))                # u_k - u_k-1, u_-1 = last applied
    H = sp.block_diag([2 * LAM * sp.kron(D.T @ D, sp.diags(S2)), Z(N * n, N * n),
                       2 * RHO2 * dt / 3600 * I(N * m)]).tocsc()
    to_dm = lambda M: ca.DM(ca.Sparsity(*M.shape, M.indptr.tolist(), M.indices.tolist()), M.data)
    H_dm, A_dm = to_dm(H), to_dm(Acon)
    # PIQP (in this casadi build: casadi.has_conic("piqp")): sparse interior point, accurate
    # with its defaults, 0.2 s for this 1.8k-variable QP. OSQP needed 1e-8 tolerances and 8 s
    # to agree, HiGHS' active set 8 s (the test's cross-check); qpOASES is dense.
    qp = ca.conic("mpc", solver, {"h": H_dm.sparsity(), "a": A_dm.sparsity()},
                  {"error_on_fail": False})
    c_ms = cp * (22.0 - T_C) / 1e3 / COP        # kW per kg/s: chiller cools room air to T_C
    g = np.concatenate([np.tile(np.r_[np.full(m, c_ms), np.ones(m)] * dt / 3600, N),
                        np.zeros(N * n), np.full(N * m, RHO1 * dt / 3600)])

    # 6. Receding horizon on the plant: the true bilinear model, exact ZOH at the MPC step,
    # driven by the true weather and gains (step means); its sensors have 0.05 K noise.
    x = tb.states[tb.data.index.get_loc(t0)]                 # the plant's true state at t0
    Tz0 = np.where(np.isin(np.arange(len(zones)), ym), x[:len(zones)], np.nan)
    xa = np.r_[model.initial_state(Tz0, dist.T_boundary_logged[k0]), np.zeros(p)]
    rng, sl = np.random.default_rng(seed), net.input_slices()
    u_prev, times, fails = np.zeros(nu), [], 0
    heat = cool = discomfort = vmax = 0.0
    for j in range(int(round(hours * 60 / DT_MIN))):
        a, ends = k0 + j * every, k0 + (j + np.arange(1, N + 1)) * every
        xa = xa + K @ (x[ym] + 0.05 * rng.standard_normal(p) - Ca @ xa)   # measurement update
        Tb = dist.T_boundary_logged[a:a + N * every].reshape(N, every, -1).mean(1)  # forecast
        gains = np.zeros(len(zones))
        gains[ym] = xa[n:]                                    # estimated gains [kW], held
        rhs = Tb @ BT.T + gains @ BQ.T
        rhs[0] += A @ xa[:n]
        lo, hi = band(dist.time[ends])                        # band at the end of each step
        on = np.repeat(dist.occupied[ends - every], m)        # AHU schedule: boxes off at night
        lbx = np.zeros(len(g))
        lbx[:N * nu].reshape(N, 2, m)[:, 0] = (on * np.tile(ms_min, N)).reshape(N, m)
        lbx[N * nu:N * (nu + n)] = -np.inf                    # states free, slacks >= 0
        ubx = np.full(len(g), np.inf)
        ubx[:N * nu].reshape(N, 2, m)[:, 0] = (on * np.tile(ms_max, N)).reshape(N, m)
        gk = g.copy()
        gk[:nu] -= 2 * LAM * S2 * u_prev                      # move penalty against u_-1
        big = np.full(N * m, np.inf)
        args = dict(h=H_dm, a=A_dm, g=gk, lbx=lbx, ubx=ubx,
                    lba=np.r_[rhs.ravel(), np.repeat(lo + BACKOFF, m), -big, -big],
                    uba=np.r_[rhs.ravel(), big, np.repeat(hi - BACKOFF, m), np.zeros(N * m)])
        t = time.perf_counter()
        u = np.asarray(qp(**args)["x"]).ravel()[:nu]
        times.append(time.perf_counter() - t)
        fails += not qp.stats()["success"]
        if j == 0:
            first = dict(args=args, u=u.copy())               # the tests re-solve this QP
        ms = np.clip(u[:m], 0.0, ms_max)                      # apply u_0, clipped to what
        q = np.clip(u[m:], 0.0, ms * cp * (TS_MAX - T_C) / 1e3)   # the box can do
        U = np.zeros(net.n_inputs)
        U[sl["ms"]][bi] = ms
        U[sl["Ts"]] = T_C
        U[sl["Ts"]][bi] += np.divide(q * 1e3, ms * cp, out=np.zeros(m), where=ms > 0)
        U[sl["T"]] = dist.T_boundary[a:a + every].mean(0)
        U[sl["Q"]] = dist.gains[a:a + every].mean(0)
        heat += q.sum() * dt / 3600
        cool += (ms * cp * (x[bi] - T_C)).sum() / 1e3 * dt / 3600
        x = tb.model.simulate(U[None], dt, x)[-1]             # the plant
        v = np.maximum(lo[0] - x[bi], 0.0) + np.maximum(x[bi] - hi[0], 0.0)
        discomfort, vmax = discomfort + v.sum() * dt / 3600, max(vmax, v.max())
        xa = Aa @ xa                                          # Kalman time update
        xa[:n] += Bu @ np.r_[ms, q] + BT @ Tb[0]
        u_prev = np.r_[ms, q]

    # 7. KPIs, from the plant's true temperatures and the inputs applied.
    res = dict(energy=heat + cool / COP, heating=heat, cooling=cool, discomfort=discomfort,
               max_violation=vmax, solve_median=float(np.median(times)), solve_max=max(times),
               failures=fails, steps=len(times), first=first, qp=dict(h=H_dm, a=A_dm),
               edges=[(e.a, e.b) for e in model.network.convection_edges])
    if verbose:
        print(f"{net.spec.name}: {len(zones)} zones; {'true' if fast else 'identified'} model: "
              f"{n} states, air paths {res['edges']}, rbar_v {np.ravel(model.rbar_v)[0]:.3g}\n"
              f"control from {t0:%a %Y-%m-%d %H:%M} for {hours:g} h; QP {H.shape[0]} variables, "
              f"{Acon.shape[0]} rows, {solver}\n"
              f"energy {res['energy']:.2f} kWh (reheat {heat:.2f} + cooling {cool:.2f} / COP "
              f"{COP:g})  discomfort {discomfort:.3f} K·h (max {vmax:.2f} K)  solve median "
              f"{res['solve_median']:.3f} s, max {res['solve_max']:.3f} s, "
              f"failed {fails}/{len(times)}")
    return res


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fast", action="store_true", help="the true model: no identification")
    ap.add_argument("--hours", type=float, default=72.0, help="control period [h]")
    ap.add_argument("--start-hour", type=float, default=0.0, help="hour of the Monday to start")
    ap.add_argument("--solver", default="piqp", help="casadi.conic plugin")
    a = ap.parse_args()
    run(a.fast, a.hours, a.start_hour, solver=a.solver)
