r"""How good is a reduced model: step responses, frequency responses, flow sweeps.

Measures (note §6):

- **step error** at times :math:`t` (default 1, 6 and 24 h): the largest absolute error
  of the scaled step-response matrix over its largest entry (inputs per kW, per K, per
  0.1 kg/s; see :class:`StepError`), also per input group. Steps are computed exactly,
  :math:`Y(t) = C A^{-1}(e^{At}-I)B + D` (in the eigenbasis for the stiff full model).
- **H∞ error** of the scaled error system :math:`W_y^{-1}(G-G_r)W_u` on a frequency grid
  that includes :math:`\omega = 0` (where balanced truncation's error peaks).
- **flow sweep**: both at other supply flows than the design one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from ..errors import ModelError
from ..model import OperatingPoint, ThermalModel, zoh
from ._lti import diagonalized, prepare
from .balanced import BalancedContext, _scales
from .network import linearize
from .result import Reduction
from .preserving import StructuredContext, kron, lumped

__all__ = ["DEFAULT_TIMES", "default_omegas", "StepError", "Reference", "step_matrices", "step_responses",
           "frequency_responses", "flow_sweep", "error_vs_order"]

DEFAULT_TIMES = (3600.0, 6 * 3600.0, 24 * 3600.0)
"""Step-response times of the error table: 1, 6 and 24 h [s]."""


def default_omegas(n: int = 40) -> np.ndarray:
    """``0`` and ``n`` log-spaced frequencies from 1e-7 to 1e-1 [rad/s]."""
    return np.concatenate([[0.0], np.logspace(-7, -1, n)])


def _lti(sys, capacitances=None):
    if sys.dt:
        raise ModelError("error metrics need a continuous system (dt = 0); reduce the "
                         "continuous model and discretize afterwards")
    s = None if capacitances is None else np.sqrt(np.asarray(capacitances, dtype=float))
    return prepare(sys.A, sys.B, sys.C, sys.D, 0.0, s=s, state_names=list(sys.state_labels))


def step_matrices(sys, times=DEFAULT_TIMES, capacitances=None) -> np.ndarray:
    """Exact step-response matrices ``Y(t)`` of a stable continuous system.

    Parameters
    ----------
    sys : control.StateSpace
    times : sequence of float
        [s]
    capacitances : array_like, optional
        State capacitances [J/K] of an RC model (detected when omitted).

    Returns
    -------
    ndarray, shape (len(times), n_outputs, n_inputs)
        [output unit per input unit]
    """
    lti = _lti(sys, capacitances)
    return _steps(lti, times)


def step_responses(sys, times, inputs=None, outputs=None, capacitances=None) -> np.ndarray:
    """Exact step responses of selected channels on a time grid.

    Parameters
    ----------
    sys : control.StateSpace
        Stable, continuous.
    times : array_like
        [s]
    inputs, outputs : list of str, optional
        Signal names (default: all).
    capacitances : array_like, optional
        State capacitances [J/K] of an RC model (detected when omitted).

    Returns
    -------
    ndarray, shape (len(times), len(outputs), len(inputs))
    """
    ins = list(sys.input_labels) if inputs is None else list(inputs)
    outs = list(sys.output_labels) if outputs is None else list(outputs)
    for what, names, have in (("input", ins, sys.input_labels), ("output", outs, sys.output_labels)):
        unknown = [n for n in names if n not in have]
        if unknown:
            raise ModelError(f"unknown {what}(s) {unknown}; the system has {list(have)[:6]} ...")
    lti = _lti(sys, capacitances)
    ii = [list(sys.input_labels).index(n) for n in ins]
    oo = [list(sys.output_labels).index(n) for n in outs]
    sub = replace(lti, B=lti.B[:, ii], C=lti.C[oo], D=lti.D[np.ix_(oo, ii)])
    return _steps(sub, np.asarray(times, dtype=float))


def _steps(lti, times):
    out = []
    diag = None if lti.modal else diagonalized(lti)
    for t in times:
        if lti.modal:
            lam = lti.lam
            g = np.expm1(lam * t) / lam   # ∫₀ᵗ e^{λτ} dτ, stable for stiff λ
            out.append(lti.C @ (g[:, None] * lti.B) + lti.D)
        elif diag is not None:
            lam, CV, VB = diag
            g = np.expm1(lam * t) / lam
            out.append(np.real(CV @ (g[:, None] * VB)) + lti.D)
        else:
            _, Gamma = zoh(lti.A, t)
            out.append(lti.C @ Gamma @ lti.B + lti.D)
    return np.array(out)


def frequency_responses(sys, omegas, capacitances=None) -> np.ndarray:
    """``G(jω)`` on a frequency grid [rad/s], shape ``(len(omegas), n_outputs, n_inputs)``."""
    return _freq(_lti(sys, capacitances), omegas)


def _freq(lti, omegas):
    out = []
    n = lti.n
    diag = None if lti.modal else diagonalized(lti)
    for w in omegas:
        if lti.modal:
            d = 1.0 / (1j * w - lti.lam)
            out.append((lti.C * d[None, :]) @ lti.B + lti.D)
        elif diag is not None:
            lam, CV, VB = diag
            out.append((CV * (1.0 / (1j * w - lam))[None, :]) @ VB + lti.D)
        else:
            out.append(lti.C @ np.linalg.solve(1j * w * np.eye(n) - lti.A, lti.B) + lti.D)
    return np.array(out)


@dataclass
class StepError:
    r"""Step-response error of a reduced model.

    Attributes
    ----------
    times : ndarray
        [s]
    rel : ndarray, shape (len(times),)
        The headline error: largest absolute error of the *scaled* step-response matrix
        over its largest entry, :math:`\max|W_y^{-1}(Y-Y_r)W_u| / \max|W_y^{-1}YW_u|` [-].
        With the default scales the entries are K per kW, per K and per 0.1 kg/s, so
        the error is measured against the biggest response a typical input causes.
    groups : list of str
        Input groups (``ms``, ``Ts``, ``T``, ``Q``) with a non-zero response.
    group_rel : ndarray, shape (len(times), len(groups))
        Per group, relative to the group's own largest response at that time [-] (harsh
        where a group barely responds yet, e.g. outside temperature behind heavy walls at 1 h).
    group_abs : ndarray, shape (len(times), len(groups))
        Per group, ``max|Y - Y_r|`` [K per input unit].
    """

    times: np.ndarray
    rel: np.ndarray
    groups: list
    group_rel: np.ndarray
    group_abs: np.ndarray

    def at(self, t: float) -> float:
        """Headline relative error at time ``t`` [s] (must be one of ``times``)."""
        k = np.flatnonzero(np.isclose(self.times, t))
        if not k.size:
            raise ModelError(f"no step error at t = {t} s; times are {self.times.tolist()}")
        return float(self.rel[k[0]])


class Reference:
    """The full model's responses, computed once and compared with any reduced model.

    Parameters
    ----------
    sys : control.StateSpace
        Full continuous model (e.g. ``linearize(model, op)``).
    times : sequence of float
        Step-response times [s].
    omegas : array_like, optional
        Frequency grid [rad/s]; default :func:`default_omegas`.
    capacitances : array_like, optional
        State capacitances [J/K] (fast eigenbasis path; detected when omitted).
    input_scale, output_scale : array_like, optional
        Scales of the H∞ error (see :func:`~thermctl.reduce.hankel_singular_values`).
    """

    def __init__(self, sys, times=DEFAULT_TIMES, omegas=None, *, capacitances=None,
                 input_scale=None, output_scale=None):
        self.sys = sys
        self.times = np.asarray(times, dtype=float)
        self.omegas = default_omegas() if omegas is None else np.asarray(omegas, dtype=float)
        self.su, self.sy = _scales(sys, input_scale, output_scale)
        self._lti = _lti(sys, capacitances)
        self._Y = None
        self._G = None
        names = list(sys.input_labels)
        self.group_of = [str(n).split("[", 1)[0] for n in names]

    @property
    def steps(self) -> np.ndarray:
        if self._Y is None:
            self._Y = _steps(self._lti, self.times)
        return self._Y

    @property
    def freq(self) -> np.ndarray:
        if self._G is None:
            self._G = _freq(self._lti, self.omegas)
        return self._G

    def _check(self, red_sys):
        if list(red_sys.input_labels) != list(self.sys.input_labels) or \
                list(red_sys.output_labels) != list(self.sys.output_labels):
            raise ModelError("the reduced model's inputs/outputs differ from the full model's "
                             f"({list(red_sys.input_labels)[:3]}... vs {list(self.sys.input_labels)[:3]}...)")

    def step_error(self, red_sys) -> StepError:
        """Relative step-response error of ``red_sys`` (same signals) at :attr:`times`."""
        self._check(red_sys)
        Y = self.steps
        dY = Y - _steps(_lti(red_sys), self.times)
        w = self.su[None, None, :] / self.sy[None, :, None]
        rel = np.abs(dY * w).max(axis=(1, 2)) / np.abs(Y * w).max(axis=(1, 2))
        groups, grel, gabs = [], [], []
        for g in dict.fromkeys(self.group_of):
            cols = [j for j, h in enumerate(self.group_of) if h == g]
            big = np.abs(Y[:, :, cols]).max(axis=(1, 2))
            if not np.all(big > 0):
                continue
            err = np.abs(dY[:, :, cols]).max(axis=(1, 2))
            groups.append(g)
            grel.append(err / big)
            gabs.append(err)
        return StepError(self.times, rel, groups, np.array(grel).T, np.array(gabs).T)

    def hinf_error(self, red_sys) -> float:
        """Largest singular value of the scaled error ``W_y⁻¹(G - G_r)W_u`` on the grid."""
        self._check(red_sys)
        E = self.freq - _freq(_lti(red_sys), self.omegas)
        E = E * self.su[None, None, :] / self.sy[None, :, None]
        return float(max(np.linalg.norm(Ek, 2) for Ek in E))

    def hinf_norm(self) -> float:
        """Largest singular value of the scaled full model on the grid (for relative errors)."""
        G = self.freq * self.su[None, None, :] / self.sy[None, :, None]
        return float(max(np.linalg.norm(Gk, 2) for Gk in G))


def _with_flow(model, op, ms):
    u = np.asarray(op.u, dtype=float).copy()
    sl = model.network.input_slices()["ms"]
    u[sl] = np.broadcast_to(np.asarray(ms, dtype=float), (model.network.n_zones,))
    return u


def flow_sweep(model: ThermalModel, reductions, flows, times=DEFAULT_TIMES) -> pd.DataFrame:
    """Step error of reduced models at supply flows away from their design point.

    At each flow the full model is relinearized at its steady state for the design
    point's other inputs. Network reductions (structured, kron, lumped) are relinearized
    too (they are bilinear, like the full model); balanced ones are used as they are —
    a linear model frozen at its design flow is what an MPC would run.

    Parameters
    ----------
    model : ThermalModel
    reductions : Reduction or list of Reduction
        All designed at the same operating point.
    flows : sequence of float or array_like
        Uniform supply flows [kg/s] (or per-zone vectors).
    times : sequence of float
        [s]

    Returns
    -------
    pandas.DataFrame
        Columns ``method``, ``order``, ``flow`` [kg/s, mean over zones], one column of
        worst relative step error per time (``err_1h``, ...).
    """
    if isinstance(reductions, Reduction):
        reductions = [reductions]
    rows = []
    cap = model.capacitances()
    refs = {}
    for ms in flows:
        for red in reductions:
            u = _with_flow(model, red.op, ms)
            key = u.tobytes()
            if key not in refs:
                op = OperatingPoint(x=model.steady_state(u), u=u)
                refs[key] = Reference(linearize(model, op), times, capacitances=cap)
            if red.network is not None:
                rnet = red.network
                rsys = rnet.to_statespace(OperatingPoint(x=rnet.steady_state(u), u=u))
            else:
                rsys = red.sys
            err = refs[key].step_error(rsys)
            row = {"method": red.method, "order": red.order, "flow": float(np.mean(ms))}
            row.update({_tlabel(t): e for t, e in zip(times, err.rel)})
            rows.append(row)
    return pd.DataFrame(rows)


def _tlabel(t: float) -> str:
    return f"err_{t / 3600:g}h"


def error_vs_order(model: ThermalModel, op: OperatingPoint, method: str, orders,
                   times=DEFAULT_TIMES, *, reference: Reference | None = None,
                   hinf: bool = False, design_ms=None) -> pd.DataFrame:
    """Step (and optionally H∞) error of one reduction method over a list of orders.

    The expensive part (balancing, edge basis, full responses) is done once.

    Parameters
    ----------
    model : ThermalModel
    op : OperatingPoint
    method : {"balanced", "truncate", "structured", "kron", "lumped"}
        ``kron`` and ``lumped`` have one order each; ``orders`` is ignored for them.
    orders : sequence of int
        Total numbers of states.
    times : sequence of float
        [s]
    reference : Reference, optional
        Reused full-model responses (must match ``linearize(model, op)`` and ``times``).
    hinf : bool
        Also compute the scaled H∞ error on the frequency grid (slow for large models).
    design_ms : list, optional
        Extra design flows for ``structured`` (see :func:`structured`).

    Returns
    -------
    pandas.DataFrame
        Columns ``method``, ``order``, ``states_per_zone``, ``err_1h`` ..., ``bound``
        (a-priori, balanced only), ``hinf`` (if requested).
    """
    nz = model.network.n_zones
    ref = reference or Reference(linearize(model, op), times, capacitances=model.capacitances())
    if method in ("balanced", "truncate"):
        ctx = BalancedContext.build(model, op)
        mode = "matchdc" if method == "balanced" else "truncate"
        make = lambda r: ctx.reduction(min(r, ctx.bal.n_min), mode)  # noqa: E731
    elif method == "structured":
        sctx = StructuredContext(model, op, design_ms)
        make = lambda r: sctx.reduction(r - nz)  # noqa: E731
    elif method in ("kron", "lumped"):
        red = (kron if method == "kron" else lumped)(model, op)
        orders = [red.order]
        make = lambda r: red  # noqa: E731
    else:
        raise ModelError(f"method must be one of balanced, truncate, structured, kron, lumped; "
                         f"found {method!r}")
    rows = []
    for r in orders:
        red = make(int(r))
        err = ref.step_error(red.sys)
        row = {"method": method, "order": red.order, "states_per_zone": red.order / nz}
        row.update({_tlabel(t): e for t, e in zip(ref.times, err.rel)})
        row["bound"] = red.error_bound
        if hinf:
            row["hinf"] = ref.hinf_error(red.sys)
        rows.append(row)
    return pd.DataFrame(rows)
