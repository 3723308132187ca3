"""Identification at building scale: one small problem per measured zone.

A zone's heat balance involves only its walls, its air paths and its neighbours'
temperatures, and those temperatures are measured. So the building splits into
independent **local problems** (local module identification in dynamic networks,
Van den Hof et al., Automatica 2013; Ramaswamy & Van den Hof, IEEE TAC 2021):

* the local model of measured zone ``i`` holds zone ``i``, the unmeasured zones it reaches
  through walls or candidate air paths up to ``latent_depth`` hops (an unmeasured hallway
  joins every local problem that touches it: a latent node on a path between inputs and the
  output must be inside the problem, not ignored; one further away enters at a steady-state
  proxy), and every wall with an end among them; each measured node outside (a neighbouring
  zone, the outdoor air) becomes a boundary node whose measured temperature is an input;
* the candidate air paths of problem ``i`` are its pairs with a known or estimable length
  (``BuildingSpec.air_path_length``) to measured zones (boundary nodes of the local model);
* each problem selects its air paths by BIC on its own Kalman likelihood
  (:func:`thermctl.selection.select_air_paths`): forward then backward from every candidate,
  or backward from the paper's SIN on the zone's neighbourhood (:func:`propose_sin`), and
  fits one R̄_v per air path.

An air path between two measured zones is seen by both problems. :func:`combine` joins the
two verdicts: ``both`` (default) and ``either`` are the AND and OR rules of neighbourhood
selection (Meinshausen & Bühlmann, Ann. Stat. 2006); ``sum`` adds the two BIC changes — the
log-likelihood of the whole building is, up to the neighbours' own noise, the sum of the
zones' conditional log-likelihoods, so summed evidence is the composite-likelihood
counterpart of the whole-building BIC (Varin, Reid & Firth, Statistica Sinica 2011). The
combined R̄_v of an edge is the geometric mean of the ends that kept it.

With ``wall_factors`` (one UA factor per wall class) every local wall keeps the class it
has in the whole building (:attr:`LocalProblem.wall_classes`: a partition to a measured
neighbour is a ``partition``, not a wall to a boundary node), the factor of a class is the
median over the local fits (:func:`combine_ua_factors`), and
:meth:`LocalIdentification.model` puts the building's walls at R/f.

Local problems are pure functions of (local spec, data columns, options) and run as
tasks: serially, on local processes, or on a ``dask.distributed`` cluster
(:func:`run_local`). No dense matrix of the whole building is formed on this path: the
largest dense matrices are those of one local problem (its state count is
:attr:`LocalProblem.n_states`).
"""

from __future__ import annotations

import inspect
import logging
import math
import time
import uuid
import warnings
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import gmean

from ._parallel import run_tasks
from .errors import BoundWarning, ConvergenceWarning, DataError, EstimationError
from .network import ThermalNetwork, air_path_name
from .spec import WALL_CLASSES, BuildingSpec, Distance, Zone, wall_class

__all__ = ["LocalProblem", "LocalResult", "LocalIdentification", "local_problems",
           "propose_sin", "local_cost_problem", "fit_local", "run_local", "combine", "assemble",
           "identify_local", "joint_local", "COMBINE_RULES", "ONE_SIDED",
           "combine_ua_factors", "combine_zone_params", "zone_params",
           "conduction_zone_params"]

log = logging.getLogger(__name__)

COMBINE_RULES = ("sum", "both", "either")

RBAR_WINDOW = 2.0
"""A combined air path whose R̄_v is more than this factor from the building's (the median
over its kept paths) is dropped (:func:`rbar_consensus`) [-]."""

ONE_SIDED = 80.0
"""An air path kept at one end only (and not beside a wall) stays when its two ends' BIC
changes sum below minus this (:func:`combine`) [-]; chosen on the 196-zone corridor
testbed, seeds 0 and 1, from 60, 80 and 100 (docs/scale.md, "Paths one end keeps")."""

RBAR_WINDOW_MIN_PATHS = 8
"""Kept air paths (with a local R̄_v) a building needs before :func:`rbar_consensus` judges
them: the median of fewer is no building value."""


# ---------------------------------------------------------------------------- split
@dataclass(frozen=True)
class LocalProblem:
    """The local model of one measured zone.

    Attributes
    ----------
    zone : str
        The measured zone whose balance this problem decides.
    spec : BuildingSpec
        Zones: ``zone`` and its latent (unmeasured) zones; boundary: the building's boundary
        nodes and the measured zones the local zones touch (their ``T:`` columns are inputs).
    candidates : tuple of (str, str, float)
        Candidate air paths ``(a, b, d)`` with one end ``zone``, ``d`` [m].
    columns : tuple of str
        Data columns the problem reads.
    aggregates : tuple of (str, tuple of (str, float))
        Boundary nodes whose temperature is a weighted mean of measured nodes.
    proposed : tuple of (str, str, float) or None
        Candidates a structure rule proposed (:func:`propose_sin`): the search starts from
        them and prunes backward. ``None``: forward from none, then backward.
    wall_classes : tuple of (str, str)
        ``(edge name, class)`` of every wall of the local network, in network order: the
        class the wall has in the *whole* building (:func:`thermctl.spec.wall_class`), not
        in the local spec, where a measured neighbour is a boundary node and a partition
        to it would be ``boundary`` (:func:`_whole_wall_classes`). Empty: the local
        spec's own classes.
    """

    zone: str
    spec: BuildingSpec
    candidates: tuple
    columns: tuple
    aggregates: tuple = ()
    proposed: tuple | None = None
    wall_classes: tuple = ()

    def network(self, convection=()) -> ThermalNetwork:
        """The local network with these air paths; it carries :attr:`wall_classes` as the
        ``wall_classes`` override that :class:`thermctl.estimate.likelihood.LikelihoodProblem`
        honours, so a UA factor per class (``wall_factors``) scales the same walls as in
        the whole building."""
        net = ThermalNetwork(self.spec, convection)
        if self.wall_classes:
            net.wall_classes = dict(self.wall_classes)
        return net

    def data(self, frame):
        """The problem's data: its columns of ``frame``, plus the aggregate boundary
        temperatures (weighted means of the zones behind an aggregated wall) [°C]."""
        sub = frame[[c for c in self.columns if c in frame.columns]].copy()
        for node, members in self.aggregates:
            if f"T:{node}" in frame.columns:        # already prepared (a task's slice)
                sub[f"T:{node}"] = frame[f"T:{node}"]
                continue
            cols = [f"T:{m}" for m, _ in members]
            missing = [c for c in cols if c not in frame.columns]
            if missing:
                raise DataError(f"local problem of {self.zone}: column(s) {missing} missing "
                                f"(needed for the aggregated walls of {node})")
            T = frame[cols].to_numpy(float)
            w = np.array([s for _, s in members], dtype=float)
            ok = np.isfinite(T)
            # renormalise over the neighbours measured at that sample: a gap in one of
            # 24 offices should not blank the hallway's whole boundary
            num = np.where(ok, T, 0.0) @ w
            den = ok.astype(float) @ w
            with np.errstate(invalid="ignore", divide="ignore"):
                sub[f"T:{node}"] = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)
        return sub

    @property
    def latent(self) -> list[str]:
        """Unmeasured zones inside the problem."""
        return [z.name for z in self.spec.zones if not z.measured]

    @property
    def n_states(self) -> int:
        """Network states of the local model with every candidate air path."""
        return len(self.spec.zones) + 2 * (len(self.spec.walls) + len(self.candidates))


