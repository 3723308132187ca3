"""The operating point of an export: given values first, then the data's typical values,
then stated defaults, each with its source (:func:`export_point`, :class:`ExportPoint`)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..errors import ModelError
from ..model import OperatingPoint, ThermalModel

__all__ = ["ExportPoint", "supply_zones", "typical_inputs", "export_point"]


_ON = 1e-6          # [kg/s]: a box "supplies air" above this flow (logged zeros are 0.0 or tiny)
_DEFAULTS = {"ms": 0.0, "Ts": 20.0, "T": 10.0, "Q": 0.0}   # ThermalNetwork.input_vector's
_UNITS = {"ms": "kg/s", "Ts": "°C", "T": "°C", "Q": "W"}


def supply_zones(meas) -> list[str]:
    """Zones whose data have supply air: an ``ms:`` column with some flow above zero, or a
    directed flow of the spec into the zone (:class:`thermctl.spec.Flow`).

    Parameters
    ----------
    meas : thermctl.data.Measurements
    """
    f = meas.frame
    fed = {fl.dst for fl in meas.spec.flows}
    return [z for z in meas.spec.zone_names
            if z in fed or (f"ms:{z}" in f
                            and np.nanmax(np.r_[f[f"ms:{z}"].to_numpy(), 0.0]) > _ON)]


def typical_inputs(meas, network) -> dict:
    """Typical values of the inputs in the data, as ``operating_point`` keyword arguments.

    ``ms``: mean flow of each zone with supply air over the samples where it supplies air
    (what the box does when it is on; the all-time mean would mix in the nights off);
    ``Ts``: the flow-weighted mean supply temperature over the same samples (so that
    ``ms·cp·(Ts − T)`` is the mean supply heat); ``T``: mean of each boundary temperature.
    Zones without supply air get ``ms = 0``.

    Parameters
    ----------
    meas : thermctl.data.Measurements
    network : ThermalNetwork

    Returns
    -------
    dict
        ``{"ms": {zone: kg/s}, "Ts": {zone: °C}, "T": {node: °C}}`` (zones without supply air
        are left out of ``Ts``).
    """
    U = meas.inputs(network)
    sl = network.input_slices()
    ms, Ts, Tb = U[:, sl["ms"]], U[:, sl["Ts"]], U[:, sl["T"]]
    fed = set(supply_zones(meas))
    out = {"ms": {}, "Ts": {}, "T": {}}
    for i, z in enumerate(network.zones):
        on = np.isfinite(ms[:, i]) & np.isfinite(Ts[:, i]) & (ms[:, i] > _ON)
        if z not in fed or not on.any():
            out["ms"][z] = 0.0
            continue
        out["ms"][z] = float(ms[on, i].mean())
        out["Ts"][z] = float((ms[on, i] * Ts[on, i]).sum() / ms[on, i].sum())
    for j, b in enumerate(network.boundary):
        v = Tb[:, j][np.isfinite(Tb[:, j])]
        if v.size == 0:
            raise ModelError(f"T:{b}: no finite sample in {meas.source}; give --op T[{b}]=VALUE")
        out["T"][b] = float(v.mean())
    return out


DESCRIBE_NODES = 12
"""Above this many nodes an input's values are summarised on the terminal
(:meth:`ExportPoint.describe`)."""


@dataclass
class ExportPoint:
    """An operating point together with where every value came from.

    Attributes
    ----------
    op : OperatingPoint
        State (steady state for the inputs) and inputs.
    values : dict
        ``{"ms": {zone: kg/s}, "Ts": {zone: °C}, "T": {node: °C}, "Q": {zone: W}}``.
    sources : dict
        Same keys: ``"given"``, ``"data"`` (typical value in the data) or ``"default"``
        per node.
    supply_zones : list of str or None
        Zones with supply air, ``None`` if unknown (no data).
    notes : list of str
        What a user must know (a zero flow used because nothing was known, a flow given
        to a zone without supply air...).
    state_names : list of str
    data : str or None
        The data file the typical values came from.
    """

    op: OperatingPoint
    values: dict
    sources: dict
    supply_zones: list | None
    notes: list = field(default_factory=list)
    state_names: list = field(default_factory=list)
    data: str | None = None

    def to_dict(self) -> dict:
        """Plain data, for the exported files."""
        return {"inputs": self.values, "source": self.sources, "units": _UNITS,
                "supply_zones": self.supply_zones, "data": self.data, "notes": list(self.notes),
                "state": dict(zip(self.state_names, np.asarray(self.op.x, float).tolist())),
                "meaning": "the linear model is in deviations from this point: x - x_op, u - u_op; "
                           "the state is the steady state for these inputs (disturbances 0)"}

    def describe(self, max_nodes: int = DESCRIBE_NODES) -> str:
        """A few lines for the terminal: every value with its source, then the notes.

        An input with more than ``max_nodes`` nodes is summarised (range, median, how many
        values came from each source, the first few): a 490-zone building's full listing
        was four lines of 5 000 characters each. Every value is in :meth:`to_dict`.
        """
        tag = {"given": "given", "data": "data", "default": "DEFAULT"}  # loud: nothing known
        lines = ["operating point (the linear model is in deviations from it):"]
        for name in ("ms", "Ts", "Q", "T"):
            vals, srcs = self.values[name], self.sources[name]
            # Q = 0 is the natural point (unmeasured gains are the disturbances): no alarm
            src = {n: "default" if name == "Q" else tag[srcs[n]] for n in vals}
            parts = [f"{n}={v:.4g} ({src[n]})" for n, v in vals.items()]
            if len(parts) > max_nodes:
                v = np.fromiter(vals.values(), float)
                count = Counter(src.values())           # in first-seen order
                parts = ([f"{len(v)} nodes, {v.min():.4g} to {v.max():.4g} (median "
                          f"{np.median(v):.4g}), "
                          + ", ".join(f"{k} {t}" for t, k in count.items())]
                         + parts[:3] + ["… (every value in the exported file)"])
            lines.append(f"  {name} [{_UNITS[name]}]: " + ", ".join(parts))
        lines += [f"  NOTE: {n}" for n in self.notes]
        return "\n".join(lines)


def export_point(model: ThermalModel, given: dict | None = None, data=None) -> ExportPoint:
    """The operating point of an export: given values first, then the data's, then defaults.

    Parameters
    ----------
    model : ThermalModel
    given : dict, optional
        ``operating_point`` keyword arguments (``thermctl.cli.export.parse_operating_point``
        makes them from ``--op``): each of ``ms``, ``Ts``, ``T``, ``Q`` a number or a mapping
        by node (``"*"``: every other node). A single number for ``ms`` goes to the zones with
        supply air only, when they are known from ``data``.
    data : thermctl.data.Measurements, optional
        Measurements of this building: typical values for what is not given
        (:func:`typical_inputs`) and which zones have supply air. Without data, what is
        not given takes the defaults ms = 0 kg/s, Ts = 20 °C, T = 10 °C, Q = 0 W, and
        :attr:`ExportPoint.notes` says so.

    Returns
    -------
    ExportPoint
    """
    net = model.network
    given = dict(given or {})
    bad = sorted(set(given) - set(_DEFAULTS))
    if bad:
        raise ModelError(f"operating point: unknown input(s) {bad}; expected ms, Ts, T, Q")
    typical = typical_inputs(data, net) if data is not None else None
    fed = supply_zones(data) if data is not None else None
    notes = []
    values, sources = {}, {}
    for name in ("ms", "Ts", "T", "Q"):
        nodes = list(net.boundary if name == "T" else net.zones)
        g = given.get(name)
        if g is not None and not isinstance(g, Mapping):
            g = {"*": float(g)}
        g = dict(g or {})
        unknown = sorted(set(g) - set(nodes) - {"*"})
        if unknown:
            raise ModelError(f"{name}: unknown node(s) {unknown}; expected one of {nodes}")
        vals, srcs = {}, {}
        for n in nodes:
            if n in g:
                vals[n], srcs[n] = float(g[n]), "given"
            elif "*" in g and not (name == "ms" and fed is not None and n not in fed):
                vals[n], srcs[n] = float(g["*"]), "given"
            elif typical is not None and n in typical.get(name, {}):
                vals[n], srcs[n] = typical[name][n], "data"
            elif name == "Ts" and typical is not None and typical["Ts"]:
                # a zone without supply air: its Ts only matters if a flow is given to it
                vals[n], srcs[n] = float(np.mean(list(typical["Ts"].values()))), "data"
            else:
                vals[n], srcs[n] = _DEFAULTS[name], "default"
        values[name], sources[name] = vals, srcs
    ms_given = given.get("ms")
    ms_all = ms_given.get("*") if isinstance(ms_given, Mapping) else ms_given   # for every zone
    if fed is not None:
        extra = [z for z in net.zones if z not in fed and values["ms"][z] > 0]
        if extra:
            notes.append(f"supply flow given to zone(s) {extra}, which have no supply air in "
                         f"{data.source}")
        if ms_all is not None:
            notes.append(f"ms={float(ms_all):g} kg/s applied to the zones with supply air "
                         f"{fed} only")
        if not fed:
            notes.append(f"no zone has supply air in {data.source}: ms = 0 kg/s everywhere, so "
                         "the supply inputs (ms, Ts) have no effect in the linear model")
    elif all(s == "default" for s in sources["ms"].values()):
        notes.append("ms = 0 kg/s in every zone, because neither --op ms=... nor data (--data) "
                     "was given: the Ts columns of B are all zero (a linear model at zero flow "
                     "cannot act through the supply temperature). Give --data DATA (typical "
                     "flow of the zones with supply air) or --op ms[zone]=VALUE")
    elif ms_all is not None:
        notes.append(f"ms={float(ms_all):g} kg/s applied to every zone: which zones have supply "
                     "air is unknown without --data (use --op ms[zone]=VALUE for some zones only)")
    defaulted = [name for name in ("Ts", "T") if "default" in sources[name].values()]
    if defaulted and data is None:
        notes.append("defaults used for " + ", ".join(
            f"{name} = {_DEFAULTS[name]:g} {_UNITS[name]}" for name in defaulted)
            + " where not given (no data)")
    op = model.operating_point(**values)
    return ExportPoint(op=op, values=values, sources=sources, supply_zones=fed, notes=notes,
                       state_names=list(net.state_names),
                       data=None if data is None else str(data.source))
