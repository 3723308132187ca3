"""The python-control side: the linearized model with its disturbance inputs as a
``control.StateSpace`` (:func:`statespace`), an exported state space read back with its
operating point (:class:`OperatingStateSpace`, :func:`load_statespace`) and
``forced_response`` inputs by name (:func:`input_signals`)."""

from __future__ import annotations

from collections.abc import Mapping

import control as ct
import numpy as np

from ..errors import ModelError
from ..model import OperatingPoint, ThermalModel, zoh
from .disturbances import disturbances

__all__ = ["statespace", "OperatingStateSpace", "load_statespace", "input_signals"]


def statespace(model: ThermalModel, op: OperatingPoint, dt: float | None = None):
    """The linearized model with the disturbance inputs appended to its inputs.

    Parameters
    ----------
    model : ThermalModel
    op : OperatingPoint
    dt : float, optional
        Sample time [s]: exact ZOH discretisation (disturbances held over the step too).

    Returns
    -------
    sys : control.StateSpace
        Inputs ``ms[z]``, ``Ts[z]``, ``T[b]``, ``Q[z]`` then :attr:`Disturbances.names`.
    dist : Disturbances
    """
    net = model.network
    dist = disturbances(model)
    A, B = model.jacobians(op)
    B = np.hstack([B, dist.E])
    C = np.zeros((net.n_zones, net.n_states))
    C[np.arange(net.n_zones), np.arange(net.n_zones)] = 1.0
    D = np.zeros((net.n_zones, B.shape[1]))
    if dt is not None:
        if not dt > 0:
            raise ModelError(f"dt must be > 0 [s], found {dt}")
        A, B = zoh(A, dt, B)
    sys = ct.ss(A, B, C, D, dt=0 if dt is None else dt, states=net.state_names,
                inputs=net.input_names + dist.names, outputs=net.output_names,
                name=net.spec.name)
    return sys, dist


_UNIT_OF = {"ms": "kg/s", "Ts": "°C", "T": "°C", "Q": "W", "solar": "W/m²", "gain": "-"}


class OperatingStateSpace(ct.StateSpace):
    """A ``control.StateSpace`` that knows the operating point it is linearized at.

    It is a ``StateSpace`` (``ct.step_response(sys)``, ``sys["T[r240]", "ms[r240]"]``...)
    in deviations from the operating point; ``print(sys)`` shows the matrices and then
    the operating point. Made by :func:`load_statespace`.

    Attributes
    ----------
    x_op : ndarray, shape (nstates,)
        State at the operating point [°C].
    u_op : ndarray, shape (ninputs,)
        Inputs at the operating point [kg/s, °C, W; disturbance inputs 0].
    info : dict
        What ``thermctl export`` stored: the operating point with the source of every
        value, the disturbance inputs.
    kalman : dict
        The identified Kalman filter's arrays, if exported.
    """

    def __init__(self, sys, x_op=None, u_op=None, info=None, kalman=None):
        super().__init__(sys)
        self.x_op = np.zeros(sys.nstates) if x_op is None else np.asarray(x_op, float)
        u = np.zeros(sys.ninputs)
        if u_op is not None:
            u[:len(u_op)] = np.asarray(u_op, float)     # disturbance inputs: 0 at the point
        self.u_op = u
        self.info = dict(info or {})
        self.kalman = dict(kalman or {})

    def operating_point(self) -> dict:
        """``{signal name: value}`` of the inputs and states at the operating point."""
        return {**dict(zip(self.input_labels, self.u_op.tolist())),
                **dict(zip(self.state_labels, self.x_op.tolist()))}

    def describe_operating_point(self) -> str:
        """The operating point as lines: inputs with unit and source, then zone temperatures."""
        src = (self.info.get("operating_point") or {}).get("source", {})
        lines = ["operating point (the model is in deviations from it):"]
        for name, v in zip(self.input_labels, self.u_op):
            kind, _, node = name.partition("[")
            node = node.rstrip("]")
            how = (src.get(kind) or {}).get(node)
            lines.append(f"  {name} = {v:.6g} {_UNIT_OF.get(kind, '')}"
                         + (f" ({how})" if how else ""))
        zones = [(n, v) for n, v in zip(self.state_labels, self.x_op) if n.startswith("T[")]
        lines.append("  state: " + ", ".join(f"{n} = {v:.4g} °C" for n, v in zones)
                     + f" (+ {self.nstates - len(zones)} wall and air-path states)")
        return "\n".join(lines)

    def __str__(self):
        return super().__str__() + "\n\n" + self.describe_operating_point()


def load_statespace(path) -> OperatingStateSpace:
    """Load a state-space file of ``thermctl export --statespace`` as a named system.

    Parameters
    ----------
    path : str or Path
        ``.npz`` written by ``thermctl export`` (or :func:`thermctl.io.save_statespace`).

    Returns
    -------
    OperatingStateSpace
        Signal names ``T[z]``, ``ms[z]``..., ``dt`` (0: continuous, else the sample time
        [s]), the operating point (printed with the system), the stored info and Kalman
        filter.

    Examples
    --------
    >>> sys = thermctl.load_statespace("ss.npz")                      # doctest: +SKIP
    >>> print(sys)                   # matrices, then the operating point  # doctest: +SKIP
    >>> ct.step_response(sys["T[r240]", "ms[r240]"], 6 * 3600)       # doctest: +SKIP
    """
    from ..io import load_statespace as _load

    sys, extras = _load(path)
    return OperatingStateSpace(sys, extras.get("x_op"), extras.get("u_op"),
                               extras.get("info"), extras.get("kalman"))


def input_signals(sys, timepts, values: Mapping) -> np.ndarray:
    """An input array for ``control.forced_response`` from signals given by name.

    Parameters
    ----------
    sys : control.StateSpace
    timepts : array_like, shape (nt,)
        Time points [s].
    values : mapping
        ``{input name: number or array of shape (nt,)}`` in the system's units (for an
        exported model: deviations from the operating point); inputs not named are 0.

    Returns
    -------
    ndarray, shape (ninputs, nt)

    Examples
    --------
    >>> T = np.arange(0, 86400, 600.0)                                    # doctest: +SKIP
    >>> U = input_signals(sys, T, {"ms[r240]": 0.02, "T[outside]": -3.0})   # doctest: +SKIP
    >>> ct.forced_response(sys, T, U).to_pandas()                         # doctest: +SKIP
    """
    t = np.asarray(timepts, float)
    names = list(sys.input_labels)
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise ModelError(f"input_signals: unknown input(s) {unknown}; {sys.name} has {names}")
    U = np.zeros((len(names), t.size))
    for name, v in values.items():
        v = np.asarray(v, float)
        if v.ndim and v.shape != t.shape:
            raise ModelError(f"input_signals: {name} has shape {v.shape}, expected {t.shape} "
                             "(one value per time point) or a number")
        U[names.index(name)] = v
    return U
