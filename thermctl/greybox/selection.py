"""Model-based selection of convection edges (forward selection, backward elimination).

Each candidate air path is judged by what it does to the fit of the whole stochastic
model, not by a correlation score: adding edge ``e`` to the current structure adds its
own R̄_v[e] (τ0 shared), and the edge is kept if the information criterion improves —
BIC (default) or AIC on the Kalman likelihood, or held-back likelihood. Candidates are
every zone pair with a known air-path length, **including pairs already joined by a
wall**: an open door beside a wall is an air path too, and the likelihood can tell a
wall's conduction from mixing only by fitting both.

Greedy search (Bacher & Madsen 2011 style, with the model of :mod:`.problem`):

1. Fit the current structure (start: no convection edge, or ``start``).
2. Screen every remaining candidate with everything else held at the current optimum
   (likelihood at a few R̄_v values, or a 1-D fit of its R̄_v): a cheap lower bound of
   the gain.
3. Refit the best candidate with all parameters free; accept it if the criterion
   improves by more than ``margin``, else stop.
4. Backward: try removing each selected edge (full refit); drop the one whose removal
   costs least if that is less than ``margin``; repeat.

The path (every screening value and every decision) and a reason per edge are kept.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import BoundWarning, ConvergenceWarning, EstimationError, SpecError
from ..network import ThermalNetwork
from .estimator import GreyboxEstimator, as_greybox_data
from .._blas import single_thread_blas

__all__ = ["Candidate", "SelectionStep", "SelectionResult", "candidate_pairs", "sin_candidates",
           "select_edges", "CRITERIA"]

log = logging.getLogger(__name__)

CRITERIA = ("bic", "aic", "holdout")


@dataclass(frozen=True)
class Candidate:
    """A possible air path.

    Attributes
    ----------
    a, b : str
        Zones (sorted).
    d : float
        Air path length [m].
    parallel : bool
        A wall joins the same two zones (the edge would run parallel to it).
    unmeasured : bool
        One end is an unmeasured zone.
    """

    a: str
    b: str
    d: float
    parallel: bool = False
    unmeasured: bool = False

    @property
    def name(self) -> str:
        return f"air:{self.a}-{self.b}"

    @property
    def pair(self) -> tuple:
        return (self.a, self.b)


@dataclass
class SelectionStep:
    """One decision of the search.

    Attributes
    ----------
    action : {"start", "add", "remove", "stop", "keep"}
        ``keep``: the backward pass ended; ``screened`` holds the criterion change of
        removing each kept edge.
    edge : str or None
    value : float
        Criterion of the structure after this step (lower is better).
    delta : float
        Change of the criterion this step caused (negative: better).
    edges : list of str
        Structure after the step.
    screened : dict
        Edge name → screening change of the criterion (forward steps).
    note : str
    """

    action: str
    edge: str | None
    value: float
    delta: float
    edges: list
    screened: dict = field(default_factory=dict)
    note: str = ""


@dataclass
class SelectionResult:
    """Outcome of :func:`select_edges`.

    Attributes
    ----------
    edges : list of (str, str, float)
        Selected convection edges ``(a, b, d)``.
    candidates : list of Candidate
    path : list of SelectionStep
    reasons : dict
        Edge name → why it is in or out.
    criterion : str
    estimator : GreyboxEstimator
        Final fit of the selected structure (shared R̄_v unless ``final_per_edge``).
    per_edge : dict
        Edge name → R̄_v of the per-edge fit of the selected structure [K/(W m)].
    time : float
        [s]
    n_fits : int
    """

    edges: list
    candidates: list
    path: list
    reasons: dict
    criterion: str
    estimator: GreyboxEstimator
    per_edge: dict
    time: float
    n_fits: int

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


def candidate_pairs(spec, zones=None, include_unmeasured: bool = True,
                    parallel: bool = True) -> list[Candidate]:
    """Every zone pair that could exchange air, flagged if a wall joins it.

    Pairs with a length in the spec's ``distances``, and (``parallel``) every pair joined
    by a wall, with the length of :meth:`BuildingSpec.air_path_length` (given, or estimated
    from the volumes: an open door in the common wall).

    Parameters
    ----------
    spec : BuildingSpec
    zones : list of str, optional
        Restrict to pairs within these zones.
    include_unmeasured : bool
        Also pairs with an unmeasured zone.
    parallel : bool
        Also pairs joined by a wall.
    """
    zset = set(spec.zone_names if zones is None else zones)
    meas = set(spec.measured_zones)
    walls = spec.wall_pairs()
    pairs = {tuple(sorted((dd.a, dd.b))) for dd in spec.distances}
    if parallel:
        pairs |= {tuple(sorted(p)) for p in walls}
    out = []
    for a, b in sorted(pairs):
        if a not in zset or b not in zset:
            continue
        unm = a not in meas or b not in meas
        if unm and not include_unmeasured:
            continue
        d, _ = spec.air_path_length(a, b)
        out.append(Candidate(a, b, float(d), frozenset((a, b)) in walls, unm))
    return out


class _Searcher:
    def __init__(self, spec, data, criterion, holdout, est_kwargs, max_iter):
        self.spec = spec
        self.criterion = criterion
        self.kw = dict(est_kwargs)
        self.kw.pop("per_edge", None)
        self.max_iter = max_iter
        self.n_fits = 0
        base = ThermalNetwork(spec, ())
        data = as_greybox_data(data, base)
        if criterion == "holdout":
            n = len(data)
            cut = int(round(n * (1.0 - holdout)))
            self.train, self.test = data.window(0, cut), data.window(cut, None)
        else:
            self.train, self.test = data, None

    on_fit = None        # called with the number of fits so far (progress of long searches)

    def fit(self, edges, init=None, fix=None, max_iter=None):
        net = ThermalNetwork(self.spec, [c.pair + (c.d,) for c in edges])
        est = GreyboxEstimator(net, per_edge=True, fix=fix, max_iter=max_iter or self.max_iter,
                               **self.kw)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BoundWarning)
            warnings.simplefilter("ignore", ConvergenceWarning)
            est.fit(self.train, init=init)
        self.n_fits += 1
        if self.on_fit is not None:
            self.on_fit(self.n_fits)
        return est, self.value(est)

    def grid_screen(self, cur, rest, base, est):
        """Criterion change of each candidate at a few R̄_v values, all else held.

        One problem holds the current edges and every candidate; a candidate is "off" at
        R̄_v = R_OFF (a conductance of ~10⁻³ W/K) and tried at the current R̄_v × {1/4, 1, 4}.
        Costs 3 likelihood evaluations per candidate instead of a fit each.
        """
        R_OFF = 1e2
        net = ThermalNetwork(self.spec, [c.pair + (c.d,) for c in cur + rest])
        lo = self.kw.get("rbar_bounds", (1e-6, 1e-2))[0]
        est2 = GreyboxEstimator(net, per_edge=True, **{**self.kw, "rbar_bounds": (lo, R_OFF)})
        init = dict(base)
        for c in rest:
            init[f"rbar_v[{c.name}]"] = R_OFF
        pb = est2.make_problem(self.train, init=init)
        eta = pb.layout.eta0()
        with single_thread_blas():
            f0 = pb.nll(eta)
            rb0 = _start_rbar(base)
            dk = 1 + (0 if any(k.startswith("tau0") for k in base) else 1)
            pen = dk * (2.0 if self.criterion == "aic" else math.log(max(pb.n_obs, 2)))
            out = {}
            for c in rest:
                i = pb.layout.index(f"rbar_v[{c.name}]")
                best = np.inf
                for f in (0.25, 1.0, 4.0):
                    e = eta.copy()
                    e[i] = math.log(rb0 * f)
                    best = min(best, pb.nll(e))
                out[c.name] = 2.0 * (best - f0) + pen
        self.n_fits += 1
        return out

    def penalty(self, est):
        """Criterion cost of one more parameter."""
        return 2.0 if self.criterion == "aic" else math.log(max(est.n_obs_, 2))

    def value(self, est):
        if self.criterion == "bic":
            return est.bic_
        if self.criterion == "aic":
            return est.aic_
        # held-back likelihood, scaled like -2 log L so the deltas read like AIC/BIC
        return 2.0 * est.score(self.test) * est.problem_for(self.test).n_obs


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
    from ..structure import StructureIdentifier
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


def select_edges(spec, data, *, candidates="all", criterion: str = "bic", direction: str = "both",
                 start=(), max_edges: int | None = None, holdout: float = 0.3,
                 final_per_edge: bool = False, final_criterion: str = "likelihood",
                 max_iter: int = 200, margin: float = 10.0,
                 screen: str = "grid", progress=None, on_fit=None,
                 **estimator_kwargs) -> SelectionResult:
    """Choose the convection edges of a building by model fit.

    Parameters
    ----------
    spec : BuildingSpec
        Walls and air-path distances (no convection edges needed).
    data : GreyboxData, Measurements or DataFrame
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
        :func:`~thermctl.greybox.uncertainty.wald_intervals`), which inflates likelihood
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
    **estimator_kwargs
        Passed to every :class:`GreyboxEstimator` (model options, solver...).

    Returns
    -------
    SelectionResult
    """
    if criterion not in CRITERIA:
        raise EstimationError(f"criterion must be one of {CRITERIA}, found {criterion!r}")
    if screen not in ("grid", "fit"):
        raise EstimationError(f"screen must be 'grid' or 'fit', found {screen!r}")
    if direction not in ("forward", "backward", "both"):
        raise EstimationError(f"direction must be 'forward', 'backward' or 'both', found {direction!r}")
    t0 = time.perf_counter()
    if isinstance(candidates, str) and candidates == "sin":
        candidates = sin_candidates(spec, data)
    elif isinstance(candidates, str) and candidates == "all":
        candidates = None
    cands = _candidates(spec, candidates)
    by_name = {c.name: c for c in cands}
    S = _Searcher(spec, data, criterion, holdout, estimator_kwargs, max_iter)
    S.on_fit = on_fit
    cur = [by_name[_name(e)] if _name(e) in by_name else _cand(spec, e) for e in start]
    if direction == "backward":
        cur = list(cands)
    est, val = S.fit(cur)
    path = [SelectionStep("start", None, val, 0.0, [c.name for c in cur],
                          note=f"{len(cur)} edge(s)")]
    reasons, best_screen = {}, {}
    say = progress or (lambda msg: None)
    if direction in ("forward", "both"):
        while max_edges is None or len(cur) < max_edges:
            rest = [c for c in cands if c not in cur]
            if not rest:
                break
            base = dict(est.params_)
            if screen == "grid":
                screened = S.grid_screen(cur, rest, base, est)
            else:
                screened = {}
                dk = 1 + (0 if any(k.startswith("tau0") for k in base) else 1)
                for c in rest:
                    init = dict(base)
                    init[f"rbar_v[{c.name}]"] = _start_rbar(base)
                    e2, _ = S.fit(cur + [c], init=init, fix=dict(base), max_iter=60)
                    # the held parameters are not free in e2: count the full model's
                    screened[c.name] = 2.0 * (e2.nll_ - est.nll_) + dk * S.penalty(e2)
            for k, v in screened.items():
                best_screen[k] = v          # the last round's value: with the final edges
            pick = min(screened, key=screened.get)
            c = by_name[pick]
            init = dict(base)
            init[f"rbar_v[{pick}]"] = _start_rbar(base)
            e_full, v_full = S.fit(cur + [c], init=init)
            d = v_full - val
            if d < -margin:
                cur = cur + [c]
                est, val = e_full, v_full
                path.append(SelectionStep("add", pick, val, d, [x.name for x in cur], screened,
                                          note=_edge_note(c, e_full)))
                reasons[pick] = f"added: {criterion} {d:+.1f} when added"
                say(f"added {pick} ({criterion} {d:+.1f})")
            else:
                path.append(SelectionStep("stop", pick, val, d, [x.name for x in cur], screened,
                                          note=f"best candidate improves the criterion by less "
                                               f"than the margin {margin:g}"))
                say(f"stop: best candidate {pick} gives {criterion} {d:+.1f}")
                break
    if direction in ("backward", "both"):
        while cur:
            trials = {}
            for c in cur:
                rest = [x for x in cur if x != c]
                init = {k: v for k, v in est.params_.items() if k != f"rbar_v[{c.name}]"}
                e2, v2 = S.fit(rest, init=init)
                trials[c.name] = (v2 - val, e2, v2)
            pick = min(trials, key=lambda k: trials[k][0])
            d, e2, v2 = trials[pick]
            if d < margin:
                cur = [x for x in cur if x.name != pick]
                est, val = e2, v2
                path.append(SelectionStep("remove", pick, val, d, [x.name for x in cur],
                                          {k: t[0] for k, t in trials.items()},
                                          note=f"it improves the criterion by less than the "
                                               f"margin {margin:g}"))
                reasons[pick] = (f"removed: {criterion} only {d:+.1f} when removed "
                                 f"(margin {margin:g})")
                say(f"removed {pick} ({criterion} {d:+.1f})")
            else:
                # the kept structure's evidence: what removing each edge would cost
                path.append(SelectionStep("keep", None, val, d, [x.name for x in cur],
                                          {k: t[0] for k, t in trials.items()},
                                          note=f"removing any edge costs more than the "
                                               f"margin {margin:g}"))
                for k, t in trials.items():
                    if k not in reasons or reasons[k].startswith("added"):
                        reasons[k] = (reasons.get(k, "in") + f"; removing it costs {criterion} "
                                      f"{t[0]:+.1f}")
                break
    per_edge = {}
    if cur:
        rb, _ = est.problem_.rbar_c(est.eta_)
        per_edge = {e.name: float(r) for e, r in zip(est.problem_.edges, rb)}
    for c in cands:
        if c.name not in reasons:
            if c in cur:
                reasons[c.name] = "in (start)"
            elif c.name in best_screen:
                reasons[c.name] = (f"out: last screening {criterion} change "
                                   f"{best_screen[c.name]:+.1f}")
            else:
                reasons[c.name] = "out"
        if c.parallel:
            reasons[c.name] += " [parallel to a wall]"
        if c.unmeasured:
            reasons[c.name] += " [unmeasured end]"
    net = ThermalNetwork(spec, [x.pair + (x.d,) for x in cur])
    final_kw = dict(estimator_kwargs)
    final_kw.pop("per_edge", None)
    if final_per_edge and final_criterion == "likelihood" and criterion != "holdout":
        # the search's last fit is this very model (per edge, likelihood, all the data):
        # refitting it would cost one more fit for the same optimum
        final = est
    else:
        final = GreyboxEstimator(net, final_criterion, per_edge=final_per_edge,
                                 max_iter=max_iter, **final_kw)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BoundWarning)
            final.fit(data, init={k: v for k, v in est.params_.items()
                                  if not k.startswith("rbar_v[")}
                      | ({"rbar_v": float(np.exp(np.mean(np.log(list(per_edge.values())))))}
                         if per_edge else {}))
        S.n_fits += 1
    return SelectionResult([x.pair + (x.d,) for x in cur], cands, path, reasons, criterion, final,
                           per_edge, time.perf_counter() - t0, S.n_fits)


def _name(e):
    if isinstance(e, Candidate):
        return e.name
    a, b = sorted((str(e[0]), str(e[1])))
    return f"air:{a}-{b}"


def _cand(spec, e):
    if isinstance(e, Candidate):
        return e
    a, b = sorted((str(e[0]), str(e[1])))
    d = float(e[2]) if len(e) > 2 else spec.air_path_length(a, b)[0]
    if d is None:
        raise SpecError(f"candidate {a}-{b}: the spec gives no distance for this pair and no "
                        "wall joins it (add it under 'distances')")
    walls = spec.wall_pairs()
    meas = set(spec.measured_zones)
    return Candidate(a, b, d, frozenset((a, b)) in walls, a not in meas or b not in meas)


def _candidates(spec, candidates):
    if candidates is None:
        out = candidate_pairs(spec)
    else:
        out = [_cand(spec, c) for c in candidates]
    if not out:
        raise SpecError(f"{spec.source}: no candidate air path (the spec lists no distances)")
    return out


def _start_rbar(params):
    vals = [v for k, v in params.items() if k.startswith("rbar_v")]
    return float(np.exp(np.mean(np.log(vals)))) if vals else 3.36e-4


def _edge_note(c, est):
    rb = est.params_.get(f"rbar_v[{c.name}]", float("nan"))
    return f"rbar_v {rb:.3g} K/(W m), d {c.d:g} m" + (" (parallel to a wall)" if c.parallel else "")
