"""Sensors, BAS export and files of the testbed: ``building.yaml``, ``data.csv``, ``truth.json``.

The data a BAS exports are not the plant's values: zone sensors have a constant offset
and noise, discharge-air sensors noise, flow stations a per-box calibration error and
noise, and the trend log rounds temperatures to 0.1 °F and flows to 1 CFM. Outdoors the
data hold the hourly weather-station values interpolated to the data step (as in the
paper). Missing samples come as runs (a sensor dropping out for a while) and as outages
of the whole export (every column of a row empty).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .. import __version__
from ..errors import DataError
from ..spec import RHO_AIR

__all__ = ["SensorNoise", "Truth", "load_truth", "CFM", "c_to_f", "f_to_c", "to_imperial",
           "write_data_csv", "bas_export", "punch_holes"]

CFM = 0.3048**3 / 60.0
"""One cubic foot per minute in m³/s."""


def c_to_f(t):
    """°C → °F."""
    return np.asarray(t, dtype=float) * 1.8 + 32.0


def f_to_c(t):
    """°F → °C."""
    return (np.asarray(t, dtype=float) - 32.0) / 1.8


@dataclass(frozen=True)
class SensorNoise:
    """Sensor and export imperfections. ``generate(noise=None)`` means perfect sensors.

    Attributes
    ----------
    T_sd : float
        White noise of zone and boundary temperature sensors [K].
    T_bias_sd : float
        Standard deviation of the constant offset of each zone sensor [K] (thermostats are
        typically within ±0.3 K).
    Ts_sd : float
        White noise of discharge air temperature sensors [K].
    flow_sd : float
        Relative white noise of flow readings [-].
    flow_gain_sd : float
        Standard deviation of the per-box flow calibration error [-] (the box delivers
        ``reading / gain``).
    quantum_F : float
        Rounding of exported temperatures [°F]; 0 for none.
    flow_quantum_cfm : float
        Rounding of exported flows [CFM]; 0 for none.
    solar_sd : float
        Relative noise of the pyranometer [-].
    """

    T_sd: float = 0.05
    T_bias_sd: float = 0.1
    Ts_sd: float = 0.1
    flow_sd: float = 0.02
    flow_gain_sd: float = 0.03
    quantum_F: float = 0.1
    flow_quantum_cfm: float = 1.0
    solar_sd: float = 0.03


@dataclass
class Truth:
    """Everything needed to score an identification of a testbed building.

    Attributes
    ----------
    edges : list of (str, str, float)
        True convection edges ``(a, b, d)``, ``d`` [m].
    rbar_v : float or list of float
        Convection resistance per unit distance [K/(W m)] (shared or one per edge).
    c_v : float or list of float
        Convection capacitance [J/K].
    alpha : float
        alpha of the spec's walls used for the convection bounds (median) [-].
    alphas : dict
        alpha of every wall [-].
    seed : int
    settings : dict
        Every generator setting (building, days, step, start, control step, HVAC, weather,
        occupancy, sensors, missing fraction, ...).
    details : dict
        Per-zone and per-node draws: zone capacitances, sensor offsets, flow calibration
        gains, VAV box sizes and set points, neighbouring spaces, occupants, and the
        products ``rbar_v·c_v`` [s/m] with the paper's bounds ``t_min/alpha``, ``t_max/alpha``.
    """

    edges: list
    rbar_v: float | list
    c_v: float | list
    alpha: float
    alphas: dict
    seed: int
    settings: dict = field(default_factory=dict)
    details: dict = field(default_factory=dict)

    @property
    def pairs(self) -> set:
        """The true edges as a set of frozensets ``{a, b}`` (for scoring)."""
        return {frozenset((a, b)) for a, b, _ in self.edges}

    def to_dict(self) -> dict:
        d = asdict(self)
        d["edges"] = [{"a": a, "b": b, "d": dd} for a, b, dd in self.edges]
        return {"generator": "thermctl.testbed", "thermctl_version": __version__, **d}

    @classmethod
    def from_dict(cls, data: dict, source: str = "<dict>") -> "Truth":
        try:
            edges = [(str(e["a"]), str(e["b"]), float(e["d"])) for e in data["edges"]]
            return cls(edges, data["rbar_v"], data["c_v"], float(data["alpha"]),
                       dict(data.get("alphas", {})), int(data["seed"]),
                       dict(data.get("settings", {})), dict(data.get("details", {})))
        except (KeyError, TypeError, ValueError) as exc:
            raise DataError(f"{source}: not a testbed truth file ({exc!r})") from None


def load_truth(path) -> Truth:
    """Read a ``truth.json`` written by :meth:`TestbedResult.write`.

    Examples
    --------
    >>> truth = load_truth("testbed/truth.json")   # doctest: +SKIP
    >>> truth.edges[0]                             # doctest: +SKIP
    ('r240', 'r243', 2.8)
    """
    from ..io import read_json_file

    return Truth.from_dict(read_json_file(path, "truth file", DataError), source=str(Path(path)))


def quantise_temperature(t, quantum_F: float):
    """Round temperatures [°C] as a BAS exporting in °F with step ``quantum_F`` does."""
    if not quantum_F:
        return t
    return f_to_c(np.round(c_to_f(t) / quantum_F) * quantum_F)


def quantise_flow(ms, quantum_cfm: float):
    """Round mass flows [kg/s] to a step of ``quantum_cfm`` CFM of air at RHO_AIR."""
    if not quantum_cfm:
        return ms
    q = quantum_cfm * CFM * RHO_AIR
    return np.round(np.asarray(ms) / q) * q


def punch_holes(values: np.ndarray, fraction: float, rng: np.random.Generator,
                mean_run: float = 3.0, outage_share: float = 0.25) -> np.ndarray:
    """Set about ``fraction`` of the entries to NaN: sensor dropouts and export outages.

    Parameters
    ----------
    values : ndarray, shape (n_rows, n_columns)
    fraction : float
        Target fraction of missing entries, in [0, 1).
    rng : numpy.random.Generator
    mean_run : float
        Mean length of a gap [rows] (geometric).
    outage_share : float
        Share of the missing entries that are whole-row outages.

    Returns
    -------
    ndarray
        A copy with NaNs.
    """
    out = np.array(values, dtype=float, copy=True)
    if fraction <= 0:
        return out
    n, m = out.shape
    mask = np.zeros((n, m), dtype=bool)

    def runs(hole, target):
        hole = hole.copy()
        while hole.sum() < target:
            start = rng.integers(0, n)
            hole[start:start + rng.geometric(1.0 / mean_run)] = True
        return hole

    mask |= runs(np.zeros(n, dtype=bool), outage_share * fraction * n)[:, None]
    for j in range(m):
        mask[:, j] = runs(mask[:, j], fraction * n)
    out[mask] = np.nan
    return out


def to_imperial(data: pd.DataFrame) -> pd.DataFrame:
    """SI testbed data → what a BAS exports: ``T:``/``Ts:`` in °F, ``vs:<zone>`` in CFM."""
    out = {}
    for col in data.columns:
        kind, _, name = col.partition(":")
        if kind in ("T", "Ts"):
            out[col] = c_to_f(data[col].to_numpy())
        elif kind == "ms":
            out[f"vs:{name}"] = data[col].to_numpy() / RHO_AIR / CFM
        else:
            out[col] = data[col].to_numpy()
    return pd.DataFrame(out, index=data.index)


def _decimals(col: str, units: str) -> int:
    kind = col.partition(":")[0]
    if kind in ("T", "Ts"):
        # quantised °F values: 5 decimals of °C (or 3 of °F) give them back exactly
        return 3 if units == "imperial" else 5
    if kind == "ms":
        return 7    # 1 CFM is 5.7e-4 kg/s
    return 2        # CFM, W/m²


def write_data_csv(data: pd.DataFrame, path, units: str = "si") -> None:
    """Write testbed data as the wide CSV of the exchange format (``time`` first, ISO 8601)."""
    if units not in ("si", "imperial"):
        raise DataError(f"units must be 'si' or 'imperial', found {units!r}")
    src = to_imperial(data) if units == "imperial" else data
    # one frame built at once: column by column, pandas warns of fragmentation at ~200 zones
    cols = {"time": [t.isoformat() for t in src.index]}
    cols |= {col: src[col].round(_decimals(col, units)).to_numpy() for col in src.columns}
    pd.DataFrame(cols).to_csv(path, index=False, na_rep="", lineterminator="\n")


def json_ready(obj):
    """Tuples, numpy scalars and arrays → plain JSON types (recursively)."""
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_ready(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_ready(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def bas_export(layout, net, dist, rec: dict, *, n_burn: int, every: int, flow_gain, noise,
               boxes: dict, missing: float, rng, rng_gaps, step_minutes: float):
    """Sensor readings → the exported table; the true gains averaged over each data step.

    Parameters
    ----------
    layout : Layout
    net : ThermalNetwork
    dist : Disturbances
        On the control grid, burn-in included.
    rec : dict
        Recorded at the data time stamps: ``T`` (zone sensor readings, measured zones),
        ``Tb`` (boundary readings), ``ms``, ``Ts`` (commands, all zones), ``x`` (true states).
    n_burn : int
        Control steps before the first data time stamp.
    every : int
        Control steps per data step.
    flow_gain : ndarray, shape (n_zones,)
        Flow station calibration gain per zone [-].
    noise : SensorNoise or None
    boxes : dict
        Zones with a VAV box.
    missing : float
        Fraction of missing samples [-].
    rng, rng_gaps : numpy.random.Generator
        For sensor noise and for the gaps.
    step_minutes : float
        Data step [min].

    Returns
    -------
    data : pandas.DataFrame
    gains : pandas.DataFrame
    """
    spec = layout.spec
    T_rec, Tb_rec, ms_rec, Ts_rec, X = rec["T"], rec["Tb"], rec["ms"], rec["Ts"], rec["x"]
    n = len(T_rec)
    index = dist.time[n_burn::every][:n]
    nz = net.n_zones
    # a hidden conditioned zone's box is not in the trend log either
    box_idx = [i for i, z in enumerate(net.zones) if z in boxes and z in spec.measured_zones]
    on = ms_rec[:, box_idx] > 0
    # discharge sensor: supply temperature while the box blows, drifting to the room when off
    duct = np.empty((n, len(box_idx)))
    keep = math.exp(-step_minutes * 60.0 / 1800.0)
    T_true = X[:, box_idx]
    duct[0] = np.where(on[0], Ts_rec[0, box_idx], T_true[0])
    for j in range(1, n):
        duct[j] = np.where(on[j], Ts_rec[j, box_idx], T_true[j] + (duct[j - 1] - T_true[j]) * keep)
    flow = ms_rec[:, box_idx] * flow_gain[box_idx]
    if noise is not None:
        duct = duct + rng.normal(0.0, noise.Ts_sd, duct.shape)
        flow = np.where(on, flow * (1.0 + rng.normal(0.0, noise.flow_sd, flow.shape)), 0.0)
        q = noise.quantum_F
        T_log = quantise_temperature(T_rec, q)
        Tb_log = quantise_temperature(Tb_rec, q)
        duct = quantise_temperature(duct, q)
        flow = quantise_flow(flow, noise.flow_quantum_cfm)
    else:
        T_log, Tb_log = T_rec, Tb_rec
    cols = {}
    for j, z in enumerate(spec.measured_zones):
        cols[f"T:{z}"] = T_log[:, j]
    for j, b in enumerate(net.boundary):
        cols[f"T:{b}"] = Tb_log[:, j]
    for q, i in enumerate(box_idx):
        cols[f"Ts:{net.zones[i]}"] = duct[:, q]
    for q, i in enumerate(box_idx):
        cols[f"ms:{net.zones[i]}"] = flow[:, q]
    if any(v > 0 for v in layout.solar_aperture.values()):
        sol = dist.solar[n_burn::every][:n]
        if noise is not None:
            sol = np.maximum(sol * (1.0 + rng.normal(0.0, noise.solar_sd, n)), 0.0)
            sol = np.round(sol, 1)
        cols["solar:south"] = sol
    names = list(cols)
    values = np.column_stack([cols[c] for c in names])
    values = punch_holes(values, missing, rng_gaps)
    index = pd.DatetimeIndex(index, name="time")
    data = pd.DataFrame(values, index=index, columns=names)
    g = dist.gains[n_burn:n_burn + n * every].reshape(n, every, nz).mean(axis=1)
    gains = pd.DataFrame(g, index=index.copy(), columns=list(net.zones))
    return data, gains
