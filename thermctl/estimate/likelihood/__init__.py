"""Stochastic grey-box identification: Kalman-filter likelihood with unmeasured gains.

Beyond the paper (docs/identification.md): the network model is
augmented with per-zone random-walk heat gains, solar apertures and noise, and fitted by
maximum likelihood through a stationary continuous–discrete Kalman filter built in
CasADi (exact derivatives), or by k-step-ahead prediction error from filtered states.

Modules: :mod:`.kalman` (discretisation, Riccati, filters), :mod:`.problem` (the model
and its CasADi criteria), :mod:`.estimator` (:class:`GreyboxEstimator`), :mod:`.kstep`
(k-step validation), :mod:`.uncertainty` (intervals and identifiability verdicts),
:mod:`.selection` (model-based convection-edge selection).
"""

from .data import GreyboxData
from .estimator import GreyboxEstimator, GreyboxResult, as_greybox_data
from .kstep import KStepResult, kstep_errors
from .problem import GreyboxOptions, GreyboxProblem
from .uncertainty import IdentifiabilityReport, ParameterInterval, identifiability

__all__ = ["GreyboxData", "GreyboxEstimator", "GreyboxResult", "GreyboxOptions",
           "GreyboxProblem", "KStepResult", "kstep_errors", "IdentifiabilityReport",
           "ParameterInterval", "identifiability", "as_greybox_data"]