def local_problems(spec: BuildingSpec, columns=None, zones=None, parallel: bool = True,
                   aggregate: bool = True, unmeasured: bool = False,
                   latent_depth: int | None = 1) -> list[LocalProblem]:
    """Split a building into one local problem per measured zone.

    Parameters
    ----------
    spec : BuildingSpec
    columns : iterable of str, optional
        Data columns available (``T:<node>``, ``ms:<zone>``...); a problem reads only
        those of its nodes. Default: every column its nodes could have.
    zones : list of str or of tuple of str, optional
        Measured zones to make problems for (default: every measured zone). A tuple of
        measured zones makes one *joint* problem of them (:func:`joint_local`): each is an
        output of the same model, named ``a+b``; its candidates are the pairs with an end
        among them.
    parallel : bool
        Pairs joined by a wall are candidates too (an open door beside a wall).
    unmeasured : bool
        Pairs with an unmeasured zone are candidates too. Off by default: such an air path
        is seen by one local problem only, so no second end can confirm it, and the latent
        zone's free temperature absorbs misfit (measured on the 7-zone testbed: 3 spurious
        hallway paths of 8 kept); the whole-building default (SIN candidates) never proposes
        them either.
    aggregate : bool
        Merge a latent zone's walls to measured zones outside the problem into one wall per
        construction, exactly (see :func:`_aggregate_far_walls`); keeps a hallway's local
        problems small whatever the length of the hallway.
    latent_depth : int or None
        How many unmeasured zones deep a problem reaches (``None``: every unmeasured zone
        connected through unmeasured zones). Beyond it, an unmeasured zone ``u`` becomes a
        boundary node at its *steady-state proxy*: the conductance-weighted mean of the
        measured zones and boundary nodes its walls join (:func:`_proxy_members`). On a
        tall corridor building the hallways chain through the floor slabs, so without a
        bound every problem holds every hallway (73–75 states at 196 zones instead of
        ~45); with depth 1 the floor above's hallway enters through the offices around it.
        An approximation (the proxy misses the hallway's own dynamics, time constants of
        hours behind a slab), where the aggregated walls are exact.

    Returns
    -------
    list of LocalProblem
        In spec order.
    """
    from .structure.search import candidate_pairs

    meas = set(spec.measured_zones)
    zone_set = set(spec.zone_names)
    # the whole building's candidates, as the whole-building selection sees them
    allc = candidate_pairs(spec, include_unmeasured=unmeasured, parallel=parallel)
    touching: dict[str, set] = {z: set() for z in zone_set}
    for a, b in [(w.a, w.b) for w in spec.walls] + [c.pair for c in allc]:
        touching.setdefault(a, set()).add(b)
        touching.setdefault(b, set()).add(a)
    out = []
    for z in (spec.measured_zones if zones is None else zones):
        inner = (z,) if isinstance(z, str) else tuple(z)
        for m in inner:
            if m not in meas:
                raise DataError(f"local problem: {m!r} is not a measured zone of {spec.source}")
        z, own = "+".join(inner), set(inner)
        # latent closure: unmeasured zones reachable through unmeasured zones, breadth
        # first up to latent_depth
        local, frontier, depth = set(inner), list(inner), 0
        while frontier and (latent_depth is None or depth < latent_depth):
            nxt = []
            for n in frontier:
                for m in sorted(touching.get(n, ())):
                    if m in zone_set and m not in meas and m not in local:
                        local.add(m)
                        nxt.append(m)
            frontier, depth = nxt, depth + 1
        zones_l = [zz for zz in spec.zones if zz.name in local]
        walls, proxies = _proxy_walls(spec, [w for w in spec.walls
                                             if w.a in local or w.b in local], local, meas)
        cands = [(c.a, c.b, c.d) for c in allc if own & set(c.pair)]
        walls, aggregates = _aggregate_far_walls(walls, local, own, meas) \
            if aggregate else (walls, [])
        nodes = {w.a for w in walls} | {w.b for w in walls}
        nodes |= {n for a, b, _ in cands for n in (a, b)}
        aggregates = aggregates + proxies
        agg_nodes = [n for n, _ in aggregates]
        bnd = [b for b in spec.boundary if b in nodes]
        bnd += [m for m in spec.zone_names if m in nodes and m not in local]
        bnd += agg_nodes
        # zone capacitances are fixed by the whole building's multiplier
        zones_l = [Zone(zz.name, zz.volume, zz.measured, spec.zone_capacitance(zz.name),
                        zz.storey) for zz in zones_l]
        dists = tuple(Distance(a, b, d) for a, b, d in cands)
        # directed flows into the problem's zones: inputs (their source temperature and
        # rate are data columns, wherever the source is)
        flows = tuple(f for f in spec.flows if f.dst in local)
        sub = BuildingSpec(f"{spec.name}:{z}", tuple(zones_l), tuple(bnd), tuple(walls), dists,
                           1.0, spec.w_s, f"{spec.source} (local problem of {z})", flows)
        cols = [f"T:{n}" for n in list(inner) + bnd if n not in agg_nodes]
        for zz in zones_l:          # spec order, not set order: the same columns every run
            cols += [f"ms:{zz.name}", f"Ts:{zz.name}", f"Q:{zz.name}"]
        for f in flows:
            cols += [c for c in (f"T:{f.src}", f.rate_column) if c not in cols]
        if columns is not None:
            have = set(columns)
            cols = [c for c in cols if c in have] + sorted(c for c in have
                                                            if c.startswith("solar:"))
        out.append(LocalProblem(z, sub, tuple(cands), tuple(cols), tuple(aggregates),
                                wall_classes=_whole_wall_classes(spec, sub, aggregates)))
    return out


def _whole_wall_classes(spec, sub, aggregates) -> tuple:
    """``((edge name, class), ...)``: each wall of the local spec ``sub`` with the class
    (:func:`thermctl.spec.wall_class`) it has in the whole building ``spec``.

    In ``sub`` a measured neighbour ``j`` is a boundary node, so ``wall_class`` calls the
    partition ``i|j`` ``boundary``; here each node of ``sub`` stands for the node of the
    whole building it replaces: a measured neighbour for itself, a proxy ``u~proxy`` for the
    unmeasured zone ``u`` (a partition), an aggregate ``near~k`` for the measured zones it
    merges (partitions: :func:`_aggregate_far_walls` merges only walls from a latent zone to
    measured zones). Counted on Pugh Hall's r240 problem: 7 walls, the local spec's classes
    4 boundary / 2 exterior / 1 partition, the whole building's 2 / 2 / 3 (r240|r241 and the
    aggregate of the hallway's 5 walls to offices move to ``partition``); over all local
    problems 14 of 24 local ``boundary`` walls are partitions (Pugh Hall), 20 of 36 (9-zone
    corridor), 68 of 116 (25-zone corridor); no other class changes.
    """
    zones = set(spec.zone_names)
    rep = {}
    for node, members in aggregates:
        # a proxy's members are the zones *around* u; the node itself stands for u
        rep[node] = node[:-len("~proxy")] if node.endswith("~proxy") else members[0][0]
    net = ThermalNetwork(sub)
    # the network's conduction edges are the spec's walls, in order
    return tuple((e.name, wall_class(rep.get(w.a, w.a), rep.get(w.b, w.b), zones))
                 for w, e in zip(sub.walls, net.conduction_edges))


def _proxy_members(spec, u, meas):
    """``((node, weight), ...)``: the measured zones and boundary nodes joined to the
    unmeasured zone ``u`` by walls, weighted by the walls' conductance ``1/ΣR`` [W/K] — the
    temperature ``u`` would settle at if those were its only neighbours."""
    w = {}
    for wall in spec.walls:
        if u not in (wall.a, wall.b):
            continue
        other = wall.b if wall.a == u else wall.a
        if other in meas or other in spec.boundary:
            w[other] = w.get(other, 0.0) + 1.0 / sum(wall.R)
    return tuple(sorted(w.items()))


def _proxy_walls(spec, walls, local, meas):
    """Walls to unmeasured zones outside the problem end at a proxy boundary node
    ``<u>~proxy`` instead (see ``latent_depth`` of :func:`local_problems`)."""
    from dataclasses import replace
    out, proxies = [], {}
    for w in walls:
        ends = [n for n in (w.a, w.b) if n not in local and n not in spec.boundary
                and n not in meas]
        if not ends:
            out.append(w)
            continue
        u = ends[0]
        if u not in proxies:
            members = _proxy_members(spec, u, meas)
            if not members:
                log.warning("unmeasured zone %s beyond the latent depth touches no measured "
                            "node: its walls into the problem are left out", u)
            proxies[u] = members
        if not proxies[u]:
            continue
        node = f"{u}~proxy"
        out.append(replace(w, a=node) if w.a == u else replace(w, b=node))
    return out, [(f"{u}~proxy", m) for u, m in proxies.items() if m]


def _wall_shape(w):
    """Key of walls that are scaled copies of one construction: ``R_j = R/s``,
    ``C_j = C·s`` (same R split and same R·C) — e.g. one partition type of several widths."""
    Rt, Ct = sum(w.R), sum(w.C)
    return (tuple(round(r / Rt, 6) for r in w.R), tuple(round(c / Ct, 6) for c in w.C),
            float(f"{Rt * Ct:.6g}"))


def _aggregate_far_walls(walls, local, own, meas):
    """Merge the walls from a latent zone to measured zones outside the problem.

    A latent hallway touches every office on its floor, and each of those walls would add
    two states to every local problem (84–94 states instead of ~20 on the 25-zone
    corridor). Walls of one construction that differ only in size are scaled copies
    (``R_j = R/s_j``, ``C_j = C·s_j``); by superposition their summed heat flow into the
    hallway equals that of one wall with ``s = Σ s_j`` whose far end is at the weighted
    mean ``Σ s_j T_j / Σ s_j`` — exact, not an approximation. The mean becomes a boundary
    node ``<zone>~<k>`` of the local problem (computed by :meth:`LocalProblem.data`).
    The walls of the problem's own zones (the set ``own``) stay separate.
    """
    from .spec import Wall
    keep, groups = [], {}
    for w in walls:
        a_in, b_in = w.a in local, w.b in local
        far = w.b if a_in else w.a
        near = w.a if a_in else w.b
        if (a_in and b_in) or near in own or far in own or far not in meas:
            keep.append(w)
            continue
        groups.setdefault((near, _wall_shape(w)), []).append((w, far))
    out_walls, aggregates = list(keep), []
    for k, ((near, _), members) in enumerate(sorted(groups.items(), key=lambda kv: str(kv[0]))):
        if len(members) == 1:
            out_walls.append(members[0][0])
            continue
        ref = members[0][0]
        s = [sum(ref.R) / sum(w.R) for w, _ in members]      # s_j relative to the first
        S = float(sum(s))
        node = f"{near}~{len(aggregates) + 1}"
        out_walls.append(Wall(near, node, tuple(r / S for r in ref.R),
                              tuple(c * S for c in ref.C),
                              None if ref.area is None else float(sum(
                                  (w.area or 0.0) for w, _ in members)),
                              f"{near}|{len(members)} walls to measured zones"))
        aggregates.append((node, tuple((far, sj) for (_, far), sj in zip(members, s))))
    return out_walls, aggregates


