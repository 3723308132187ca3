"""The paper's concentration graph on one zone's neighbourhood (local SIN).

SIN over a whole building (:class:`~thermctl.structure.StructureIdentifier`) needs
``N >= n + 2`` complete days for ``n`` measured zones: 50 days for a 48-zone floor. The
air paths of zone ``i`` are decided by the partial correlations of ``T_i`` with its
neighbours *given the rest of its neighbourhood*; conditioning on a zone far away adds
little (its influence passes through the neighbours, which are conditioned on), so the
neighbourhood's concentration graph needs only ``N >= |neighbourhood| + 2`` days (the
neighbourhood-selection idea of Meinshausen & Bühlmann, Ann. Stat. 2006, with the
paper's SIN test in place of the lasso).
"""

from __future__ import annotations

import numpy as np

from ..data.days import day_array
from ..errors import DataError
from .identifier import StructureIdentifier
from .sin import _partial, _sin_from_partial

__all__ = ["NeighbourhoodStructureIdentifier", "neighbourhood_scores"]


def neighbourhood_scores(frame, zone: str, neighbours, level: float = 0.05,
                         adjust: str = "sidak", trim: bool = False) -> dict:
    """SIN scores of ``zone`` with each neighbour, on the neighbourhood's zones only.

    Parameters
    ----------
    frame : pandas.DataFrame
        ``T:<node>`` columns [°C] on a regular DatetimeIndex.
    zone : str
    neighbours : sequence of str
        Measured nodes around ``zone`` (each needs a ``T:`` column), most important first.
    level : float
        SIN significance level.
    adjust : {"sidak", "holm", "none"}
        Multiple-testing adjustment over the neighbourhood's pairs.
    trim : bool
        With fewer than ``len(neighbours) + 3`` complete days, keep the first ``N − 3``
        neighbours (the order given) instead of raising; the others get no score.

    Returns
    -------
    dict
        Neighbour → score in [0, 1]: the fraction of the times of day at which the SIN
        graph of the neighbourhood joins it to ``zone`` (the paper's score, eq. 2).

    Raises
    ------
    DataError
        Too few complete days (fewer than ``len(neighbours) + 3``, or than 4 with
        ``trim``), or a neighbourhood whose temperatures are collinear at every time of day.
    """
    nodes = [zone] + [n for n in neighbours if n != zone]
    if len(nodes) < 2:
        return {}
    da = day_array(frame, nodes)
    X = np.array(da.values, dtype=float)
    N, K, n = X.shape
    if trim and n + 2 > N >= 4:
        n = N - 2
        nodes, X = nodes[:n], X[:, :, :n]
    if N < n + 2:
        raise DataError(f"local SIN of {zone}: needs >= {n + 2} complete days for a "
                        f"neighbourhood of {n} zones, found {N}")
    X -= X.mean(axis=0)
    sd = X.std(axis=0)
    ok = (sd > 1e-9).all(axis=1)                       # times of day with no flat zone
    if not ok.any():
        raise DataError(f"local SIN of {zone}: a neighbourhood temperature is constant "
                        "over the days at every time of day")
    X = X[:, ok] / sd[ok]
    R = np.einsum("nki,nkj->kij", X, X) / N
    # a time of day whose correlation matrix is (nearly) singular has no graph (as the
    # building's identifier): with 4 days two zones can be collinear at one time
    pc, _, sing = _partial(R)
    good = (np.linalg.cond(R) < 1e12) & ~sing
    if not good.any():
        raise DataError(f"local SIN of {zone}: the neighbourhood's temperatures are "
                        "collinear at every time of day")
    P = _sin_from_partial(pc[good], N, adjust)
    hits = (P[:, 0, 1:] <= level).sum(axis=0)
    # times of day without a usable graph count as times without an edge (as the paper)
    return {nb: float(h) / K for nb, h in zip(nodes[1:], hits)}


