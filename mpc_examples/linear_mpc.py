r"""Linear MPC of a VAV building with the exported ``StateSpace``, solved as a QP.

Run from the repository root::

    python -m mpc_examples.linear_mpc              # 3 days, identified model
    python -m mpc_examples.linear_mpc --hours 6    # fast mode

The same task as :mod:`mpc_examples.economic_mpc` (same comfort band, same energy model,
same plant), but the controller only uses what ``ThermalModel.to_statespace(op, dt)``
exports: discrete matrices :math:`(A, B)` at an operating point, and solves one QP per
step (OSQP through ``casadi.qpsol``).

The bilinear term and the linearization point
---------------------------------------------
The model is bilinear, :math:`C_z\dot T_z = \dots + \dot m_z c_p (T_{s,z} - T_z) + Q_z`, so
a linearization in :math:`(\dot m, T_s)` is only good near its operating point. But *for a
fixed flow* the model is exactly linear in the state, in :math:`T_s` and in :math:`Q`. So:

* **Linearization point**: the supply flow the mode prescribes anyway — the ventilation
  minimum :math:`\dot m_{min}` in occupied mode, zero otherwise — with :math:`T_s = T_c`
  (cold deck) and :math:`Q = 0`. Two exported systems, switched by the (known) schedule;
  each is exact, not an approximation, for every state, boundary temperature and heat
  input, because the dropped second-order terms all contain :math:`\delta\dot m`.
* **Bilinear term as virtual heat**: whatever the box adds to that base supply enters
  through the ``Q[z]`` input as heat :math:`q_{h} - q_{c}` [kW], both :math:`\ge 0`.
  In occupied mode :math:`q_h` *is* the reheat at minimum flow (exact:
  :math:`\dot m_{min} c_p (T_s - T_c)`), :math:`q_c` the cooling of extra flow
  :math:`\delta\dot m\,c_p (T_z - T_c)`; unoccupied, :math:`q_h` is air at
  :math:`T_{s,max}` and :math:`q_c` air at :math:`T_c`.
* **Recovering flow and temperature** from the first step's :math:`q`:
  :math:`\dot m = \dot m_{min} + q_c / (c_p (T_z - T_c))` and
  :math:`T_s = T_c + q_h / (\dot m c_p)` (occupied), or the air flow that carries
  :math:`q` at :math:`T_{s,max}` / :math:`T_c` (unoccupied), with the estimated :math:`T_z`.
* **What is approximated**: only the costs and limits that depend on the flow and on
  :math:`T_z` — the extra flow per kW (:math:`1/(c_p (T_z - T_c))`), the coil duty of that
  flow, the capacity limits :math:`q_c \le (\dot m_{max} - \dot m_{min}) c_p (T_z - T_c)` —
  are evaluated on the previous solution's predicted :math:`T_z` (linear time-varying),
  and the cubic fan law is replaced by its second-order Taylor expansion at the previous
  predicted total flow (convex). ``iterations > 1`` repeats the QP with the new
  prediction (successive linearization, Kelman & Borrelli 2011).

The KPI table and the figure are those of the economic example.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from thermctl.model import ThermalModel

from .common import Forecast, HVACModel, MPCSolution

__all__ = ["LinearWeights", "LinearMPC", "main"]

log = logging.getLogger(__name__)

_MIN_LIFT = 1.0  # [K] floor of T_z − T_c and T_s,max − T_z in the flow-per-kW coefficients


@dataclass(frozen=True)
class LinearWeights:
    """Penalty weights of the linear MPC (energy in kWh, as the economic MPC).

    Attributes
    ----------
    comfort_linear : float
        [kWh per K·h]
    comfort_quadratic : float
        [kWh per K²·h]
    move : float
        [kWh per kW²] of change of ``q_h`` and ``q_c`` from step to step.
    """

    comfort_linear: float = 5.0
    comfort_quadratic: float = 50.0
    move: float = 1e-3


class LinearMPC:
    """Linear MPC on the exported discrete ``StateSpace`` (see the module docstring).

    Parameters
    ----------
    model : ThermalModel
        The controller's model; only its ``to_statespace`` export is used for the dynamics.
    hvac : HVACModel
    comfort_zones : list of str
    dt : float
        MPC step [s] (the ``StateSpace`` is discretised at it, exact ZOH).
    horizon : int
        Number of steps N.
    solver : str
        ``casadi.conic`` plugin for the dense QP: ``qpoases`` (default: dense active set,
        0.1-0.4 s here), ``osqp`` or ``piqp`` (about 3 s: thousands of ADMM / tens of
        interior-point iterations on this condensed QP), ``highs`` (fast when it works, but
        its active set cycled until its time limit on some closed-loop steps).
    weights : LinearWeights
    iterations : int
        QPs per step (1: coefficients from the previous step's prediction).
    T_c0 : float
        Cold-deck temperature of the linearization point [°C] (any value: the model is
        affine in ``Ts`` at fixed flow).

    Examples
    --------
    >>> mpc = LinearMPC(model, hvac, ["r240", "r241"], dt=900, horizon=24)  # doctest: +SKIP
    >>> sol = mpc.solve(x_hat, forecast)                                    # doctest: +SKIP
    """

    def __init__(self, model: ThermalModel, hvac: HVACModel, comfort_zones, dt: float = 900.0,
                 horizon: int = 24, solver: str = "qpoases", weights: LinearWeights = LinearWeights(),
                 iterations: int = 1, T_c0: float = 12.8):
        if int(horizon) != horizon or horizon < 1:
            raise ValueError(f"horizon must be a positive integer, found {horizon!r}")
        if int(iterations) != iterations or iterations < 1:
            raise ValueError(f"iterations must be a positive integer, found {iterations!r}")
        net = model.network
        self.model, self.hvac, self.weights = model, hvac, weights
        self.dt, self.N, self.iterations = float(dt), int(horizon), int(iterations)
        self.solver_name = solver
        self.zones = list(net.zones)
        unknown = [z for z in comfort_zones if z not in self.zones]
        if unknown:
            raise ValueError(f"comfort zones {unknown} are not zones of the model {self.zones}")
        self.comfort_idx = np.array([self.zones.index(z) for z in comfort_zones], dtype=int)
        self.sup = hvac.supplied
        self._prev = None
        t0 = time.perf_counter()
        self.systems = {on: self._export(on, T_c0) for on in (True, False)}
        self._qp = None
        self.build_time = time.perf_counter() - t0

    # ---- the exported linear models ------------------------------------------
    def _export(self, on: bool, T_c0: float) -> dict:
        """``x+ = A x + B_Ts Ts + B_T T_b + B_Q Q + c`` at the mode's base flow."""
        net = self.model.network
        m_lo = np.asarray(self.hvac.ms_min, float) if on else np.zeros(net.n_zones)
        op = self.model.operating_point(ms=dict(zip(self.zones, m_lo)), Ts=T_c0, T=15.0, Q=0.0)
        sys = self.model.to_statespace(op, dt=self.dt)
        labels = list(sys.input_labels)
        cols = {g: [labels.index(f"{g}[{n}]") for n in names]
                for g, names in (("Ts", self.zones), ("T", net.boundary), ("Q", self.zones))}
        A, B = np.asarray(sys.A), np.asarray(sys.B)
        # deviation form → affine form in (Ts, T_b, Q); the flow stays at the base value, so
        # the ms columns drop out (their deviation is always zero)
        used = cols["Ts"] + cols["T"] + cols["Q"]
        c = op.x - A @ op.x - B[:, used] @ op.u[used]
        return {"A": A, "B_Ts": B[:, cols["Ts"]], "B_T": B[:, cols["T"]], "B_Q": B[:, cols["Q"]],
                "c": c, "ms": m_lo, "sys": sys, "op": op}

    # ---- QP (condensed: the states are eliminated) ------------------------------
    NU = 3  # inputs per box and step: q_r (reheat at base flow), q_x (hot air), q_c (cold air)

    def _predict(self, x0, fc: Forecast):
        """Zone temperatures as affine functions of the inputs, ``Y_k = Yc_k + Ym_k U``.

        ``U`` stacks ``u_k = [q_r; q_x; q_c]`` [kW] of the supplied zones for k = 0..N-1;
        the heat into zone z is ``q_r + q_x − q_c``. The exported system switches with the
        (known) occupied mode of each step.

        Returns
        -------
        Yc : ndarray, shape (N + 1, ns)
        Ym : ndarray, shape (N + 1, ns, 3 ns N)
        rollout : callable
            ``rollout(U) -> X``, the full predicted state, shape (N + 1, n_states).
        """
        N, ns, nz = self.N, len(self.sup), len(self.zones)
        nu = self.NU * ns
        E = np.zeros((nz, nu))   # u_k [kW] → heat per zone [W]
        for j, sign in enumerate((1e3, 1e3, -1e3)):
            E[self.sup, j * ns + np.arange(ns)] = sign
        on = np.asarray(fc.hvac_on[:N], bool)
        v = np.asarray(x0, float).copy()
        M = np.zeros((len(v), nu * N))
        Yc = np.empty((N + 1, ns))
        Ym = np.empty((N + 1, ns, nu * N))
        Yc[0], Ym[0] = v[self.sup], 0.0
        steps = []
        for k in range(N):
            sysd = self.systems[bool(on[k])]
            Gk = sysd["B_Q"] @ E
            e = (sysd["B_Q"] @ fc.gains[k] + sysd["B_Ts"] @ np.full(nz, fc.T_c[k])
                 + sysd["B_T"] @ fc.T_boundary[k] + sysd["c"])
            v = sysd["A"] @ v + e
            M = sysd["A"] @ M
            M[:, nu * k: nu * (k + 1)] += Gk
            Yc[k + 1], Ym[k + 1] = v[self.sup], M[self.sup]
            steps.append((sysd["A"], Gk, e))

        def rollout(U):
            X = np.empty((N + 1, len(x0)))
            X[0] = x0
            for k, (A, Gk, e) in enumerate(steps):
                X[k + 1] = A @ X[k] + Gk @ U[nu * k: nu * (k + 1)] + e
            return X

        return Yc, Ym, rollout

    def _coefficients(self, fc: Forecast, T_pred):
        """LTV coefficients from predicted mid-step zone temperatures ``T_pred`` (ns, N) [°C]."""
        hv, N = self.hvac, self.N
        on = np.asarray(fc.hvac_on[:N], float)
        T_c = np.asarray(fc.T_c[:N], float)
        lift_c = np.maximum(T_pred - T_c[None, :], _MIN_LIFT)        # T_z − T_c [K]
        lift_h = np.maximum(hv.Ts_max - T_pred, _MIN_LIFT)            # Ts_max − T_z [K]
        m_lo = np.asarray(hv.ms_min, float)[self.sup]
        return {"a_c": 1e3 / (hv.cp * lift_c),          # extra cold-air flow per kW [kg/s]
                "a_x": 1e3 / (hv.cp * lift_h),          # extra hot-air flow per kW [kg/s]
                "kappa": (hv.Ts_max - T_c[None, :]) / lift_h,   # reheat per kW of hot air [-]
                "base": m_lo[:, None] * on[None, :]}    # base flow [kg/s]

    def _qp_data(self, x0, fc: Forecast, T_pred, m_pred, u_prev):
        """Dense QP ``min ½zᵀHz + gᵀz, lba ≤ Az ≤ uba, lbz ≤ z ≤ ubz`` of one MPC step."""
        hv, w = self.hvac, self.weights
        N, ns, nc = self.N, len(self.sup), len(self.comfort_idx)
        cp, dth, nu = hv.cp, self.dt / 3600.0, self.NU * ns
        nU = nu * N
        iSL, iSH, iCC, iCH = nU, nU + nc * N, nU + 2 * nc * N, nU + 2 * nc * N + N
        nzv = iCH + N
        Yc, Ym, rollout = self._predict(x0, fc)
        T_c, T_o = np.asarray(fc.T_c[:N], float), np.asarray(fc.T_out[:N], float)
        co = self._coefficients(fc, T_pred)
        a_c, a_x, kappa, base = co["a_c"], co["a_x"], co["kappa"], co["base"]
        ms_max = np.asarray(hv.ms_max, float)[self.sup]
        H = np.zeros((nzv, nzv))
        g = np.zeros(nzv)
        rows, lo_r, hi_r = [], [], []
        pos = {z: j for j, z in enumerate(self.sup)}
        P0, md = hv.fan_design_power / 1e3, hv.ms_design
        r_, x_, c_ = (slice(j * ns, (j + 1) * ns) for j in range(3))
        for k in range(N):
            o = nu * k
            blk = slice(o, o + nu)
            # reheat: 1 per kW at base flow, kappa per kW of hot air (linear)
            g[o: o + ns] += dth / hv.eta_heat
            g[o + ns: o + 2 * ns] += dth * kappa[:, k] / hv.eta_heat
            # total flow m_k = m0 + f·u_k; fan: 2nd-order Taylor of P0 (m/md)³ at m_pred
            f = np.concatenate([np.zeros(ns), a_x[:, k], a_c[:, k]])
            m0, mb = base[:, k].sum(), m_pred[k]
            c1, c2 = 3 * P0 * mb ** 2 / md ** 3, 3 * P0 * mb / md ** 3
            g[blk] += dth * (c1 + 2 * c2 * (m0 - mb)) * f
            H[blk, blk] += dth * 2 * c2 * np.outer(f, f)
            # coil split: CC − CH − coil(U) = c0 [kW]; the base flow sees the predicted state,
            # the extra flow the LTV temperature
            mix_hat = hv.f_oa * T_o[k] + (1 - hv.f_oa) * T_pred[:, k] - T_c[k]
            row = np.zeros(nzv)
            row[:nU] -= (base[:, k] * cp * (1 - hv.f_oa) / 1e3) @ Ym[k]
            row[blk] -= f * cp * np.tile(mix_hat, 3) / 1e3
            row[iCC + k], row[iCH + k] = 1.0, -1.0
            c0 = np.sum(base[:, k] * cp * (hv.f_oa * T_o[k] + (1 - hv.f_oa) * Yc[k] - T_c[k])) / 1e3
            rows.append(row), lo_r.append(c0), hi_r.append(c0)
            g[iCC + k] += dth / hv.cop_cool
            g[iCH + k] += dth / hv.eta_heat
            # box capacity: base + extra hot + extra cold flow <= ms_max
            for j in range(ns):
                row = np.zeros(nzv)
                row[o + ns + j], row[o + 2 * ns + j] = a_x[j, k], a_c[j, k]
                rows.append(row), lo_r.append(-np.inf), hi_r.append(ms_max[j] - base[j, k])
            # comfort, soft: lo ≤ T + s_lo, T − s_hi ≤ hi at the end of the step
            for j, z in enumerate(self.comfort_idx):
                p = pos[z]
                row = np.zeros(nzv)
                row[:nU] = Ym[k + 1, p]
                row[iSL + k * nc + j] = 1.0
                rows.append(row), lo_r.append(fc.lo[k] - Yc[k + 1, p]), hi_r.append(np.inf)
                row = np.zeros(nzv)
                row[:nU] = Ym[k + 1, p]
                row[iSH + k * nc + j] = -1.0
                rows.append(row), lo_r.append(-np.inf), hi_r.append(fc.hi[k] - Yc[k + 1, p])
        slack = slice(iSL, iCC)
        g[slack] += dth * w.comfort_linear
        H[slack, slack] += np.eye(2 * nc * N) * dth * 2 * w.comfort_quadratic
        # moves: λ Σ ||u_k − u_{k−1}||², u_{−1} = the input applied now
        D = np.eye(nU) - np.eye(nU, k=-nu)
        H[:nU, :nU] += 2 * w.move * D.T @ D
        g[:nu] -= 2 * w.move * u_prev
        # reheat at base flow up to Ts_max (0 when the base flow is 0)
        ubz = np.full(nzv, np.inf)
        cap_r = (base * cp * (hv.Ts_max - T_c[None, :])) / 1e3
        Ub = ubz[:nU].reshape(N, self.NU, ns)
        Ub[:, 0, :] = cap_r.T
        ubz[:nU] = Ub.ravel()
        return {"H": H, "g": g, "A": np.array(rows), "lba": np.array(lo_r),
                "uba": np.array(hi_r), "lbz": np.zeros(nzv), "ubz": ubz, "rollout": rollout,
                "coef": co, "nU": nU}

    def _make_solver(self, H, A):
        opts = {"error_on_fail": False}
        if self.solver_name == "qpoases":
            opts["printLevel"] = "none"
        elif self.solver_name == "osqp":
            # kW and °C keep the QP well scaled; 1e-5 is far below sensor noise
            opts["osqp"] = {"verbose": False, "eps_abs": 1e-5, "eps_rel": 1e-5,
                            "max_iter": 50000, "polish": True}
        elif self.solver_name == "highs":
            opts["highs"] = {"output_flag": False, "time_limit": 30.0}
        return ca.conic("linear_mpc", self.solver_name,
                        {"h": ca.Sparsity.dense(*H.shape), "a": ca.Sparsity.dense(*A.shape)}, opts)

    # ---- solve -----------------------------------------------------------------
    def solve(self, x0, fc: Forecast) -> MPCSolution:
        """Solve the QP (``iterations`` times) and recover flows and supply temperatures.

        Parameters
        ----------
        x0 : array_like, shape (n_states,)
            Current (estimated) state [°C].
        fc : Forecast

        Returns
        -------
        MPCSolution
        """
        N, ns = self.N, len(self.sup)
        if len(fc) < N:
            raise ValueError(f"forecast covers {len(fc)} steps, the horizon needs {N}")
        x0 = np.asarray(x0, float)
        hv = self.hvac
        if self._prev is None:
            T_pred = np.repeat(x0[self.sup][:, None], N, axis=1)
            m_pred = np.full(N, float(np.sum(hv.ms_min)))
            u_prev = np.zeros(self.NU * ns)
            z0 = None
        else:
            T_pred = np.hstack([self._prev["T"][:, 1:], self._prev["T"][:, -1:]])
            m_pred = np.concatenate([self._prev["m"][1:], self._prev["m"][-1:]])
            u_prev = self._prev["z"][: self.NU * ns]
            z0 = self._prev["z"]
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(self.iterations):
            qp = self._qp_data(x0, fc, T_pred, m_pred, u_prev)
            if self._qp is None:
                self._qp = self._make_solver(qp["H"], qp["A"])
            args = {"h": qp["H"], "g": qp["g"], "a": qp["A"], "lba": qp["lba"], "uba": qp["uba"],
                    "lbx": qp["lbz"], "ubx": qp["ubz"]}
            if z0 is not None:
                args["x0"] = z0
            r = self._qp(**args)
            z = np.asarray(r["x"]).ravel()
            Uk = z[: qp["nU"]].reshape(N, self.NU, ns)     # [step, (q_r, q_x, q_c), box]
            X = qp["rollout"](z[: qp["nU"]])
            co = qp["coef"]
            m_pred = (co["base"] + co["a_x"] * Uk[:, 1].T + co["a_c"] * Uk[:, 2].T).sum(axis=0)
            T_pred = _mid(X)[:, self.sup].T
            z0 = z
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        st = self._qp.stats()
        self._prev = {"z": z, "T": T_pred, "m": m_pred}
        ms_plan, Ts_plan = self._recover(Uk, fc, X, x0)
        return MPCSolution(ms=ms_plan, Ts=Ts_plan, X=X, success=bool(st.get("success", False)),
                           status=str(st.get("return_status", "")),
                           iterations=int(st.get("iter_count", -1) or -1),
                           solve_time=wall, cpu_time=cpu, cost=float(r["cost"]))

    def _recover(self, Uk, fc: Forecast, X, x0):
        """Flow [kg/s] and supply temperature [°C] of every step from ``q_r, q_x, q_c``.

        ``ms = base + q_x / (c_p (Ts_max − T_z)) + q_c / (c_p (T_z − T_c))`` and
        ``Ts = T_c + (q_r + κ q_x) / (ms c_p)``, with the zone temperature at mid-step
        (the heat a fixed flow delivers falls as the zone approaches the supply temperature).
        """
        N, nz = self.N, len(self.zones)
        hv = self.hvac
        T_c = np.asarray(fc.T_c[:N], float)
        Tz = _mid(X)[:, self.sup].T
        co = self._coefficients(fc, Tz)
        qr, qx, qc = (Uk[:, j].T for j in range(3))                     # (ns, N) [kW]
        flow = co["base"] + co["a_x"] * qx + co["a_c"] * qc
        reheat = 1e3 * (qr + co["kappa"] * qx)                          # [W]
        ms_max = np.asarray(hv.ms_max, float)[self.sup]
        flow = np.clip(flow, 0.0, ms_max[:, None])
        lift = np.where(flow > 1e-9, reheat / (np.maximum(flow, 1e-9) * hv.cp), 0.0)
        ms = np.zeros((N, nz))
        Ts = np.repeat(T_c[:, None], nz, axis=1)
        ms[:, self.sup] = flow.T
        Ts[:, self.sup] = np.clip(T_c[None, :] + lift, T_c[None, :], hv.Ts_max).T
        return ms, Ts

    def reset(self) -> None:
        """Forget the previous solution."""
        self._prev = None


def _mid(X):
    """Mid-step states of a trajectory (N + 1, n) → (N, n) (trapezoid of the step ends)."""
    return 0.5 * (X[:-1] + X[1:])


def main(argv=None):
    """Run the linear MPC against the baseline on the testbed; print and save the table."""
    from .simulator import run_example
    return run_example("linear", argv)


if __name__ == "__main__":
    main()
