r"""Estimation of the convection parameters (R̄_v, C_v) of a thermal network.

One data window, one set of bounds, two criteria:

* :class:`EstimationData` — a block of data on a regular grid (from arrays, a table or
  :class:`thermctl.data.Measurements`), read by both criteria;
* :mod:`.bounds` — the paper's ranges of R̄_v and of the convective time constant;
* :class:`FitResult` — what every fit reports (success, message, iterations, wall time,
  bounds reached, parameter names and values, ``summary()``), the base of both results;
* :mod:`.simulation` — the paper's prediction cost J (eq. 3) minimised by the paper's grid
  and by a CasADi/IPOPT multiple-shooting NLP (:class:`SimulationEstimator`);
* :mod:`.likelihood` — beyond the paper: the Kalman-filter likelihood of the network
  augmented with unmeasured random-walk gains, solar apertures and noise, and the k-step
  prediction criterion (:class:`LikelihoodEstimator`).

Both estimators follow one convention, ``Estimator(network, **options).fit(data)``
returning the estimator, with learned values ending in ``_``.

Examples
--------
>>> from thermctl.estimate import EstimationData, LikelihoodEstimator  # doctest: +SKIP
>>> data = EstimationData.from_frame(meas, net)                        # doctest: +SKIP
>>> est = LikelihoodEstimator(net).fit(data)                           # doctest: +SKIP
>>> est.params_["rbar_v"]                                              # doctest: +SKIP
"""

from .bounds import RBAR_BOUNDS, T_MAX, T_MIN
from .data import EstimationData, as_estimation_data
from .likelihood import LikelihoodEstimator, LikelihoodOptions
from .result import FitResult
from .simulation import SimulationEstimator

__all__ = ["EstimationData", "as_estimation_data", "RBAR_BOUNDS", "T_MIN", "T_MAX", "FitResult",
           "LikelihoodEstimator", "LikelihoodOptions", "SimulationEstimator"]
