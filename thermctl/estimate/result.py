"""What every fit reports, whatever its criterion: the common base of the result types.

:class:`~thermctl.estimate.simulation.result.EstimationResult` (the paper's simulation
criterion) and :class:`~thermctl.estimate.likelihood.estimator.LikelihoodResult` (the Kalman
likelihood) both derive from :class:`FitResult`, so a report or a pipeline reads
``success``, ``message``, ``iterations``, ``wall_time``, ``active_bounds``,
``param_names``/``param_values`` and ``summary()`` the same way from either.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

__all__ = ["FitResult"]


class FitResult(ABC):
    """Common base of the estimation results.

    Not a dataclass itself, on purpose: a dataclass base puts its fields first in the
    subclass's ``__init__``, which would reorder the positional arguments of
    ``LikelihoodResult(criterion, value, ...)``. The subclasses are dataclasses that
    declare the attributes below as their own fields, each in its existing place.

    Attributes
    ----------
    success : bool
        The optimiser converged and the criterion is finite. False: do not use the values
        without looking.
    message : str
        The optimiser's message (why it stopped) [-].
    iterations : int
        Optimiser iterations.
    wall_time : float
        Duration of the whole fit [s].
    active_bounds : list of str
        Bounds the estimate lies on: there the criterion, not the building, chose the value.
    param_names : list of str
        Names of the estimated parameters (:class:`thermctl.model.ConvectionParameters`
        spells the convection ones).
    """

    success: bool
    message: str
    iterations: int
    wall_time: float
    active_bounds: list
    param_names: list

    @property
    @abstractmethod
    def param_values(self) -> dict:
        """``{name: value}`` of the estimated parameters in natural units (R̄_v [K/(W m)],
        C_v [J/K], noise parameters in their own units)."""

    @property
    def on_bound(self) -> bool:
        """Whether any estimate lies on a bound of its search range."""
        return bool(self.active_bounds)

    @abstractmethod
    def summary(self) -> str:
        """The fit in a few lines for a log or a terminal: values, criterion, convergence
        (flagged when it failed) and the bounds reached."""
