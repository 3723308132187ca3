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
from .sin import sin_pvalues

__all__ = ["neighbourhood_scores"]


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
    good = np.linalg.cond(R) < 1e12
    if not good.any():
        raise DataError(f"local SIN of {zone}: the neighbourhood's temperatures are "
                        "collinear at every time of day")
    P = sin_pvalues(R[good], N, adjust)
    hits = (P[:, 0, 1:] <= level).sum(axis=0)
    # times of day without a usable graph count as times without an edge (as the paper)
    return {nb: float(h) / K for nb, h in zip(nodes[1:], hits)}