# ---------------------------------------------------------------------------- fit one
@dataclass
class LocalResult:
    """What one local problem found (plain numbers: cheap to send between processes).

    Attributes
    ----------
    zone : str
    edges : list of str
        Air paths kept, ``air:a-b``.
    evidence : dict
        Edge name → criterion change of having the edge (negative: the data want it) [-]:
        minus the cost of removing a kept edge, or the last screening value of one left out.
    rbar_v : dict
        Edge name → R̄_v of the local per-edge fit [K/(W m)].
    tau0 : float
        τ0 = R̄_v·C_v of the local fit [s] (NaN without air paths).
    n_states : int
    n_obs : int
    n_fits : int
    time : float
        Wall time [s].
    cpu : float
        CPU time of the process that ran it [s].
    reasons : dict
        Edge name → why in or out.
    error : str or None
        Why the problem failed (its edges are then undecided).
    ua_factor : dict
        Wall class → fitted UA factor of the local model [-], classes as in the whole
        building (:attr:`LocalProblem.wall_classes`); empty without ``wall_factors`` and
        for a problem with no candidate (no fit).
    confirmed : dict
        Edge name → ``(ok, delta, t, note, rbar_v)`` of an air path another problem kept
        and this one's search did not, tested here directly (:func:`confirm_local`).
    params : dict
        The local fit's other parameters under the whole building's names
        (:func:`zone_params`): the zone's solar apertures, gain profile and noise, its
        latent zones' heat noise and apertures, building-level noise parameters. Units as
        :data:`thermctl.estimate.likelihood.params.GROUP_UNITS`.
    at_bounds : list of str
        Which of ``params`` ended on a search bound (``"sigma_v[r1] at its lower bound
        0.0001 [K]"``).
    days : int
        Days of data the search's daily-gain test compared (0 without a search) [-].
    """

    zone: str
    edges: list
    evidence: dict
    rbar_v: dict
    tau0: float
    n_states: int
    n_obs: int = 0
    n_fits: int = 0
    time: float = 0.0
    cpu: float = 0.0
    reasons: dict = field(default_factory=dict)
    error: str | None = None
    ua_factor: dict = field(default_factory=dict)
    confirmed: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)
    at_bounds: list = field(default_factory=list)
    days: int = 0


# groups a local fit shares over its zones (``noise="shared"``) that belong to one zone of
# the whole building: the sensor noise and the gain's random walk are the measured zone's
# (it is the problem's only output), the heat noise every local zone's
_OWN_SHARED = ("sigma_v", "sigma_phi")
# what LocalResult carries in its own fields (R̄_v, τ0, UA factors), not in ``params``
_OWN_FIELDS = ("rbar_v", "tau0", "ua_factor")


def zone_params(problem: "LocalProblem", params: dict) -> dict:
    """A local fit's parameters under the whole building's names.

    A parameter already named by zone (``aperture[r1,solar:south]``, ``sigma_q[r1]``)
    keeps its name; one the local fit shares over its zones gets the zone's name
    (``sigma_v`` → ``sigma_v[r1]``; ``sigma_q`` → one ``sigma_q[z]`` per local zone);
    building-level ones (``tau_g``, ``occ_ratio``…) keep theirs. R̄_v, τ0 and the UA
    factors are left out (:class:`LocalResult` has fields for them).

    Parameters
    ----------
    problem : LocalProblem
    params : dict
        ``LikelihoodEstimator.params_`` of the problem's fit.

    Returns
    -------
    dict
    """
    out = {}
    local = [problem.zone] + problem.latent
    for k, v in params.items():
        group = k.split("[")[0]
        if group in _OWN_FIELDS:
            continue
        if "[" in k:
            out[k] = float(v)
        elif group in _OWN_SHARED:
            out[f"{group}[{problem.zone}]"] = float(v)
        elif group == "sigma_q":
            out.update({f"sigma_q[{z}]": float(v) for z in local})
        else:
            out[k] = float(v)
    return out


def _renamed_bounds(problem, est) -> list:
    """``est``'s active bounds under :func:`zone_params`' names (parameters left out there
    are left out here)."""
    out = []
    for s in est.result_.active_bounds:
        name, sep, rest = str(s).partition(" at its ")
        for new in zone_params(problem, {name: 0.0}):
            out.append(new + sep + rest)
    return out


def fit_local(problem: LocalProblem, frame, *, criterion: str = "bic", margin: float = 10.0,
              solar: bool = True, fit_rows: str = "all", max_iter: int = 200,
              **options) -> LocalResult:
    """Select and fit the air paths of one local problem.

    Without proposals (``problem.proposed is None``): forward selection from no air path,
    then backward elimination (BIC on the local Kalman likelihood, ``margin``). With
    proposals (:func:`propose_sin`): backward elimination from them. Then one R̄_v per
    kept edge. With ``wall_factors=True`` the selected structure is fitted once more on
    the whole building's wall classes (:func:`_whole_class_fit`), and its UA factors, R̄_v
    and τ0 are the result's. Measured on Pugh Hall (partitions 2× UA, 6 days, seeds 1 and
    2): the median partition factor was 2.22 and 1.87 this way, 2.23 and 1.91 with the
    whole building's classes in every fit of the selection too (same combined air paths).

    Parameters
    ----------
    problem : LocalProblem
    frame : pandas.DataFrame
        Calibration data with at least ``problem.columns`` (SI units, regular index).
    criterion : {"bic", "aic", "holdout"}
    margin : float
        Criterion improvement an edge must bring [-].
    solar : bool
        Solar apertures on ``solar:`` columns.
    fit_rows : {"all", "auto", "supply_off"}
        Samples whose innovations count (:class:`thermctl.estimate.likelihood.LikelihoodOptions`). Default
        ``all``: a local problem has only its own zones' supply flows as inputs, and the
        supply-off hours alone (``auto``, the whole-building default) found 9 of 18 true air
        paths on the 7-, 9- and 25-zone testbeds; all samples found 18 of 18 (with the
        ``both`` rule, :func:`combine`). Measured in docs/identification.md.
    max_iter : int
        Per fit.
    **options
        Other :class:`thermctl.estimate.likelihood.LikelihoodOptions` fields (``basis``, ``harmonics``...).

    Returns
    -------
    LocalResult
    """
    from .selection import per_path_rbar, select_air_paths

    t0, c0 = time.perf_counter(), time.process_time()
    sub = problem.data(frame)
    n_states = problem.n_states
    cands, direction = list(problem.candidates), "both"
    if problem.proposed is not None:
        cands, direction = list(problem.proposed), "backward"
    if not cands:
        # nothing to select; the zone's apertures, gains and noise still come from here (the
        # whole-building model of a large building takes them from this fit). Its UA factors
        # are not reported: the problems that decide air paths set those, as before
        reasons = {air_path_name(a, b): "out: not proposed" for a, b, _ in problem.candidates}
        est = _local_estimator(problem.network(), max_iter, solar=solar, fit_rows=fit_rows,
                               **options)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", BoundWarning)
                warnings.simplefilter("ignore", ConvergenceWarning)
                est.fit(sub)
        except Exception as exc:    # noqa: BLE001 - its verdicts stand without parameters
            log.warning("local problem of %s: the fit for its parameters failed (%s); its "
                        "zone gets the other zones' median noise", problem.zone, exc)
            return LocalResult(problem.zone, [], {}, {}, float("nan"), n_states,
                               time=time.perf_counter() - t0, cpu=time.process_time() - c0,
                               reasons=reasons)
        return LocalResult(problem.zone, [], {}, {}, float("nan"), n_states, int(est.n_obs_), 1,
                           time.perf_counter() - t0, time.process_time() - c0, reasons,
                           params=zone_params(problem, est.params_),
                           at_bounds=_renamed_bounds(problem, est))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", BoundWarning)
        warnings.simplefilter("ignore", ConvergenceWarning)
        sel = select_air_paths(problem.spec, sub, candidates=cands,
                               criterion=criterion, direction=direction, margin=margin,
                               final_per_edge=True, max_iter=max_iter, solar=solar,
                               fit_rows=fit_rows, **options)
    evidence = {}
    for st in sel.path:
        if st.action in ("add", "stop", "reject"):
            evidence.update({k: float(v) for k, v in st.screened.items()})
        if st.action in ("add", "reject"):
            evidence[st.edge] = float(st.delta)
        if st.action == "remove":
            evidence[st.edge] = -float(st.delta)     # what removing it cost, negated
        if st.action == "keep":
            evidence.update({k: -float(v) for k, v in st.screened.items()})
    kept = [air_path_name(a, b) for a, b, _ in sel.edges]
    for k in kept:          # a kept edge always has a removal cost (keep step) or an add delta
        evidence.setdefault(k, -float(margin))
    est, rb, n_fits, ua = sel.estimator, dict(sel.per_edge), sel.n_fits, {}
    if _wall_factors(options):
        est, refit = _whole_class_fit(problem, sub, sel, max_iter, solar=solar,
                                      fit_rows=fit_rows, **options)
        n_fits += refit
        ua = est.problem_.ua_factors(est.eta_)
        if kept:
            rb = per_path_rbar(est)
    tau0 = float(est.tau0_) if kept else float("nan")
    return LocalResult(problem.zone, kept, evidence, rb, tau0, n_states, int(est.n_obs_),
                       n_fits, time.perf_counter() - t0, time.process_time() - c0,
                       dict(sel.reasons), ua_factor=ua, params=zone_params(problem, est.params_),
                       at_bounds=_renamed_bounds(problem, est), days=sel.days)


