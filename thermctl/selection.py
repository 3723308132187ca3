"""Model-based selection of a building's air paths: the structure search on the likelihood.

Joins the two method packages, which do not know each other: the greedy search over
structures (:func:`thermctl.structure.search.search_edges`) and the Kalman-likelihood
criterion it asks (:class:`thermctl.estimate.likelihood.scoring.LikelihoodScorer`), with
the paper's SIN picks as an optional candidate set
(:class:`thermctl.structure.StructureIdentifier`).
"""

from __future__ import annotations

import inspect
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import gmean

from .errors import BoundWarning, EstimationError
from .model import ConvectionParameters
from .estimate.likelihood import LikelihoodEstimator
from .estimate.likelihood.scoring import CRITERIA, LikelihoodScorer
from .network import ThermalNetwork
from .structure.search import RECHECK, _cand, as_candidates, candidate_pairs, search_edges

__all__ = ["SelectionResult", "select_air_paths", "sin_candidates", "judge_air_paths", "CRITERIA",
           "per_path_rbar", "shared_start", "air_path_scorer"]


@dataclass
class SelectionResult:
    """Outcome of :func:`select_air_paths`.

    Attributes
    ----------
    edges : list of (str, str, float)
        Selected convection edges ``(a, b, d)``.
    candidates : list of Candidate
    path : list of SelectionStep
    reasons : dict
        Edge name → why it is in or out.
    criterion : str
    estimator : LikelihoodEstimator
        Final fit of the selected structure (shared R̄_v unless ``final_per_edge``).
    per_edge : dict
        Edge name → R̄_v of the per-edge fit of the selected structure [K/(W m)].
    time : float
        [s]
    n_fits : int
    trials : dict
        The search's fit of the selected structure and its last removal trials
        (:attr:`~thermctl.structure.search.SearchResult.trials`), for a search that starts
        from these edges (``select_air_paths(known=...)``).
    days : int
        Days of data the daily-gain test compared (the D of its t statistic) [-].
    """

    edges: list
    candidates: list
    path: list
    reasons: dict
    criterion: str
    estimator: LikelihoodEstimator
    per_edge: dict
    time: float
    n_fits: int
    trials: dict = field(default_factory=dict, repr=False)
    days: int = 0

    def summary(self) -> str:
        lines = [f"model-based edge selection ({self.criterion}): {len(self.edges)} edge(s) "
                 f"in {self.n_fits} fits, {self.time:.0f} s"]
        for st in self.path:
            lines.append(f"  {st.action:6s} {st.edge or '':24s} {self.criterion} {st.value:12.2f} "
                         f"(Δ {st.delta:+.2f}) {st.note}")
        lines.append("reasons:")
        for c in self.candidates:
            lines.append(f"  {c.name}: {self.reasons.get(c.name, '')}")
        return "\n".join(lines)


def sin_candidates(spec, data, level: float = 0.05, allow_parallel: bool = True) -> list:
    """Pairs picked by the paper's SIN scores (argmax ∪ threshold rule, walls allowed).

    Parameters
    ----------
    spec : BuildingSpec
    data : pandas.DataFrame or thermctl.data.Measurements
    level : float
        SIN significance level.
    allow_parallel : bool
        Let SIN propose pairs joined by a wall too.
    """
    from .structure import StructureIdentifier
    frame = getattr(data, "frame", data)
    if not hasattr(frame, "columns"):
        raise EstimationError("candidates='sin' needs the data as a DataFrame or Measurements")
    net = ThermalNetwork(spec, ())
    out = set()
    for rule in ("paper", "threshold"):
        sid = StructureIdentifier(level=level, rule=rule,
                                  allow_parallel=allow_parallel).fit(frame, net)
        out |= {tuple(sorted((e.a, e.b))) for e in sid.edges_}
    return [_cand(spec, p) for p in sorted(out)]


def per_path_rbar(est) -> dict:
    """Edge name → R̄_v of a fit with one R̄_v per convection edge [K/(W m)]."""
    rb, _ = est.problem_.rbar_c(est.eta_)
    return {e.name: float(r) for e, r in zip(est.problem_.edges, rb)}


