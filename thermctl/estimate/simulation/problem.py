r"""The estimation problem of the paper (III-B): data window, parameters, initial state.

:class:`EstimationData` holds a block of measured data on a regular grid;
:class:`CostProblem` fixes everything that defines the prediction cost

.. math::

    J(\theta) = \sum_{k=1}^{K_T} \sum_{i \in Z} (\hat T_i(k) - T_i(k))^2

(paper eq. 3): the window (first sample and ``K_T``), the zone subset ``Z``, how the
simulation is started, and the parameter space with its bounds. The simulators
(:mod:`.sim`), the grid (:mod:`.grid`) and the NLPs (:mod:`.nlp`) all read it, so
they minimise the same function.

Parameters are handled in log space, scaled to O(1):
``eta = log(theta / theta_ref)`` with ``theta = [rbar_v (1 or m values), c_v]``.
The paper's bound on the time constant per unit distance becomes
``log(t_min/alpha) <= log rbar_v[e] + log c_v <= log(t_max/alpha)``, a linear
constraint in ``eta``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from ...errors import DataError, EstimationError
from ...model import ConvectionParameters, ThermalModel
from ...network import ThermalNetwork
from ..bounds import RBAR_BOUNDS, T_MAX, T_MIN
from ..data import EstimationData

__all__ = ["CostProblem", "INITIAL_STATES"]

log = logging.getLogger(__name__)

INITIAL_STATES = ("paper", "burn_in", "estimate", "given")


@dataclass
class _Window:
    s0: int            # first simulated sample (burn-in start)
    start: int         # first sample of the cost window (the paper's k = 0)
    K_T: int           # steps in the cost window
    n_burn: int        # burn-in steps


class CostProblem:
    r"""The paper's prediction cost on a data window, with its parameter space.

    Parameters
    ----------
    network : ThermalNetwork
        Must have at least one convection edge.
    data : EstimationData
    window : float
        Length of the cost window [s]; default 12 h (the paper: ``K_T = 144`` at 5 min).
    K_T : int, optional
        Number of steps in the window; overrides ``window``.
    start : int, optional
        Sample index where the window starts (the paper's ``k = 0``). Default 0, or
        the end of the burn-in for ``initial_state="burn_in"``.
    zones : list of str, optional
        The zone subset ``Z`` of J (default: every measured zone in ``data``).
    initial_state : {"paper", "burn_in", "estimate", "given"}
        ``paper``: measured zones at their first sample, unmeasured zones at the mean of
        their measured neighbours, edge states at the mean of their end nodes (paper IV-A).
        ``burn_in``: start that way ``burn_in`` seconds before the window and simulate
        with the same parameters up to it (J counts the window only).
        ``estimate``: the paper's start plus a free deviation of every state that is
        not a measured zone temperature (walls, edges, unmeasured zones); J(θ) is then
        the minimum over that deviation (variable projection for the grid, decision
        variables for the NLP).
        ``given``: ``x0`` (e.g. the true state of a simulated building).
    burn_in : float
        Burn-in length [s] for ``initial_state="burn_in"`` (default 24 h).
    x0 : array_like, shape (n_states,), optional
        Initial state [°C] for ``initial_state="given"``.
    per_edge : bool
        One rbar_v per convection edge (``m + 1`` parameters) instead of one shared
        value (the paper). ``c_v`` stays shared.
    t_min, t_max : float
        Bounds of the convective time constant per unit distance [s/m]; the bound on
        ``tau0 = rbar_v·c_v`` [s/m] is ``[t_min/alpha, t_max/alpha]``.
    rbar_bounds : (float, float)
        Range of rbar_v [K/(W m)] (default the paper's search range [1e-6, 1e-2]).
    alpha : float, optional
        Default :meth:`BuildingSpec.alpha` (median over the walls).
    x0_weight : float
        Weight [1/K²] of ``Σ δ²`` added to J for ``initial_state="estimate"`` (δ the
        free initial deviation [K]); a tiny value only fixes the directions the data
        cannot see. Reported J never includes it.
    simulator : {"exact", "radau"}
        How J is simulated everywhere (grid, NLPs, reports): ``exact`` zero-order hold
        (dense eigendecomposition per distinct supply flow; the reference) or ``radau``
        (the model's L-stable Radau IIA step with sparse LU; for hundreds of states with
        flows that change every step).
    substeps : int, optional
        Radau sub-steps per sample (default one per minute).

    Attributes
    ----------
    model : ThermalModel
    alpha, tau_bounds, eta_lb, eta_ub, theta_ref, param_names
    U_sim : ndarray, shape (n_steps, n_inputs)
        Inputs of every simulated step (burn-in and window).
    Y_obs : ndarray, shape (K_T, n_cost_zones)
        Measurements at the window's samples ``1..K_T`` (NaN where missing).
    obs_index : ndarray of int
        Simulated step (1-based state index) of each row of ``Y_obs``.
    zone_index : ndarray of int
        State index of each cost zone.
    x0_ref : ndarray, shape (n_states,)
        The paper's (or the given) initial state at the first simulated sample.
    free_index : ndarray of int
        States whose initial value is free (``estimate``), else empty.

    Examples
    --------
    >>> prob = CostProblem(net, EstimationData.from_frame(df, net))   # doctest: +SKIP
    >>> prob.cost(3.36e-4, 1.19e3)                                     # doctest: +SKIP
    """

    def __init__(self, network: ThermalNetwork, data: EstimationData, *,
                 window: float = 12 * 3600.0, K_T: int | None = None, start: int | None = None, zones=None,
                 initial_state: str = "paper", burn_in: float = 24 * 3600.0, x0=None,
                 per_edge: bool = False, t_min: float = T_MIN, t_max: float = T_MAX,
                 rbar_bounds=RBAR_BOUNDS, alpha: float | None = None, x0_weight: float = 1e-6,
                 simulator: str = "exact", substeps: int | None = None):
        if isinstance(network, ThermalModel):
            network = network.network
        data.check(network)
        self.network = network
        self.data = data
        self.model = ThermalModel(network)
        self.m = len(network.convection_edges)
        if self.m == 0:
            raise EstimationError("the network has no convection edges: there is nothing to "
                                  "estimate (add edges from the structure identification)")
        if initial_state not in INITIAL_STATES:
            raise EstimationError(f"initial_state must be one of {INITIAL_STATES}, "
                                  f"found {initial_state!r}")
        if (x0 is not None) != (initial_state == "given"):
            raise EstimationError("pass x0 exactly when initial_state='given'")
        self.initial_state = initial_state
        if simulator not in ("exact", "radau"):
            raise EstimationError(f"simulator must be 'exact' or 'radau', found {simulator!r}")
        self.simulator_kind = simulator
        self.substeps = substeps
        self.per_edge = bool(per_edge)
        self.x0_weight = float(x0_weight) if initial_state == "estimate" else 0.0
        if self.x0_weight < 0:
            raise EstimationError(f"x0_weight must be >= 0 [1/K²], found {x0_weight}")
        self._set_bounds(t_min, t_max, rbar_bounds, alpha)
        self._set_window(window, K_T, start, burn_in)
        self._set_zones(zones)
        self._set_initial_state(x0)

    # ---- setup ---------------------------------------------------------------
    def _set_bounds(self, t_min, t_max, rbar_bounds, alpha):
        spec = self.network.spec
        self.alpha = float(spec.alpha() if alpha is None else alpha)
        if not (0 < t_min < t_max):
            raise EstimationError(f"need 0 < t_min < t_max [s/m], found t_min={t_min}, "
                                  f"t_max={t_max}")
        lo, hi = (float(v) for v in rbar_bounds)
        if not (0 < lo < hi):
            raise EstimationError("rbar_bounds must satisfy 0 < low < high [K/(W m)], "
                                  f"found {rbar_bounds}")
        self.t_min, self.t_max = float(t_min), float(t_max)
        self.rbar_bounds = (lo, hi)
        self.tau_bounds = (self.t_min / self.alpha, self.t_max / self.alpha)
        tau_ref = math.sqrt(self.tau_bounds[0] * self.tau_bounds[1])
        rbar_ref = math.sqrt(lo * hi)
        n_r = self.m if self.per_edge else 1
        self.n_eta = n_r + 1
        self.theta_ref = np.array([rbar_ref] * n_r + [tau_ref / rbar_ref])
        names = ([ConvectionParameters.key(e.name) for e in self.network.convection_edges]
                 if self.per_edge
                 else ["rbar_v"])
        self.param_names = names + ["c_v"]
        # box bounds on eta: rbar_v from rbar_bounds; c_v from what the tau bound allows
        c_lo, c_hi = self.tau_bounds[0] / hi, self.tau_bounds[1] / lo
        self.theta_lb = np.array([lo] * n_r + [c_lo])
        self.theta_ub = np.array([hi] * n_r + [c_hi])
        self.eta_lb = np.log(self.theta_lb / self.theta_ref)
        self.eta_ub = np.log(self.theta_ub / self.theta_ref)
        # linear constraint: lo_tau <= eta_r[e] + eta_c + log(rbar_ref c_ref) <= hi_tau
        self.tau_matrix = np.zeros((n_r, self.n_eta))
        self.tau_matrix[np.arange(n_r), np.arange(n_r)] = 1.0
        self.tau_matrix[:, -1] = 1.0
        off = math.log(rbar_ref * self.theta_ref[-1])
        self.tau_lb = np.full(n_r, math.log(self.tau_bounds[0]) - off)
        self.tau_ub = np.full(n_r, math.log(self.tau_bounds[1]) - off)
        # p = M @ exp(eta) * ref  (per-edge model vector from the decision vector)
        M = np.zeros((2 * self.m, self.n_eta))
        for e in range(self.m):
            M[e, e if self.per_edge else 0] = 1.0
            M[self.m + e, -1] = 1.0
        self.p_map = M

    def _set_window(self, window, K_T, start, burn_in):
        data = self.data
        dt = data.dt
        N = len(data)
        if K_T is None:
            K_T = int(round(float(window) / dt))
        K_T = int(K_T)
        if K_T < 1:
            raise EstimationError(f"the cost window must have at least one step, found K_T={K_T}")
        n_burn = 0
        if self.initial_state == "burn_in":
            n_burn = int(round(float(burn_in) / dt))
            if n_burn < 1:
                raise EstimationError(f"burn_in must be at least one step ({dt} s), "
                                      f"found {burn_in} s")
        if start is None:
            start = n_burn
        start = int(start)
        if start - n_burn < 0:
            raise EstimationError(f"burn-in of {n_burn} steps needs data before the window start "
                                  f"(sample {start}); pass start >= {n_burn} or a shorter burn_in")
        if start + K_T >= N:
            raise DataError(f"the cost window needs samples {start}..{start + K_T} "
                            f"(K_T = {K_T} steps of {dt:g} s) but the data have {N} samples")
        self.win = _Window(start - n_burn, start, K_T, n_burn)
        s0 = self.win.s0
        self.U_sim = data.U[s0:start + K_T]
        bad = ~np.isfinite(self.U_sim)
        if bad.any():
            k, j = np.argwhere(bad)[0]
            raise DataError(f"input {data.input_names[j]!r} is missing (NaN) at sample {s0 + k} "
                            "inside the estimation window; choose a window without gaps")
        self.obs_index = np.arange(n_burn + 1, n_burn + K_T + 1)
        self.dt = dt

    def _set_zones(self, zones):
        data, net = self.data, self.network
        zones = list(data.zones if zones is None else zones)
        missing = [z for z in zones if z not in data.zones]
        if missing:
            raise EstimationError(f"cost zone(s) {missing} are not measured in the data "
                                  f"(measured: {data.zones})")
        if not zones:
            raise EstimationError("the cost needs at least one measured zone")
        self.zones = zones
        cols = [data.zones.index(z) for z in zones]
        w = self.win
        self.Y_obs = data.Y[w.start + 1:w.start + w.K_T + 1][:, cols]
        self.mask = np.isfinite(self.Y_obs)
        if not self.mask.any():
            raise DataError(f"no measurement of zones {zones} inside the cost window")
        self.zone_index = np.array([net.zones.index(z) for z in zones])
        self.n_res = int(self.mask.sum())

    def _set_initial_state(self, x0):
        net, data = self.network, self.data
        s0 = self.win.s0
        Tz = np.full(net.n_zones, np.nan)
        for j, z in enumerate(data.zones):
            Tz[net.zones.index(z)] = data.Y[s0, j]
        if self.initial_state == "given":
            x0 = np.asarray(x0, dtype=float)
            if x0.shape != (net.n_states,) or not np.all(np.isfinite(x0)):
                raise EstimationError(f"x0: expected {net.n_states} finite values "
                                      f"({net.state_names[:3]}...), found shape {x0.shape}")
            self.x0_ref = x0.copy()
        else:
            Tb = self.U_sim[0, net.input_slices()["T"]]
            self.x0_ref = self.model.initial_state(Tz, Tb)
        if self.initial_state == "estimate":
            fixed = np.isfinite(Tz)
            self.free_index = np.array([i for i in range(net.n_states)
                                        if not (i < net.n_zones and fixed[i])], dtype=int)
        else:
            self.free_index = np.zeros(0, dtype=int)

    def start_state(self, delta=None) -> np.ndarray:
        """Initial state [°C]: :attr:`x0_ref` plus ``delta`` [K] on the free states.

        Parameters
        ----------
        delta : array_like, shape (n_free,), optional
            Deviation of the free initial states (``initial_state="estimate"``) [K].
        """
        x0 = self.x0_ref.copy()
        if delta is not None:
            x0[self.free_index] += delta
        return x0

    # ---- parameters ----------------------------------------------------------
    @property
    def n_free(self) -> int:
        return len(self.free_index)

    def eta_from_theta(self, rbar_v, c_v) -> np.ndarray:
        """Scaled log-parameters from ``rbar_v`` [K/(W m)] (scalar or per edge), ``c_v`` [J/K]."""
        n_r = self.n_eta - 1
        r = np.asarray(rbar_v, dtype=float)
        r = np.broadcast_to(r, (n_r,)) if r.ndim == 0 else r
        if r.shape != (n_r,):
            if not self.per_edge and r.size and np.allclose(r, r.flat[0]):
                r = np.array([r.flat[0]])
            else:
                what = "one value per convection edge" if self.per_edge else "a scalar"
                raise EstimationError(f"rbar_v: expected {what} ({n_r}), found shape {r.shape}")
        c = float(np.asarray(c_v, dtype=float).ravel()[0]) if np.ndim(c_v) else float(c_v)
        th = np.concatenate([r, [c]])
        if not np.all(np.isfinite(th)) or np.any(th <= 0):
            raise EstimationError("parameters must be finite and > 0, found "
                                  f"rbar_v={rbar_v}, c_v={c_v}")
        return np.log(th / self.theta_ref)

    def theta(self, eta) -> np.ndarray:
        """``[rbar_v..., c_v]`` from the scaled log-parameters."""
        return self.theta_ref * np.exp(np.asarray(eta, dtype=float))

    def p(self, eta) -> np.ndarray:
        """The model's per-edge parameter vector ``[rbar_v[e]..., c_v[e]...]``."""
        return self.p_map @ self.theta(eta)

    def dp_deta(self, eta) -> np.ndarray:
        """Jacobian of :meth:`p` with respect to ``eta``, shape (2m, n_eta)."""
        return self.p_map * self.theta(eta)[None, :]

    def feasible(self, eta, tol: float = 1e-9) -> bool:
        eta = np.asarray(eta, dtype=float)
        g = self.tau_matrix @ eta
        return bool(np.all(eta >= self.eta_lb - tol) and np.all(eta <= self.eta_ub + tol)
                    and np.all(g >= self.tau_lb - tol) and np.all(g <= self.tau_ub + tol))

    def active_bounds(self, eta, rtol: float = 1e-3) -> list:
        """Bounds within ``rtol`` (relative, i.e. in log space) of ``eta``, in plain words."""
        eta = np.asarray(eta, dtype=float)
        out = []
        n_r = self.n_eta - 1
        for i, name in enumerate(self.param_names):
            unit = "K/(W m)" if i < n_r else "J/K"
            if eta[i] - self.eta_lb[i] < rtol:
                out.append(f"{name} at its lower bound {self.theta_lb[i]:.3g} {unit}")
            if self.eta_ub[i] - eta[i] < rtol:
                out.append(f"{name} at its upper bound {self.theta_ub[i]:.3g} {unit}")
        g = self.tau_matrix @ eta
        for e in range(n_r):
            lab = "tau0" if not self.per_edge else f"tau0[{self.network.convection_edges[e].name}]"
            if g[e] - self.tau_lb[e] < rtol:
                out.append(f"{lab} = rbar_v·c_v at its lower bound t_min/alpha = "
                           f"{self.tau_bounds[0]:.3g} s/m")
            if self.tau_ub[e] - g[e] < rtol:
                out.append(f"{lab} = rbar_v·c_v at its upper bound t_max/alpha = "
                           f"{self.tau_bounds[1]:.3g} s/m")
        return out

    def project(self, eta) -> np.ndarray:
        """The nearest feasible point (clip the box, then pull c_v into the tau range)."""
        eta = np.clip(np.asarray(eta, dtype=float), self.eta_lb, self.eta_ub)
        g = self.tau_matrix @ eta
        lo = max(np.max(self.tau_lb - (g - eta[-1])), self.eta_lb[-1])
        hi = min(np.min(self.tau_ub - (g - eta[-1])), self.eta_ub[-1])
        if lo > hi:   # per-edge rbar_v too far apart for one c_v: pull them together
            mid = 0.5 * (lo + hi)
            eta[-1] = mid
            for e in range(self.n_eta - 1):
                eta[e] = np.clip(eta[e], self.tau_lb[e] - mid, self.tau_ub[e] - mid)
            return eta
        eta[-1] = np.clip(eta[-1], lo, hi)
        return eta

    # ---- description ----------------------------------------------------------
    @property
    def time_window(self) -> tuple[float, float]:
        """Start and end of the cost window [s] from the first sample of the data."""
        return self.win.start * self.dt, (self.win.start + self.win.K_T) * self.dt

    def describe(self) -> str:
        w = self.win
        return (f"J over {w.K_T} steps of {self.dt:g} s (samples {w.start}..{w.start + w.K_T}), "
                f"zones {self.zones}, initial state '{self.initial_state}'"
                + (f" after {w.n_burn} burn-in steps" if w.n_burn else "")
                + (f" with {self.n_free} free initial states" if self.n_free else "")
                + f"; parameters {self.param_names}, alpha = {self.alpha:.4g}, "
                f"tau0 in [{self.tau_bounds[0]:.3g}, {self.tau_bounds[1]:.3g}] s/m")

    # ---- the cost --------------------------------------------------------------
    def cost(self, rbar_v, c_v) -> float:
        """J(θ) of paper eq. (3) [K²] (minimised over the free initial states if any).

        Parameters
        ----------
        rbar_v : float or array_like
            [K/(W m)]; one per convection edge if ``per_edge``.
        c_v : float
            [J/K].
        """
        return self.simulator.cost(self.eta_from_theta(rbar_v, c_v)).J

    @property
    def simulator(self):
        """The simulator of this problem (:class:`.sim.ExactSimulator` or
        :class:`.radau.RadauSimulator`, built once)."""
        if getattr(self, "_simulator", None) is None:
            if self.simulator_kind == "exact":
                from .sim import ExactSimulator
                self._simulator = ExactSimulator(self)
            else:
                from .radau import RadauSimulator
                self._simulator = RadauSimulator(self, self.substeps)
        return self._simulator
