"""The Kalman likelihood as a structure criterion: BIC, AIC or held-back likelihood.

:class:`LikelihoodScorer` is what :func:`thermctl.structure.search.search_edges` asks
for the criterion of a structure: it fits the network with one R̄_v per air path (τ0
shared) by maximum likelihood and returns BIC, AIC or ``-2 log L`` of held-back data, and
ranks the candidates it could add cheaply (:meth:`LikelihoodScorer.screen`).
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np
from scipy.stats import binomtest, gmean

from ..._blas import ignore_warnings, single_thread_blas
from ..._parallel import ThreadPool, thread_map
from ...errors import BoundWarning, ConvergenceWarning, EstimationError
from ...model import ConvectionParameters
from ...network import ThermalNetwork
from ..bounds import RBAR_BOUNDS
from ..data import as_estimation_data
from .estimator import LikelihoodEstimator
from .kstep import kstep_block_mse
from .optimize import STALL

__all__ = ["LikelihoodScorer", "FitPool", "hooked", "cold_start_from", "required_t", "CRITERIA",
           "SCREENS"]

log = logging.getLogger(__name__)

CRITERIA = ("bic", "aic", "holdout")
SCREENS = ("grid", "fit")
RBAR_START = 3.36e-4
"""R̄_v a first air path starts from when no other is fitted yet [K/(W m)] (the paper's
estimate for Pugh Hall)."""


class LikelihoodScorer:
    """Structure criterion on the Kalman likelihood of a network.

    Parameters
    ----------
    spec : BuildingSpec
        Walls; the air paths come from the structures asked for.
    data : EstimationData, Measurements or DataFrame
    criterion : {"bic", "aic", "holdout"}
        ``holdout``: fit on the first ``1 − holdout`` of the data, judge by the
        likelihood of the rest (scaled like ``-2 log L`` so that changes read like BIC).
    holdout : float
        Fraction of the data held back [-].
    screen : {"grid", "fit"}
        How candidates are ranked: ``grid`` evaluates the likelihood at three R̄_v values
        per candidate with everything else held (one problem for all candidates); ``fit``
        optimises each candidate's R̄_v (a problem and a 1-D fit per candidate, ~5–10×
        slower).
    max_iter : int
        Per full fit warm-started from another (removal, addition and swap trials).
    start_iter : int
        Per cold fit: the search's start, from which the first trials are warm-started.
        A start stopped short by ``max_iter`` hands its unfinished descent to every trial:
        on the twin house N2 the 9-path start stopped at 200 iterations and 6 of its 9
        removal trials spent all of their own 200 on the same noise parameters. Converged
        (443 evaluations), the trials took 22–194 evaluations instead of 139–206, the same
        structures ended at the same likelihoods (within 0.7 nat) and the selection used
        14 % fewer evaluations.
    tol : float
        Tolerance of the selection's fits on the likelihood per observation [-]. 1e-7 gave
        the same edges with 21 % less CPU on the 25-zone corridor's local problems (and
        1994 instead of 2524 CPU s at 196 zones), but the final fit, warm-started from a
        looser selection fit, then ended elsewhere along the flat τ0 direction on the demo
        (C_v 6840 → 3080 J/K) and its R̄_v interval [2.69e-4, 3.29e-4] no longer held the
        truth 3.36e-4 ([2.62e-4, 3.38e-4] at 1e-9): kept at 1e-9 until the final fit no
        longer depends on where the selection stopped.
    stall : (int, float) or None
        A fit stops once it has gained less than ``stall[1]`` nats over its last
        ``stall[0]`` likelihood evaluations (:data:`~thermctl.estimate.likelihood.optimize.STALL`);
        None: L-BFGS-B's own tests only.
    on_fit : callable, optional
        ``on_fit(n)`` after each full fit (``n`` so far): a heartbeat for long searches.
    min_t : float
        Consistency an air path's gain must show (:meth:`consistent`): the t statistic of
        its daily likelihood gains [-]; 0: reported, not required.
    min_t_days : float or None
        The record ``min_t`` is asked of [days]: on D > ``min_t_days`` days the t statistic
        must reach ``min_t·√(D / min_t_days)`` (:func:`required_t`). None: ``min_t`` on
        any record.
    block : float
        Length of the blocks of that test [s] (a day: the gains' own period).
    predict_t : float or None
        Consistency an air path must show in prediction: the t statistic of its daily
        reduction of the ``predict_horizon``-ahead prediction error (:meth:`consistent`)
        [-]; None: not tested. Negative: a veto on paths that predict worse.
    entry_rbar_window : float or None
        A path that comes in by a swap or an addition (:meth:`admits`) must have its R̄_v
        within this factor of the median of the other paths' [-] (> 1); None: not asked.
    predict_horizon : float
        [s]
    cold_start : dict, optional
        Start values by parameter name (natural units) of every cold fit, the search's
        start among them; what it does not name starts at the defaults. The identification
        gives the solar apertures and gain noises of its conduction-only fit
        (:func:`cold_start_from`).
    **estimator_kwargs
        Passed to every :class:`LikelihoodEstimator` (model options, solver...).

    Attributes
    ----------
    n_fits : int
        Full fits and screening problems so far.
    """

    def __init__(self, spec, data, criterion: str = "bic", holdout: float = 0.3,
                 screen: str = "grid", max_iter: int = 200, start_iter: int = 1000,
                 tol: float = 1e-9, stall=STALL, on_fit=None,
                 min_t: float = 0.0, block: float = 86400.0, predict_t: float | None = None,
                 predict_horizon: float = 6 * 3600.0, cold_start: dict | None = None,
                 min_t_days: float | None = None, entry_rbar_window: float | None = None,
                 **estimator_kwargs):
        if criterion not in CRITERIA:
            raise EstimationError(f"criterion must be one of {CRITERIA}, found {criterion!r}")
        if screen not in SCREENS:
            raise EstimationError(f"screen must be one of {SCREENS}, found {screen!r}")
        self.spec = spec
        self.name = self.criterion = criterion
        self.screen_mode = screen
        self.kw = dict(estimator_kwargs)
        self.kw.pop("per_edge", None)
        self.max_iter = max_iter
        self.start_iter = start_iter
        self.tol = tol
        self.stall = None if stall is None else tuple(stall)
        self.on_fit = on_fit
        self.min_t = float(min_t)
        if min_t_days is not None and not min_t_days > 0:
            raise EstimationError(f"min_t_days must be > 0 [days] or None, found {min_t_days!r}")
        self.min_t_days = None if min_t_days is None else float(min_t_days)
        self.block = float(block)
        self.predict_t = None if predict_t is None else float(predict_t)
        if entry_rbar_window is not None and not entry_rbar_window > 1:
            raise EstimationError(f"entry_rbar_window must be a factor above 1 or None, found "
                                  f"{entry_rbar_window!r}")
        self.entry_rbar_window = None if entry_rbar_window is None else float(entry_rbar_window)
        self.predict_horizon = float(predict_horizon)
        self.cold_start = None if not cold_start else {k: float(v) for k, v in cold_start.items()}
        self.n_fits = 0
        self._count = threading.Lock()
        self._ahead = {}            # structure (frozenset of names) -> Future of _fit
        self._stops = {}            # the same keys -> Event that stops that fit
        data = as_estimation_data(data, ThermalNetwork(spec, ()))
        if criterion == "holdout":
            cut = int(round(len(data) * (1.0 - holdout)))
            self.train, self.test = data.window(0, cut), data.window(cut, None)
        else:
            self.train, self.test = data, None

    # ---- the Scorer protocol ----------------------------------------------------------
    def fit(self, edges, warm=None):
        """``(estimator, criterion)`` of the structure ``edges`` (list of Candidate), warm
        started from the parameters of ``warm`` (air paths new to it start at the geometric
        mean of its R̄_v)."""
        ahead = self._ahead.pop(frozenset(c.name for c in edges), None) if warm is None else None
        if ahead is not None:
            return self.count_fit(ahead.result())
        return self._fit(edges, init=_warm_init(edges, warm), step_scale=_warm_scale(warm))

    @contextlib.contextmanager
    def pool(self, workers: int):
        """A :class:`FitPool` of ``workers`` threads, for fits started and stopped one by one.

        The search's backward pass starts there the trials of the round it expects next
        while the last trials of a round run (:func:`thermctl.structure.search.search_edges`).
        The main thread holds the process-wide warnings filter and BLAS limit until the
        pool is closed (see :func:`thermctl._blas.ignore_warnings`); closing it stops the
        fits still open. Only L-BFGS-B fits stop early: an IPOPT fit (``solver="ipopt"``)
        runs to its end, and the pool waits for it.
        """
        with ignore_warnings(BoundWarning, ConvergenceWarning), single_thread_blas(), \
                ThreadPool(workers) as threads:
            yield FitPool(self, threads)

    def speculate(self, edges):
        """Start the cold :meth:`fit` of ``edges`` in a thread now and return its Future.

        A later ``fit(edges)`` without ``warm`` (on this scorer, or on one that
        :meth:`adopt` s it) returns that result: the same numbers, fitted earlier, while
        the main thread does something else (the whole-building identification fits its
        full candidate structure this way while it decides the gain model, with the gain
        model the decision is heading for). The caller holds, in the main thread, one
        ``ignore_warnings(BoundWarning, ConvergenceWarning)`` and one
        ``single_thread_blas()`` until the Future is done (both are process-wide; see
        :func:`thermctl._blas.ignore_warnings`).
        """
        edges = list(edges)
        key = frozenset(c.name for c in edges)
        stop = self._stops[key] = threading.Event()
        pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="thermctl-ahead")
        fut = pool.submit(self._fit, edges, count=False, stop=stop)
        pool.shutdown(wait=False)
        self._ahead[key] = fut
        return fut

    def cancel_ahead(self, wait_: bool = True) -> list:
        """Stop the fits started ahead at their next likelihood evaluation (a wrong guess
        should not hold a core: on the demo the unneeded fit took longer than the decision
        it was started beside), wait for their threads (unless ``wait_`` is False), and
        forget them. Returns their futures. Only L-BFGS-B fits stop early."""
        for stop in self._stops.values():
            stop.set()
        futs = list(self._ahead.values())
        self._ahead, self._stops = {}, {}
        if wait_:
            wait(futs)
        return futs

    def adopt(self, other: "LikelihoodScorer") -> None:
        """Take the fits ``other`` started ahead (:meth:`speculate`); ``other`` must ask the
        same questions of the same data (options, criterion, rows), else EstimationError."""
        same = (other.kw == self.kw and other.criterion == self.criterion
                and other.tol == self.tol and other.stall == self.stall
                and other.max_iter == self.max_iter
                and other.start_iter == self.start_iter
                and other.cold_start == self.cold_start
                and _same_data(other.train, self.train))
        if not same:
            raise EstimationError("adopt: the fits started ahead used other options or data "
                                  "than this search's")
        self._ahead.update(other._ahead)
        self._stops.update(other._stops)
        other._ahead, other._stops = {}, {}

    def fit_many(self, structures, warm=None, workers: int = 1) -> list:
        """:meth:`fit` of every structure in ``structures``, ``workers`` at a time.

        The fits run in threads: CasADi's evaluation and BLAS release the GIL (two
        gradients of the demo's 61-state problem in two threads took 4.4 s of wall time
        against 8.2 s one after the other). The results are those of the serial loop, in
        its order; each fit is deterministic with one BLAS thread.
        """
        # the warnings filters are process-wide and catch_warnings is not thread-safe:
        # one context here, none in the threads (see ignore_warnings)
        with ignore_warnings(BoundWarning, ConvergenceWarning):
            return thread_map(lambda s: self.fit(s, warm=warm), structures, workers)

    def screen_many(self, jobs, workers: int = 1) -> list:
        """:meth:`screen` of every ``(edges, rest, fitted)`` in ``jobs``, ``workers`` at a
        time (threads, as :meth:`fit_many`); the results are the serial loop's.

        The grid screening builds each job's problem (jobs side by side), then evaluates
        every candidate of every job on the ``workers`` threads: one job (the additions'
        screening) or a few of different sizes (a swap round's) keep them all busy. On the
        ring of offices with hourly occupancy the screenings were 11 of the selection's 60 s,
        the additions' one on one core.
        """
        with ignore_warnings(BoundWarning, ConvergenceWarning):
            if self.screen_mode != "grid" or workers <= 1:
                return thread_map(lambda j: self.screen(*j), jobs, workers)
            grids = thread_map(lambda j: self._grid_problem(j[0], j[1], dict(j[2].params_)),
                               jobs, workers)
            tasks = [(g, c) for g, (_, rest, _) in zip(grids, jobs) for c in rest]
            vals = iter(thread_map(lambda t: _grid_value(*t), tasks, workers))
            return [{c.name: next(vals) for c in rest} for _, rest, _ in jobs]

    def screen(self, edges, rest, fitted) -> dict:
        """Edge name → criterion change of adding each of ``rest``, everything else held."""
        if self.screen_mode == "grid":
            return self._grid_screen(edges, rest, dict(fitted.params_))
        base = dict(fitted.params_)
        dk = 1 + (0 if any(k.startswith("tau0") for k in base) else 1)
        out = {}
        for c in rest:
            init = dict(base)
            init[_key(c)] = _start_rbar(base)
            e2, _ = self._fit(edges + [c], init=init, fix=dict(base), max_iter=60)
            # the held parameters are not free in e2: count the full model's
            out[c.name] = 2.0 * (e2.nll_ - fitted.nll_) + dk * self.penalty(e2)
        return out

    def consistent(self, small, big):
        """Whether ``big`` (``small`` plus an air path) fits better day after day.

        An information criterion adds the gains of all samples as if the innovations were
        independent; when the model is only approximately right they are not (on the twin
        house the robust variance of R̄_v is ~250× the model's), and a path that helps on
        a few days and hurts on others passes BIC by 10²–10⁴. Here the gain is split by
        day, ``g_d = nll_d(small) − nll_d(big)``, and judged by its t statistic
        ``t = mean(g) / (sd(g) / √D)`` over the D days: a Vuong-type comparison whose
        variance comes from the data, so it holds under misfit and autocorrelation within
        a day. For an air path that is not there, a local expansion gives ``g_d ≈ s_d δ −
        ½ I_d δ²`` with ``δ`` the fitted step, hence ``t ≈ |Z| / 2`` with Z the robust
        score statistic: ``min_t = 2`` asks for ``|Z| ≥ 4`` (~3 × 10⁻³ with a t
        distribution on 9 days), while a true path gains on nearly every day.

        With ``predict_t`` the path must also predict better day after day: ``g_d`` is then
        the reduction of day d's mean squared ``predict_horizon``-ahead prediction error
        (from filtered states, :func:`~thermctl.estimate.likelihood.kstep.kstep_block_mse`),
        judged the same way. The likelihood scores one step ahead; a coupling that passes
        a disturbance common to two rooms on to the next step can help there and still
        not help, or hurt, the hours ahead an MPC acts over (on the twin house BIC keeps
        doorway–kitchen, a coupling between closed rooms whose likelihood gain has t 5.2
        over 31 days, and it predicts 6 h ahead worse on 28 of them; the Pugh Hall
        testbed's true paths predict better on 20 of 20 days, t 7–8). A day's squared
        prediction error is heavy-tailed, so a prediction gain that fails its t test still
        holds when the sign test says it is better on nearly every day (one-sided p ≤
        :data:`SIGN_P`).

        Returns
        -------
        ok : bool
        t : float
            Of the likelihood gains; of the prediction gains when only that test fails (the
            search drops the weakest failing edge first).
        note : str
            A few words for the selection path.
        """
        if self.test is not None:
            return True, float("nan"), ""
        g = self._daily_gains(small, big)
        need = required_t(self.min_t, len(g), self.min_t_days)
        t, note = _day_t(g, need, "daily gain")
        ok = need <= 0 or not t < need
        if self.predict_t is not None:
            gk = self._daily_prediction_gains(small, big)
            tk, note_k = _day_t(gk, self.predict_t, f"{self.predict_horizon / 3600:g}-h prediction")
            if ok and tk < self.predict_t:
                # a day's squared prediction error is heavy-tailed: one day of a large
                # disturbance can outweigh nine better ones (Pugh Hall, perfect sensors,
                # seed 0: the true r240-r243 predicts 6 h ahead better on 9 of 10 days, t
                # -0.8). Better on nearly every day, by the sign test, also holds
                p = _sign_p(gk)
                if p <= SIGN_P:
                    note_k += f" (sign test p {p:.3f}: holds)"
                else:
                    ok, t = False, tk
            note = f"{note}; {note_k}"
        return ok, t, note

    def admits(self, small, big):
        """:meth:`consistent` of a path that comes in by a swap or an addition (``big`` in
        place of ``small``), and with ``entry_rbar_window`` its R̄_v within that factor of
        the median of ``big``'s other paths.

        The paper's model has one R̄_v for the building: a path whose own value is far
        from the others' conducts what no door of its length does at theirs, and stands in
        for something the model lacks. The test is asked where a search overturns an
        earlier verdict (the gain-schedule check's swaps and additions,
        ``selection.schedule_adds``), not of the paths it keeps. Returns as
        :meth:`consistent`."""
        ok, t, note = self.consistent(small, big)
        w = self.entry_rbar_window
        if not ok or w is None:
            return ok, t, note
        rb = {k: v for k, v in big.params_.items() if ConvectionParameters.is_rbar(k)}
        new = set(rb) - set(small.params_)
        others = [rb[k] for k in rb if k not in new]
        if not new or not others:
            return ok, t, note
        m = float(np.median(others))
        for k in sorted(new):
            ratio = rb[k] / m
            if not abs(math.log(ratio)) <= math.log(w):
                return False, t, (f"{note}; its R̄_v {rb[k]:.3g} K/(W m) is ×{ratio:.2f} the "
                                  f"median of the other {len(others)} paths', outside "
                                  f"×{1 / w:.2g}–{w:g}")
        return ok, t, note

    @property
    def lost_days(self) -> float:
        """Fit samples lost (a zone temperature or an input missing: gaps the reader did
        not fill, an outage), in days [d]."""
        if getattr(self, "_lost", None) is None:
            d = self.train
            bad = ~(np.isfinite(d.Y).all(axis=1) & np.isfinite(d.U).all(axis=1))
            self._lost = float(bad.sum()) * d.dt / 86400.0
        return self._lost

    def lost_data(self, small, big, cost: float, margin: float) -> str:
        """Whether the samples lost could have turned the verdict on ``big``'s extra path.

        The criterion change of the path is a sum of daily gains ``g_d``
        (:meth:`consistent`); the ``L`` days lost would have added about ``L`` more. Had
        they gone like the path's worst tenth of days (``q10``, or its best tenth for a path
        left out), its cost ``cost`` [criterion units: removing it from ``big`` when
        ``cost > margin`` (kept), adding it otherwise] would be ``cost + 2 L q``. When that
        crosses ``margin`` the verdict rests on the data that happened to survive.

        Returns
        -------
        str
            "" when the verdict holds (or nothing was lost, or too few days to say), else a
            few words for the selection's reasons, starting with "uncertain (data lost)".
        """
        L = self.lost_days
        if L <= 0 or self.test is not None:
            return ""
        g = self._daily_gains(small, big)
        if len(g) < 4:
            return ""
        kept = cost >= margin
        q = float(np.quantile(g, 0.1 if kept else 0.9))
        shifted = cost + 2.0 * L * (min(q, 0.0) if kept else max(q, 0.0))
        if (shifted >= margin) == kept:
            return ""
        how = "worst" if kept else "best"
        return (f"uncertain (data lost): {L:.2g} day(s) of samples lost; had they gone like "
                f"its {how} tenth of days ({q:+.1f} per day in log-likelihood), "
                f"{'removing' if kept else 'adding'} it would {'cost' if kept else 'gain'} "
                f"{self.name} {shifted:+.1f}, {'under' if kept else 'over'} the margin "
                f"{margin:g}")

    def _daily_gains(self, small, big) -> np.ndarray:
        """``nll_d(small) − nll_d(big)`` per block (day) present in both."""
        with single_thread_blas():
            ids_s, ls = small.problem_.block_nll(small.eta_, self.block)
            ids_b, lb = big.problem_.block_nll(big.eta_, self.block)
        return _paired_difference(ids_s, ls, ids_b, lb)

    def _daily_prediction_gains(self, small, big) -> np.ndarray:
        """``mse_d(small) − mse_d(big)`` of the ``predict_horizon``-ahead predictions per
        block (day) present in both [K²]."""
        return _paired_difference(*self._block_mse(small), *self._block_mse(big))

    def _block_mse(self, est):
        """:func:`kstep_block_mse` of a fitted estimator, kept on it: a backward step tests
        every trial against the same current model (0.2 s a call on the twin house)."""
        memo = est.__dict__.setdefault("_block_mse", {})
        key = (self.predict_horizon, self.block)
        if key not in memo:
            memo[key] = kstep_block_mse(est.problem_, est.eta_, self.predict_horizon,
                                        block=self.block)
        return memo[key]

    def describe(self, c, fitted) -> str:
        """One line on air path ``c`` in ``fitted``."""
        rb = fitted.params_.get(_key(c), float("nan"))
        return f"rbar_v {rb:.3g} K/(W m), d {c.d:g} m" + (" (parallel to a wall)"
                                                            if c.parallel else "")

    # ---- internals --------------------------------------------------------------------
    def _fit(self, edges, init=None, fix=None, max_iter=None, count=True, stop=None,
             step_scale=None):
        net = ThermalNetwork(self.spec, [c.pair + (c.d,) for c in edges])
        cold = init is None and fix is None
        if max_iter is None:
            max_iter = self.start_iter if cold else self.max_iter
        if cold and self.cold_start:
            init = dict(self.cold_start)
        est = LikelihoodEstimator(net, per_edge=True, fix=fix, tol=self.tol,
                                  max_iter=max_iter, stall=self.stall, **self.kw)
        if stop is not None:
            est.make_problem = _stoppable(est.make_problem, stop)
        with ignore_warnings(BoundWarning, ConvergenceWarning):
            est.fit(self.train, init=init, step_scale=step_scale)
        out = est, self.value(est)
        return self.count_fit(out) if count else out

    def count_fit(self, out=None):
        """Count one full fit (and tell ``on_fit``); returns ``out``. Also for a fit made
        outside the scorer on its behalf (the selection's final fit)."""
        with self._count:
            self.n_fits += 1
            n = self.n_fits
        if self.on_fit is not None:
            self.on_fit(n)
        return out

    def _grid_screen(self, cur, rest, base):
        """Criterion change of each candidate at a few R̄_v values, all else held.

        One problem holds the current edges and every candidate; a candidate is "off" at
        R̄_v = ``_R_OFF`` (a conductance of ~10⁻³ W/K) and tried at the current R̄_v ×
        {1/4, 1, 4}.
        Costs 3 likelihood evaluations per candidate instead of a fit each.
        """
        grid = self._grid_problem(cur, rest, base)
        with single_thread_blas():
            return {c.name: _grid_value(grid, c) for c in rest}

    def _grid_problem(self, cur, rest, base) -> tuple:
        """``(problem, eta, f0, rb0, pen)`` of :meth:`_grid_screen`: the problem with every
        candidate off, its start, its criterion there, the R̄_v a candidate is tried around
        and the criterion's price of one parameter; counted as one fit."""
        net = ThermalNetwork(self.spec, [c.pair + (c.d,) for c in cur + rest])
        lo = self.kw.get("rbar_bounds", RBAR_BOUNDS)[0]
        est2 = LikelihoodEstimator(net, per_edge=True,
                                   **{**self.kw, "rbar_bounds": (lo, _R_OFF)})
        init = dict(base)
        for c in rest:
            init[_key(c)] = _R_OFF
        pb = est2.make_problem(self.train, init=init)
        eta = pb.layout.eta0()
        with single_thread_blas():
            f0 = pb.nll(eta)
        dk = 1 + (0 if any(k.startswith("tau0") for k in base) else 1)
        pen = dk * (2.0 if self.criterion == "aic" else math.log(max(pb.n_obs, 2)))
        with self._count:
            self.n_fits += 1
        return pb, eta, f0, _start_rbar(base), pen

    def penalty(self, est):
        """Criterion cost of one more parameter."""
        return 2.0 if self.criterion == "aic" else math.log(max(est.n_obs_, 2))

    def value(self, est):
        """Criterion of a fitted estimator (lower is better)."""
        if self.criterion == "bic":
            return est.bic_
        if self.criterion == "aic":
            return est.aic_
        # held-back likelihood, scaled like -2 log L so the deltas read like AIC/BIC
        return 2.0 * est.score(self.test) * est.problem_for(self.test).n_obs


def _paired_difference(ids_s, vs, ids_b, vb) -> np.ndarray:
    """``vs − vb`` over the blocks present in both (block numbers ``ids_s``, ``ids_b``)."""
    _, i_s, i_b = np.intersect1d(ids_s, ids_b, return_indices=True)
    return vs[i_s] - vb[i_b]


SIGN_P = 0.025
"""One-sided sign-test p value at or below which a prediction gain that fails its t test still
holds day after day [-]: better on at least 9 of 10, 10 of 12, 12 of 14 or 22 of 31 days."""


def _sign_p(g) -> float:
    """One-sided sign-test p value of more positive than negative daily gains ``g`` (ties
    left out; 1 with fewer than 4 days)."""
    pos, neg = int(np.sum(g > 0)), int(np.sum(g < 0))
    if pos + neg < 4:
        return 1.0
    return float(binomtest(pos, pos + neg, 0.5, alternative="greater").pvalue)


def required_t(min_t: float, days: int, min_t_days: float | None = None) -> float:
    """The t statistic the daily gains of ``days`` days must reach [-].

    ``min_t`` on up to ``min_t_days`` days; on a longer record ``min_t·√(days /
    min_t_days)``, the same mean daily gain against its day-to-day spread, since
    ``t = mean/sd·√D``. For an air path that is not there, ``t`` does not grow with the
    record (``t ≈ |Z|/2``, :meth:`LikelihoodScorer.consistent`), so a fixed ``min_t``
    holds; one that stands in for what the model lacks (a disturbance two zones share, a
    loop acting between samples) gains a fixed amount per day, and its ``t`` grows as √D.
    Measured on the 49-zone corridor testbed (seeds 0–3, local problems, ``min_t`` 2): 14
    days (10 calibration days) 41/52 true paths and 4 false, 28 days (21) 50/52 and 27
    false; with ``min_t_days`` 10 on 28 days (t ≥ 2.9) 48/52 and 6 false.

    Examples
    --------
    >>> required_t(2.0, 10, 10.0), required_t(2.0, 40, 10.0), required_t(2.0, 40)
    (2.0, 4.0, 2.0)
    """
    if min_t_days is None or days <= min_t_days:
        return float(min_t)
    return float(min_t) * math.sqrt(days / min_t_days)


def _day_t(g, need: float, what: str) -> tuple[float, str]:
    """t statistic ``mean(g) / (sd(g) / √D)`` of daily gains ``g`` (NaN with fewer than 4
    days) and a few words on it."""
    D = len(g)
    if D < 4:
        return float("nan"), f"{what}: {D} day(s), too few to test consistency"
    sd = float(np.std(g, ddof=1))
    t = math.inf if sd == 0.0 else float(np.mean(g)) / (sd / math.sqrt(D))
    req = f" (needs {need:g})" if need else ""
    return t, f"{what} t {t:.1f}{req}, better on {int(np.sum(g > 0))} of {D} days"


class FitPool:
    """:meth:`LikelihoodScorer.fit` on the threads of a :class:`~thermctl._parallel.ThreadPool`
    (made by :meth:`LikelihoodScorer.pool`).

    ``submit(edges, warm)`` starts the fit that ``fit(edges, warm)`` would make (the same
    start, hence the same numbers), ``result`` takes it and counts it as ``fit`` does,
    ``cancel`` stops one that is not needed at its next likelihood evaluation; a cancelled
    fit is never counted.
    """

    def __init__(self, scorer: LikelihoodScorer, threads: ThreadPool):
        self.scorer, self.threads = scorer, threads

    def submit(self, edges, warm):
        """Future of ``(estimator, criterion)`` of ``edges`` warm started from ``warm``."""
        edges = list(edges)
        return self.threads.submit(self.scorer._fit, edges, init=_warm_init(edges, warm),
                                   count=False, step_scale=_warm_scale(warm))

    def idle(self) -> bool:
        """Whether a fit submitted now would start at once."""
        return self.threads.idle()

    def cancel(self, fut) -> None:
        self.threads.cancel(fut)

    def result(self, fut):
        """``(estimator, criterion)`` of a submitted fit (waits for it), counted."""
        return self.scorer.count_fit(fut.result())


_R_OFF = 1e2
"""R̄_v of a candidate the grid screening holds off [K/(W m)]: a conductance of ~10⁻³ W/K."""


def _grid_value(grid, c) -> float:
    """Criterion change of adding ``c`` in the grid screening's problem ``grid``
    (:meth:`LikelihoodScorer._grid_problem`): the best of its R̄_v at rb0 × {1/4, 1, 4}.
    Thread-safe: a problem keeps buffers per thread."""
    pb, eta, f0, rb0, pen = grid
    i = pb.layout.index(_key(c))
    best = np.inf
    for f in (0.25, 1.0, 4.0):
        e = eta.copy()
        e[i] = math.log(rb0 * f)
        best = min(best, pb.nll(e))
    return 2.0 * (best - f0) + pen


#: Parameters a cold fit takes from the conduction-only fit (:func:`cold_start_from`).
COLD_START = ("aperture[", "sigma_phi[")


def cold_start_from(fit) -> dict:
    """Start values for the search's cold fits from a conduction-only fit ``fit`` (a fitted
    :class:`LikelihoodEstimator`): its solar apertures and gain noises, which air paths
    change little. The sensor and heat noises keep their default start: with one noise
    level per zone the likelihood has a mode for each way of splitting a misfit between
    the two, and the conduction-only fit's split (its misfit is the air paths' heat) leads
    elsewhere. Measured on the twin house N2 (SIN's 9 picks, one thread): cold 21.0 s of CPU
    to −log L −69 083.31; every parameter from the conduction-only fit 11.0 s to −69 075.74
    (7.6 nats worse); its apertures only 12.5 s to −69 081.92; apertures and gain noises
    11.4 s to −69 083.40. The demo: 2.8 → 1.4 s to the same optimum (within 0.01 nat).
    """
    return {k: float(v) for k, v in fit.params_.items() if k.startswith(COLD_START)}


def _warm_scale(warm):
    """L-BFGS-B's coordinate scales for a fit warm-started from ``warm`` (its own, learned at
    its end; None: the identity)."""
    return None if warm is None else getattr(warm, "step_scale_", None)


def _warm_init(edges, warm):
    """Start values of the structure ``edges`` from the fit ``warm`` (None: the defaults): its
    parameters less the air paths ``edges`` lacks; an air path new to it starts at the
    geometric mean of its R̄_v."""
    if warm is None:
        return None
    keep = {_key(c) for c in edges}
    init = {k: v for k, v in warm.params_.items() if not k.startswith("rbar_v[") or k in keep}
    for c in edges:
        init.setdefault(_key(c), _start_rbar(warm.params_))
    return init


class _Stopped(Exception):
    """A fit started ahead was stopped (:meth:`LikelihoodScorer.cancel_ahead`)."""


def hooked(make_problem, before=None, after=None):
    """``make_problem`` whose problems call ``before()`` ahead of every likelihood
    evaluation with its gradient (``nll_grad``, what L-BFGS-B calls) and ``after(value,
    problem)`` after it, with the negative log-likelihood there [-]. A fit started ahead
    stops through ``before`` (:meth:`LikelihoodScorer.speculate`); the gain-model decision
    follows its fit through ``after`` (``thermctl.identify``). Both run in the fitting
    thread. A RuntimeError from either reads as a failed evaluation (L-BFGS-B steps back
    from it), any other error ends the fit."""
    def make(*args, **kwargs):
        pb = make_problem(*args, **kwargs)
        fg = pb.nll_grad

        def nll_grad(eta):
            if before is not None:
                before()
            f, g = fg(eta)
            if after is not None:
                after(f, pb)
            return f, g
        pb.nll_grad = nll_grad
        return pb
    return make


def _stoppable(make_problem, stop):
    """``make_problem`` whose problems raise :class:`_Stopped` at the next likelihood
    evaluation once ``stop`` is set."""
    def check():
        if stop.is_set():
            raise _Stopped
    return hooked(make_problem, before=check)


def _same_data(a, b) -> bool:
    """Whether two EstimationData hold the same samples (a cheap check: 0.2 ms on 31 days)."""
    return (a.dt == b.dt and a.zones == b.zones and a.input_names == b.input_names
            and np.array_equal(a.U, b.U, equal_nan=True)
            and np.array_equal(a.Y, b.Y, equal_nan=True))


def _key(c) -> str:
    return ConvectionParameters.key(c.name)


def _start_rbar(params):
    vals = [v for k, v in params.items() if k.startswith("rbar_v")]
    return float(gmean(vals)) if vals else RBAR_START
