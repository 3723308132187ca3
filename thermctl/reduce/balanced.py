r"""Balanced truncation and singular-perturbation (DC-matching) reduction.

For the scaled system :math:`G_s = W_y^{-1} G W_u` with Hankel singular values
:math:`\sigma_1 \ge \dots \ge \sigma_n`, both reductions to order :math:`r` keep stability
and satisfy (Glover 1984; Liu & Anderson 1989)

.. math::

    \| W_y^{-1} (G - G_r) W_u \|_\infty \le 2 \sum_{i > r} \sigma_i .

Balanced truncation is exact at :math:`\omega = \infty` and wrong at DC, where an RC
network's error is largest; singular perturbation ("matchdc", the default) residualizes
the discarded states and is exact at DC.

The computation runs in the symmetric coordinates of the RC network when the state
matrix is symmetrisable (always for thermctl's models), else through scipy's
Bartels–Stewart solvers. python-control's ``balanced_reduction`` (slycot ``ab09nd``)
is an independent cross-check in the tests; it returns neither names nor the
transformation, and silently caps the order.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import control as ct
import numpy as np

from ..errors import ModelError
from ..model import OperatingPoint, ThermalModel
from ._lti import balance, prepare
from .network import linearize
from .result import Reduction

__all__ = ["INPUT_SCALES", "default_scales", "hankel_singular_values", "balanced_reduction"]

log = logging.getLogger(__name__)

INPUT_SCALES = {"ms": 0.1, "Ts": 1.0, "T": 1.0, "Q": 1000.0}
"""Typical size of each input group: supply flow 0.1 [kg/s], temperatures 1 [K], heat 1 [kW].

