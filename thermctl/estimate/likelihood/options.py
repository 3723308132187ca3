"""Options of the stochastic grey-box model and its criteria (:class:`LikelihoodOptions`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import EstimationError
from ..bounds import RBAR_BOUNDS, T_MAX, T_MIN

__all__ = ["LikelihoodOptions"]


@dataclass(frozen=True)
class LikelihoodOptions:
    """Model and criterion options of :class:`LikelihoodProblem`.

    Attributes
    ----------
    per_edge : bool
        One R̄_v per convection edge (τ0 stays shared) instead of one for all.
    disturbance : {"random_walk", "none"}
        Random-walk gain state per measured zone, or none (white heat noise only).
    fast_gain : bool
        Also a fast gain per measured zone: a first-order (Ornstein–Uhlenbeck) process
        with its own time constant ``τ_g`` and standard deviation ``σ_g`` (both fitted,
        shared by the zones), beside the random walk. Occupancy that changes by the hour
        is a level that jumps and comes back, which a random walk can only follow by
        wandering everywhere; the fast gain takes the hour-scale part, the random walk the
        slow drift.
    common_gain : int
        Common (factor) gains: this many first-order processes ``c_k`` of unit variance,
        time constant ``τ_c`` (fitted, shared), each heating every measured zone with its
        own fitted loading ``loading[z,ck]`` [W] (either sign). A disturbance several rooms
        feel at once (sun through one glazing, the ventilation supply's temperature, the
        weather the boundary temperatures miss) makes their innovations move together;
        with independent gains per zone only an air path can explain that. Gain k has no
        loading on the first k measured zones: with a shared τ_c the data see the loadings
        only through λλᵀ, and this lower-triangular choice leaves one solution up to signs.
        Measured (docs/identification.md, "A busy room, or a disturbance rooms share"): on
        the twin house and the testbed one gain loads on one or two rooms (a slow extra
        gain for the busiest room), and it changes no selected path. 0 (default): none.
    unmeasured_gain : bool
        Unmeasured zones (a hallway) get the time-of-day basis too (and a constant without
        random walk). Their temperature is only seen through their neighbours, so no
        random walk there (it would not be detectable); a constant alone would be
        indistinguishable from shifted gains of the measured zones.
    basis : {None, "levels", "fourier"}
        Deterministic time-of-day part of the gains of each measured zone: ``levels`` =
        an occupied-hours indicator, ``fourier`` = ``harmonics`` daily harmonics. Without
        the random walk every measured zone also gets a constant gain.
    harmonics : int
    occupied_hours : (float, float)
        Local hours of the ``levels`` indicator and of ``gain_schedule`` [h].
    weekdays_only : bool
        ``levels`` indicator on Monday–Friday only.
    gain_schedule : {None, "occupied"}
        ``occupied``: the random-walk gains wander faster in ``occupied_hours`` (every day,
        weekends too): their noise intensity there is ``occ_ratio`` (fitted, shared, one
        number) times the rest of the day's. People, their equipment and lights come and go
        by the hour in those hours; at night a gain holds. With one intensity for the whole
        day the filter must either follow the daytime jumps with a gain that also wanders at
        night, or call them misfit that an air path to a neighbour with the same hours may
        take up. The filter is stationary within each regime: a stationary Kalman gain and
        innovation covariance per regime, switching at the schedule's hours, so the
        likelihood is exact within a regime and approximate for the covariance's transient
        after a switch (its time constant is that of the filter, minutes to an hour). Needs
        the random-walk disturbance and timestamps. None (default): one intensity.
    loop_gain : bool
        A zone's own control loop acting between samples. A VAV box's PI loop acts every
        minute or faster; the log holds one sample per step, so a row's supply is what the
        box did at the stamp, and within the step the loop keeps answering the zone's
        temperature. That is a heat ``k_z·(y_{z,k} − T_z(t))`` [W] over the step: the
        reading the loop last saw, held, against the temperature now (for a proportional
        action ``k_z`` is its gain in W/K: a 2 K band on a 0.1 kg/s box at 10 K supply
        difference is ~500 W/K). ``True``: one ``loop_gain[z]`` per measured zone with
        supply air, fitted (log scale, 0.01–10⁴ W/K), acting in the rows where any such
        zone's supply is on. A neighbour's temperature, loop-controlled to a similar set
        point, resembles the held reading, so without the term an air path to it can stand
        in for it. Two regimes, supply on and off, each with its stationary filter (as
        ``gain_schedule``, with which it does not combine). The identified building model
        does not carry it: it describes the data's controller, not the building. Measured
        (docs/identification.md, "A loop between samples"): a pull toward the last reading
        is also what the filter's correction does, so the fitted gain is confounded with
        the heat noise (Pugh Hall with its boxes acting at the data step still fits 1 300–
        1 800 W/K in three of six zones), and on the corridor floors it traded 2 false air
        paths for 3 true ones at 1.9× the CPU. False (default): no such term.
    solar : "auto", bool or list of str
        Solar apertures: ``auto``/True = every zone × every ``solar:`` column; a list =
        those zones; False = none.
    noise : {"shared", "zone"}
        One σ_q, σ_φ, σ_v for all zones, or one per zone.
    burn_in : float
        Time at the start of every data segment left out of the likelihood and the k-step
        restarts (the filter still runs through it) [s].
    initial_state : {"steady", "paper"}
        ``steady``: zones at their first sample, all other states at the steady state of
        the first day's mean inputs, gains at that day's mean imbalance (depends on θ);
        ``paper``: the paper's mean-of-ends start, zero gains.
    supply_temperature : {"midpoint", "start"}
        Zone temperature used in the supply heat of a step: mean of the bracketing
        samples, or the sample at its start (causal).
    horizon : float
        Horizon of the k-step criterion [s].
    stride : float or None
        Spacing of the k-step restarts [s] (default: the horizon).
    rbar_bounds : (float, float)
        [K/(W m)]
    t_min, t_max : float
        Convective time constant per unit distance [s/m] (paper: 4 and 20).
    alpha : float or None
        Default: the spec's (median of its walls).
    sda_iterations : int
        Doubling iterations of the stationary Riccati solution in the graph.
    riccati : {"implicit", "doubling"}
        ``implicit``: the stationary Riccati equation is solved in numpy and differentiated
        through its adjoint Stein equation (fast; second derivatives by finite differences
        of that exact adjoint). ``doubling``: ``sda_iterations`` doubling steps inside the
        CasADi graph (exact derivatives of every order, ~3× slower).
    measurement : {"white", "ar1"}
        Sensor error model: white, or white plus a first-order autoregressive error per
        measured zone (``σ_e``, ``τ_e``) — what quantisation of a slowly moving
        temperature looks like (a 0.1 °F step is crossed only every few samples).
    innovations : {"gaussian", "student"}
        Distribution of the one-step innovations in the likelihood. ``student``: a
        multivariate t with ``nu`` degrees of freedom and the filter's innovation
        covariance S as its scale matrix, ``½[(ν + p)·log(1 + eᵀS⁻¹e/ν) + log det S]`` per
        sample plus constants (p measured zones). The filter itself stays the linear
        Kalman filter, so this is a robust M-estimator on its innovations: a sample with a
        large innovation (an occupancy gain that jumps, which the random-walk gain model
        cannot follow) counts logarithmically instead of quadratically. ν → ∞ gives the
        Gaussian likelihood.
    nu : float or "fit"
        Degrees of freedom of ``innovations="student"`` [-] (> 2), or ``"fit"``: estimated
        with the other parameters within ``nu_bounds`` (the data say how heavy their tails
        are; at the upper bound the t is nearly Gaussian).
    nu_bounds : (float, float)
        Bounds of a fitted ``nu`` [-].
    boundary_noise : None, "outdoor", "all" or list of str
        A first-order autoregressive error (``σ_b``, ``τ_b``, shared) on these boundary
        temperatures: what the walls see differs from the logged value (a station away
        from the facade, sun on the wall, gusts). The error is common to every zone on
        that boundary, so without it the fit may explain it as mixing between zones.
    fit_rows : "auto", "all", "supply_off" or array of bool
        Rows whose one-step innovations enter the likelihood and whose horizons the k-step
        restarts may cover; the filter runs through all rows either way. ``supply_off``:
        only samples after ``holdoff`` without supply air in any zone (nights, weekends);
        ``auto``: ``supply_off`` if that leaves at least 15 % of the samples and a day,
        else ``all``. Why: a zone controller acts on readings the log
        does not hold (between samples, before rounding), so in closed loop the logged
        supply carries information about the state the filter cannot see, which biases
        the likelihood toward strong mixing; with the supply off the inputs are exact.
    holdoff : float
        With ``fit_rows="supply_off"``: time after the supply went off before samples
        count [s].
    internal_mass : bool or "factor"
        ``True``/``"factor"``: a fitted capacity factor ``cap_factor[zone]`` = f_z >= 1 per
        measured zone multiplies the zone's capacitance C_z (spec ``capacitance`` or
        ``capacity_multiplier·ρ·cp·V``): furniture, columns and wall surface layers the
        spec omits. Every term of the zone's equation (walls, heat inputs, gain, heat
        noise) is divided by f_z·C_z; the fitted model's spec carries f_z·C_z.
        Why a factor, not an internal-mass RC node per zone (capacity and conductance):
        the data see a zone's capacity through its time constant f_z·C_z/ΣG, and only
        through the zone's own temperature. Air alone is quasi-static on a 10-min step
        (twin house N2: 0.8–3.8 min with ΣG = 210–460 W/K), so one number per zone is
        what the data fix first: on the Pugh-Hall testbed (15–21 min at f = 1, 5-min
        data) a plant 3× heavier gives factors 3.2–4.3 in 6 days (exact inputs, no sensor
        noise: 2.75–3.65), a plant without extra mass 1.15–1.52: biased up by 20–40 % by
        sensor rounding and control between samples, more than the 90 % intervals
        (±10–25 %) admit, but never mistaking 1 for 3. A node adds a second, slower mode (a 0.93 MJ/K concrete column
        behind ≈ 100 W/K of surface film: ≈ 2.6 h) and doubles the parameters; not
        built yet. Needs known heat inputs in the fitted rows: with the supply-off rows
        of ``fit_rows="auto"`` on closed-loop data the factor only shapes the noise
        spectrum and drifts to 10–30 with or without extra mass (use ``fit_rows="all"``
        there). Optimised in ``log f`` within ``cap_factor_bounds``.
    cap_factor_bounds : (float, float)
        Bounds of the capacity factors [-]: 1 (the spec's capacitance is a lower bound) to
        100 (the twin house's 0.93 MJ/K column is 40× the kitchen's 23 kJ/K of air; with
        30 its corridor sat on the bound).
    wall_factors : bool
        A fitted UA factor per wall class, ``ua_factor[exterior]``, ``ua_factor[partition]``,
        ``ua_factor[boundary]`` (only the classes the network has): walls of uncertain
        construction, for a user who knows the floor plan but not the U-values. Classes
        (:func:`thermctl.spec.wall_class`): ``exterior`` = a wall to an outdoor boundary node
        (:func:`thermctl.spec.is_outdoor`), ``partition`` = between two zones,
        ``boundary`` = to any other boundary node (cellar, attic, a neighbour's space, the
        floor above). A factor f multiplies the conductance 1/R of all three resistances
        of every wall of its class (``R → R/f``); the wall capacities are kept. Why UA and
        not C: the data see a wall mainly through its steady conductance (the zones'
        response to the outdoor and neighbour temperatures over days), while its two
        capacities act on the hours-scale shape of that response and trade off against the
        zone capacity factor and the gain noise; and the spec's C (area × thickness ×
        ρc) is known better than its U (insulation, thermal bridges, air leaks). Scaling
        all three R keeps the wall's internal resistance split, so a uniform f leaves its
        steady-state temperature profile unchanged. Optimised in ``log f`` within
        ``ua_factor_bounds``, start 1 (the spec).
    ua_factor_bounds : (float, float)
        Bounds of the UA factors [-].
    """

    per_edge: bool = False
    disturbance: str = "random_walk"
    fast_gain: bool = False
    common_gain: int = 0
    unmeasured_gain: bool = True
    basis: str | None = None
    harmonics: int = 2
    occupied_hours: tuple = (7.0, 19.0)
    weekdays_only: bool = True
    gain_schedule: str | None = None
    loop_gain: bool = False
    solar: object = "auto"
    noise: str = "shared"
    burn_in: float = 6 * 3600.0
    initial_state: str = "steady"
    supply_temperature: str = "midpoint"
    horizon: float = 3600.0
    stride: float | None = None
    rbar_bounds: tuple = RBAR_BOUNDS
    t_min: float = T_MIN
    t_max: float = T_MAX
    alpha: float | None = None
    sda_iterations: int = 30
    riccati: str = "implicit"
    measurement: str = "white"
    innovations: str = "gaussian"
    nu: object = "fit"
    nu_bounds: tuple = (2.5, 200.0)
    boundary_noise: object = None
    fit_rows: object = "auto"
    holdoff: float = 3 * 3600.0
    internal_mass: object = False
    cap_factor_bounds: tuple = (1.0, 100.0)
    wall_factors: bool = False
    ua_factor_bounds: tuple = (0.2, 5.0)

    def check(self):
        if self.riccati not in ("implicit", "doubling"):
            raise EstimationError(f"riccati must be 'implicit' or 'doubling', found {self.riccati!r}")
        if self.measurement not in ("white", "ar1"):
            raise EstimationError(f"measurement must be 'white' or 'ar1', found {self.measurement!r}")
        if self.innovations not in ("gaussian", "student"):
            raise EstimationError(f"innovations must be 'gaussian' or 'student', found "
                                  f"{self.innovations!r}")
        if self.nu != "fit" and not (isinstance(self.nu, (int, float)) and self.nu > 2.0):
            raise EstimationError(f"nu (degrees of freedom of the t innovations) must be > 2 "
                                  f"or 'fit', found {self.nu!r}")
        lo, hi = self.nu_bounds
        if not 2.0 < lo < hi:
            raise EstimationError(f"nu_bounds: need 2 < lower < upper [-], found {lo}, {hi}")
        if not (isinstance(self.common_gain, (int, np.integer))
                and not isinstance(self.common_gain, bool) and self.common_gain >= 0):
            raise EstimationError(f"common_gain must be an integer >= 0 (common gains), found "
                                  f"{self.common_gain!r}")
        if self.disturbance not in ("random_walk", "none"):
            raise EstimationError(f"disturbance must be 'random_walk' or 'none', found "
                                  f"{self.disturbance!r}")
        if self.basis not in (None, "levels", "fourier"):
            raise EstimationError(f"basis must be None, 'levels' or 'fourier', found {self.basis!r}")
        if self.gain_schedule not in (None, "occupied"):
            raise EstimationError(f"gain_schedule must be None or 'occupied', found "
                                  f"{self.gain_schedule!r}")
        if self.gain_schedule is not None and self.disturbance != "random_walk":
            raise EstimationError("gain_schedule needs disturbance='random_walk' (it scales the "
                                  "random-walk gains' noise in occupied hours)")
        if self.loop_gain not in (False, True):
            raise EstimationError(f"loop_gain must be True or False, found {self.loop_gain!r}")
        if self.loop_gain and self.gain_schedule is not None:
            raise EstimationError("loop_gain and gain_schedule do not combine (each gives the "
                                  "filter two regimes of its own); choose one")
        if self.noise not in ("shared", "zone"):
            raise EstimationError(f"noise must be 'shared' or 'zone', found {self.noise!r}")
        if self.initial_state not in ("steady", "paper"):
            raise EstimationError(f"initial_state must be 'steady' or 'paper', found "
                                  f"{self.initial_state!r}")
        if self.supply_temperature not in ("midpoint", "start"):
            raise EstimationError("supply_temperature must be 'midpoint' or 'start', found "
                                  f"{self.supply_temperature!r}")
        if self.internal_mass not in (False, None, True, "factor"):
            raise EstimationError(f"internal_mass must be False, True or 'factor', found "
                                  f"{self.internal_mass!r}")
        lo, hi = self.cap_factor_bounds
        if not 0 < lo < hi:
            raise EstimationError(f"cap_factor_bounds: need 0 < lower < upper [-], found {lo}, {hi}")
        if self.wall_factors not in (False, None, True):
            raise EstimationError(f"wall_factors must be True or False, found {self.wall_factors!r}")
        lo, hi = self.ua_factor_bounds
        if not 0 < lo <= 1.0 <= hi or lo == hi:
            raise EstimationError(f"ua_factor_bounds: need 0 < lower <= 1 <= upper [-] (1: the "
                                  f"spec's walls), found {lo}, {hi}")
        if not 0 < self.t_min < self.t_max:
            raise EstimationError(f"need 0 < t_min < t_max [s/m], found {self.t_min}, {self.t_max}")