def _wall_factors(options) -> bool:
    return bool(options.get("wall_factors")
                or getattr(options.get("options"), "wall_factors", False))


def _local_estimator(net, max_iter, **options):
    """A per-edge :class:`~thermctl.estimate.likelihood.LikelihoodEstimator` of a local
    network with the estimator's keywords of ``options`` (the selection's own, such as
    ``min_t``, left out)."""
    from .estimate.likelihood import LikelihoodEstimator
    from .selection import select_air_paths

    skip = set(inspect.signature(select_air_paths).parameters)
    kw = {k: v for k, v in options.items() if k not in skip}
    return LikelihoodEstimator(net, per_edge=True, tol=1e-9, max_iter=max_iter, **kw)


def _whole_class_fit(problem, sub, sel, max_iter, **options):
    """``(estimator, fits run)``: the selected structure of a local problem fitted with the
    whole building's wall classes (:attr:`LocalProblem.wall_classes`).

    :func:`thermctl.selection.select_air_paths` builds its networks from the local spec, on
    which a partition to a measured neighbour is class ``boundary``; its UA factors then
    mean something else in every local problem. This one fit, on :meth:`LocalProblem.network`,
    gives factors that mean what the whole building's mean (the structure and the evidence
    stay the selection's). Started from the selection's parameters, except the factors of
    classes whose walls changed (those start at the spec, 1). No fit when the selection's
    last fit already had these classes.
    """
    net = problem.network([tuple(e) for e in sel.edges])
    have = list(sel.estimator.problem_.wall_classes)
    want = list(dict(problem.wall_classes).get(e.name, c)
                for e, c in zip(net.conduction_edges, have))
    if not problem.wall_classes or have == want:
        return sel.estimator, 0
    same = {c for c in set(have) | set(want)
            if [h == c for h in have] == [w == c for w in want]}
    init = {k: v for k, v in sel.estimator.params_.items()
            if not k.startswith("ua_factor[") or k[len("ua_factor["):-1] in same}
    est = _local_estimator(net, max_iter, **options)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", BoundWarning)
        warnings.simplefilter("ignore", ConvergenceWarning)
        est.fit(sub, init=init)
    return est, 1


def local_cost_problem(spec: BuildingSpec, edges, frame, *, window: float = 12 * 3600.0,
                       initial_state: str = "estimate", latent_depth: int | None = 1):
    """The paper's simulation criterion of a building as a sum over its local problems.

    Parameters
    ----------
    spec : BuildingSpec
        The whole building.
    edges : iterable of (str, str, float)
        Selected air paths ``(a, b, d)`` between measured zones.
    frame : pandas.DataFrame
        Calibration data (SI, regular index).
    window : float
        Cost window of each local problem [s] (paper: 12 h).
    initial_state : str
        As :class:`thermctl.estimate.simulation.CostProblem`.
    latent_depth : int or None
        As :func:`local_problems`.

    Returns
    -------
    thermctl.estimate.simulation.CompositeCostProblem
        One part per measured zone with at least one selected air path (a zone without one
        adds a constant to J); every part uses the building's ``alpha``, so the parts share
        the parameter bounds.
    """
    from .estimate import EstimationData
    from .estimate.simulation import CompositeCostProblem, CostProblem

    edges = [tuple(e) for e in edges]
    ends = {z for a, b, _ in edges for z in (a, b)}
    alpha = spec.alpha()
    parts, names = [], []
    for p in local_problems(spec, frame.columns, zones=sorted(ends), latent_depth=latent_depth):
        mine = [e for e in edges if p.zone in e[:2]]
        if not mine:
            continue
        net = ThermalNetwork(p.spec).with_convection(mine)
        data = EstimationData.from_frame(p.data(frame), net)
        parts.append(CostProblem(net, data, window=window, initial_state=initial_state,
                                 alpha=alpha))
        names.append(p.zone)
    return CompositeCostProblem(parts, names)


def propose_sin(problems, frame, level: float = 0.05, s_min: float = 0.25) -> tuple:
    """The paper's structure rule on every zone's neighbourhood: proposals for the searches.

    Each problem's zone and its measured candidate partners form a neighbourhood whose SIN
    concentration graph (:func:`thermctl.structure.neighbourhood.neighbourhood_scores`,
    ``N >= |neighbourhood| + 2`` days instead of the building's ``n + 2``) scores the
    zone's pairs; the zone's best partner and every pair scoring at least ``s_min`` are
    picked (the paper's rule ∪ the threshold rule, as the whole-building default). An air
    path picked from either end is proposed to both ends' problems — the whole-building
    rule also picks a pair when it is the best of either zone. Cheap (correlations only):
    runs before the tasks are sent.

    Parameters
    ----------
    problems : list of LocalProblem
    frame : pandas.DataFrame
        Calibration data.
    level, s_min : float
        SIN level and score threshold [-].

    Returns
    -------
    problems : list of LocalProblem
        With ``proposed`` set (left ``None`` where SIN could not run: too few days for
        that neighbourhood).
    scores : dict
        Air-path name → {zone: local SIN score}.
    """
    from dataclasses import replace
    picks, scores, failed = set(), {}, set()
    for p in problems:
        got = _sin_picks(p, frame, level, s_min)
        if got is None:
            failed.add(p.zone)
            continue
        sc, chosen = got
        picks |= chosen
        for nm, v in sc.items():
            scores.setdefault(nm, {})[p.zone] = v
    if failed:
        log.warning("local SIN could not run for %d zone(s) (too few complete days for their "
                    "neighbourhoods): their searches start from every candidate: %s",
                    len(failed), sorted(failed)[:10])
    out = [p if p.zone in failed else
           replace(p, proposed=tuple(c for c in p.candidates if air_path_name(*c[:2]) in picks))
           for p in problems]
    return out, scores


def _sin_picks(problem, frame, level, s_min):
    """``(scores by air-path name, names picked)`` by SIN on the problem's neighbourhood,
    or ``None`` when SIN cannot run (too few days)."""
    from .structure.neighbourhood import neighbourhood_scores
    z = problem.zone
    other = {(b if a == z else a): (a, b, d) for a, b, d in problem.candidates}
    if not other:
        return {}, set()
    # nearest partners first: with few days the neighbourhood keeps the closest ones
    order = sorted(other, key=lambda n: (other[n][2], n))
    try:
        scores = neighbourhood_scores(frame, z, order, level=level, trim=True)
    except DataError as exc:
        log.info("local SIN of %s: %s", z, exc)
        return None
    pairs = {tuple(sorted(other[n][:2])): sc for n, sc in scores.items()}
    dist = {tuple(sorted(other[n][:2])): other[n][2] for n in scores}
    # the paper's rule for this zone (its best partner, if it scores at all) ∪ the threshold
    # rule, both on z's pairs only (structure.selection's rules would give every neighbour
    # its best pair too, and count per zone over the whole building)
    picked = {p for p, v in pairs.items() if v >= s_min and v > 0}
    best = min(pairs, key=lambda p: (-pairs[p], dist[p], p), default=None)
    if best is not None and pairs[best] > 0:
        picked.add(best)
    return ({air_path_name(*p): v for p, v in pairs.items()},
            {air_path_name(*p) for p in picked})


def _fit_task(problem, frame, kwargs):
    """A task: one local problem, one-threaded BLAS, errors returned, not raised."""
    from ._blas import single_thread_blas
    try:
        with single_thread_blas():
            return fit_local(problem, frame, **kwargs)
    except Exception as exc:            # noqa: BLE001 - one zone's failure must not stop the rest
        log.warning("local problem of %s failed: %s", problem.zone, exc)
        return LocalResult(problem.zone, [], {}, {}, float("nan"), problem.n_states,
                           error=f"{type(exc).__name__}: {exc}")


# ---------------------------------------------------------------------------- run many
def run_local(problems, frame, *, workers: int | None = None, client=None, progress=None,
              stage: str = "local problems", **kwargs) -> list[LocalResult]:
    """Fit local problems: serially, on local processes, or on a Dask cluster.

    Parameters
    ----------
    problems : list of LocalProblem
    frame : pandas.DataFrame or list of DataFrame
        Calibration data (each task gets only its problem's columns); a list gives one
        table per problem (problems of several buildings in one run).
    workers : int, optional
        Local processes; default: every core (``os.cpu_count()``); 1 runs in this process.
        Ignored with ``client``.
    client : distributed.Client or str, optional
        A Dask client, or a scheduler address (``tcp://host:8786``): the tasks go there.
    progress : callable, optional
        ``progress(stage, done, total)`` after each finished problem.
    stage : str
        The stage name ``progress`` and the log lines give.
    **kwargs
        Passed to :func:`fit_local`.

    Returns
    -------
    list of LocalResult
        In the order of ``problems`` (the same whatever ran them).
    """
    n = len(problems)
    frames = list(frame) if isinstance(frame, (list, tuple)) else [frame] * n
    if len(frames) != n:
        raise EstimationError(f"run_local: {len(frames)} tables for {n} problems")
    say = progress or (lambda *a: None)
    results: dict[int, LocalResult] = {}
    t0 = time.perf_counter()

    def done(i, res):
        results[i] = res
        k = len(results)
        eta = (time.perf_counter() - t0) / k * (n - k)
        log.info("%s %d/%d: %s (%d states) %s in %.1f s; ETA %.0f s", stage, k, n, res.zone,
                 res.n_states, ", ".join(res.edges) or "no air path", res.time, eta)
        say(stage, k, n)

    say(stage, 0, n)
    # largest problems first: the last task to start is a short one
    order = sorted(range(n), key=lambda i: -problems[i].n_states)
    tasks = [(p, p.data(f), kwargs) for p, f in zip(problems, frames)]
    _dispatch(_fit_task, tasks, order, workers, client, done, "local")
    return [results[i] for i in range(n)]