With raw SI units the Hankel singular values rank units, not physics (note §2: the
``ms`` channel's first HSV was 10⁴ times the ``Q`` channel's in W).
"""


def default_scales(input_names, output_names):
    """Input and output scales from signal names (:data:`INPUT_SCALES`; outputs 1 K).

    Signals whose prefix (text before ``[``) is unknown get scale 1.

    Returns
    -------
    input_scale : ndarray, shape (n_inputs,)
    output_scale : ndarray, shape (n_outputs,)
    """
    su = np.array([INPUT_SCALES.get(str(n).split("[", 1)[0], 1.0) for n in input_names])
    return su, np.ones(len(output_names))


def _linear_system(source, op, capacitances):
    """``(sys, s, op, state_names)`` from a ThermalModel + op or a StateSpace."""
    if isinstance(source, ThermalModel):
        if op is None:
            raise ModelError("reducing a ThermalModel needs an operating point: pass "
                             "op=model.operating_point(ms=..., Ts=..., T=...)")
        sys = linearize(source, op)
        s = np.sqrt(source.capacitances())
        return sys, s, op, list(source.network.state_names)
    if not isinstance(source, ct.StateSpace):
        raise ModelError(f"expected a ThermalModel or a control.StateSpace, found {type(source).__name__}")
    sys = source
    if sys.nstates == 0:
        raise ModelError("the system has no states; nothing to reduce")
    s = None
    if capacitances is not None:
        cap = np.asarray(capacitances, dtype=float)
        if cap.shape != (sys.nstates,) or np.any(~(cap > 0)):
            raise ModelError(f"capacitances: expected {sys.nstates} positive values [J/K], "
                             f"found shape {cap.shape}")
        s = np.sqrt(cap)
    if op is None:
        op = OperatingPoint(x=np.zeros(sys.nstates), u=np.zeros(sys.ninputs))
    return sys, s, op, list(sys.state_labels)


def _scales(sys, input_scale, output_scale):
    su, sy = default_scales(sys.input_labels, sys.output_labels)
    for what, given, default in (("input_scale", input_scale, su), ("output_scale", output_scale, sy)):
        if given is None:
            continue
        given = np.broadcast_to(np.asarray(given, dtype=float), default.shape).copy() \
            if np.ndim(given) == 0 else np.asarray(given, dtype=float)
        if given.shape != default.shape or np.any(~(given > 0)):
            raise ModelError(f"{what}: expected {default.size} positive values, found {given!r}")
        if what == "input_scale":
            su = given
        else:
            sy = given
    return su, sy


def _balanced(sys, s, su, sy, names):
    lti = prepare(sys.A, sys.B * su, sys.C / sy[:, None], sys.D * su / sy[:, None],
                  dt=float(sys.dt or 0.0), s=s, state_names=names)
    return balance(lti)


def hankel_singular_values(source, op=None, *, input_scale=None, output_scale=None,
                           capacitances=None) -> np.ndarray:
    """Hankel singular values of the scaled system, descending.

    Parameters
    ----------
    source : ThermalModel or control.StateSpace
        A stable system (continuous or discrete).
    op : OperatingPoint, optional
        Required for a ThermalModel.
    input_scale : array_like, shape (n_inputs,), optional
        Typical size of each input [its unit]; default :func:`default_scales`.
    output_scale : array_like, shape (n_outputs,), optional
        [K]; default 1.
    capacitances : array_like, shape (n_states,), optional
        For a StateSpace of an RC network: the state capacitances [J/K] (detected from
        the state matrix when omitted).

    Returns
    -------
    ndarray, shape (n_states,)
        Values below about 1e-11 of the largest (1e-6 above 1000 states, where a faster
        eigenvalue method is used) are not resolved; beyond the rank of the Gramian
        factors they are 0.

    Examples
    --------
    >>> hsv = hankel_singular_values(model, model.operating_point(ms=0.1, Ts=14, T=5))  # doctest: +SKIP
    """
    ctx = BalancedContext.build(source, op, capacitances, input_scale, output_scale)
    return _padded(ctx.bal.hsv, ctx.sys.nstates)


def _padded(hsv, n):
    out = np.zeros(n)
    out[:len(hsv)] = hsv
    return out


def balanced_reduction(source, op=None, order: int | None = None, tol: float | None = None,
                       method: str = "matchdc", *, input_scale=None, output_scale=None,
                       capacitances=None, name: str | None = None) -> Reduction:
    r"""Balanced reduction of a linearized model, with its a-priori H∞ error bound.

    Parameters
    ----------
    source : ThermalModel or control.StateSpace
        The full model (with ``op``) or a stable linear system, continuous or discrete.
    op : OperatingPoint, optional
        Design operating point (required for a ThermalModel).
    order : int, optional
        Number of states to keep, ``1 ≤ order``; capped at the numerically minimal
        order (logged). Give ``order`` or ``tol``.
    tol : float, optional
        Largest admissible bound :math:`2\sum_{i>r}\sigma_i` on the H∞ norm of the scaled
        error [K per scaled input unit, e.g. K per kW of heat or per K of outside
        temperature]; the smallest order meeting it is used.
    method : {"matchdc", "truncate"}
        ``matchdc``: singular perturbation, exact DC gain (the default, what an MPC needs).
        ``truncate``: balanced truncation.
    input_scale, output_scale : array_like, optional
        See :func:`hankel_singular_values`.
    capacitances : array_like, optional
        See :func:`hankel_singular_values`.
    name : str, optional
        Name of the reduced system.

    Returns
    -------
    Reduction
        ``sys`` has the full model's input and output names and states ``xr[k]``;
        ``error_bound`` is the a-priori bound.

    Examples
    --------
    >>> op = model.operating_point(ms=0.1, Ts=14, T=5)  # doctest: +SKIP
    >>> red = balanced_reduction(model, op, tol=0.01)  # doctest: +SKIP
    >>> red.order, red.error_bound  # doctest: +SKIP
    """
    t0 = time.perf_counter()
    if method not in ("matchdc", "truncate"):
        raise ModelError(f"method must be 'matchdc' or 'truncate', found {method!r}")
    ctx = BalancedContext.build(source, op, capacitances, input_scale, output_scale)
    r = _choose_order(ctx.bal, order, tol, ctx.sys.nstates)
    return ctx.reduction(r, method, name=name, t0=t0)


@dataclass
class BalancedContext:
    """A balanced realization computed once, reducible to any order (used by the metrics)."""

    sys: ct.StateSpace
    op: OperatingPoint
    names: list
    su: np.ndarray
    sy: np.ndarray
    bal: object

    @classmethod
    def build(cls, source, op=None, capacitances=None, input_scale=None, output_scale=None):
        sys, s, op, names = _linear_system(source, op, capacitances)
        su, sy = _scales(sys, input_scale, output_scale)
        return cls(sys, op, names, su, sy, _balanced(sys, s, su, sy, names))

    def reduction(self, r: int, method: str = "matchdc", name=None, t0=None) -> Reduction:
        t0 = time.perf_counter() if t0 is None else t0
        sys, su, sy, bal = self.sys, self.su, self.sy, self.bal
        A, B, C, D, to_x, from_x = bal.reduce(r, method)
        B, C, D = B / su, C * sy[:, None], D * sy[:, None] / su
        label = "balanced" if method == "matchdc" else "truncate"
        rsys = ct.ss(A, B, C, D, dt=sys.dt, states=[f"xr[{k}]" for k in range(r)],
                     inputs=list(sys.input_labels), outputs=list(sys.output_labels),
                     name=name or f"{sys.name}-{label}{r}")
        hsv = _padded(bal.hsv, sys.nstates)
        bound = bal.bound(r)
        log.info("%s reduction: %d -> %d states, H-inf bound %.3g", label, sys.nstates, r, bound)
        return Reduction(method=label, sys=rsys, op=self.op, x_op=np.zeros(r),
                         full_order=sys.nstates, full_state_names=self.names, hsv=hsv,
                         error_bound=bound, input_scale=su, output_scale=sy, to_x=to_x,
                         from_x=from_x, elapsed=time.perf_counter() - t0,
                         info={"n_minimal": bal.n_min, "residualized": method == "matchdc"})


def _choose_order(bal, order, tol, n) -> int:
    if (order is None) == (tol is None):
        raise ModelError("give exactly one of order (number of states) or tol (error bound [K])")
    if tol is not None:
        if not (np.isfinite(tol) and tol > 0):
            raise ModelError(f"tol must be > 0 [K per scaled input unit], found {tol}")
        return bal.order_for(tol)
    if isinstance(order, bool) or int(order) != order or not 1 <= order <= n:
        raise ModelError(f"order must be an integer in [1, {n}] (the full model has {n} states), "
                         f"found {order!r}")
    order = int(order)
    if order > bal.n_min:
        log.warning("order %d capped at %d, the numerically minimal order (the remaining "
                    "Hankel singular values are not resolved)", order, bal.n_min)
        order = bal.n_min
    return order
