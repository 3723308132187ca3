r"""Linear MPC of a VAV building with the exported ``StateSpace``, solved as a QP.

Run from the repository root::

    python -m mpc_examples.linear_mpc              # 3 days, identified model
    python -m mpc_examples.linear_mpc --hours 3 --start-day 10 --start-hour 5   # fast mode

The same task as :mod:`mpc_examples.economic_mpc` (same comfort band, same energy model,
same plant), but the controller only uses what ``ThermalModel.to_statespace(op, dt)``
exports: discrete matrices :math:`(A, B)` at an operating point, and solves one sparse QP
per step (states kept as variables, the exported steps as equality rows; PIQP through
``casadi.conic``, OSQP, qpOASES and HiGHS are options).

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
from scipy import sparse

from thermctl.model import ThermalModel

from .common import Forecast, HVACModel, MPCSolution, RecedingHorizonMPC
from .sparse import TRANSCRIPTIONS, at_flow, step_rows

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


class LinearMPC(RecedingHorizonMPC):
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
        ``casadi.conic`` plugin for the sparse QP. ``piqp`` (default: sparse interior
        point, 0.36 s for one 6-h, 10-min QP of the 7-zone building: 2916 variables, 2664
        rows); ``osqp`` (ADMM, 1.5 s on the same QP); ``qpoases`` and ``highs`` (active
        set: many times slower on this many active bounds; qpOASES took 1.5-3 s on the
        *condensed* QP, which this class no longer builds).
    weights : LinearWeights
    iterations : int
        QPs per step (1: coefficients from the previous step's prediction).
    T_c0 : float
        Cold-deck temperature of the linearization point [°C] (any value: the model is
        affine in ``Ts`` at fixed flow).
    transcription : {"zoh", "euler", "radau", "radau-dense"}
        How a step is written (:mod:`mpc_examples.sparse`): ``zoh`` the exported discrete
        ``StateSpace`` (dense ``A_k``, exact; default, fastest up to ~100 states),
        ``euler`` / ``radau`` sparse implicit rows of the continuous model (for big
        buildings: 125 k instead of 16 M nonzeros on the 49-zone floor).
    tariff : bool
        Price energy with the forecasts' :class:`~mpc_examples.common.Tariff`, charge
        the peak electric power and soften the event cap (extra rows and variables).
    steps : sequence of int, optional
        A non-uniform prediction grid: the length of each of the ``horizon`` steps in
        multiples of ``dt`` (default all 1). E.g. ``dt=600, horizon=16,
        steps=[1] * 6 + [3] * 10``: the first hour in 10-min steps, then 30-min steps to
        6 h. The forecast's step ``k`` must then cover step ``k`` of this grid
        (:meth:`mpc_examples.simulator.Scenario.forecast` with ``steps``). Why: PIQP's
        sparse factorization on the 49-zone floor grows about as N³ with the number of
        steps (AMD's separators span the whole horizon; measured 4.0 s CPU for 36 steps,
        0.34 s for this grid), while the applied input comes from the first steps: on the
        7-zone warm-up it is the uniform grid's to 3e-5 K (supply temperature), and 8 h
        closed loop use the same energy to 0.002 % (docs/mpc.md). Coarse steps from 30 min
        on moved the 06:20 reheat by up to 17 K: keep the first hour fine. The tail is
        costed and constrained at its own steps (the band at each step's end only).

    Examples
    --------
    >>> mpc = LinearMPC(model, hvac, ["r240", "r241"], dt=900, horizon=24)  # doctest: +SKIP
    >>> sol = mpc.solve(x_hat, forecast)                                    # doctest: +SKIP
    """

    def __init__(self, model: ThermalModel, hvac: HVACModel, comfort_zones, dt: float = 900.0,
                 horizon: int = 24, solver: str = "piqp", weights: LinearWeights = LinearWeights(),
                 iterations: int = 1, T_c0: float = 12.8, transcription: str = "zoh",
                 tariff: bool = False, steps=None):
        if int(iterations) != iterations or iterations < 1:
            raise ValueError(f"iterations must be a positive integer, found {iterations!r}")
        if transcription not in TRANSCRIPTIONS:
            raise ValueError(f"transcription must be one of {TRANSCRIPTIONS}, found {transcription!r}")
        super().__init__(model, hvac, comfort_zones, dt, horizon, weights)
        steps = np.ones(self.N, int) if steps is None else np.asarray(steps)
        if steps.shape != (self.N,) or np.any(steps < 1) or np.any(steps != np.round(steps)):
            raise ValueError(f"steps must be {self.N} positive integers, found {steps!r}")
        self.steps = steps.astype(int)
        self.h = self.dt * self.steps   # [s] length of each prediction step
        self.iterations = int(iterations)
        self.solver_name = solver
        self.transcription = transcription
        self.tariff = bool(tariff)
        t0 = time.perf_counter()
        # the step rows of each mode and step length; ``systems[on]``: those of the first step
        self.grid_systems = {(on, int(m)): self._export(on, T_c0, m * self.dt)
                             for on in (True, False) for m in np.unique(self.steps)}
        self.systems = {on: self.grid_systems[on, self.steps[0]] for on in (True, False)}
        self.stages = self.systems[True]["L"].shape[0] // model.network.n_states
        self._unify()
        self._qp = self._pattern = None
        self.n_variables = self._layout()["n"]
        self.n_nonzeros = None   # of the QP's H and A, known after the first solve
        self.build_time = time.perf_counter() - t0

    # ---- the step rows at the two base flows ---------------------------------
    def _export(self, on: bool, T_c0: float, h: float) -> dict:
        """``L x+ = A x + B_Ts Ts + B_T T_b + B_Q Q + c`` at the mode's base flow.

        ``zoh``: the exported discrete ``StateSpace`` (``L = I``); the others: the step rows
        of :func:`mpc_examples.sparse.step_rows` from the continuous sparse matrices.
        """
        net = self.model.network
        m_lo = np.asarray(self.hvac.ms_min, float) if on else np.zeros(net.n_zones)
        if self.transcription != "zoh":
            r = step_rows(at_flow(self.model, m_lo), h, self.transcription)
            return {"L": r.L, "A": r.N, "B_Ts": r.B_Ts, "B_T": r.B_T, "B_Q": r.B_Q,
                    "c": np.zeros(r.L.shape[0]), "ms": m_lo}
        op = self.model.operating_point(ms=dict(zip(self.zones, m_lo)), Ts=T_c0, T=15.0, Q=0.0)
        sys = self.model.to_statespace(op, dt=h)
        labels = list(sys.input_labels)
        cols = {g: [labels.index(f"{g}[{n}]") for n in names]
                for g, names in (("Ts", self.zones), ("T", net.boundary), ("Q", self.zones))}
        A, B = np.asarray(sys.A), np.asarray(sys.B)
        # deviation form → affine form in (Ts, T_b, Q); the flow stays at the base value, so
        # the ms columns drop out (their deviation is always zero)
        used = cols["Ts"] + cols["T"] + cols["Q"]
        c = op.x - A @ op.x - B[:, used] @ op.u[used]
        return {"L": np.eye(net.n_states), "A": A, "B_Ts": B[:, cols["Ts"]], "B_T": B[:, cols["T"]],
                "B_Q": B[:, cols["Q"]], "c": c, "ms": m_lo, "sys": sys, "op": op}

    def _unify(self):
        """Triplets of ``L``, ``A`` and ``B_Q E`` on one pattern for both modes and every
        step length (explicit zeros kept), so the QP's sparsity never changes and one
        solver serves every step."""
        nz, ns = len(self.zones), len(self.sup)
        E = sparse.lil_matrix((nz, self.NU * ns))   # u_k [kW] → heat per zone [W]
        for j, sign in enumerate((1e3, 1e3, -1e3)):
            E[self.sup, j * ns + np.arange(ns)] = sign
        E = sparse.csr_matrix(E)
        systems = list(self.grid_systems.values())
        for s in systems:
            s["G"] = sparse.csr_matrix(s["B_Q"]) @ E
        for key in ("L", "A", "G"):
            Ms = [sparse.csr_matrix(s[key]) for s in systems]
            P = sum(abs(M) for M in Ms).tocoo()
            r, c = P.row, P.col
            for s, M in zip(systems, Ms):
                s[key + "_t"] = (r, c, np.asarray(M[r, c]).ravel())

    # ---- QP (sparse: states stay decision variables) -----------------------------
    NU = 3  # inputs per box and step: q_r (reheat at base flow), q_x (hot air), q_c (cold air)

    def _layout(self):
        """Offsets of the QP's variable blocks: U (inputs), X (states 1..N, each after its
        Radau stage state if any), S (comfort slacks), CC / CH (coil cooling / preheat), MF
        (extra supply flow), EX (electric power above the cap), PK (peak electric power)."""
        N, ns, nc = self.N, len(self.sup), len(self.comfort_idx)
        nx, nu = self.model.network.n_states, self.NU * ns
        iX = nu * N
        iS = iX + self.stages * nx * N
        iCC = iS + nc * N
        iCH = iCC + N
        iMF = iCH + N
        iEX = iMF + N
        iPK = iEX + N * self.tariff
        return {"nu": nu, "nx": nx, "nw": self.stages * nx, "U": 0, "X": iX, "S": iS, "CC": iCC, "CH": iCH,
                "MF": iMF, "EX": iEX, "PK": iPK, "n": iPK + self.tariff}

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
        """Sparse QP ``min ½zᵀHz + gᵀz, lba ≤ Az ≤ uba, lbz ≤ z ≤ ubz`` of an MPC step.

        ``z = [u_0..u_{N-1}, x_1..x_N, s, CC, CH, MF, EX, PK]``: the steps are equality rows
        ``L_k x_{k+1} − A_k x_k − G_k u_k = e_k`` (of the mode of step k; ``L = I`` for the
        explicit forms), so the problem grows linearly with the horizon, and H and A are as
        sparse as the step rows. The fan's quadratic model acts on the extra flow ``MF_k``
        (one row ``MF_k = f·u_k``), which keeps H diagonal in it. H and A are returned as
        ``scipy.sparse.csc_matrix`` whose pattern does not depend on the data (explicit zeros
        are kept), so one solver serves every step.
        """
        hv, w = self.hvac, self.weights
        N, ns, nc = self.N, len(self.sup), len(self.comfort_idx)
        L = self._layout()
        nu, nx, n = L["nu"], L["nx"], L["n"]
        cp = hv.cp
        dth = self.h / 3600.0   # [h] per step
        nz = len(self.zones)
        T_c, T_o = np.asarray(fc.T_c[:N], float), np.asarray(fc.T_out[:N], float)
        on = np.asarray(fc.hvac_on[:N], bool)
        tf = fc.tariff
        p_el = np.ones(N) if tf is None else np.asarray(tf.elec[:N], float)
        p_ht = np.ones(N) if tf is None else np.asarray(tf.heat[:N], float)
        # no cap: a finite one no building reaches (a row free on both sides makes PIQP warn)
        cap = (np.full(N, 1e6) if tf is None or tf.elec_cap is None
               else np.minimum(np.asarray(tf.elec_cap[:N], float), 1e6))
        co = self._coefficients(fc, T_pred)
        a_c, a_x, kappa, base = co["a_c"], co["a_x"], co["kappa"], co["base"]
        ms_max = np.asarray(hv.ms_max, float)[self.sup]
        P0, md = hv.fan_design_power / 1e3, hv.ms_design
        x0 = np.asarray(x0, float)
        g = np.zeros(n)
        Ar, Ac, Av, lba, uba = [], [], [], [], []
        row = 0

        def put(rows, cols, vals):
            Ar.append(np.asarray(rows, dtype=np.int64).ravel())
            Ac.append(np.asarray(cols, dtype=np.int64).ravel())
            Av.append(np.asarray(vals, dtype=float).ravel())

        def bounds(lo, hi, m):
            lba.append(np.broadcast_to(np.asarray(lo, float), (m,)))
            uba.append(np.broadcast_to(np.asarray(hi, float), (m,)))

        nw = L["nw"]
        iu = lambda k: L["U"] + nu * k            # noqa: E731
        iw = lambda k: L["X"] + nw * (k - 1)      # noqa: E731  (w_k: [stage,] x_k, k = 1..N)
        ix = lambda k: iw(k) + nw - nx            # noqa: E731  (x_k, k = 1..N)
        fan_c = []
        for k in range(N):
            sysd = self.grid_systems[bool(on[k]), self.steps[k]]
            e = (sysd["B_Q"] @ fc.gains[k] + sysd["B_Ts"] @ np.full(nz, T_c[k])
                 + sysd["B_T"] @ fc.T_boundary[k] + sysd["c"])
            e = np.asarray(e).ravel()
            # dynamics: L x_{k+1} − A x_k − G u_k = e (x_0 is data)
            r, c, v = sysd["L_t"]
            put(row + r, iw(k + 1) + c, v)
            r, c, v = sysd["A_t"]
            if k == 0:
                e = e + np.asarray(sysd["A"] @ x0).ravel()
            else:
                put(row + r, ix(k) + c, -v)
            r, c, v = sysd["G_t"]
            put(row + r, iu(k) + c, -v)
            bounds(e, e, nw)
            row += nw
            # reheat: 1 per kW at base flow, kappa per kW of hot air (linear)
            o = iu(k)
            g[o: o + ns] += dth[k] * p_ht[k] / hv.eta_heat
            g[o + ns: o + 2 * ns] += dth[k] * p_ht[k] * kappa[:, k] / hv.eta_heat
            # extra flow MF_k = f·u_k; fan: 2nd-order Taylor of P0 (m/md)³ at m_pred
            f = np.concatenate([a_x[:, k], a_c[:, k]])
            put(np.full(2 * ns + 1, row), np.r_[L["MF"] + k, o + ns + np.arange(2 * ns)],
                np.r_[1.0, -f])
            bounds(0.0, 0.0, 1)
            row += 1
            m0, mb = base[:, k].sum(), m_pred[k]
            c1, c2 = 3 * P0 * mb ** 2 / md ** 3, 3 * P0 * mb / md ** 3
            g[L["MF"] + k] += dth[k] * p_el[k] * (c1 + 2 * c2 * (m0 - mb))
            fan_c.append((c1, c2, P0 * (mb / md) ** 3 + c1 * (m0 - mb)))  # fan ≈ c + c1 MF
            # coil split: CC − CH − coil = const [kW]; the base flow sees the zone state at
            # the step's start, the extra flow the LTV temperature
            mix_hat = hv.f_oa * T_o[k] + (1 - hv.f_oa) * T_pred[:, k] - T_c[k]
            kb = base[:, k] * cp * (1 - hv.f_oa) / 1e3
            fu = np.concatenate([np.zeros(ns), f])
            cols = [L["CC"] + k, L["CH"] + k, *(o + np.arange(nu))]
            vals = [1.0, -1.0, *(-fu * cp * np.tile(mix_hat, 3) / 1e3)]
            c0 = np.sum(base[:, k] * cp * (hv.f_oa * T_o[k] - T_c[k])) / 1e3
            if k == 0:
                c0 += kb @ x0[self.sup]
            else:
                cols += list(ix(k) + self.sup)
                vals += list(-kb)
            put(np.full(len(cols), row), cols, vals)
            bounds(c0, c0, 1)
            row += 1
            g[L["CC"] + k] += dth[k] * p_el[k] / hv.cop_cool
            g[L["CH"] + k] += dth[k] * p_ht[k] / hv.eta_heat
            # electric power (fan linearised + chiller): PK ≥ it; above the cap costs EX
            c1, _, cf = fan_c[-1]
            if self.tariff:
                put([row] * 3, [L["PK"], L["MF"] + k, L["CC"] + k], [1.0, -c1, -1.0 / hv.cop_cool])
                bounds(cf, np.inf, 1)
                put([row + 1] * 3, [L["EX"] + k, L["MF"] + k, L["CC"] + k],
                    [-1.0, c1, 1.0 / hv.cop_cool])
                bounds(-np.inf, cap[k] - cf, 1)
                row += 2
            # box capacity: base + extra hot + extra cold flow <= ms_max
            j = np.arange(ns)
            put(np.repeat(row + j, 2), np.column_stack([o + ns + j, o + 2 * ns + j]),
                np.column_stack([a_x[:, k], a_c[:, k]]))
            bounds(-np.inf, ms_max - base[:, k], ns)
            row += ns
            # comfort, soft: lo ≤ T + s, T − s ≤ hi at the end of the step (one slack: the
            # band is wider than zero, so at most one side is violated)
            j = np.arange(nc)
            sc = L["S"] + k * nc + j
            xz = ix(k + 1) + self.comfort_idx
            put(np.repeat(row + j, 2), np.column_stack([xz, sc]), np.tile([1.0, 1.0], nc))
            bounds(fc.lo[k], np.inf, nc)
            put(np.repeat(row + nc + j, 2), np.column_stack([xz, sc]), np.tile([1.0, -1.0], nc))
            bounds(-np.inf, fc.hi[k], nc)
            row += 2 * nc
        g[L["S"]:L["CC"]] += np.repeat(dth, nc) * w.comfort_linear
        if self.tariff:
            if tf is None:
                raise ValueError("a LinearMPC built with tariff=True needs forecasts with a tariff")
            g[L["EX"]:L["PK"]] += dth * tf.cap_penalty
            # a peak without a charge is not unique: an interior point would wander along it
            g[L["PK"]] += max(tf.demand, 1e-4)
        # H: comfort (quadratic), fan (on MF), moves λ Σ ||u_k − u_{k−1}||², u_{−1} = now
        Hr, Hc, Hv = [], [], []
        sl = np.arange(L["S"], L["CC"])
        Hr.append(sl), Hc.append(sl), Hv.append(np.repeat(dth, nc) * 2 * w.comfort_quadratic)
        mf = L["MF"] + np.arange(N)
        Hr.append(mf), Hc.append(mf)
        Hv.append(np.array([dth[k] * p_el[k] * 2 * fan_c[k][1] for k in range(N)]))
        diag = np.full(nu * N, 4.0 * w.move)
        diag[-nu:] = 2.0 * w.move
        Hr.append(np.arange(nu * N)), Hc.append(np.arange(nu * N)), Hv.append(diag)
        off = np.arange(nu, nu * N)
        Hr += [off, off - nu]
        Hc += [off - nu, off]
        Hv += [np.full(off.size, -2 * w.move)] * 2
        g[: nu] -= 2 * w.move * u_prev
        lbz = np.full(n, -np.inf)
        ubz = np.full(n, np.inf)
        lbz[:L["X"]] = 0.0
        lbz[L["S"]:] = 0.0
        lbz[L["MF"]:L["EX"]] = -np.inf
        if self.tariff:
            lbz[L["PK"]] = tf.peak_floor
        # reheat at base flow up to Ts_max (0 when the base flow is 0)
        cap_r = (base * cp * (hv.Ts_max - T_c[None, :])) / 1e3
        for k in range(N):
            ubz[iu(k): iu(k) + ns] = cap_r[:, k]
        H = sparse.csc_matrix((np.concatenate(Hv), (np.concatenate(Hr), np.concatenate(Hc))),
                              shape=(n, n))
        A = sparse.csc_matrix((np.concatenate(Av), (np.concatenate(Ar), np.concatenate(Ac))),
                              shape=(row, n))
        H.sum_duplicates(), A.sum_duplicates()
        return {"H": H, "g": g, "A": A, "lba": np.concatenate(lba), "uba": np.concatenate(uba),
                "lbz": lbz, "ubz": ubz, "coef": co, "layout": L}

    def _make_solver(self, H, A):
        opts = {"error_on_fail": False}
        if self.solver_name == "qpoases":
            opts.update(printLevel="none", sparse=True)
        elif self.solver_name == "osqp":
            # kW and °C keep the QP well scaled; 1e-5 is far below sensor noise
            opts["osqp"] = {"verbose": False, "eps_abs": 1e-5, "eps_rel": 1e-5,
                            "max_iter": 50000, "polish": True}
        elif self.solver_name == "highs":
            opts["highs"] = {"output_flag": False, "time_limit": 30.0}
        return ca.conic("linear_mpc", self.solver_name,
                        {"h": _sparsity(H), "a": _sparsity(A)}, opts)

    def _same_pattern(self, qp) -> bool:
        return all(np.array_equal(p, M.indptr) and np.array_equal(i, M.indices)
                   for (p, i), M in zip(self._pattern[2], (qp["H"], qp["A"])))

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
        self.check_forecast(fc)
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
            if self._qp is None or not self._same_pattern(qp):
                # the solver is built once (the pattern never changes): not solve time
                t_b = time.perf_counter()
                self._pattern = (_sparsity(qp["H"]), _sparsity(qp["A"]),
                                 [(M.indptr.copy(), M.indices.copy()) for M in (qp["H"], qp["A"])])
                self._qp = self._make_solver(qp["H"], qp["A"])
                self.n_nonzeros = int(qp["H"].nnz + qp["A"].nnz)
                self.n_rows = int(qp["A"].shape[0])
                dt_b = time.perf_counter() - t_b
                self.build_time += dt_b
                t0 += dt_b
            args = {"h": ca.DM(self._pattern[0], qp["H"].data), "g": qp["g"],
                    "a": ca.DM(self._pattern[1], qp["A"].data), "lba": qp["lba"], "uba": qp["uba"],
                    "lbx": qp["lbz"], "ubx": qp["ubz"]}
            if z0 is not None:
                args["x0"] = z0
            r = self._qp(**args)
            z = np.asarray(r["x"]).ravel()
            L = qp["layout"]
            Uk = z[: L["X"]].reshape(N, self.NU, ns)       # [step, (q_r, q_x, q_c), box]
            X = np.vstack([x0, z[L["X"]: L["S"]].reshape(N, L["nw"])[:, -L["nx"]:]])
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


def _sparsity(M) -> ca.Sparsity:
    """CasADi sparsity of a ``scipy.sparse.csc_matrix`` (explicit zeros included)."""
    return ca.Sparsity(M.shape[0], M.shape[1], M.indptr.tolist(), M.indices.tolist())


def _mid(X):
    """Mid-step states of a trajectory (N + 1, n) → (N, n) (trapezoid of the step ends)."""
    return 0.5 * (X[:-1] + X[1:])


def main(argv=None):
    """Run the linear MPC against the baseline on the testbed; print and save the table."""
    from .simulator import run_example
    return run_example("linear", LinearMPC, argv)


if __name__ == "__main__":
    main()
