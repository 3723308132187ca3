"""Convection edges from pair scores: the paper's best-partner rule and a threshold rule."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

__all__ = ["ScoredEdge", "select_edges"]


@dataclass(frozen=True)
class ScoredEdge:
    """A selected convection edge.

    Attributes
    ----------
    a, b : str
        The two zones (alphabetical order, as in :class:`~thermctl.network.ThermalNetwork`).
    score : float
        Fraction of time-of-day indices whose concentration graph has the edge [-].
    d : float
        Air path length between the zones [m].
    """

    a: str
    b: str
    score: float
    d: float


def select_edges(scores: dict, distances: dict, zones: Sequence[str], rule: str = "paper",
                 s_min: float = 0.25, max_per_zone: int | None = None) -> list[ScoredEdge]:
    """Choose convection edges from pair scores.

    Parameters
    ----------
    scores : dict of (str, str) to float
        Score of every candidate pair (only candidates: pairs allowed to become edges).
    distances : dict of (str, str) to float
        Air path length [m] of every candidate pair (same keys).
    zones : sequence of str
        The measured zones (order used by the paper rule).
    rule : {"paper", "threshold"}
        ``paper``: every zone gets its highest-scoring partner (ties: shorter path,
        then name); a zone whose best score is 0 gets none. ``threshold``: every pair
        with score >= ``s_min``, strongest first, at most ``max_per_zone`` per zone.
    s_min : float
        Score threshold of the ``threshold`` rule, in [0, 1].
    max_per_zone : int, optional
        Limit of the ``threshold`` rule.

    Returns
    -------
    list of ScoredEdge
        Sorted by decreasing score.
    """
    def key(pair):  # best first: high score, short path, names
        return (-scores[pair], distances[pair], pair)

    chosen = set()
    if rule == "paper":
        best = {}
        for p in scores:
            if scores[p] > 0:
                for z in p:
                    if z not in best or key(p) < key(best[z]):
                        best[z] = p
        chosen = set(best.values())
    elif rule == "threshold":
        count = dict.fromkeys(zones, 0)
        for p in sorted(scores, key=key):
            if scores[p] < s_min or scores[p] <= 0:
                break
            if max_per_zone is not None and (count[p[0]] >= max_per_zone
                                             or count[p[1]] >= max_per_zone):
                continue
            chosen.add(p)
            count[p[0]] += 1
            count[p[1]] += 1
    else:
        raise ValueError(f"rule must be 'paper' or 'threshold', found {rule!r}")
    return [ScoredEdge(*sorted(p), scores[p], distances[p]) for p in sorted(chosen, key=key)]
