"""The result of a reduction, and its file format.

File format (``.npz``, read with ``numpy.load(path, allow_pickle=False)``)
--------------------------------------------------------------------------
One NumPy archive; every entry is a plain array, nothing is pickled:

``A, B, C, D, dt``
    The reduced ``StateSpace`` at the design operating point, in deviation variables
    (``y - y_op = C (x_r - x_op) + D (u - u_op)``); ``dt`` is 0 (continuous) or the
    sample time [s].
``op_x, op_u``
    Design operating point of the *full* model: state [°C] and inputs (``ms`` [kg/s],
    ``Ts`` [°C], ``T`` [°C], ``Q`` [W]).
``x_op``
    Reduced state at the design point (absolute [°C] for network reductions, zeros for
    balanced ones).
``hsv, input_scale, output_scale``
    Hankel singular values of the scaled full system (empty if not computed) and the
    scales used [unit of each input per unit] / [K per unit].
``to_x, from_x``
    Deviation maps between full and reduced states (empty if not stored).
``net_cap, net_K, net_G, net_lift_x, net_lift_b, net_restrict``
    The bilinear :class:`~thermctl.reduce.ReducedNetwork` (structured, kron, lumped only).
``meta``
    A JSON string: ``format`` (``"thermctl-reduced"``), ``version``, ``method``, ``name``,
    ``state_names``, ``input_names``, ``output_names``, ``full_state_names``, ``zones``,
    ``boundary``, ``measured``, ``cp``, ``full_order``, ``error_bound``, ``elapsed``, ``info``.

:func:`load_reduction` restores a :class:`Reduction` whose ``sys`` has the same matrices
and signal names.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import control as ct
import numpy as np

from ..errors import ModelError
from ..model import OperatingPoint, zoh
from .network import ReducedNetwork

__all__ = ["Reduction", "load_reduction", "FORMAT", "FORMAT_VERSION"]

FORMAT = "thermctl-reduced"
FORMAT_VERSION = 1


@dataclass
class Reduction:
    """A reduced model and what is known about its error.

    Attributes
    ----------
    method : str
        ``"balanced"`` (singular perturbation, DC-matching), ``"truncate"`` (balanced
        truncation), ``"structured"``, ``"kron"`` or ``"lumped"``.
    sys : control.StateSpace
        Reduced model linearized at the design point (continuous, or discrete if the full
        system given was), deviation variables,
        named signals (inputs ``ms[z]``, ``Ts[z]``, ``T[b]``, ``Q[z]``; outputs ``T[z]``).
    op : OperatingPoint
        Design operating point of the full model.
    x_op : ndarray, shape (order,)
        Reduced state at ``op`` [°C] (zeros for balanced reductions, which are deviation
        models only).
    full_order : int
    full_state_names : list of str
    hsv : ndarray or None
        Hankel singular values of the scaled full system (descending).
    error_bound : float or None
        A-priori bound on the H∞ norm of the scaled error system ``2 Σ_{i>r} σ_i`` [K per
        scaled input unit]; None for methods that have none.
    input_scale : ndarray, shape (n_inputs,)
        Typical size of each input used to weigh the channels [kg/s, K, K, W].
    output_scale : ndarray, shape (n_outputs,)
        [K]
    to_x, from_x : ndarray or None
        ``x - op.x ≈ to_x @ (x_r - x_op)`` and ``x_r - x_op = from_x @ (x - op.x)``.
    network : ReducedNetwork or None
        The bilinear reduced network (valid at every supply flow) for ``structured``,
        ``kron`` and ``lumped``.
    elapsed : float
        Time to reduce [s].
    info : dict
        Method details (e.g. design flows, number of edge modes).
    """

    method: str
    sys: ct.StateSpace
    op: OperatingPoint
    x_op: np.ndarray
    full_order: int
    full_state_names: list
    hsv: np.ndarray | None = None
    error_bound: float | None = None
    input_scale: np.ndarray | None = None
    output_scale: np.ndarray | None = None
    to_x: np.ndarray | None = None
    from_x: np.ndarray | None = None
    network: ReducedNetwork | None = None
    elapsed: float = 0.0
    info: dict = field(default_factory=dict)

    @property
    def order(self) -> int:
        """Number of states of the reduced model."""
        return self.sys.nstates

    @property
    def state_names(self) -> list[str]:
        return list(self.sys.state_labels)

    def operating_point(self, x=None, **inputs) -> OperatingPoint:
        """A reduced-model operating point (network reductions only).

        See :meth:`ReducedNetwork.operating_point`.
        """
        if self.network is None:
            raise ModelError(f"a {self.method!r} reduction is a linear model at its design point "
                             "only; use method='structured' for a model valid at every flow")
        return self.network.operating_point(x=x, **inputs)

    def to_statespace(self, op: OperatingPoint | None = None, dt: float | None = None):
        """The reduced ``StateSpace``: at the design point, or relinearized at ``op``.

        Parameters
        ----------
        op : OperatingPoint, optional
            Reduced-model operating point from :meth:`operating_point` (network
            reductions only). Default: the design point.
        dt : float, optional
            Sample time [s]: exact ZOH discretization.
        """
        if op is not None:
            if self.network is None:
                raise ModelError(f"a {self.method!r} reduction cannot be relinearized; "
                                 "it holds at its design point")
            return self.network.to_statespace(op, dt=dt, name=self.sys.name)
        if dt is None or (self.sys.dt and dt == self.sys.dt):
            return self.sys
        if self.sys.dt:
            raise ModelError(f"this reduced model is discrete (dt = {self.sys.dt} s); reduce the "
                             f"continuous model to discretize at dt = {dt} s")
        if not dt > 0:
            raise ModelError(f"dt must be > 0 [s], found {dt}")
        Phi, Gamma = zoh(self.sys.A, dt)
        return ct.ss(Phi, Gamma @ self.sys.B, self.sys.C, self.sys.D, dt=dt,
                     states=self.state_names, inputs=list(self.sys.input_labels),
                     outputs=list(self.sys.output_labels), name=self.sys.name)

    # ---- file format -------------------------------------------------------
    def save(self, path) -> Path:
        """Write the reduction to ``path`` (``.npz``; the format is in this module's docstring)."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(path.suffix + ".npz") if path.suffix else path.with_suffix(".npz")
        net = self.network
        empty = np.zeros((0,))
        meta = {
            "format": FORMAT, "version": FORMAT_VERSION, "method": self.method,
            "name": self.sys.name, "state_names": self.state_names,
            "input_names": list(self.sys.input_labels), "output_names": list(self.sys.output_labels),
            "full_state_names": list(self.full_state_names), "full_order": int(self.full_order),
            "error_bound": self.error_bound, "elapsed": float(self.elapsed), "info": self.info,
            "zones": None if net is None else list(net.zones),
            "boundary": None if net is None else list(net.boundary),
            "cp": None if net is None else float(net.cp),
            "measured": None if net is None else net.measured,
        }
        arrays = dict(A=self.sys.A, B=self.sys.B, C=self.sys.C, D=self.sys.D,
                      dt=np.float64(self.sys.dt or 0.0),
                      op_x=self.op.x, op_u=self.op.u, x_op=self.x_op,
                      hsv=empty if self.hsv is None else self.hsv,
                      input_scale=empty if self.input_scale is None else self.input_scale,
                      output_scale=empty if self.output_scale is None else self.output_scale,
                      to_x=empty if self.to_x is None else self.to_x,
                      from_x=empty if self.from_x is None else self.from_x,
                      meta=np.array(json.dumps(meta, default=_json_default)))
        if net is not None:
            arrays.update(net_cap=net.cap, net_K=net.K, net_G=net.G,
                          net_lift_x=empty if net.lift_x is None else net.lift_x,
                          net_lift_b=empty if net.lift_b is None else net.lift_b,
                          net_restrict=empty if net.restrict is None else net.restrict)
        with open(path, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def load(cls, path) -> "Reduction":
        """Read a file written by :meth:`save`."""
        return load_reduction(path)


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"cannot store {type(obj).__name__} in the reduction metadata")


def _opt(arr):
    return None if arr.size == 0 else arr


def load_reduction(path) -> Reduction:
    """Load a reduced model written by :meth:`Reduction.save`.

    Parameters
    ----------
    path : str or Path
        ``.npz`` file.

    Returns
    -------
    Reduction

    Raises
    ------
    ModelError
        If the file is missing, not a thermctl reduction, or of a newer format version.

    Examples
    --------
    >>> red = load_reduction("office-structured.npz")  # doctest: +SKIP
    >>> sys = red.to_statespace(dt=300.0)  # doctest: +SKIP
    """
    path = Path(path)
    if not path.is_file():
        raise ModelError(f"{path}: reduced model file not found")
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (ValueError, OSError) as exc:
        raise ModelError(f"{path}: not a NumPy .npz archive ({exc})") from None
    if "meta" not in data:
        raise ModelError(f"{path}: no 'meta' entry; not a thermctl reduced model")
    meta = json.loads(str(data["meta"]))
    if meta.get("format") != FORMAT:
        raise ModelError(f"{path}: format is {meta.get('format')!r}, expected {FORMAT!r}")
    if meta.get("version", 0) > FORMAT_VERSION:
        raise ModelError(f"{path}: format version {meta['version']} is newer than this thermctl "
                         f"reads ({FORMAT_VERSION}); upgrade thermctl")
    dt = float(data["dt"]) if "dt" in data else 0.0
    sys = ct.ss(data["A"], data["B"], data["C"], data["D"], dt if dt > 0 else 0, states=meta["state_names"],
                inputs=meta["input_names"], outputs=meta["output_names"], name=meta["name"])
    net = None
    if "net_cap" in data:
        net = ReducedNetwork(meta["state_names"], meta["zones"], meta["boundary"], data["net_cap"],
                             data["net_K"], data["net_G"], meta["cp"], meta["name"],
                             _opt(data["net_lift_x"]), _opt(data["net_lift_b"]),
                             _opt(data["net_restrict"]), meta["full_state_names"],
                             meta.get("measured"))
    return Reduction(method=meta["method"], sys=sys, op=OperatingPoint(x=data["op_x"], u=data["op_u"]),
                     x_op=data["x_op"], full_order=meta["full_order"],
                     full_state_names=meta["full_state_names"], hsv=_opt(data["hsv"]),
                     error_bound=meta["error_bound"], input_scale=_opt(data["input_scale"]),
                     output_scale=_opt(data["output_scale"]), to_x=_opt(data["to_x"]),
                     from_x=_opt(data["from_x"]), network=net, elapsed=meta["elapsed"],
                     info=meta["info"])