def _dispatch(fn, tasks, order, workers, client, done, tag):
    """``fn(*task)`` for every task on local processes (:func:`run_tasks`) or on a Dask
    cluster (``client``: a Client or a scheduler address); ``done(i, result)`` as each
    finishes."""
    if client is None:
        run_tasks(fn, tasks, workers=workers, order=order, on_done=done)
        return
    own = False
    if isinstance(client, str):
        from distributed import Client
        client, own = Client(client), True
    try:
        from distributed import as_completed
        # a key names a result on the cluster: unique per call, or a second run on the
        # same client would be handed the first run's results
        run = uuid.uuid4().hex[:8]
        futs = {client.submit(fn, *tasks[i], pure=False, key=f"thermctl-{tag}-{run}-{i}"): i
                for i in order}
        for fut in as_completed(list(futs)):
            done(futs[fut], fut.result())
    finally:
        if own:
            client.close()


def one_sided(problems, results, groups=None) -> dict:
    """Air paths kept by some local problems and not by others that see them.

    Parameters
    ----------
    problems : list of LocalProblem
    results : list of LocalResult
    groups : list, optional
        A label per problem (its building, or its resample): paths are matched within a
        group only. Default: one group.

    Returns
    -------
    dict
        Index of a problem that did not keep the path (and did not fail) → list of such
        ``(a, b, d)``.
    """
    groups = [0] * len(problems) if groups is None else list(groups)
    kept = {(g, nm) for g, r in zip(groups, results) if r.error is None for nm in r.edges}
    out: dict[int, list] = {}
    for i, (p, r) in enumerate(zip(problems, results)):
        if r.error is not None:
            continue
        for a, b, d in p.candidates:
            nm = air_path_name(a, b)
            if (groups[i], nm) in kept and nm not in r.edges and nm not in r.confirmed:
                out.setdefault(i, []).append((a, b, d))
    return out


def _confirm_task(problem, sub, kept, tests, kwargs):
    """A task: test ``tests`` against ``kept`` in one local problem (errors returned: an
    empty verdict)."""
    from ._blas import single_thread_blas
    from .selection import judge_air_paths
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        with single_thread_blas(), warnings.catch_warnings():
            warnings.simplefilter("ignore", BoundWarning)
            warnings.simplefilter("ignore", ConvergenceWarning)
            got = judge_air_paths(problem.spec, sub, kept, tests, **kwargs)
    except Exception as exc:            # noqa: BLE001 - one zone's failure must not stop the rest
        log.warning("testing %s in the local problem of %s failed: %s",
                    ", ".join(air_path_name(a, b) for a, b, _ in tests), problem.zone, exc)
        got = {}
    return got, time.perf_counter() - t0, time.process_time() - c0


def confirm_local(problems, results, frame, *, workers: int | None = None, client=None,
                  progress=None, groups=None, **kwargs) -> list[LocalResult]:
    """Test, at every end that did not keep it, an air path another end kept.

    A local search is greedy: it stops at the first candidate that fails the margin or the
    day-by-day test, so a path its neighbour keeps strongly may never have been fitted
    there. Each such path is added alone to the problem's own kept structure and judged
    as the search would have judged it (:func:`thermctl.selection.judge_air_paths`); the
    verdicts go to :attr:`LocalResult.confirmed`, and :func:`combine` counts a passed test
    as that end's vote.

    Parameters
    ----------
    problems : list of LocalProblem
    results : list of LocalResult
        Of :func:`run_local`, same order; updated in place and returned.
    frame : pandas.DataFrame or list of DataFrame
    workers, client, progress
        As :func:`run_local`.
    groups : list, optional
        A label per problem: several buildings (or resamples) in one run (:func:`one_sided`).
    **kwargs
        :func:`fit_local`'s keywords (``criterion``, ``margin``, ``min_t``, ``solar``...).

    Returns
    -------
    list of LocalResult
    """
    n = len(problems)
    frames = list(frame) if isinstance(frame, (list, tuple)) else [frame] * n
    todo = one_sided(problems, results, groups)
    if not todo:
        return results
    idx = sorted(todo)
    say = progress or (lambda *a: None)
    cands = [{air_path_name(a, b): (a, b, d) for a, b, d in problems[i].candidates} for i in idx]
    tasks = [(problems[i], problems[i].data(frames[i]),
              [c[nm] for nm in results[i].edges], todo[i], kwargs) for i, c in zip(idx, cands)]
    got = {}
    t0 = time.perf_counter()

    def done(k, out):
        got[k] = out
        i, res = idx[k], out[0]
        log.info("confirm %d/%d: %s tested %s: %s in %.0f s", len(got), len(idx), problems[i].zone,
                 ", ".join(air_path_name(a, b) for a, b, _ in todo[i]),
                 ", ".join(f"{nm} {'in' if v[0] else 'out'}" for nm, v in res.items()) or "failed",
                 time.perf_counter() - t0)
        say("confirming one-sided air paths", len(got), len(idx))

    say("confirming one-sided air paths", 0, len(idx))
    order = sorted(range(len(idx)), key=lambda k: -problems[idx[k]].n_states)
    _dispatch(_confirm_task, tasks, order, workers, client, done, "confirm")
    for k, i in enumerate(idx):
        res, wall, cpu = got[k]
        r = results[i]
        r.confirmed.update(res)
        r.time += wall              # the problem's cost includes its tests
        r.cpu += cpu
        r.n_fits += 1 + len(todo[i])
    return results


def joint_local(spec, frame, li, *, workers: int | None = None, client=None, progress=None,
                parallel: bool = True, latent_depth: int | None = 1, **kwargs):
    """Test every kept air path between two measured zones in one problem of both.

    A local problem takes its neighbours' temperatures as exact inputs, so a neighbour that
    shares a zone's unmeasured disturbances (the same occupancy hours, the same façade) is
    a free proxy for them there, and the AND rule of :func:`combine` keeps such a path when
    both ends are fooled alike. In a joint problem of both ends (:func:`local_problems`
    with the pair as one group: both temperatures are outputs, predicted together, each
    zone's other kept air paths and measured neighbours as in its own problem) the path
    must explain both zones' innovations with one symmetric coupling, as in the
    whole-building likelihood: the remedy for correlated disturbances that local module
    identification names (widen the local problem to predict correlated neighbours
    jointly; Ramaswamy & Van den Hof, IEEE TAC 2021). A path is kept when adding it to the
    joint problem's other kept paths passes the local search's own test
    (:func:`thermctl.selection.judge_air_paths`: ``margin`` and the daily gain ``min_t``).

    Measured on the 49-zone corridor (14 days, seeds 0 and 1): every one of the 26 paths the
    AND rule kept passed, the 4 false ones included (neighbouring offices on one side, BIC
    −116 and t 2.5 for f1n10–f1n11), for 1.8× the CPU; so it is not part of ``identify``'s
    default (``split.joint``), and what fools the local problems is not the exact-input
    approximation (docs/identification.md).

    Parameters
    ----------
    spec : BuildingSpec
    frame : pandas.DataFrame
        Calibration data.
    li : LocalIdentification
        Of :func:`assemble`; a new one is returned, its verdicts' reasons extended.
    workers, client, progress
        As :func:`run_local`.
    parallel, latent_depth
        As :func:`local_problems` (the zone problems' own).
    **kwargs
        :func:`fit_local`'s keywords (``criterion``, ``margin``, ``min_t``, ``solar``...).

    Returns
    -------
    LocalIdentification
    """
    from dataclasses import replace
    meas = set(spec.measured_zones)
    kept = [(v.a, v.b, v.d) for v in li.verdicts if v.kept]
    pairs = [e for e in kept if e[0] in meas and e[1] in meas]
    if not pairs:
        return li
    t0 = time.perf_counter()
    probs = local_problems(spec, frame.columns, zones=[(a, b) for a, b, _ in pairs],
                           parallel=parallel, latent_depth=latent_depth)
    tasks = []
    for (a, b, d), p in zip(pairs, probs):
        names = {air_path_name(x, y) for x, y, _ in p.candidates}
        base = [e for e in kept if air_path_name(e[0], e[1]) in names
                and {e[0], e[1]} != {a, b}]
        tasks.append((p, p.data(frame), base, [(a, b, d)], kwargs))
    say = progress or (lambda *a: None)
    got = {}

    def done(k, out):
        got[k] = out
        (a, b, _), res = pairs[k], out[0].get(air_path_name(*pairs[k][:2]))
        log.info("joint check %d/%d: %s (%d states) %s in %.0f s", len(got), len(pairs),
                 air_path_name(a, b), probs[k].n_states,
                 "failed" if res is None else f"{'in' if res[0] else 'out'}: {res[3]}",
                 out[1])
        say("joint checks", len(got), len(pairs))

    say("joint checks", 0, len(pairs))
    order = sorted(range(len(pairs)), key=lambda k: -probs[k].n_states)
    _dispatch(_confirm_task, tasks, order, workers, client, done, "joint")
    verdicts, cpu = [], 0.0
    index = {air_path_name(a, b): k for k, (a, b, _) in enumerate(pairs)}
    for v in li.verdicts:
        k = index.get(v.name)
        if k is None:
            verdicts.append(v)
            continue
        res, _, c = got[k]
        cpu += c
        r = res.get(v.name)
        if r is None:           # the test failed: the zones' verdicts stand
            verdicts.append(replace(v, reason=v.reason + "; joint check failed, not applied"))
            continue
        ok, _, _, note, rb = r
        verdicts.append(replace(v, kept=bool(ok), rbar_v=v.rbar_v if ok else float("nan"),
                                reason=(v.reason if ok else v.reason.replace("in by", "out by",
                                                                            1))
                                + f"; joint check ({probs[k].zone}): "
                                + f"{'in' if ok else 'out'}, {note}"))
    edges = [(v.a, v.b, v.d) for v in verdicts if v.kept]
    return replace(li, verdicts=verdicts, edges=edges,
                   rbar_v={v.name: v.rbar_v for v in verdicts if v.kept},
                   time=li.time + time.perf_counter() - t0, cpu=li.cpu + cpu)