def shared_start(params: dict, per_edge: dict) -> dict:
    """Start values of a fit with one shared R̄_v from a fit's ``params``: every parameter
    but the per-path R̄_v, and, unless the fit had a shared one, the geometric mean of the
    per-path values ``per_edge`` (none without them)."""
    init = {k: v for k, v in params.items() if not ConvectionParameters.is_rbar(k, per_edge=True)}
    if per_edge:
        init.setdefault("rbar_v", float(gmean(list(per_edge.values()))))
    return init


def select_air_paths(spec, data, *, candidates="all", criterion: str = "bic",
                     direction: str = "both", start=(), max_edges: int | None = None,
                     holdout: float = 0.3, final_per_edge: bool = False,
                     final_criterion: str = "likelihood", max_iter: int = 200,
                     margin: float = 10.0, screen: str = "grid", progress=None, on_fit=None,
                     min_t: float = 0.0, predict_t: float | None = None, workers: int = 1,
                     ahead=None, swaps=None, adds: bool = False, known=None,
                     final=None, recheck: float | None = RECHECK, union: bool = False,
                     cold_start: dict | None = None, min_t_days: float | None = None,
                     entry_rbar_window: float | None = None,
                     **estimator_kwargs) -> SelectionResult:
    """Choose the convection edges of a building by model fit.

    Parameters
    ----------
    spec : BuildingSpec
        Walls and air-path distances (no convection edges needed).
    data : EstimationData, Measurements or DataFrame
    candidates : "all", "sin" or list of Candidate / (a, b[, d])
        ``all`` (default): :func:`candidate_pairs` (every pair with a distance, walls or
        not). ``sin``: the union of the paper's SIN picks (argmax and threshold rules,
        :class:`thermctl.structure.StructureIdentifier`, walls allowed) — with
        ``direction="backward"`` the likelihood then prunes what SIN proposed; measured on
        the testbed family this gives the fewest false edges (see
        ``benchmarks/identification.py``). Needs a DataFrame or ``Measurements``.
    criterion : {"bic", "aic", "holdout"}
        ``holdout``: fit on the first ``1 − holdout`` of the data, judge by the
        likelihood of the rest.
    direction : {"forward", "backward", "both"}
        ``backward`` starts from all candidates.
    start : sequence
        Edges in the model from the start (forward / both).
    max_edges : int, optional
    holdout : float
        Fraction of the data held back [-].
    final_per_edge : bool
        Final fit with one R̄_v per edge (default: shared, the paper's model).
    final_criterion : {"likelihood", "kstep"}
        Criterion of the final fit of the selected structure (the selection itself always
        uses the likelihood).
    max_iter : int
        Per full fit.
    margin : float
        Improvement of the criterion an edge must bring to enter (and must keep bringing
        to stay) [-]. Default 10, "very strong" evidence on Kass & Raftery's BIC scale:
        the model is only approximately right (its innovations are not white, see
        :func:`~thermctl.estimate.likelihood.uncertainty.wald_intervals`), which inflates likelihood
        differences; measured on the testbed, true air paths improve BIC by 10²–10³, and
        spurious ones among SIN's picks by up to ~6 — but offered every pair (walls and the
        unmeasured hallway included), BIC lets 2.3 false edges per building in, and on the
        twin house every pair improves it by 10²–10⁴ (benchmarks/identification.py,
        benchmarks/twinhouse.py): a good pruner, a poor gatekeeper.
    screen : {"grid", "fit"}
        How candidates are ranked before the best one is refitted: ``grid`` evaluates the
        likelihood at three R̄_v values per candidate with everything else held (one
        problem for all candidates); ``fit`` optimises each candidate's R̄_v (a problem
        and a 1-D fit per candidate, ~5–10× slower).
    progress : callable, optional
        ``progress(message)`` after each decision.
    on_fit : callable, optional
        ``on_fit(n)`` after each full fit (``n`` fits so far): a heartbeat for long searches.
    min_t : float
        An edge's gain must also hold day by day: the t statistic of its daily likelihood
        gains (:meth:`LikelihoodScorer.consistent`) [-]; 0: off.
    min_t_days : float or None
        The record ``min_t`` is for [days]; on longer records the t statistic must grow as
        √days (:func:`~thermctl.estimate.likelihood.scoring.required_t`). None: ``min_t``
        on any record.
    predict_t : float or None
        And in prediction: the t statistic of its daily reduction of the 6-h-ahead
        prediction error (:meth:`LikelihoodScorer.consistent`) [-]; None: not tested.
    entry_rbar_window : float or None
        A path that comes in by a swap or an addition must have its R̄_v within this factor
        of the median of the other paths' (:meth:`LikelihoodScorer.admits`) [-]; None: not
        asked.
    workers : int
        Trial fits of a backward step side by side, in threads
        (:meth:`LikelihoodScorer.fit_many`); the selection is the same as with 1.
    swaps : "all" or list of Candidate / (a, b[, d]), optional
        After the backward pass, replacements of each kept edge by one of these that shares
        a zone with it (:func:`~thermctl.structure.search.search_edges`); ``all``: every
        pair of measured zones with a length. None: no swaps.
    adds : bool
        With ``swaps``: when no swap is made, also try adding one of them, and prune again
        (:func:`~thermctl.structure.search.search_edges`).
    union : bool
        With ``adds``: a last backward pass from the selection and every path away from
        walls whose addition screened below 0
        (:func:`~thermctl.structure.search.search_edges`).
    known : dict, optional
        Structures fitted already with the same data and model options (another
        selection's :attr:`SelectionResult.trials`); taken instead of fitted again.
    recheck : float or None
        After a removal the backward pass tries again only the edges whose removal cost on
        an earlier structure was below ``recheck × margin``, and every edge before it stops
        (:func:`~thermctl.structure.search.search_edges`) [-]; None: every edge every round.
    final : LikelihoodEstimator, optional
        The final fit of the ``candidates``' structure, made already (another selection's
        :attr:`SelectionResult.estimator`): returned, not refitted, when the search keeps
        every candidate.
    ahead : LikelihoodScorer, optional
        Fits started ahead (:meth:`LikelihoodScorer.speculate`) with the same options and
        data: the search takes their results instead of fitting again
        (:meth:`LikelihoodScorer.adopt` raises if the options differ).
    cold_start : dict, optional
        Start values of the search's cold fits by parameter name (natural units)
        (:class:`~thermctl.estimate.likelihood.scoring.LikelihoodScorer`).
    **estimator_kwargs
        Passed to every :class:`LikelihoodEstimator` (model options, solver...).

    Returns
    -------
    SelectionResult
    """
    t0 = time.perf_counter()
    if isinstance(candidates, str) and candidates == "sin":
        candidates = sin_candidates(spec, data)
    elif isinstance(candidates, str) and candidates == "all":
        candidates = None
    cands = as_candidates(spec, candidates)
    by_name = {c.name: c for c in cands}
    scorer = LikelihoodScorer(spec, data, criterion, holdout=holdout, screen=screen,
                              max_iter=max_iter, on_fit=on_fit, min_t=min_t,
                              predict_t=predict_t, cold_start=cold_start,
                              min_t_days=min_t_days, entry_rbar_window=entry_rbar_window,
                              **estimator_kwargs)
    if ahead is not None:
        scorer.adopt(ahead)
    start = [by_name.get(_cand(spec, e).name, _cand(spec, e)) for e in start]
    if isinstance(swaps, str) and swaps == "all":
        swaps = candidate_pairs(spec, include_unmeasured=False)
    swaps = None if swaps is None else [by_name.get(c.name, c) for c in as_candidates(spec, swaps)]
    res = search_edges(cands, scorer, direction=direction, start=start, max_edges=max_edges,
                       margin=margin, progress=progress, workers=workers, swaps=swaps,
                       adds=adds, known=known, recheck=recheck, union=union)
    est, cur = res.fitted, res.edges
    per_edge = per_path_rbar(est) if cur else {}
    net = ThermalNetwork(spec, [x.pair + (x.d,) for x in cur])
    final_kw = dict(estimator_kwargs)
    final_kw.pop("per_edge", None)
    if final is not None and {x.name for x in cur} == {c.name for c in cands}:
        pass                                # the structure it was made for: nothing to refit
    elif final_per_edge and final_criterion == "likelihood" and criterion != "holdout":
        # the search's last fit is this very model (per edge, likelihood, all the data):
        # refitting it would cost one more fit for the same optimum
        final = est
    else:
        final = LikelihoodEstimator(net, final_criterion, per_edge=final_per_edge,
                                    max_iter=max_iter, **final_kw)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BoundWarning)
            final.fit(data, init=shared_start(est.params_, per_edge))
        scorer.count_fit()                  # counted and shown like the search's fits
    return SelectionResult([x.pair + (x.d,) for x in cur], res.candidates, res.path, res.reasons,
                           criterion, final, per_edge, time.perf_counter() - t0, scorer.n_fits,
                           res.trials, est.problem_.n_blocks(scorer.block))


