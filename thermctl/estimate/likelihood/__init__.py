"""Stochastic grey-box identification: Kalman-filter likelihood with unmeasured gains.

Beyond the paper (docs/identification.md): the network model is
augmented with per-zone random-walk heat gains, solar apertures and noise, and fitted by
maximum likelihood through a stationary continuous–discrete Kalman filter built in
CasADi (exact derivatives), or by k-step-ahead prediction error from filtered states.

Modules: :mod:`.kalman` (discretisation, Riccati, filters), :mod:`.problem` (the model
and its CasADi criteria), :mod:`.estimator` (:class:`LikelihoodEstimator`), :mod:`.kstep`
(k-step validation), :mod:`.uncertainty` (intervals and identifiability verdicts),
:mod:`.selection` (model-based convection-edge selection).
"""

from .estimator import LikelihoodEstimator, LikelihoodResult
from .kstep import KStepResult, kstep_errors
from .problem import LikelihoodOptions, LikelihoodProblem
from .uncertainty import IdentifiabilityReport, ParameterInterval, identifiability, wald_intervals

__all__ = ["LikelihoodEstimator", "LikelihoodResult", "LikelihoodOptions",
           "LikelihoodProblem", "KStepResult", "kstep_errors", "IdentifiabilityReport",
           "ParameterInterval", "identifiability", "wald_intervals"]