# ---------------------------------------------------------------------------- combine
@dataclass
class EdgeVerdict:
    """The combined decision on one air path.

    Attributes
    ----------
    a, b : str
    d : float
        [m]
    kept : bool
    evidence : dict
        Local problem (zone) → criterion change of having the edge there [-].
    rbar_v : float
        Combined R̄_v [K/(W m)] (NaN if not kept).
    reason : str
    rbar_ratio : float
        Of a path :func:`rbar_consensus` put out: its combined R̄_v over the building's
        [-]; NaN otherwise.
    """

    a: str
    b: str
    d: float
    kept: bool
    evidence: dict
    rbar_v: float
    reason: str
    rbar_ratio: float = float("nan")

    @property
    def name(self) -> str:
        return air_path_name(self.a, self.b)

    @property
    def out_by_rbar(self) -> bool:
        """Whether :func:`rbar_consensus` put the path out."""
        return math.isfinite(self.rbar_ratio)


def combine(problems, results, rule: str = "both", margin: float = 10.0,
            one_sided: float | None = None) -> list[EdgeVerdict]:
    """Join the local verdicts on every candidate air path.

    Parameters
    ----------
    problems : list of LocalProblem
    results : list of LocalResult
        In the same order.
    rule : {"both", "sum", "either"}
        ``both`` (default): kept by every problem that sees it — the AND rule of
        neighbourhood selection, which keeps the fewest false edges; ``sum``: the sum of its
        BIC changes over the problems that see it is below ``-margin``; ``either``: kept by
        at least one (OR rule). On the 7-, 9- and 25-zone testbeds (all samples): ``both``
        18/18 true paths and 14 false, ``sum`` 18/18 and 29 false, ``either`` 18/18 and 38
        false.
    margin : float
        [-]
    one_sided : float or None
        With ``both``: a path one end keeps and the other does not is kept too when its
        BIC changes summed over the ends that see it (each finite) are below
        ``-one_sided`` [-]: the composite likelihood of the two local problems wants it
        by that much. Not a path beside a wall: to temperature data it is one term with
        the wall's conduction, and such a path kept at one end was, on the corridor
        testbed, most often two neighbouring offices. None: no such path is kept.

    Returns
    -------
    list of EdgeVerdict
        One per candidate, sorted by name.
    """
    if rule not in COMBINE_RULES:
        raise EstimationError(f"combine rule must be one of {COMBINE_RULES}, found {rule!r}")
    seen: dict[str, dict] = {}
    walls = set() if one_sided is None else {
        frozenset((w.a, w.b)) for p in problems for w in getattr(p.spec, "walls", ())}
    for p, r in zip(problems, results):
        for a, b, d in p.candidates:
            e = seen.setdefault(air_path_name(a, b), {"a": min(a, b), "b": max(a, b), "d": d,
                                                   "ev": {}, "kept": {}, "rb": {}})
            if r.error is not None:
                continue
            nm = air_path_name(a, b)
            e["ev"][p.zone] = float(r.evidence.get(nm, np.nan))
            e["kept"][p.zone] = nm in r.edges
            if nm in r.rbar_v and nm in r.edges:
                e["rb"][p.zone] = float(r.rbar_v[nm])
            elif nm in r.confirmed:
                ok, delta, t, note, rb = r.confirmed[nm]
                e["ev"][p.zone] = float(delta)
                e["kept"][p.zone] = bool(ok)
                e.setdefault("tested", {})[p.zone] = note
                if ok and np.isfinite(rb):
                    e["rb"][p.zone] = float(rb)
    out = []
    for nm in sorted(seen):
        e = seen[nm]
        votes = e["kept"]
        if not votes:
            out.append(EdgeVerdict(e["a"], e["b"], e["d"], False, {}, float("nan"),
                                   "undecided: every local problem that sees it failed"))
            continue
        by_sum = ""
        if rule == "both":
            kept = all(votes.values())
            ev = list(e["ev"].values())
            if (not kept and one_sided is not None and any(votes.values())
                    and frozenset((e["a"], e["b"])) not in walls
                    and all(np.isfinite(ev)) and sum(ev) < -one_sided):
                kept, by_sum = True, (f"; kept at one end, and the ends' BIC changes sum to "
                                      f"{sum(ev):+.1f}, below -{one_sided:g}")
        elif rule == "either":
            kept = any(votes.values())
        else:
            ev = [v for v in e["ev"].values() if np.isfinite(v)]
            kept = bool(ev) and sum(ev) < -margin
        rbs = list(e["rb"].values())
        rb = float(gmean(rbs)) if kept and rbs else float("nan")
        tested = e.get("tested", {})
        desc = ", ".join(f"{z}: {'kept' if votes[z] else 'out'} ({e['ev'][z]:+.1f})"
                         + (f" when tested alone ({tested[z]})" if z in tested else "")
                         for z in votes)
        reason = f"{'in' if kept else 'out'} by rule {rule!r}: {desc}{by_sum}"
        if kept and not rbs:
            reason += "; no local fit kept it, R̄_v from the global refit"
        out.append(EdgeVerdict(e["a"], e["b"], e["d"], kept, dict(e["ev"]), rb, reason))
    return out


OUT_BY_RBAR = "out by R̄_v"
"""How the reason of an air path :func:`rbar_consensus` left out begins."""


def rbar_consensus(verdicts, window: float | None = RBAR_WINDOW,
                   min_paths: int = RBAR_WINDOW_MIN_PATHS) -> tuple[list, float]:
    """Drop the kept air paths whose R̄_v the building's other paths do not share.

    The paper's model has one R̄_v for the building: an air path of length d conducts
    1/(R̄_v·d). A local problem fits each path's R̄_v freely, and a path kept with a value
    far below the others' conducts several times what a door of its length does at the
    building's R̄_v: it stands in for something the zone's model lacks (a common
    disturbance of offices on one side of a corridor), not for a door. The building's value
    is the median over the kept paths, taken again over the paths within ``window`` of it
    until it settles (false paths pull it down); a path outside ``[m/window, m·window]``
    is out. Measured on the 196-zone corridor testbed (14 days, seed 0): the 32 true paths
    kept lie within ×0.55–1.6 of the median; of the 20 false ones, 15 join two offices on
    one side of a corridor and 10 lie below ×0.5 (docs/scale.md, "One R̄_v for the
    building").

    Parameters
    ----------
    verdicts : list of EdgeVerdict
        :func:`combine`'s.
    window : float or None
        Factor [-] (> 1); None: no test.
    min_paths : int
        Kept paths with a finite R̄_v needed for the test (fewer: no test).

    Returns
    -------
    verdicts : list of EdgeVerdict
        The same, those outside the window now out (with why).
    rbar_v : float
        The building's R̄_v, the median of the paths kept [K/(W m)]; NaN without a test.
    """
    if window is not None and not window > 1:
        raise EstimationError(f"the R̄_v window must be a factor above 1, found {window!r}")
    judged = [v for v in verdicts if v.kept and math.isfinite(v.rbar_v) and v.rbar_v > 0]
    if window is None or len(judged) < min_paths:
        return list(verdicts), float("nan")
    log_w = math.log(window)
    inside = judged
    for _ in range(50):
        m = float(np.median([math.log(v.rbar_v) for v in inside]))
        now = [v for v in judged if abs(math.log(v.rbar_v) - m) <= log_w + 1e-12]
        if now == inside:
            break
        inside = now
    med, keep = math.exp(m), {v.name for v in inside}
    out_names = {v.name for v in judged} - keep
    out = []
    for v in verdicts:
        if v.name in out_names:
            ratio = v.rbar_v / med
            v = EdgeVerdict(v.a, v.b, v.d, False, v.evidence, float("nan"),
                            f"{OUT_BY_RBAR}: {v.reason}; but its R̄_v {v.rbar_v:.3g} K/(W m) is "
                            f"×{ratio:.2f} the building's {med:.3g} (median of {len(inside)} "
                            f"kept air paths), outside ×{1 / window:.2g}–{window:g}: "
                            f"{1 / ratio:.1f}× the conductance 1/(R̄_v·d) of a door "
                            f"{v.d:.1f} m long, so it stands in for something else", ratio)
        out.append(v)
    return out, med


