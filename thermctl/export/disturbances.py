"""The disturbance inputs of an identified model: solar apertures and time-of-day gains of
``model.meta["greybox"]`` as extra inputs of the state equation (:func:`disturbances`)."""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..errors import ModelError
from ..model import ThermalModel

__all__ = ["Disturbances", "disturbances", "greybox_params"]


@dataclass
class Disturbances:
    """Disturbance inputs ``d`` of the identified model: ``xdot = ... + E d``.

    Attributes
    ----------
    names : list of str
        ``solar[<column>]`` (irradiance of a ``solar:`` data column [W/m²]) and
        ``gain[<basis>]`` (a time-of-day signal of the identified gains [-]: ``const`` is
        1, ``occupied`` is 1 in occupied hours, ``cos1``/``sin1``... are
        ``cos(2πk·hour/24)``...).
    E : ndarray, shape (n_states, n_d)
        Input matrix [K/s per unit of the input]: aperture [m²] or gain [W] over the zone's
        capacitance.
    heat : dict
        ``{input name: {zone: W per unit}}``: aperture [m²] or gain level [W].
    units : list of str
    """

    names: list
    E: np.ndarray
    heat: dict
    units: list

    def to_dict(self) -> dict:
        return {"names": self.names, "units": self.units, "heat_per_unit": self.heat,
                "meaning": "xdot += E d; zone heat = sum over d of heat_per_unit · d [W]"}


_PARAM_RE = re.compile(r"^(aperture|gain)\[([^,\]]+),([^\]]+)\]$")


def greybox_params(model) -> dict:
    return dict((model.meta.get("greybox") or {}).get("params") or {})


def disturbances(model: ThermalModel) -> Disturbances:
    """The solar and gain inputs identified with the grey-box criterion (none otherwise).

    Parameters
    ----------
    model : ThermalModel
        With ``meta["greybox"]["params"]`` holding ``aperture[zone,column]`` [m²] and
        ``gain[zone,basis]`` [W] (what ``thermctl identify`` stores).
    """
    net = model.network
    zi = {z: i for i, z in enumerate(net.zones)}
    cz = 1.0 / np.asarray(model.sym.inv_cz, float)
    heat = {}
    for name, value in greybox_params(model).items():
        m = _PARAM_RE.match(name)
        if not m:
            continue
        kind, zone, sig = m.groups()
        if zone not in zi:
            raise ModelError(f"model.json meta greybox.params: {name} names zone {zone!r}, which "
                             f"is not a zone of the model ({net.zones})")
        key = f"{'solar' if kind == 'aperture' else 'gain'}[{sig}]"
        heat.setdefault(key, {})[zone] = float(value)
    names = sorted(heat, key=lambda k: (not k.startswith("solar"), k))
    E = np.zeros((net.n_states, len(names)))
    for j, k in enumerate(names):
        for z, v in heat[k].items():
            E[zi[z], j] = v / cz[zi[z]]
    units = ["W/m²" if k.startswith("solar") else "-" for k in names]
    return Disturbances(names, E, heat, units)