class NeighbourhoodStructureIdentifier:
    r"""The paper's structure rule on neighbourhood concentration graphs (any building size).

    :class:`~thermctl.structure.StructureIdentifier` needs ``N >= n + 2`` complete days
    for ``n`` measured zones (50 days at 48 zones). Here every measured zone ``i`` gets
    its own small concentration graph (:func:`neighbourhood_scores`): ``i``, its
    nearest candidate partner, its measured wall neighbours (they drive ``T_i`` and are
    conditioned on) and its other candidates, nearest first, trimmed to ``N - 2`` zones
    when the days are few. A pair is scored by both ends' graphs; its score is their mean (one end's when
    the other end's graph trimmed it away). The paper's rules then run unchanged on these
    scores (:func:`~thermctl.structure.select_edges`). This is the neighbourhood
    selection of Meinshausen & Bühlmann (Ann. Stat. 34, 2006) with SIN's test in place of
    the lasso; the mean of the two ends is their "and/or" rule made continuous.

    Parameters
    ----------
    level : float
        SIN significance level in (0, 1) (paper: 0.05).
    adjust : {"sidak", "holm"}
        Multiple-testing adjustment within each neighbourhood.
    rule : {"paper", "threshold"}
        Edge selection (:func:`~thermctl.structure.select_edges`).
    s_min : float
        Score threshold of the ``threshold`` rule, in [0, 1].
    allow_parallel : bool
        Keep pairs joined by a wall as candidates (the paper removes them).

    Attributes
    ----------
    zones_ : list of str
        Measured zones.
    neighbourhoods_ : dict of str to list of str
        Each zone's neighbourhood as scored (after trimming), the zone first.
    zone_scores_ : dict of (str, str) to dict
        Candidate pair → {end zone: that end's neighbourhood score}.
    scores_ : dict of (str, str) to float
        Candidate pair → mean score of the ends that scored it.
    score_matrix_ : ndarray, shape (n, n)
        ``scores_`` as a symmetric matrix over ``zones_`` (0 where unscored).
    days_used_ : list of datetime.date
        Days complete in every measured zone (a neighbourhood may use more: only its own
        zones must be complete).
    days_dropped_ : list of (datetime.date, str)
    conduction_pairs_ : set of frozenset
        Measured-zone pairs joined by a wall.
    skipped_ : dict of str to str
        Zones whose neighbourhood could not be scored, and why (e.g. fewer than 4
        complete days).
    candidates_ : list of (str, str)
    edges_ : list of ScoredEdge
    network_ : ThermalNetwork

    Examples
    --------
    >>> sid = NeighbourhoodStructureIdentifier().fit(df, network)  # doctest: +SKIP
    >>> [(e.a, e.b, round(e.score, 2)) for e in sid.edges_]  # doctest: +SKIP
    """

    method = "sin"

    def __init__(self, level: float = 0.05, adjust: str = "sidak", rule: str = "paper",
                 s_min: float = 0.25, allow_parallel: bool = False):
        self.level = level
        self.adjust = adjust
        self.rule = rule
        self.s_min = s_min
        self.allow_parallel = allow_parallel

    def fit(self, data, network) -> "NeighbourhoodStructureIdentifier":
        """Score every zone's neighbourhood and select convection edges.

        Parameters
        ----------
        data : pandas.DataFrame
            ``T:<zone>`` temperatures [°C] on a regular DatetimeIndex.
        network : ThermalNetwork
            Measured zones, walls and (through its spec) air path lengths.

        Returns
        -------
        self

        Raises
        ------
        DataError
            Fewer than 2 measured zones, or no neighbourhood could be scored.
        """
        from .selection import select_edges
        if not 0 < self.level < 1:
            raise ValueError(f"level must be in (0, 1), found {self.level!r}")
        if self.rule not in ("paper", "threshold"):
            raise ValueError(f"rule must be 'paper' or 'threshold', found {self.rule!r}")
        zones = list(network.measured_zones)
        if len(zones) < 2:
            raise DataError(f"structure identification needs >= 2 measured zones, "
                            f"{network.spec.source} has {zones}")
        meas = set(zones)
        walls = {z: set() for z in zones}
        for e in network.conduction_edges:
            if e.a in meas and e.b in meas:
                walls[e.a].add(e.b)
                walls[e.b].add(e.a)
        dist = {}
        for x in network.spec.distances:
            if x.a in meas and x.b in meas and (self.allow_parallel or x.b not in walls[x.a]):
                dist[tuple(sorted((x.a, x.b)))] = x.d
        if self.allow_parallel:
            for a in zones:
                for b in walls[a]:
                    p = tuple(sorted((a, b)))
                    if p not in dist:
                        d, _ = network.spec.air_path_length(*p)   # a door beside the wall
                        if d is not None:
                            dist[p] = d
        partners = {z: [] for z in zones}
        for (a, b), d in dist.items():
            partners[a].append((d, b))
            partners[b].append((d, a))
        self.zones_, self.neighbourhoods_, self.skipped_ = zones, {}, {}
        da = day_array(data, zones)
        self.days_used_, self.days_dropped_ = da.days, da.dropped
        self.conduction_pairs_ = {frozenset((a, b)) for a in zones for b in walls[a]}
        zone_scores = {}
        for z in zones:
            cand = [b for _, b in sorted(partners[z])]
            # the nearest candidate, then the wall neighbours (they drive T_z through its
            # walls: conditioning on them matters more than scoring the farthest
            # candidates when few days trim the neighbourhood), then the other candidates
            order = cand[:1] + sorted(walls[z] - set(cand)) + cand[1:]
            if not cand:
                continue
            try:
                sc = neighbourhood_scores(data, z, order, level=self.level, adjust=self.adjust,
                                          trim=True)
            except DataError as exc:
                self.skipped_[z] = str(exc)
                continue
            self.neighbourhoods_[z] = [z] + list(sc)
            for b, v in sc.items():
                p = tuple(sorted((z, b)))
                if p in dist:
                    zone_scores.setdefault(p, {})[z] = v
        if not zone_scores:
            raise DataError("neighbourhood SIN: no zone's neighbourhood could be scored ("
                            + "; ".join(f"{z}: {m}" for z, m in list(self.skipped_.items())[:3])
                            + ")")
        self.zone_scores_ = zone_scores
        self.scores_ = {p: float(np.mean(list(v.values()))) for p, v in zone_scores.items()}
        idx = {z: i for i, z in enumerate(zones)}
        M = np.zeros((len(zones), len(zones)))
        for (a, b), v in self.scores_.items():
            M[idx[a], idx[b]] = M[idx[b], idx[a]] = v
        self.score_matrix_ = M
        self.candidates_ = list(self.scores_)
        self.edges_ = select_edges(self.scores_, {p: dist[p] for p in self.scores_}, zones,
                                   self.rule, self.s_min)
        self.network_ = network.with_convection([(e.a, e.b, e.d) for e in self.edges_])
        return self

    # indices of two measured zones into ``score_matrix_``: as the building's identifier
    pair_index = StructureIdentifier.pair_index