def settle(problems, results, frame, *, rule: str = "both",
           rbar_window: float | None = RBAR_WINDOW, one_sided: float | None = ONE_SIDED,
           again: bool = True,
           wall: float = float("nan"), workers: int | None = None, client=None,
           progress=None, **kwargs) -> tuple[LocalIdentification, list, list]:
    """:func:`assemble`, and (``again``) the local problems at the ends of the paths out by
    R̄_v searched again without them.

    A path that conducts more than a door of its length (:func:`rbar_consensus`) was a
    candidate of its ends' searches, and there it may have kept a true partner out (on the
    196-zone corridor testbed, seeds 0 and 1, 6 of the 20 false paths out by R̄_v share a
    zone with a missed true path: a neighbour on the same side in place of the office
    across the corridor).
    Those problems are searched once more without the paths that are out, and the verdicts
    combined again (and judged by R̄_v again, with no further search).

    Parameters
    ----------
    problems, results : list
        Of :func:`run_local`, in the same order.
    frame : pandas.DataFrame
        Calibration data.
    rule, rbar_window, one_sided, wall
        As :func:`assemble`.
    again : bool
        Search the ends again; False: :func:`assemble` alone.
    workers, client, progress, **kwargs
        As :func:`run_local` (``margin`` also :func:`assemble`'s).

    Returns
    -------
    li : LocalIdentification
        With the verdicts of the paths out by R̄_v kept (their reason says so).
    problems, results : list
        The problems and results ``li`` rests on.
    """
    from dataclasses import replace
    margin = kwargs.get("margin", 10.0)
    li = assemble(problems, results, rule, margin, wall, rbar_window, one_sided)
    out = {v.name: v for v in li.verdicts if v.out_by_rbar} if again else {}
    ends = [i for i, p in enumerate(problems)
            if any(air_path_name(a, b) in out for a, b, _ in p.candidates)]
    if not ends:
        return li, list(problems), list(results)
    t0, c0 = time.perf_counter(), li.cpu

    def without(cands):
        return None if cands is None else tuple(
            c for c in cands if air_path_name(c[0], c[1]) not in out)

    problems, results = list(problems), list(results)
    redo = [replace(problems[i], candidates=without(problems[i].candidates),
                    proposed=without(problems[i].proposed)) for i in ends]
    log.info("%d air path(s) out by R̄_v; the local problems of %s searched again without them",
             len(out), ", ".join(p.zone for p in redo))
    got = run_local(redo, frame, workers=workers, client=client, progress=progress,
                    stage=f"local problems again ({len(out)} air path"
                          f"{'s' if len(out) != 1 else ''} out by R̄_v)", **kwargs)
    for i, p, r in zip(ends, redo, got):
        problems[i], results[i] = p, r
    li2 = assemble(problems, results, rule, margin, wall + time.perf_counter() - t0,
                   rbar_window, one_sided)
    # the paths no problem offers any more keep the verdict that put them out
    seen = {v.name for v in li2.verdicts}
    li2.verdicts = sorted(li2.verdicts + [v for nm, v in out.items() if nm not in seen],
                          key=lambda v: v.name)
    li2.cpu = c0 + float(sum(r.cpu for r in got))
    return li2, problems, results


# ---------------------------------------------------------------------------- all of it
@dataclass
class LocalIdentification:
    """Outcome of :func:`identify_local`.

    Attributes
    ----------
    problems : list of LocalProblem
    results : list of LocalResult
    verdicts : list of EdgeVerdict
    edges : list of (str, str, float)
        Selected air paths ``(a, b, d)``.
    rbar_v : dict
        Edge name → combined local R̄_v [K/(W m)].
    tau0 : float
        Median local τ0 [s].
    rule : str
    time : float
        Wall time [s].
    cpu : float
        CPU time summed over the tasks [s].
    ua_factor : dict
        Wall class → combined UA factor of the local fits [-] (:func:`combine_ua_factors`);
        empty without ``wall_factors``.
    rbar_v_building : float
        The building's R̄_v that :func:`rbar_consensus` judged the paths by [K/(W m)]; NaN
        when it judged none.
    rbar_window : float or None
        Its factor [-].
    one_sided : float or None
        :func:`combine`'s ``one_sided`` [-].
    """

    problems: list
    results: list
    verdicts: list
    edges: list
    rbar_v: dict
    tau0: float
    rule: str
    time: float
    cpu: float
    ua_factor: dict = field(default_factory=dict)
    rbar_v_building: float = float("nan")
    rbar_window: float | None = None
    one_sided: float | None = None

    @property
    def reasons(self) -> dict:
        return {v.name: v.reason for v in self.verdicts}

    def model(self, spec: BuildingSpec, meta: dict | None = None):
        """The whole-building model with the combined per-edge R̄_v and C_v = τ0/R̄_v, with
        ``wall_factors`` every wall of a class with a combined factor f at ``R/f``, and with
        ``internal_mass`` every measured zone at its own problem's capacity factor
        (:meth:`fitted_spec`)."""
        from .model import C_V_PAPER, RBAR_V_PAPER, ThermalModel
        net = ThermalNetwork(self.fitted_spec(spec), self.edges)
        if not self.edges:
            return ThermalModel(net, RBAR_V_PAPER, C_V_PAPER, meta=meta)
        rb = np.array([self.rbar_v.get(e.name, np.nan) for e in net.convection_edges])
        fill = float(np.exp(np.nanmean(np.log(rb)))) if np.isfinite(rb).any() else RBAR_V_PAPER
        rb = np.where(np.isfinite(rb), rb, fill)
        tau = self.tau0 if math.isfinite(self.tau0) else RBAR_V_PAPER * C_V_PAPER
        return ThermalModel(net, rb, tau / rb, meta=meta)

    def fitted_spec(self, spec: BuildingSpec) -> BuildingSpec:
        """``spec`` with the combined UA factors: every wall of a class (its class in
        ``spec``, :func:`thermctl.spec.wall_class`) with factor f gets all three resistances
        ``R/f``, capacities kept; and with capacity factors (``cap_factor[z]`` of a zone's
        own problem, :func:`combine_zone_params`) every such zone the capacitance f·C_z
        [J/K] — what the whole-building fit's
        :meth:`~thermctl.estimate.likelihood.LikelihoodProblem.fitted_network` does. Without
        factors, ``spec`` itself."""
        from dataclasses import replace
        cap = {k[len("cap_factor["):-1]: v for k, v in combine_zone_params(spec, self.results)[0]
               .items() if k.startswith("cap_factor[")}
        if cap:
            spec = replace(spec, zones=tuple(
                replace(z, capacitance=float(cap[z.name]) * spec.zone_capacitance(z.name))
                if z.name in cap else z for z in spec.zones))
        if not self.ua_factor:
            return spec
        zones = set(spec.zone_names)
        walls = []
        for w in spec.walls:
            f = self.ua_factor.get(wall_class(w.a, w.b, zones), 1.0)
            walls.append(w if f == 1.0 else replace(w, R=tuple(float(r) / f for r in w.R)))
        return replace(spec, walls=tuple(walls))

    def summary(self) -> str:
        st = sorted(p.n_states for p in self.problems)
        lines = [f"local identification: {len(self.problems)} problems (median "
                 f"{st[len(st) // 2] if st else 0} states, max {st[-1] if st else 0}), "
                 f"{len(self.edges)} air path(s) by rule {self.rule!r}, {self.time:.0f} s wall, "
                 f"{self.cpu:.0f} s CPU"]
        if self.ua_factor:
            lines.append("  UA factors (median of the local fits): " + ", ".join(
                f"{c} {f:.3g}" for c, f in self.ua_factor.items()))
        lines += [f"  {v.name}: {v.reason}" for v in self.verdicts if v.kept]
        failed = [r for r in self.results if r.error]
        lines += [f"  local problem of {r.zone} failed: {r.error}" for r in failed]
        return "\n".join(lines)


