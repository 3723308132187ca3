"""Parameters of the stochastic grey-box model: names, units, transforms, bounds.

The optimiser works in ``eta``: ``eta = log(value)`` for positive parameters (R̄_v, τ0,
noise intensities), ``eta = value / scale`` for the linear ones (solar apertures, gain
levels), so that every coordinate is O(1–10) and the Hessian is well scaled.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ...errors import EstimationError

__all__ = ["Param", "ParamLayout", "GROUP_UNITS"]

GROUP_UNITS = {
    "rbar_v": "K/(W m)",
    "tau0": "s/m",
    "sigma_v": "K",
    "sigma_q": "W s^0.5",
    "sigma_phi": "W/s^0.5",
    "sigma_e": "K",
    "sigma_b": "K",
    "tau_b": "s",
    "tau_e": "s",
    "aperture": "m²",
    "gain": "W",
    "cap_factor": "-",
    "ua_factor": "-",
    "nu": "-",
    "sigma_g": "W",
    "tau_g": "s",
    "loading": "W",
    "tau_c": "s",
    "occ_ratio": "-",
    "loop_gain": "W/K",
}
"""Unit of each parameter group."""


@dataclass
class Param:
    """One parameter.

    Attributes
    ----------
    name : str
        ``rbar_v``, ``rbar_v[air:a-b]``, ``tau0``, ``sigma_v``, ``sigma_q[zone]``,
        ``sigma_phi``, ``aperture[zone,solar]``, ``gain[zone,basis]``...
    group : str
        One of :data:`GROUP_UNITS`.
    log : bool
        Optimised as ``log(value)`` (else as ``value / scale``).
    init, lower, upper : float
        Start value and bounds, in natural units.
    scale : float
        For linear parameters, ``eta = value / scale``.
    target : tuple
        Where it acts (edge index, zone index, ...), for the model builder.
    fixed : bool
        Held at ``init``.
    """

    name: str
    group: str
    log: bool
    init: float
    lower: float
    upper: float
    scale: float = 1.0
    target: tuple = ()
    fixed: bool = False

    @property
    def unit(self) -> str:
        return GROUP_UNITS[self.group]

    def to_eta(self, value: float) -> float:
        return float(np.log(value)) if self.log else float(value) / self.scale

    def from_eta(self, eta: float) -> float:
        return float(np.exp(eta)) if self.log else float(eta) * self.scale


@dataclass
class ParamLayout:
    """The ordered parameter vector.

    Attributes
    ----------
    params : list of Param
    """

    params: list = field(default_factory=list)

    def __len__(self):
        return len(self.params)

    def __iter__(self):
        return iter(self.params)

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.params]

    def index(self, name: str) -> int:
        for i, p in enumerate(self.params):
            if p.name == name:
                return i
        raise EstimationError(f"no parameter named {name!r}; parameters are {self.names}")

    def group(self, group: str) -> list[int]:
        """Indices of the parameters of one group."""
        return [i for i, p in enumerate(self.params) if p.group == group]

    def add(self, p: Param) -> int:
        if p.name in self.names:
            raise EstimationError(f"parameter {p.name!r} defined twice")
        if not (p.lower <= p.init <= p.upper):
            raise EstimationError(f"{p.name}: start value {p.init:g} [{p.unit}] outside its "
                                  f"bounds [{p.lower:g}, {p.upper:g}]")
        self.params.append(p)
        return len(self.params) - 1

    def eta0(self) -> np.ndarray:
        return np.array([p.to_eta(p.init) for p in self.params])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds in ``eta`` (equal for fixed parameters, at their start value)."""
        lo = np.array([p.to_eta(p.init) if p.fixed else p.to_eta(p.lower) for p in self.params])
        hi = np.array([p.to_eta(p.init) if p.fixed else p.to_eta(p.upper) for p in self.params])
        return lo, hi

    def free(self) -> np.ndarray:
        return np.array([not p.fixed for p in self.params], dtype=bool)

    def values(self, eta) -> dict:
        """Natural values keyed by name."""
        return {p.name: p.from_eta(e) for p, e in zip(self.params, np.asarray(eta, float))}

    def eta_from(self, values: dict, eta=None) -> np.ndarray:
        """``eta`` with the given natural values set (others from ``eta`` or the start)."""
        out = self.eta0() if eta is None else np.array(eta, dtype=float)
        for name, v in values.items():
            i = self.index(name)
            out[i] = self.params[i].to_eta(v)
        return out

    def with_fixed(self, names, values: dict | None = None) -> "ParamLayout":
        """A copy with these parameters fixed (at ``values[name]`` or their start)."""
        values = values or {}
        names = set(names)
        unknown = names - set(self.names)
        if unknown:
            raise EstimationError(f"cannot fix unknown parameter(s) {sorted(unknown)}; "
                                  f"parameters are {self.names}")
        out = []
        for p in self.params:
            if p.name in names:
                init = values.get(p.name, p.init)
                p = replace(p, fixed=True, init=float(np.clip(init, p.lower, p.upper)))
            out.append(p)
        return ParamLayout(out)

    def _on_bounds(self, eta, rtol: float):
        """``(param, "lower" | "upper")`` of every free parameter within ``rtol`` (relative
        in eta-range) of a bound."""
        lo, hi = self.bounds()
        eta = np.asarray(eta, dtype=float)
        for i, p in enumerate(self.params):
            if p.fixed:
                continue
            span = max(hi[i] - lo[i], 1e-12)
            if eta[i] - lo[i] <= rtol * span:
                yield p, "lower"
            elif hi[i] - eta[i] <= rtol * span:
                yield p, "upper"

    def at_bounds(self, eta, rtol: float = 1e-3) -> list[str]:
        """Free parameters within ``rtol`` (relative in eta-range) of a bound, in words."""
        return [f"{p.name} at its {side} bound {p.lower if side == 'lower' else p.upper:g} "
                f"[{p.unit}]" for p, side in self._on_bounds(eta, rtol)]

    def at_bound_names(self, eta, rtol: float = 1e-3) -> set[str]:
        """Names of the free parameters :meth:`at_bounds` lists."""
        return {p.name for p, _ in self._on_bounds(eta, rtol)}