#: keywords of :func:`select_air_paths` that are its search's and its final model's, not
#: the scorer's (from the signatures, so that a new keyword of either is placed by itself)
_SEARCH_KEYS = (frozenset(inspect.signature(select_air_paths).parameters)
                - frozenset(inspect.signature(LikelihoodScorer).parameters))


def air_path_scorer(spec, data, **select_kw) -> LikelihoodScorer:
    """The scorer that :func:`select_air_paths` ``(spec, data, **select_kw)`` scores its
    structures with: its keywords without those of the search and its final model.

    For a fit outside the search that must be scored as the search scores (a check of
    its result, whose fits enter the search again through ``known``)."""
    return LikelihoodScorer(spec, data, **{k: v for k, v in select_kw.items()
                                           if k not in _SEARCH_KEYS})


def judge_air_paths(spec, data, kept, tests, *, criterion: str = "bic", margin: float = 10.0,
                   min_t: float = 0.0, max_iter: int = 200, min_t_days: float | None = None,
                   **estimator_kwargs) -> dict:
    """Test air paths one at a time against a fixed structure.

    ``kept`` is fitted once; each of ``tests`` is added to it alone and fitted (warm
    started), and its verdict is what the forward search would have said had it reached
    it: in when the criterion improves by more than ``margin`` and the gain holds day by
    day (``min_t``, :meth:`LikelihoodScorer.consistent`).

    Parameters
    ----------
    spec : BuildingSpec
    data : EstimationData, Measurements or DataFrame
    kept : sequence of (a, b[, d])
        The structure every test is added to.
    tests : sequence of (a, b[, d])
    criterion : {"bic", "aic", "holdout"}
    margin : float
        [-]
    min_t : float
        [-]; 0: reported, not required.
    max_iter : int
        Per fit.
    min_t_days : float or None
        As :func:`select_air_paths`.
    **estimator_kwargs
        Passed to every :class:`LikelihoodEstimator`.

    Returns
    -------
    dict
        Edge name → ``(ok, delta, t, note, rbar_v)``: the verdict, the criterion change of
        adding it [-], the daily-gain t [-], a few words, its fitted R̄_v [K/(W m)].
    """
    scorer = LikelihoodScorer(spec, data, criterion, max_iter=max_iter, min_t=min_t,
                              min_t_days=min_t_days, **estimator_kwargs)
    cur = as_candidates(spec, list(kept)) if kept else []
    base, val = scorer.fit(cur)
    out = {}
    for e in tests:
        c = _cand(spec, e)
        big, v = scorer.fit(cur + [c], warm=base)
        d = v - val
        ok, t, why = scorer.consistent(base, big)
        rb = float(big.params_.get(ConvectionParameters.key(c.name), np.nan))
        verdict = bool(d < -margin and ok)
        note = (f"{criterion} {d:+.1f} when added to the {len(cur)} kept here"
                + (f", {why}" if why else ""))
        out[c.name] = (verdict, float(d), float(t), note, rb)
    return out
