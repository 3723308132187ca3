r"""The paper's simulation criterion J for the convection edges (paper section III-B).

The paper's prediction cost (eq. 3),

.. math::

    J(\bar R_v, C_v) = \sum_{k=1}^{K_T} \sum_{i \in Z} (\hat T_i(k) - T_i(k))^2,

simulated from the first sample of a window (default 12 h) with the measured inputs,
is minimised over ``rbar_v`` [K/(W m)] and ``c_v`` [J/K] subject to
``t_min/alpha <= rbar_v·c_v <= t_max/alpha``.

* :class:`CostProblem` — window, zone subset, initial-state handling
  (``paper``, ``burn_in``, ``estimate``, ``given``), parameters and bounds; ``cost()``.
* :func:`grid_search` — the paper's exhaustive search, the reference.
* :func:`fit` / :class:`SimulationEstimator` — IPOPT: multiple shooting (default; nodes
  every hour, the problem's simulator between them), single shooting (the fast path), or
  a pure-CasADi Radau NLP (``casadi_radau``, inspectable).
* :class:`ExactSimulator` (exact ZOH, the reference) and :class:`RadauSimulator` (sparse,
  for large networks) compute J, its gradient and a Gauss–Newton Hessian.
* :func:`identifiability_report` — profiles of J and the log-space Hessian, in words.

Every callable that works for a while takes ``progress(stage, done, total)``.

Examples
--------
>>> from thermctl.estimate import EstimationData
>>> from thermctl.estimate.simulation import CostProblem, grid_search, fit
>>> data = EstimationData.from_frame(df, net)                      # doctest: +SKIP
>>> prob = CostProblem(net, data, initial_state="estimate")        # doctest: +SKIP
>>> grid = grid_search(prob)                                       # doctest: +SKIP
>>> res = fit(prob)                                                # doctest: +SKIP
>>> res.J <= grid.best_J                                           # doctest: +SKIP
True
"""

from .composite import CompositeCostProblem
from .fit import METHODS, SimulationEstimator, fit
from .grid import grid_search
from .identifiability import identifiability_report
from .nlp import IPOPT_DEFAULTS, CasadiMultipleShootingNLP, SingleShootingNLP
from .radau import RadauSimulator
from .shooting import MultipleShootingNLP
from .problem import INITIAL_STATES, CostProblem
from .result import EstimationResult, GridResult, ProfileReport, ParameterProfile
from .sim import CostEval, ExactSimulator, Simulator

__all__ = [
    "CostProblem", "CompositeCostProblem", "grid_search", "fit", "SimulationEstimator",
    "identifiability_report", "Simulator", "ExactSimulator", "RadauSimulator", "CostEval",
    "MultipleShootingNLP", "CasadiMultipleShootingNLP", "SingleShootingNLP",
    "EstimationResult", "GridResult", "ProfileReport", "ParameterProfile",
    "IPOPT_DEFAULTS", "INITIAL_STATES", "METHODS",
]
