r"""Structure identification: which zones exchange air (paper section III-A).

Each day is one sample of the zone temperatures at every time of day. For each
time-of-day index :math:`k = 0, \dots, K-1` (:math:`K = 86400\,\mathrm{s} / \Delta t`)
the :math:`N` days give a sample covariance :math:`S_k` of the :math:`n` measured
zone temperatures, and a concentration graph :math:`\hat G(k)`: an edge
:math:`i - j` when the partial correlation of zones :math:`i, j` given all others
is significantly non-zero. Conduction pairs (walls) are removed and every other
pair gets the score

.. math::

    s_{ij} = \frac{\#\{k : i - j \in \hat G(k)\}}{K}.

Two graph methods:

``sin``
    Drton & Perlman (2004), *Model selection for Gaussian concentration graphs*,
    Biometrika 91, 591-602: partial correlations
    :math:`\hat\rho_{ij} = -P_{ij}/\sqrt{P_{ii}P_{jj}}` with :math:`P = S^{-1}`, Fisher
    :math:`z_{ij} = \operatorname{atanh}(\hat\rho_{ij})\sqrt{N - n - 1}`, raw p-values
    :math:`2(1 - \Phi(|z_{ij}|))` and simultaneous p-values by Šidák,
    :math:`1 - (1 - p_{ij})^{E}` with :math:`E = n(n-1)/2`, or Holm's step-down.
    Needs :math:`N \ge n + 2` days.
``glasso``
    Graphical lasso on the per-time correlation matrix, with the scikit-learn
    objective (:func:`sklearn.covariance.graphical_lasso`: off-diagonal
    :math:`\ell_1` penalty), solved by ADMM vectorised over all time indices
    (scikit-learn's solver, called once per time index, is 10-100× slower here).
    The penalty is chosen by cross-validation over days by default, or set from the
    level (Banerjee et al. 2008), or given. Works for any :math:`N \ge 3`.

Selection rules: ``paper`` gives every measured zone its best-scoring partner;
``threshold`` keeps every pair with :math:`s_{ij} \ge s_{\min}`. Only pairs whose
air path length is known (spec ``distances``) can become convection edges.

Layout: :mod:`.sin` (partial correlations, SIN p-values), :mod:`.glasso` (batched ADMM
graphical lasso, level penalty, cross-validation), :mod:`.selection` (:class:`ScoredEdge`,
:func:`select_edges`), :mod:`.identifier` (:class:`StructureIdentifier`). The day × time
of day shaping is :func:`thermctl.data.day_array` (re-exported here).
"""

from ..data.days import DayArray, day_array
from .glasso import graphical_lasso_batch, level_penalty
from .identifier import StructureIdentifier
from .neighbourhood import NeighbourhoodStructureIdentifier, neighbourhood_scores
from .selection import ScoredEdge, select_edges
from .sin import partial_correlations, sin_pvalues

__all__ = ["DayArray", "NeighbourhoodStructureIdentifier", "ScoredEdge", "StructureIdentifier",
           "neighbourhood_scores", "day_array", "partial_correlations",
           "sin_pvalues", "graphical_lasso_batch", "level_penalty", "select_edges"]
