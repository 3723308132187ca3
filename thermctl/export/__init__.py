"""What an MPC designer needs beside the linear model: its operating point, the disturbance
inputs and the identified state estimator.

* :func:`export_point` chooses the operating point explicitly: per-node values given by
  the user, else the data's typical values (supply flow of the zones that have supply air,
  supply temperature, boundary temperatures), else stated defaults — and says which is
  which (:meth:`ExportPoint.describe`, :meth:`ExportPoint.to_dict`).
* :func:`disturbances` turns the identified solar apertures and time-of-day gains of
  ``model.meta["greybox"]`` into extra inputs of the state equation.
* :func:`kalman_filter` builds the grey-box model's noise model (the one the likelihood
  was computed with): the state augmented with one random-walk heat gain per measured
  zone, continuous process-noise intensity, sensor-noise variance and, at a sample time,
  the stationary Kalman gain.

``thermctl export`` writes all three into the exported files. For control toolboxes:

* :func:`casadi_functions` gives CasADi functions ``f(x, u)`` and ``F(x, u, dt)`` with the
  parameters built in;

* :func:`to_do_mpc` builds do-mpc models (bilinear, and linear at the operating point);
* :func:`load_statespace` reads an exported state space as an :class:`OperatingStateSpace`,
  a ``control.StateSpace`` that prints its operating point; :func:`input_signals` makes a
  ``forced_response`` input array from signals given by name.

Examples
--------
>>> model = load_model("out/model.json")                                  # doctest: +SKIP
>>> point = export_point(model, {"T": {"*": 21.0, "outside": -5.0}}, data=meas)  # doctest: +SKIP
>>> print(point.describe())                                               # doctest: +SKIP
>>> sys, dist = statespace(model, point.op, dt=600.0)                     # doctest: +SKIP
>>> kf = kalman_filter(model, point.op, dt=600.0)                         # doctest: +SKIP

One module a job: :mod:`.point` (the operating point), :mod:`.disturbances`,
:mod:`.statespace` (python-control), :mod:`.kalman` (the identified filter),
:mod:`.casadi_model` (CasADi functions) and :mod:`.dompc` (do-mpc); this package re-exports
their public names, so ``from thermctl.export import X`` is the way to use them.
"""

from __future__ import annotations

from .casadi_model import casadi_functions
from .disturbances import Disturbances, disturbances
from .dompc import DoMpcModels, to_do_mpc
from .kalman import KalmanFilter, kalman_filter
from .point import ExportPoint, export_point, supply_zones, typical_inputs
from .statespace import OperatingStateSpace, input_signals, load_statespace, statespace

__all__ = ["ExportPoint", "Disturbances", "KalmanFilter", "supply_zones", "typical_inputs",
           "export_point", "disturbances", "statespace", "kalman_filter", "DoMpcModels",
           "to_do_mpc", "OperatingStateSpace", "load_statespace", "input_signals",
           "casadi_functions"]
