r"""Economic nonlinear MPC of a VAV building with the identified (bilinear) CasADi model.

Run from the repository root::

    python -m mpc_examples.economic_mpc              # 3 days, identified model
    python -m mpc_examples.economic_mpc --hours 3 --start-day 10 --start-hour 5   # fast mode
    python -m mpc_examples.economic_mpc --model identified,true,conduction-only  # model error
    python -m mpc_examples.economic_mpc --grid "6x1 5x6" --rti 1 --transcription euler  # building scale

At every MPC step (default 15 min) the controller solves, over a horizon of N steps
(default 6 h),

.. math::

    \min \sum_{k=0}^{N-1} \Delta t\,\Big[P_{fan,k} + \frac{Q_{rh,k} + Q^{-}_{coil,k}}{\eta_h}
        + \frac{Q^{+}_{coil,k}}{\mathrm{COP}}\Big]
        + \Delta t \sum_{k,z} \big(\rho_1 s_{z,k} + \rho_2 s_{z,k}^2\big)
        + \lambda \sum_k \|\Delta u_k\|^2

over the supply flow :math:`\dot m_{z,k}` and supply (reheat) temperature :math:`T_{s,z,k}`
of every VAV box, subject to the model's dynamics at the shooting nodes, the comfort band
softened by slacks :math:`s \ge 0` (lower and upper), box limits
(:math:`\dot m_{min}` in occupied mode, 0 otherwise, up to :math:`\dot m_{max}`;
:math:`T_c \le T_s \le T_{s,max}`) and the coil split
:math:`Q^{+}_{coil} - Q^{-}_{coil} = Q_{coil}`, :math:`Q^{\pm}_{coil} \ge 0` (exact at the
optimum because both are priced). The energy model is :class:`~mpc_examples.common.HVACModel`.

Transcription: multiple shooting, one shooting interval per MPC step. The step is the
model's own L-stable Radau IIA (Padé 1/2) rational step, the same as
``ThermalModel.to_casadi().F``. Two equivalent ways to write the continuity constraints:

``explicit``
    :math:`x_{k+1} - F(x_k, u_k) = 0` with ``F.map(N)``; ``F`` solves a dense linear system
    per step, so its derivatives are dense.
``implicit`` (default)
    :math:`D(u_k)\,x_{k+1} - N(u_k)\,x_k - c(u_k) = 0`, the same step multiplied by its
    (nonsingular) matrix :math:`D`; written with the model's ``f(x, u, p)`` only, it is
    polynomial and as sparse as the network, so IPOPT's Jacobian and Hessian stay sparse.
    With ``substeps > 1`` the intermediate states become decision variables.
``euler``
    :math:`x_{k+1} - x_k - h f(x_{k+1}, u_k) = 0`: implicit Euler (first order, L-stable),
    the linear MPC's default step. Its rows are one-hop (``A``, not ``A²``), so the QP of the
    SQP real-time iteration factors as fast as the linear MPC's; not the same optimum.

``implicit`` and ``explicit`` give the same optimum (the tests check it). Warm start: the previous primal and dual
solution shifted by one step (last step repeated), IPOPT ``warm_start_init_point``.

Building scale (docs/mpc.md, "The economic NMPC at building scale"): ``steps=`` gives a
non-uniform prediction grid (an hour of 10-min steps, then 1-h steps: 11 instead of 36
steps), ``rti_iter=`` a real-time iteration (by default one SQP step per control step: a
convex QP with a Gauss-Newton Hessian, solved by PIQP), ``transcription="euler"`` one-hop
rows that keep that QP cheap. On the 49-zone floor (661 states) with that grid and the Euler
rows: 0.18 s CPU per step with one SQP step, 0.61 s converged; closed-loop energy of the two
within 0.01 %.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from thermctl._step import radau_residual
from thermctl.model import ThermalModel

from .common import Forecast, HVACModel, MPCSolution, RecedingHorizonMPC
from .sparse import at_flow, casadi_rhs, row_scale

__all__ = ["EconomicWeights", "EconomicMPC", "TRANSCRIPTIONS", "main"]

TRANSCRIPTIONS = ("implicit", "euler", "explicit")
"""The economic MPC's step rows (the module docstring): Radau, sparse (default); implicit
Euler, sparse and one-hop; Radau through its dense solve."""

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class EconomicWeights:
    """Penalty weights of the economic MPC (the energy term is in kWh).

    Attributes
    ----------
    comfort_linear : float
        Price of discomfort [kWh per K·h]; far above the marginal energy cost of
        keeping a zone 1 K warmer for an hour (about 0.05 kWh here), so the band is
        exact whenever it is feasible.
    comfort_quadratic : float
        [kWh per K²·h]: spreads unavoidable violations over zones and time.
    move_flow : float
        [kWh per (Δṁ/ṁ_max)²] per step: damps flow chatter under model error
        (Cigler et al. 2013: purely economic MPC oscillates under mismatch).
    move_temp : float
        [kWh per K²] of supply temperature change per step.
    """

    comfort_linear: float = 5.0
    comfort_quadratic: float = 50.0
    move_flow: float = 2e-3
    move_temp: float = 2e-5


class _Blocks:
    """Named matrix blocks stacked column-major into one vector, with a receding shift.

    Each block's columns are either untouched by the shift (``kind`` None) or indexed by
    ``"node"`` (state nodes), ``"interval"`` (shooting intervals) or ``"step"`` (control
    steps); ``maps[kind][j]`` is the column of the previous solution that new column ``j``
    takes (:func:`_shift_maps`: on a uniform grid ``j + 1``, last repeated).
    """

    def __init__(self, blocks, maps):
        self.blocks = blocks  # [(name, rows, cols, kind)]
        self.maps = maps
        self.offsets = {}
        o = 0
        for name, r, c, _ in blocks:
            self.offsets[name] = (o, r, c)
            o += r * c
        self.size = o

    def get(self, v, name):
        o, r, c = self.offsets[name]
        return np.asarray(v[o:o + r * c]).reshape((r, c), order="F")

    def shift(self, v):
        v = np.asarray(v, dtype=float).ravel()
        out = np.empty_like(v)
        for name, r, c, kind in self.blocks:
            M = self.get(v, name)
            if kind is not None:
                M = M[:, self.maps[kind]]
            o = self.offsets[name][0]
            out[o:o + r * c] = M.ravel(order="F")
        return out


def _shift_maps(steps, s: int) -> dict:
    """Where each column of the next problem is in the previous one, one control step later.

    A column at time ``t`` (in control steps from now) takes the previous solution's last
    column starting at or before ``t + 1``: on the uniform grid the classic shift (column
    ``j + 1``, the last one repeated); on a coarse tail, e.g. ``[1]*6 + [6]*5``, the 1-h
    step starting in 60 min keeps the previous 60-120 min step, which covers 70 min.

    Parameters
    ----------
    steps : ndarray of int, shape (N,)
        Step lengths in control steps.
    s : int
        Shooting nodes per step (Radau sub-steps of the implicit form, 1 for the explicit).
    """
    start = np.concatenate([[0], np.cumsum(steps)[:-1]]).astype(float)     # [control steps]
    node_t = np.concatenate([(start[:, None] + np.arange(s)[None, :] * steps[:, None] / s).ravel(),
                             [float(np.sum(steps))]])

    def take(t):   # last column starting at or before t + 1 (1e-9: exact ties on the grid)
        return np.searchsorted(t, t + 1.0 + 1e-9, side="right") - 1

    node = np.minimum(take(node_t), len(node_t) - 1)
    return {"node": node, "interval": np.minimum(node[:-1], len(node_t) - 2),
            "step": np.minimum(take(start), len(start) - 1)}


class EconomicMPC(RecedingHorizonMPC):
    """Economic NMPC on a :class:`~thermctl.model.ThermalModel` (see the module docstring).

    Parameters
    ----------
    model : ThermalModel
        The controller's model.
    hvac : HVACModel
        Boxes (``ms_min``, ``ms_max`` per zone) and energy model.
    comfort_zones : list of str
        Zones held in the comfort band.
    dt : float
        MPC step [s].
    horizon : int
        Number of steps N.
    substeps : int
        Radau sub-steps per MPC step (1 is accurate to about 1 % on the slowest
        decay factor per step at dt = 15 min; see docs/mpc.md).
    transcription : {"implicit", "euler", "explicit"}
        See the module docstring. ``euler`` (implicit Euler, first order) keeps every row
        one-hop like the linear MPC's: the SQP real-time iteration's QP then factors as
        fast as the linear MPC's (the Radau rows carry A², two-hop: measured in docs/mpc.md).
    weights : EconomicWeights
    max_iter : int
        IPOPT iteration limit per (fully converged) solve.
    steps : sequence of int, optional
        A non-uniform prediction grid, as :class:`~mpc_examples.linear_mpc.LinearMPC`'s:
        the length of each of the ``horizon`` steps in multiples of ``dt`` (default all 1),
        e.g. ``dt=600, horizon=11, steps=[1] * 6 + [6] * 5``: the first hour in 10-min
        steps, then 1-h steps to 6 h. The forecast's step ``k`` must cover step ``k`` of
        this grid (``Scenario.forecast(steps=...)``). Each step is one shooting interval of
        ``substeps`` Radau sub-steps of its own length; energy and comfort are priced over
        each step's length, the band is checked at the step ends only.
    rti_iter : int, optional
        Real-time iteration: after the first (cold, converged) solve, take this many
        iterations (``sqp``: at most this many; it stops at its fixed point, a step below
        :attr:`_SQPRealTimeIteration.STEP_TOL`) from the shifted previous primal-dual
        solution instead of converging;
        what is left of the optimization is carried to the next step. None (default):
        converge every step. May be changed between solves (the RTI solver is built on
        first use).
    rti_method : {"sqp", "ipopt"}
        ``sqp`` (default): each iteration one convex QP, the constraints linearized and a
        Gauss-Newton Hessian (the convex terms' curvature), solved by ``qp_solver``
        (:class:`_SQPRealTimeIteration`). ``ipopt``: IPOPT stopped after ``rti_iter``
        iterations (``warm_start_init_point``, barrier parameter 1e-5, bound pushes 1e-5;
        an ``iteration_callback`` counts them): its iterates carry a barrier-shifted active
        set, measured far worse in closed loop (docs/mpc.md).
    qp_solver : str
        ``casadi.conic`` plugin of the SQP real-time iteration (default ``piqp``).

    Examples
    --------
    >>> mpc = EconomicMPC(model, hvac, ["r240", "r241"], dt=900, horizon=32)  # doctest: +SKIP
    >>> sol = mpc.solve(x_hat, forecast)                                      # doctest: +SKIP
    >>> ms, Ts = sol.ms[0], sol.Ts[0]                                          # doctest: +SKIP
    """

    def __init__(self, model: ThermalModel, hvac: HVACModel, comfort_zones, dt: float = 900.0,
                 horizon: int = 24, substeps: int = 1, transcription: str = "implicit",
                 weights: EconomicWeights = EconomicWeights(), max_iter: int = 300,
                 steps=None, rti_iter: int | None = None, rti_method: str = "sqp",
                 qp_solver: str = "piqp"):
        if transcription not in TRANSCRIPTIONS:
            raise ValueError(f"transcription must be one of {TRANSCRIPTIONS}, found {transcription!r}")
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, found {substeps!r}")
        super().__init__(model, hvac, comfort_zones, dt, horizon, weights)
        steps = np.ones(self.N, int) if steps is None else np.asarray(steps)
        if steps.shape != (self.N,) or np.any(steps < 1) or np.any(steps != np.round(steps)):
            raise ValueError(f"steps must be {self.N} positive integers, found {steps!r}")
        if rti_iter is not None and (int(rti_iter) != rti_iter or rti_iter < 1):
            raise ValueError(f"rti_iter must be a positive integer or None, found {rti_iter!r}")
        if rti_method not in ("sqp", "ipopt"):
            raise ValueError(f"rti_method must be 'sqp' or 'ipopt', found {rti_method!r}")
        self.rti_method, self.qp_solver = rti_method, qp_solver
        self.steps = steps.astype(int)
        self.h = self.dt * self.steps   # [s] length of each prediction step
        self.rti_iter = None if rti_iter is None else int(rti_iter)
        self.s = int(substeps)
        self.transcription = transcription
        self.max_iter = int(max_iter)
        t0 = time.perf_counter()
        self._build()
        self.build_time = time.perf_counter() - t0

    # ---- NLP ---------------------------------------------------------------
    def _build(self):
        net, hv, w = self.model.network, self.hvac, self.weights
        nx, nz, nb = net.n_states, net.n_zones, len(net.boundary)
        N, s, ns, nc = self.N, self.s, len(self.sup), len(self.comfort_idx)
        implicit = self.transcription != "explicit"    # symbolic sparse rows
        sym = ca.SX.sym if implicit else ca.MX.sym
        nn = N * s + 1 if implicit else N + 1
        X = sym("X", nx, nn)
        PHI = sym("phi", ns, N)     # flow as a fraction of the box maximum: O(1)
        TS = sym("Ts", ns, N)
        SL, SH = sym("s_lo", nc, N), sym("s_hi", nc, N)
        CC, CH = sym("q_cool", 1, N), sym("q_preheat", 1, N)   # coil split [kW]
        # total supply flow as its own variable (one equality row per step): the fan's cubic
        # in it keeps the Hessian diagonal there, where the cubic in the sum of the box flows
        # was a dense n_boxes² block per step (49 zones: 25 k of the Euler NLP's 52 k
        # nonzeros; 196 zones: 405 k)
        PHT = sym("phi_total", 1, N)     # Σ ṁ / ṁ_design [-]
        x0 = sym("x0", nx)
        TB, QG = sym("T_b", nb, N), sym("gains", nz, N)
        TO, TC, LO, HI = (sym(n, 1, N) for n in ("T_out", "T_c", "lo", "hi"))
        UP = sym("u_prev", 2 * ns)

        ms_max = np.asarray(hv.ms_max, dtype=float)[self.sup]
        Ssel = np.zeros((nz, ns))
        Ssel[self.sup, np.arange(ns)] = 1.0
        MS = ca.diag(ca.DM(ms_max)) @ PHI                      # [kg/s], supplied zones
        ms_all = ca.DM(Ssel) @ MS
        rest = np.ones((nz, 1)) - Ssel.sum(axis=1, keepdims=True)
        Ts_all = ca.DM(Ssel) @ TS + ca.DM(rest) @ TC           # unsupplied: irrelevant (ms = 0)
        U = ca.vertcat(ms_all, Ts_all, TB, QG)

        if implicit:
            # one residual per step length (uniform grid: one), mapped over its intervals
            gaps = [None] * (N * s)
            for m in np.unique(self.steps):
                res = self._implicit_residual(m * self.dt / s)
                ks = np.flatnonzero(self.steps == m)
                idx = (ks[:, None] * s + np.arange(s)[None, :]).ravel().tolist()
                g_m = res.map(len(idx))(X[:, idx], X[:, [i + 1 for i in idx]],
                                        U[:, [i // s for i in idx]])
                for j, i in enumerate(idx):
                    gaps[i] = g_m[:, j]
            gaps = ca.horzcat(*gaps)
            Xk = X[:, ::s]
        else:
            _, F = _dynamics(self.model, s)
            gaps = X[:, 1:] - F.map(N)(X[:, :-1], U, ca.DM(self.h).T)
            Xk = X
        T_sup = Xk[self.sup.tolist(), :-1] if ns else ca.DM(0, N)
        rep_ns = lambda v: ca.repmat(v, ns, 1)  # noqa: E731
        fan = hv.fan_design_power * PHT ** 3 / 1e3              # [kW], 1 × N
        reheat = hv.reheat(MS, TS, rep_ns(TC)) / 1e3
        coil = hv.coil_duty(MS, T_sup, rep_ns(TO), rep_ns(TC)) / 1e3
        T_c = Xk[self.comfort_idx.tolist(), 1:]
        dth = ca.DM(self.h / 3600.0).T     # [h] per step, 1 × N
        energy = ca.sum2(dth * (fan + (reheat + CH) / hv.eta_heat + CC / hv.cop_cool))
        comfort = ca.sum2(dth * ca.sum1(w.comfort_linear * (SL + SH)
                                        + w.comfort_quadratic * (SL ** 2 + SH ** 2)))
        dphi = ca.horzcat(PHI[:, 0] - UP[:ns], PHI[:, 1:] - PHI[:, :-1])
        dts = ca.horzcat(TS[:, 0] - UP[ns:], TS[:, 1:] - TS[:, :-1])
        move = w.move_flow * ca.sumsqr(dphi) + w.move_temp * ca.sumsqr(dts)
        J = energy + comfort + move

        g = [X[:, 0] - x0, ca.vec(gaps), ca.vec(CC - CH - coil),
             ca.vec(PHT - ca.sum1(MS) / hv.ms_design),
             ca.vec(T_c + SL - ca.repmat(LO, nc, 1)), ca.vec(ca.repmat(HI, nc, 1) + SH - T_c)]
        maps = _shift_maps(self.steps, s if implicit else 1)
        self._wb = _Blocks([("X", nx, nn, "node"), ("phi", ns, N, "step"),
                            ("Ts", ns, N, "step"), ("s_lo", nc, N, "step"), ("s_hi", nc, N, "step"),
                            ("q_cool", 1, N, "step"), ("q_preheat", 1, N, "step"),
                            ("phi_total", 1, N, "step")], maps)
        self._gb = _Blocks([("x0", nx, 1, None), ("gaps", nx, nn - 1, "interval"),
                            ("coil", 1, N, "step"), ("fan", 1, N, "step"), ("lo", nc, N, "step"),
                            ("hi", nc, N, "step")], maps)
        wv = ca.vertcat(*[ca.vec(v) for v in (X, PHI, TS, SL, SH, CC, CH, PHT)])
        pv = ca.vertcat(x0, ca.vec(TB), ca.vec(QG), TO.T, TC.T, LO.T, HI.T, UP)
        gv = ca.vertcat(*g)
        n_eq = nx * nn + 2 * N
        self._lbg = np.concatenate([np.zeros(n_eq), np.zeros(2 * nc * N)])
        self._ubg = np.concatenate([np.zeros(n_eq), np.full(2 * nc * N, np.inf)])
        self.n_variables, self.n_constraints = int(wv.numel()), int(gv.numel())
        nlp = {"x": wv, "p": pv, "f": J, "g": gv}
        # MUMPS with AMD ordering: on the 49-zone floor (11-step grid, 10 066 variables) the
        # default ordering choice (7, automatic) reported a wrong inertia at every iteration,
        # so IPOPT regularized and refactored: 4 cold iterations took 14.9 s CPU, with AMD
        # 1.6 s (METIS 2.5 s), the same iterates without regularization
        base = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                "ipopt.tol": 1e-6, "ipopt.max_iter": self.max_iter, "ipopt.mumps_pivot_order": 0}
        # Warm start: IPOPT keeps the shifted primal-dual point only with a small barrier
        # parameter. mu_init 1e-3 with equally small bound pushes took 6-22 iterations per
        # closed-loop step on the 7-zone testbed (1e-4 / 1e-6: 5-73; IPOPT's defaults:
        # 14-27). The first solve has no duals: IPOPT's defaults there (the warm options from
        # a cold guess took 4× the iterations with the identified model).
        warm = dict(base, **{"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-3,
                             "ipopt.warm_start_bound_push": 1e-3,
                             "ipopt.warm_start_slack_bound_push": 1e-3,
                             "ipopt.warm_start_mult_bound_push": 1e-3})
        self._cold = ca.nlpsol("economic_mpc_cold", "ipopt", nlp, base)
        self._warm = ca.nlpsol("economic_mpc", "ipopt", nlp, warm)
        # Real-time iteration: a third solver, stopped after rti_iter iterations by a callback
        # (called once at the start point, then after every iteration), so rti_iter can change
        # between solves. Its barrier starts at 1e-5 with bound pushes of 1e-5: closer to the
        # shifted point's active set than the converging warm start's 1e-3. Measured on the
        # 7-zone warm-up (the first supply temperature's error [K] against the converged solve
        # at 06:10, 06:20, 06:30, each from a converged previous solve; groups: after 1 | 2 |
        # 3 | 15 iterations):
        #   mu_init, pushes 1e-3, 1e-3: 9.3 4.3 1.7 | 7.9 4.2 2.6 | 3.2 4.3 2.6 | converged in 9
        #                   1e-4, 1e-4: 3.7 1.5 3.3 | 0.7 1.3 2.4 | 0.9 1.2 0.6 | 0.00 0.01 0.00
        #     (this)        1e-5, 1e-5: 0.4 1.5 3.3 | 0.4 1.0 2.4 | 0.1 0.1 0.1 | 0.01 0.01 0.00
        #                   1e-6, 1e-9: 1.3 1.4 1.4 | 1.3 0.3 1.1 | 1.3 0.2 0.1 | 1.3 (stalls) 0.01 0.00
        #   Mehrotra (mu_strategy adaptive): 3.2 1.4 1.6 | 3.2 0.9 1.4 | 1.1 0.6 1.1
        # In closed loop (each step from the previous *unconverged* iterate) it is far worse:
        # docs/mpc.md, "The economic NMPC at building scale".
        self._nlp = nlp
        self._rti_opts = dict(warm, **{"ipopt.mu_init": 1e-5, "ipopt.warm_start_bound_push": 1e-5,
                                       "ipopt.warm_start_slack_bound_push": 1e-5,
                                       "ipopt.warm_start_mult_bound_push": 1e-5})
        self._stop = _IterationLimit(wv.numel(), gv.numel(), pv.numel())
        self._rti_opts["iteration_callback"] = self._stop
        self._rti = None
        self.n_nonzeros = _kkt_nonzeros(self._warm)
        self._diag = ca.Function("diag", [wv, pv], [energy, comfort, move],
                                 ["w", "p"], ["energy", "comfort", "move"])
        # the SQP real-time iteration's Gauss-Newton model: the curvature of the convex
        # terms only (fan power, comfort slacks, moves); built on first use
        self._gn = (ca.sum2(dth * fan) + comfort + move, wv, pv)
        self._sqp = None
        if self.rti_iter is not None:
            self._rti_solver() if self.rti_method == "ipopt" else self._sqp_solver()

    def _rti_solver(self):
        """The real-time-iteration solver, built on first use (its build time is added to
        ``build_time``, not to a solve's)."""
        if self._rti is None:
            t0 = time.perf_counter()
            self._rti = ca.nlpsol("economic_mpc_rti", "ipopt", self._nlp, self._rti_opts)
            if hasattr(self, "build_time"):
                self.build_time += time.perf_counter() - t0
        return self._rti

    def _sqp_solver(self):
        """The SQP real-time iteration (:class:`_SQPRealTimeIteration`), built on first use
        (its build time is added to ``build_time``)."""
        if self._sqp is None:
            t0 = time.perf_counter()
            Jc, wv, pv = self._gn
            self._sqp = _SQPRealTimeIteration(self._nlp, Jc, wv, pv, self.qp_solver)
            if hasattr(self, "build_time"):
                self.build_time += time.perf_counter() - t0
        return self._sqp

    def _implicit_residual(self, h: float) -> ca.Function:
        """``G(xa, xb, u)``: ``D xb − N xa − c`` of one Radau sub-step of ``h`` [s] (``implicit``)
        or ``xb − xa − h f(xb, u)`` of an implicit-Euler one (``euler``), from ``f`` only."""
        f = casadi_rhs(self.model)   # sparse also for a ReducedNetwork
        nx, nu = self.model.network.n_states, self.model.network.n_inputs
        xa, xb, u = ca.SX.sym("xa", nx), ca.SX.sym("xb", nx), ca.SX.sym("u", nu)
        b = f(ca.DM.zeros(nx), u)
        Au = lambda v: f(v, u) - b  # noqa: E731  (f is affine in x: A_u v = f(v) − f(0))
        # rows scaled by their largest coefficient at the minimum flows (fast states have
        # h²/6·|A|² entries of 1e3 and more): the same constraints, a better-conditioned KKT
        euler = self.transcription == "euler"
        scale = row_scale(at_flow(self.model, self.hvac.ms_min), h, "euler" if euler else "radau")
        r = ca.DM(scale) * (xb - xa - h * f(xb, u) if euler else radau_residual(Au, xa, xb, b, h))
        return ca.Function("G", [xa, xb, u], [r], ["xa", "xb", "u"], ["residual"])

    # ---- solve -------------------------------------------------------------
    def _bounds(self, fc: Forecast):
        hv, N, ns = self.hvac, self.N, len(self.sup)
        wb = self._wb
        lb = np.full(wb.size, -np.inf)
        ub = np.full(wb.size, np.inf)
        phi_lo = np.where(np.asarray(fc.hvac_on)[None, :], self.frac_min[:, None], 0.0)
        ts_lo = np.repeat(np.asarray(fc.T_c, float)[None, :], ns, axis=0)

        def put(name, lo, hi):
            o, r, c = wb.offsets[name]
            lb[o:o + r * c] = np.broadcast_to(lo, (r, c)).ravel(order="F")
            ub[o:o + r * c] = np.broadcast_to(hi, (r, c)).ravel(order="F")

        put("phi", phi_lo, 1.0)
        put("Ts", ts_lo, max(hv.Ts_max, float(np.max(fc.T_c))))
        for name in ("s_lo", "s_hi", "q_cool", "q_preheat", "phi_total"):
            put(name, 0.0, np.inf)
        return lb, ub

    def _cold_guess(self, x0, fc: Forecast):
        """A dynamically consistent first guess: the mode's minimum flow at 20 °C supply,
        simulated with the model (zero shooting gaps), slacks and coil split to match."""
        wb, hv, N, s = self._wb, self.hvac, self.N, self.s
        net = self.model.network
        phi = self.frac_min[:, None] * np.asarray(fc.hvac_on[:N], float)[None, :]
        m = self.steps
        Ts = np.full((len(self.sup), N), 20.0)
        ms_all = np.zeros((N, net.n_zones))
        ms_all[:, self.sup] = (phi * np.asarray(hv.ms_max, float)[self.sup, None]).T
        Ts_all = np.full((N, net.n_zones), 20.0)
        U = np.column_stack([ms_all, Ts_all, fc.T_boundary[:N], fc.gains[:N]])
        nodes = s if self.transcription != "explicit" else 1
        # exact (dense expm) for small models, the sparse Radau step for big ones; simulated
        # at dt / nodes (every grid node lies on it: node j of step k at (start_k + j m_k / s) dt)
        big = net.n_states > 400
        Xf = self.model.simulate(np.repeat(U, m * nodes, axis=0), self.dt / nodes, x0,
                                 method="radau" if big else "exact", **({"substeps": 10} if big else {}))
        start = np.concatenate([[0], np.cumsum(m)[:-1]])
        at = np.concatenate([((start[:, None] * nodes + np.arange(nodes)[None, :] * m[:, None])).ravel(),
                             [int(np.sum(m)) * nodes]])
        X = Xf[at]
        Xk = X[::nodes]
        Tc = Xk[1:, self.comfort_idx].T
        T_sup = Xk[:-1, self.sup].T
        coil = hv.coil_duty(ms_all[:, self.sup], T_sup.T, fc.T_out[:N], fc.T_c[:N]) / 1e3
        v = np.zeros(wb.size)
        for name, val in (("X", X.T), ("phi", phi), ("Ts", Ts),
                          ("s_lo", np.maximum(fc.lo[None, :N] - Tc, 0.0)),
                          ("s_hi", np.maximum(Tc - fc.hi[None, :N], 0.0)),
                          ("q_cool", np.maximum(coil, 0.0)[None, :]),
                          ("q_preheat", np.maximum(-coil, 0.0)[None, :]),
                          ("phi_total", ms_all.sum(axis=1)[None, :] / hv.ms_design)):
            o, r, c = wb.offsets[name]
            v[o:o + r * c] = np.asarray(val, float).ravel(order="F")
        return v

    def parameters(self, x0, fc: Forecast, u_prev=None) -> np.ndarray:
        """The NLP parameter vector for state ``x0`` [°C] and forecast ``fc``."""
        N, ns = self.N, len(self.sup)
        self.check_forecast(fc)
        if u_prev is None:  # nothing applied yet: the mode's minimum at the cold deck
            u_prev = np.concatenate([self.frac_min * bool(fc.hvac_on[0]),
                                     np.full(ns, fc.T_c[0])])
        return np.concatenate([np.asarray(x0, float), fc.T_boundary[:N].T.ravel(order="F"),
                               fc.gains[:N].T.ravel(order="F"), fc.T_out[:N], fc.T_c[:N],
                               fc.lo[:N], fc.hi[:N], u_prev])

    def solve(self, x0, fc: Forecast, warm: bool = True) -> MPCSolution:
        """Solve the NLP for the current state estimate and forecast.

        Parameters
        ----------
        x0 : array_like, shape (n_states,)
            Current (estimated) model state [°C].
        fc : Forecast
            At least ``horizon`` steps.
        warm : bool
            Start from the previous solution shifted by one step (if there is one).

        Returns
        -------
        MPCSolution
        """
        N, ns = self.N, len(self.sup)
        prev = self._prev
        u_prev = None
        if prev is not None:
            u_prev = np.concatenate([self._wb.get(prev["x"], "phi")[:, 0],
                                     self._wb.get(prev["x"], "Ts")[:, 0]])
        P = self.parameters(x0, fc, u_prev)
        lbx, ubx = self._bounds(fc)
        # the cold guess simulates the horizon: only where a cold solve is planned (a failed
        # warm or SQP step makes its own below)
        cold = None if (warm and prev is not None) else self._cold_guess(np.asarray(x0, float), fc)
        rti = warm and prev is not None and self.rti_iter is not None
        sqp = rti and self.rti_method == "sqp"
        if rti:   # built before the clock starts
            self._sqp_solver() if sqp else self._rti_solver()
        t0, c0 = time.perf_counter(), time.process_time()
        r = st = None
        x_shift = None if prev is None else np.clip(self._wb.shift(prev["x"]), lbx, ubx)
        if sqp:
            w, lam_x, lam_g, f, ok, msg, n = self._sqp.solve(x_shift, P, lbx, ubx, self._lbg,
                                                             self._ubg, self.rti_iter)
            if ok:
                r = {"x": w, "lam_x": lam_x, "lam_g": lam_g, "f": f}
                st = {"return_status": msg, "iter_count": n, "success": True}
            else:
                log.info("economic MPC: %s, solving cold", msg)
        elif warm and prev is not None:
            solver = self._rti if rti else self._warm
            self._stop.arm(self.rti_iter)
            r = solver(p=P, lbx=lbx, ubx=ubx, lbg=self._lbg, ubg=self._ubg, x0=x_shift,
                       lam_x0=self._wb.shift(prev["lam_x"]), lam_g0=self._gb.shift(prev["lam_g"]))
            self._stop.arm(None)
            st = solver.stats()
            if not _accepted(st, r):  # a bad warm start (after a large disturbance) can stall IPOPT
                log.info("economic MPC: warm solve failed (%s), retrying cold", st["return_status"])
                r = None
        if r is None:
            if cold is None:
                cold = self._cold_guess(np.asarray(x0, float), fc)
            r = self._cold(p=P, lbx=lbx, ubx=ubx, lbg=self._lbg, ubg=self._ubg, x0=cold)
            st = self._cold.stats()
        ok = _accepted(st, r)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        wsol = np.asarray(r["x"]).ravel()
        self._prev = {"x": wsol, "lam_x": np.asarray(r["lam_x"]).ravel(),
                      "lam_g": np.asarray(r["lam_g"]).ravel()}
        nz = len(self.zones)
        ms = np.zeros((N, nz))
        Ts = np.repeat(np.asarray(fc.T_c[:N], float)[:, None], nz, axis=1)
        ms[:, self.sup] = (self._wb.get(wsol, "phi") * np.asarray(self.hvac.ms_max, float)[self.sup, None]).T
        Ts[:, self.sup] = self._wb.get(wsol, "Ts").T
        X = self._wb.get(wsol, "X")[:, :: (self.s if self.transcription != "explicit" else 1)].T
        return MPCSolution(ms=np.maximum(ms, 0.0), Ts=Ts, X=X, success=ok,
                           status=str(st["return_status"]), iterations=int(st["iter_count"]),
                           solve_time=wall, cpu_time=cpu, cost=float(r["f"]))

    def cost_terms(self, sol_vector, P) -> dict:
        """Energy [kWh], comfort penalty and move penalty of a solution vector."""
        e, c, m = self._diag(sol_vector, P)
        return {"energy": float(e), "comfort": float(c), "move": float(m)}


class _SQPRealTimeIteration:
    """Real-time iteration as SQP steps: each a convex QP solved by a sparse ``casadi.conic``.

    At the (shifted) previous solution ``w`` the NLP's constraints are linearized and its
    objective replaced by its gradient plus a Gauss-Newton Hessian: the curvature of the
    convex terms only (fan power, the comfort slacks' squares, the move penalties). The
    bilinear terms (flow × temperature in the dynamics, reheat and coil) keep their first
    order only, so the QP is convex and PIQP solves it in the linear MPC's time. A full step
    ``w + Δw`` is taken and the QP's multipliers become the next ones (Diehl, Bock and
    Schlöder 2005, "A real-time iteration scheme for nonlinear optimization in optimal
    feedback control"; Gros et al. 2020, "From linear to nonlinear MPC: bridging the gap via
    the real-time iteration"). The current state enters through the linearized initial-value
    row ``X₀ − x₀ = 0`` (initial value embedding).

    Parameters
    ----------
    nlp : dict
        CasADi NLP (``x``, ``p``, ``f``, ``g``; SX).
    J_convex : casadi.SX
        The convex part of ``f`` whose Hessian is the QP's.
    wv, pv : casadi.SX
        The NLP's variables and parameters.
    qp_solver : str
        ``casadi.conic`` plugin (``piqp``, ``osqp``, ``highs``...).
    """

    def __init__(self, nlp, J_convex, wv, pv, qp_solver: str = "piqp"):
        f, g = nlp["f"], nlp["g"]
        H, _ = ca.hessian(J_convex, wv)
        Jg = ca.jacobian(g, wv)
        self.lin = ca.Function("economic_rti_lin", [wv, pv], [ca.gradient(f, wv), g, Jg, H])
        self.f = ca.Function("economic_rti_f", [wv, pv], [f])
        opts = {"error_on_fail": False}
        if qp_solver == "osqp":
            opts["osqp"] = {"verbose": False, "eps_abs": 1e-6, "eps_rel": 1e-6,
                            "max_iter": 50000, "polish": True}
        elif qp_solver == "highs":
            opts["highs"] = {"output_flag": False}
        self.qp = ca.conic("economic_rti_qp", qp_solver,
                           {"h": H.sparsity(), "a": Jg.sparsity()}, opts)
        self.qp_solver = qp_solver

    #: Largest step (any variable, in its own unit: kg/s, K, -) at which the iteration has
    #: reached its fixed point and stops [-]. Near it the QP's solution is a zero step, on
    #: which PIQP can stall: measured at 06:30 of the warm-up (tests/test_mpc_rti.py) the
    #: steps shrink ~25× per iteration (1.8, 0.079, 3.0e-3, 1.1e-4, 4.3e-6), and with two
    #: BLAS threads the sixth QP (a step of 1.6e-7) ended at PIQP's iteration limit, which
    #: threw the whole step to a cold IPOPT solve (16 iterations).
    STEP_TOL = 1e-5

    def solve(self, w, P, lbx, ubx, lbg, ubg, iterations: int):
        """At most ``iterations`` SQP steps from ``w``, fewer when a step is below
        :attr:`STEP_TOL`; returns (w, lam_x, lam_g, f, success, message, steps)."""
        w = np.asarray(w, float).copy()
        lam_x = lam_g = None
        ok, msg, n = True, "SQP_RTI", 0
        for _ in range(iterations):
            grad, gval, Jg, H = self.lin(w, P)
            gval = np.asarray(gval).ravel()
            r = self.qp(h=H, g=grad, a=Jg, lba=lbg - gval, uba=ubg - gval,
                        lbx=lbx - w, ubx=ubx - w)
            st = self.qp.stats()
            dw = np.asarray(r["x"]).ravel()
            if not st["success"] or not np.all(np.isfinite(dw)):
                ok, msg = False, f"SQP_RTI QP failed: {st.get('return_status', '?')}"
                break
            w = np.clip(w + dw, lbx, ubx)   # clip: the QP's bounds hold to its tolerance only
            lam_x, lam_g = np.asarray(r["lam_x"]).ravel(), np.asarray(r["lam_a"]).ravel()
            n += 1
            if np.max(np.abs(dw), initial=0.0) < self.STEP_TOL:
                break
        return w, lam_x, lam_g, float(self.f(w, P)), ok, msg, n


class _IterationLimit(ca.Callback):
    """IPOPT ``iteration_callback`` that stops after ``limit`` iterations (None: never)."""

    def __init__(self, nx: int, ng: int, np_: int):
        ca.Callback.__init__(self)
        self.nx, self.ng, self.np_ = int(nx), int(ng), int(np_)
        self.limit, self.calls = None, 0
        self.construct("rti_stop", {})

    def arm(self, limit):
        self.limit, self.calls = limit, 0

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        n = ca.nlpsol_out(i)
        if n in ("f",):
            return ca.Sparsity.scalar()
        if n in ("x", "lam_x"):
            return ca.Sparsity.dense(self.nx)
        if n in ("g", "lam_g"):
            return ca.Sparsity.dense(self.ng)
        if n == "lam_p":
            return ca.Sparsity.dense(self.np_)
        return ca.Sparsity(0, 0)

    def eval(self, arg):
        self.calls += 1   # the first call is the start point, before any iteration
        stop = self.limit is not None and self.calls > self.limit
        return [1 if stop else 0]


def _accepted(stats, r) -> bool:
    """Converged, or stopped by the real-time-iteration limit at a finite point."""
    if stats["success"]:
        return True
    return (stats["return_status"] == "User_Requested_Stop"
            and bool(np.all(np.isfinite(np.asarray(r["x"])))))


def _kkt_nonzeros(solver):
    """Stored entries of the constraint Jacobian plus the Lagrangian Hessian (what IPOPT
    factors); None if the solver does not expose them."""
    try:
        return int(solver.get_function("nlp_jac_g").sparsity_out("jac_g_x").nnz()
                   + solver.get_function("nlp_hess_l").sparsity_out(0).nnz())
    except RuntimeError:
        return None


def _dynamics(model, substeps: int):
    """``f(x, u)`` (SX) and ``F(x, u, dt)`` of a ThermalModel (parameters fixed) or of a
    :class:`thermctl.reduce.ReducedNetwork` (whose ``to_casadi`` returns ``(f, F)``)."""
    cas = model.to_casadi(substeps=substeps)
    if isinstance(cas, tuple):
        f, F = cas
        return (f.expand() if f.is_a("MXFunction") else f), F
    p = ca.DM(model.p)
    nx, nu = model.network.n_states, model.network.n_inputs
    x, u, dt = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.MX.sym("dt")
    f = ca.Function("f", [x, u], [cas.f(x, u, p)], ["x", "u"], ["xdot"])
    xm, um = ca.MX.sym("x", nx), ca.MX.sym("u", nu)
    F = ca.Function("F", [xm, um, dt], [cas.F(xm, um, p, dt)], ["x", "u", "dt"], ["x_next"])
    return f, F


def _extra_parser():
    """The options only the economic example has (the shared runner does not know them)."""
    import argparse
    p = argparse.ArgumentParser(add_help=False, prog="python -m mpc_examples.economic_mpc")
    p.add_argument("--grid", default=None,
                   help="non-uniform prediction grid in multiples of --step, e.g. '6x1 5x6' (an "
                        "hour of 10-min steps, then 1-h steps to 6 h: 11 instead of 36 steps); "
                        "default: uniform")
    p.add_argument("--rti", type=int, default=None,
                   help="real-time iteration: iterations per step after the first "
                        "(converged) solve; default: converge every step")
    p.add_argument("--rti-method", choices=["sqp", "ipopt"], default="sqp",
                   help="real-time iteration by SQP steps (a convex QP each, PIQP) or by "
                        "IPOPT stopped early")
    return p


def main(argv=None):
    """Run the economic MPC against the baseline on the testbed; print and save the table.

    ``--grid`` and ``--rti`` (:func:`_extra_parser`) are taken off the command line here;
    everything else goes to :func:`mpc_examples.simulator.run_example`.
    """
    import functools
    import sys

    from .simulator import run_example
    extra = _extra_parser()
    opts, rest = extra.parse_known_args(sys.argv[1:] if argv is None else argv)
    if "-h" in rest or "--help" in rest:
        extra.print_help()
        print()
    if opts.grid is None and opts.rti is None:
        return run_example("economic", EconomicMPC, rest)
    return run_example("economic", functools.partial(_make, grid=opts.grid, rti_iter=opts.rti,
                                                     rti_method=opts.rti_method), rest)


def _make(model, hvac, comfort_zones, dt: float, horizon: int, grid=None, **options):
    """:class:`EconomicMPC` with ``grid`` (``"6x1 5x6"``, multiples of ``dt``) over the
    ``horizon · dt`` the runner asks for."""
    from .scaling import parse_grid
    steps = parse_grid(grid, dt / 60.0, horizon * dt / 3600.0)
    return EconomicMPC(model, hvac, comfort_zones, dt=dt,
                       horizon=horizon if steps is None else len(steps), steps=steps, **options)


if __name__ == "__main__":
    main()