def identify_local(spec: BuildingSpec, frame, *, rule: str = "both", criterion: str = "bic",
                   margin: float = 10.0, solar: bool = True, workers: int | None = None,
                   client=None, progress=None, parallel: bool = True,
                   fit_rows: str = "all", latent_depth: int | None = 1,
                   candidates: str = "all", level: float = 0.05,
                   s_min: float = 0.25, min_t: float = 0.0, confirm: bool = False,
                   joint: bool = False, rbar_window: float | None = RBAR_WINDOW,
                   one_sided: float | None = ONE_SIDED, search_again: bool = False,
                   **options) -> LocalIdentification:
    """Air paths and per-edge R̄_v of a whole building from its local problems.

    Parameters
    ----------
    spec : BuildingSpec
    frame : pandas.DataFrame
        Calibration data (``Measurements.frame``: SI units, regular index).
    rule : {"both", "sum", "either"}
        How the two ends' verdicts on an air path combine (:func:`combine`).
    criterion : {"bic", "aic", "holdout"}
    margin : float
        [-]
    solar : bool
    workers : int, optional
        Local processes (default: every core).
    client : distributed.Client or str, optional
        Dask client or scheduler address.
    progress : callable, optional
        ``progress(stage, done, total)``.
    parallel : bool
        Air paths beside walls are candidates.
    fit_rows : {"all", "auto", "supply_off"}
        Samples of the local likelihoods (:func:`fit_local`).
    latent_depth : int or None
        Unmeasured zones deep a problem reaches (:func:`local_problems`).
    candidates : {"all", "sin"}
        What each local search starts from (:func:`fit_local`).
    level, s_min : float
        ``candidates="sin"``: SIN level and score threshold [-].
    min_t : float
        Daily consistency an air path's gain must show in its local search
        (:meth:`thermctl.estimate.likelihood.scoring.LikelihoodScorer.consistent`); 0: off.
    confirm : bool
        With ``rule="both"``: test every air path kept at one end only at its other end
        (:func:`confirm_local`).
    joint : bool
        Test every kept air path between measured zones once more in a joint problem of
        both ends (:func:`joint_local`).
    rbar_window : float or None
        Combined air paths whose R̄_v is more than this factor from the building's median
        are out (:func:`rbar_consensus`) [-]; None: no test.
    one_sided : float or None
        With ``rule="both"``: a path kept at one end only is kept when the ends' BIC
        changes sum below minus this (:func:`combine`) [-]; None: never.
    search_again : bool
        The problems at the ends of the paths out by R̄_v are searched again without them
        (:func:`settle`; with ``confirm``, not tested again).
    **options
        Other :class:`thermctl.estimate.likelihood.LikelihoodOptions` fields of the local
        fits (``internal_mass``...).

    Returns
    -------
    LocalIdentification

    Examples
    --------
    >>> from thermctl.local import identify_local           # doctest: +SKIP
    >>> li = identify_local(meas.spec, cal.frame, workers=2)   # doctest: +SKIP
    >>> print(li.summary())                                  # doctest: +SKIP
    """
    t0 = time.perf_counter()
    problems = local_problems(spec, frame.columns, parallel=parallel, latent_depth=latent_depth)
    if candidates == "sin":
        problems, _ = propose_sin(problems, frame, level, s_min)
    results = run_local(problems, frame, workers=workers, client=client, progress=progress,
                        criterion=criterion, margin=margin, solar=solar, fit_rows=fit_rows,
                        min_t=min_t, **options)
    if confirm and rule == "both":
        results = confirm_local(problems, results, frame, workers=workers, client=client,
                                progress=progress, criterion=criterion, margin=margin,
                                solar=solar, fit_rows=fit_rows, min_t=min_t, **options)
    li, _, _ = settle(problems, results, frame, rule=rule, rbar_window=rbar_window,
                      one_sided=one_sided, again=search_again, wall=time.perf_counter() - t0,
                      workers=workers,
                      client=client, progress=progress, criterion=criterion, margin=margin,
                      solar=solar, fit_rows=fit_rows, min_t=min_t, **options)
    if joint:
        li = joint_local(spec, frame, li, workers=workers, client=client, progress=progress,
                         parallel=parallel, latent_depth=latent_depth, criterion=criterion,
                         margin=margin, solar=solar, fit_rows=fit_rows, min_t=min_t, **options)
    return li


def assemble(problems, results, rule: str = "both", margin: float = 10.0,
             wall: float = float("nan"), rbar_window: float | None = RBAR_WINDOW,
             one_sided: float | None = ONE_SIDED) -> LocalIdentification:
    """A :class:`LocalIdentification` from fitted local problems (:func:`combine` with
    ``one_sided``, then :func:`rbar_consensus` with ``rbar_window``, and the combined
    parameters); ``wall`` is the wall time it took [s]."""
    verdicts, med = rbar_consensus(combine(problems, results, rule, margin, one_sided),
                                   rbar_window)
    edges = [(v.a, v.b, v.d) for v in verdicts if v.kept]
    rb = {v.name: v.rbar_v for v in verdicts if v.kept}
    taus = [r.tau0 for r in results if math.isfinite(r.tau0)]
    tau0 = float(np.median(taus)) if taus else float("nan")
    return LocalIdentification(problems, results, verdicts, edges, rb, tau0, rule, wall,
                               float(sum(r.cpu for r in results)),
                               combine_ua_factors(results), med, rbar_window, one_sided)


def _zone_of(name: str):
    """The zone a parameter name refers to (``aperture[r1,solar:s]`` → ``r1``), or None."""
    if "[" not in name:
        return None
    return name[name.index("[") + 1:].rstrip("]").split(",")[0]


# the noise groups a whole-building filter needs for every zone (sigma_q) or every
# measured zone (sigma_v, sigma_phi) (thermctl.export.kalman.augment_noise)
_NOISE_EVERY = (("sigma_q", False), ("sigma_v", True), ("sigma_phi", True))


def combine_zone_params(spec: BuildingSpec, results) -> tuple[dict, list, list]:
    """The whole building's apertures, gain profiles and noise from its local fits.

    A measured zone's parameters are those of its own problem, the one whose output it is
    (its neighbours' problems see it as an exact input and fit nothing of it). An unmeasured
    zone sits in every problem that reaches it: the median of their values. A
    building-level parameter (``tau_g``…): the median over the problems. A zone without a
    value of a noise group the whole-building filter needs (its problem failed, or an
    unmeasured zone no problem holds) gets the median of the others, and a note says so;
    such a zone has no apertures and no gain profile.

    Parameters
    ----------
    spec : BuildingSpec
        The whole building.
    results : list of LocalResult

    Returns
    -------
    params : dict
        Names and units as :class:`~thermctl.estimate.likelihood.LikelihoodEstimator`'s
        ``params_`` with one noise level per zone.
    at_bounds : list of str
        The measured zones' own parameters that ended on a bound, and the medians of values
        that ended on the same bound in more than half of the problems that fit them.
    notes : list of str
    """
    own, shared, latent, bounds, sides = {}, {}, {}, [], {}
    for r in results:
        if r.error is not None or not r.params:
            continue
        for k, v in r.params.items():
            z = _zone_of(k)
            if z is None:
                shared.setdefault(k, []).append(v)
            elif z == r.zone:
                own[k] = v
            else:
                latent.setdefault(k, []).append(v)
        for b in r.at_bounds:
            name, _, side = b.partition(" at its ")
            if _zone_of(name) == r.zone:
                bounds.append(b)
            else:
                sides.setdefault(name, []).append(side)
    out = dict(own)
    for k, vs in latent.items():
        out.setdefault(k, float(np.median(vs)))
    for k, vs in shared.items():
        out[k] = float(np.median(vs))
    for k, ss in sides.items():
        if k in own:            # a measured zone's own problem decides its value
            continue
        # a median of values on the same bound in most problems is on it too
        vs = shared.get(k) or latent.get(k, [])
        side, n = Counter(ss).most_common(1)[0]
        if vs and 2 * n > len(vs):
            bounds.append(f"{k} at its {side} (in {n} of {len(vs)} local problems)")
    notes = []
    measured = set(spec.measured_zones)
    for group, only_measured in _NOISE_EVERY:
        have = [v for k, v in out.items() if k.startswith(group + "[")]
        if not have:
            continue
        zones = [z for z in spec.zone_names if z in measured or not only_measured]
        miss = [z for z in zones if f"{group}[{z}]" not in out]
        if miss:
            fill = float(np.median(have))
            out.update({f"{group}[{z}]": fill for z in miss})
            notes.append(f"{group} of {len(miss)} zone(s) without a local fit of their own "
                         f"({', '.join(miss[:5])}{', …' if len(miss) > 5 else ''}): the median "
                         f"of the others, {fill:.3g}")
    return out, bounds, notes


def conduction_zone_params(spec: BuildingSpec, frame, *, workers: int | None = None,
                           progress=None, latent_depth: int | None = 1,
                           **options) -> tuple[dict, list]:
    """Apertures and noise of the conduction-only model of ``spec``, by local problems.

    One fit per measured zone of its local problem without air paths (:func:`fit_local`
    with no candidate), combined as :func:`combine_zone_params` does: the filter of the
    conduction-only model built the way a large building's identified model gets its own
    (``thermctl validate`` compares their k-step errors without a whole-building fit).

    Parameters
    ----------
    spec : BuildingSpec
    frame : pandas.DataFrame
        Calibration data.
    workers, progress
        As :func:`run_local`.
    latent_depth : int or None
        As :func:`local_problems`.
    **options
        :func:`fit_local` keywords (``solar``, ``fit_rows``…).

    Returns
    -------
    params : dict
    notes : list of str
    """
    from dataclasses import replace
    probs = [replace(p, candidates=(), proposed=None)
             for p in local_problems(spec, frame.columns, latent_depth=latent_depth)]
    res = run_local(probs, frame, workers=workers, progress=progress, **options)
    params, _, notes = combine_zone_params(spec, res)
    return params, notes


def combine_ua_factors(results) -> dict:
    """Wall class → median of the local fits' UA factors of that class [-].

    Every local problem that has walls of a class fits its own factor for them (classes of
    the whole building, :attr:`LocalProblem.wall_classes`) from its own few walls, and some
    of those factors the data do not pin down: measured on Pugh Hall (exact inputs, seeds
    1–2, 3 and 6 days, 8 runs of 6 problems), ``ua_factor[boundary]`` (truth 1) sat on its
    bound 5 in 13 of 48 local fits; its median over a run was 0.90–2.24, its mean 1.47–2.68.
    For partitions 2× the spec's UA the single local factors scattered over 0.60–5.0
    (3 days) and 1.07–2.79 (6 days), their median 1.87–2.28, their mean 1.78–2.45 and
    geometric mean 1.70–2.23; with the plant as the spec the median was 0.90–1.09. The
    median follows the bulk of the problems, not the ones on a bound. Failed problems and
    fits without factors count for nothing; empty when no local fit had factors.
    """
    by = {}
    for r in results:
        if r.error is None:
            for c, f in (r.ua_factor or {}).items():
                if math.isfinite(f):
                    by.setdefault(c, []).append(float(f))
    return {c: float(np.median(by[c])) for c in WALL_CLASSES if c in by}
