r"""HVAC energy model, comfort band, KPIs and the table / figure every example writes.

HVAC energy model
-----------------
A single-duct VAV system with reheat. The air handler (AHU) mixes outdoor and return
air, cools (or preheats) it to the cold-deck temperature :math:`T_c`, and its fan pushes
it to the zones; each zone's VAV box sets the flow :math:`\dot m_z` and reheats the air
from :math:`T_c` to the supply temperature :math:`T_{s,z} \ge T_c`. Per zone air stream
the return air is that zone's air (so the AHU's return temperature is the flow-weighted
mean of the zone temperatures), and the mixed air is

.. math::

    T_{mix,z} = f_{oa} T_o + (1 - f_{oa}) T_z .

Heat rates [W] at each step:

.. math::

    Q_{coil} &= \sum_z \dot m_z c_p (T_{mix,z} - T_c)
        \quad(\text{cooling coil if} > 0,\ \text{preheat coil if} < 0),\\
    Q_{rh}   &= \sum_z \dot m_z c_p (T_{s,z} - T_c) \ \ge 0 \quad(\text{reheat}),\\
    P_{fan}  &= P_{fan,des} \Big(\frac{\sum_z \dot m_z}{\dot m_{des}}\Big)^3
        \quad(\text{fan affinity law}),

with :math:`\dot m_{des} = \sum_z \dot m_{max,z}` and
:math:`P_{fan,des} = \mathrm{SFP}\cdot\dot m_{des}/\rho`. Heating energy is reheat plus
preheat (a gas boiler, efficiency :math:`\eta_h`), cooling energy is the cooling-coil duty
(a chiller, :math:`\mathrm{COP}`), fan energy is electric. The *total* the MPCs minimise and
the table reports is the delivered (site) energy

.. math::

    E = E_{fan} + E_{heat}/\eta_h + E_{cool}/\mathrm{COP}.

Defaults: outdoor-air fraction 0.3 (a typical minimum-outdoor-air setting without
economiser), :math:`\eta_h = 0.9` (condensing boiler), COP 3.5 (air-cooled chiller),
SFP 1.5 kW/(m³/s) (ASHRAE 90.1 fan-power limit for VAV is about 1.6 kW/(m³/s)).

Comfort
-------
A band per zone: [21, 24] °C in comfort hours (weekdays 07:00–19:00, i.e. the testbed's
HVAC occupied mode minus its first hour, which belongs to warm-up), a setback band
[16, 28] °C otherwise. Discomfort is :math:`\int \max(0, L - T) + \max(0, T - U)\,dt` in
K·h, summed over the comfort zones (the measured offices) — BOPTEST's ``tdis_tot`` times
the number of zones.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from thermctl.spec import RHO_AIR

__all__ = ["J_PER_KWH", "ComfortBand", "HVACModel", "Forecast", "Tariff", "MPCSolution",
           "RecedingHorizonMPC", "ClosedLoopResult", "kpis", "kpi_table", "format_table",
           "plot_closed_loop", "save_outputs", "example_parser"]

J_PER_KWH = 3.6e6


@dataclass(frozen=True)
class ComfortBand:
    """Comfort band with night setback.

    Attributes
    ----------
    occupied : (float, float)
        Lower and upper zone temperature in comfort hours [°C].
    unoccupied : (float, float)
        Setback / setup band outside comfort hours [°C].
    hours : (float, float)
        Comfort hours [h local time], weekdays only when ``weekdays_only``.
    weekdays_only : bool
    """

    occupied: tuple = (21.0, 24.0)
    unoccupied: tuple = (16.0, 28.0)
    hours: tuple = (7.0, 19.0)
    weekdays_only: bool = True

    def in_hours(self, time: pd.DatetimeIndex) -> np.ndarray:
        """Whether each time stamp lies in comfort hours."""
        h = np.asarray(time.hour + time.minute / 60.0, dtype=float)
        on = (h >= self.hours[0]) & (h < self.hours[1])
        if self.weekdays_only:
            on &= np.asarray(time.day_of_week) < 5
        return on

    def bounds(self, time: pd.DatetimeIndex):
        """Lower and upper bound at each time stamp [°C], shape (len(time),) each."""
        on = self.in_hours(time)
        lo = np.where(on, self.occupied[0], self.unoccupied[0])
        hi = np.where(on, self.occupied[1], self.unoccupied[1])
        return lo, hi

    def violation(self, T, time: pd.DatetimeIndex) -> np.ndarray:
        """Distance outside the band [K], shape like ``T`` (rows = time stamps)."""
        lo, hi = self.bounds(time)
        T = np.asarray(T, dtype=float)
        return np.maximum(lo[:, None] - T, 0.0) + np.maximum(T - hi[:, None], 0.0)


def _sum_zones(v):
    """Sum over the zone axis: the last axis of an ndarray, the rows of a CasADi column."""
    if isinstance(v, np.ndarray):
        return v.sum(axis=-1)
    import casadi as ca
    return ca.sum1(v)


@dataclass(frozen=True)
class HVACModel:
    """Simple VAV-with-reheat energy model (see the module docstring for the equations).

    Attributes
    ----------
    cp : float
        Specific heat of the supply air [J/(kg K)].
    ms_min : ndarray, shape (n_zones,)
        Minimum (ventilation) supply flow per zone in occupied mode [kg/s]; 0 for zones
        without a VAV box.
    ms_max : ndarray, shape (n_zones,)
        Maximum supply flow per zone [kg/s]; 0 for zones without a VAV box.
    Ts_max : float
        Highest supply (discharge) temperature after reheat [°C].
    f_oa : float
        Outdoor-air fraction of the mixed air [-].
    eta_heat : float
        Boiler efficiency [-].
    cop_cool : float
        Chiller coefficient of performance [-].
    sfp : float
        Specific fan power at design flow [W/(m³/s)].
    """

    cp: float
    ms_min: np.ndarray
    ms_max: np.ndarray
    Ts_max: float = 35.0
    f_oa: float = 0.3
    eta_heat: float = 0.9
    cop_cool: float = 3.5
    sfp: float = 1500.0

    @property
    def supplied(self) -> np.ndarray:
        """Indices of the zones with a VAV box."""
        return np.flatnonzero(np.asarray(self.ms_max) > 0)

    @property
    def ms_design(self) -> float:
        """Design system flow [kg/s]."""
        return float(np.sum(self.ms_max))

    @property
    def fan_design_power(self) -> float:
        """Fan power at design flow [W]."""
        return self.sfp * self.ms_design / RHO_AIR

    def fan_power(self, ms):
        """Fan power [W] for supply flows ``ms`` [kg/s] (zones on the last axis / rows)."""
        return self.fan_design_power * (_sum_zones(ms) / self.ms_design) ** 3

    def coil_duty(self, ms, T_zone, T_out, T_c):
        """AHU coil duty [W]: cooling if > 0, preheat if < 0.

        Parameters
        ----------
        ms : array_like or casadi column
            Supply flow per zone [kg/s].
        T_zone : same shape as ``ms``
            Zone (return air) temperatures [°C].
        T_out, T_c : float or array broadcasting against ``ms`` without its zone axis
            Outdoor and cold-deck temperature [°C].
        """
        if isinstance(ms, np.ndarray):
            T_out = np.asarray(T_out, dtype=float)[..., None]
            T_c = np.asarray(T_c, dtype=float)[..., None]
        mix = self.f_oa * T_out + (1.0 - self.f_oa) * T_zone
        return _sum_zones(ms * self.cp * (mix - T_c))

    def reheat(self, ms, Ts, T_c):
        """Reheat [W] to raise the cold-deck air to ``Ts`` (no negative reheat)."""
        if isinstance(ms, np.ndarray):
            lift = np.maximum(np.asarray(Ts, float) - np.asarray(T_c, float)[..., None], 0.0)
            return _sum_zones(ms * self.cp * lift)
        return _sum_zones(ms * self.cp * (Ts - T_c))

    def powers(self, ms, Ts, T_zone, T_out, T_c) -> dict:
        """Fan, heating and cooling power [W] per step, all arrays of shape (N,).

        Parameters
        ----------
        ms, Ts, T_zone : ndarray, shape (N, n_zones)
            Supply flow [kg/s], supply temperature [°C], zone temperature at the start of
            each step [°C].
        T_out, T_c : ndarray, shape (N,)
            Outdoor and cold-deck temperatures [°C].
        """
        ms = np.asarray(ms, dtype=float)
        coil = self.coil_duty(ms, np.asarray(T_zone, float), T_out, T_c)
        return {"fan": self.fan_power(ms),
                "heating": self.reheat(ms, Ts, T_c) + np.maximum(-coil, 0.0),
                "cooling": np.maximum(coil, 0.0)}

    def site_power(self, p: dict):
        """Delivered (site) power ``fan + heating/η + cooling/COP`` [W]."""
        return p["fan"] + p["heating"] / self.eta_heat + p["cooling"] / self.cop_cool


@dataclass
class Forecast:
    """What the controller knows about the next ``N`` steps (each held over one MPC step).

    Attributes
    ----------
    T_boundary : ndarray, shape (N, n_boundary)
        Boundary temperatures [°C] (the logged values: a perfect forecast of what the
        BAS will record).
    gains : ndarray, shape (N, n_zones)
        Heat gains [W] the model assumes (the Kalman filter's estimate, held).
    T_out : ndarray, shape (N,)
        Outdoor temperature [°C] for the energy model.
    T_c : ndarray, shape (N,)
        Cold-deck temperature [°C] (the last reading, held).
    hvac_on : ndarray of bool, shape (N,)
        Occupied mode: supply at least the ventilation minimum.
    lo, hi : ndarray, shape (N,)
        Comfort band at the end of each step [°C].
    tariff : Tariff, optional
        Prices over the horizon (the linear MPC then minimises cost instead of site
        energy); None: every kWh of site energy costs 1.
    """

    T_boundary: np.ndarray
    gains: np.ndarray
    T_out: np.ndarray
    T_c: np.ndarray
    hvac_on: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    tariff: "Tariff | None" = None

    def __len__(self) -> int:
        return len(self.T_c)


@dataclass
class Tariff:
    """What the next ``N`` steps of energy cost (see :mod:`mpc_examples.demand_response`).

    Attributes
    ----------
    elec : ndarray, shape (N,)
        Price of electricity (fan, chiller) [$/kWh].
    heat : ndarray, shape (N,)
        Price of delivered heat (boiler fuel) [$/kWh of fuel].
    demand : float
        Demand charge for the horizon's peak electric power [$/kW] (0: none).
    peak_floor : float
        Peak already reached in the billing period [kW]: the charge only sees more.
    elec_cap : ndarray, shape (N,)
        Electric power limit [kW] (``inf``: none), e.g. a demand-response event.
    cap_penalty : float
        Price of power above ``elec_cap`` [$/kWh] (soft: the fan minimum must run).
    """

    elec: np.ndarray
    heat: np.ndarray
    demand: float = 0.0
    peak_floor: float = 0.0
    elec_cap: np.ndarray | None = None
    cap_penalty: float = 50.0


@dataclass
class MPCSolution:
    """One MPC solve.

    Attributes
    ----------
    ms, Ts : ndarray, shape (N, n_zones)
        Planned supply flow [kg/s] and supply temperature [°C], all zones.
    X : ndarray, shape (N + 1, n_states)
        Predicted model state [°C].
    success : bool
    status : str
    iterations : int
    solve_time : float
        Wall time of the solver call [s].
    cpu_time : float
        CPU time of this process during the call [s] (robust to other load on the machine
        when the solver runs single-threaded, ``OMP_NUM_THREADS=1``).
    cost : float
        Objective value (site energy [kWh] plus penalties).
    """

    ms: np.ndarray
    Ts: np.ndarray
    X: np.ndarray
    success: bool
    status: str
    iterations: int
    solve_time: float
    cpu_time: float
    cost: float


class RecedingHorizonMPC:
    """What both MPCs share: the model, the energy model, the step, the horizon, which zones
    are scored and supplied, and the previous solution (for the warm start).

    Parameters
    ----------
    model : ThermalModel or thermctl.reduce.ReducedNetwork
        The controller's model.
    hvac : HVACModel
        Its ``ms_min`` / ``ms_max`` have one entry per model zone.
    comfort_zones : list of str
        Zones whose temperature must stay in the band.
    dt : float
        MPC step [s], > 0.
    horizon : int
        Number of steps N, >= 1.
    weights : dataclass
        The formulation's penalty weights.

    Attributes
    ----------
    zones : list of str
    comfort_idx : ndarray of int
        Model zone index of each comfort zone.
    sup : ndarray of int
        Model zone indices with a VAV box.
    frac_min : ndarray, shape (len(sup),)
        Ventilation minimum flow as a fraction of the box maximum [-].
    """

    def __init__(self, model, hvac: HVACModel, comfort_zones, dt: float, horizon: int, weights):
        if int(horizon) != horizon or horizon < 1:
            raise ValueError(f"horizon must be a positive integer, found {horizon!r}")
        if not dt > 0:
            raise ValueError(f"dt must be > 0 [s], found {dt!r}")
        net = model.network
        self.model, self.hvac, self.weights = model, hvac, weights
        self.dt, self.N = float(dt), int(horizon)
        self.zones = list(net.zones)
        unknown = [z for z in comfort_zones if z not in self.zones]
        if unknown:
            raise ValueError(f"comfort zones {unknown} are not zones of the model {self.zones}")
        if len(hvac.ms_max) != net.n_zones or len(hvac.ms_min) != net.n_zones:
            raise ValueError(f"hvac.ms_min / ms_max have {len(hvac.ms_min)} / "
                             f"{len(hvac.ms_max)} values, the model has {net.n_zones} zones")
        self.comfort_idx = np.array([self.zones.index(z) for z in comfort_zones], dtype=int)
        self.sup = hvac.supplied
        self.frac_min = (np.asarray(hvac.ms_min, float)[self.sup]
                         / np.asarray(hvac.ms_max, float)[self.sup])
        self._prev = None

    def check_forecast(self, fc: "Forecast") -> None:
        """Raise ``ValueError`` unless ``fc`` covers the horizon."""
        if len(fc) < self.N:
            raise ValueError(f"forecast covers {len(fc)} steps, the horizon needs {self.N}")

    def reset(self) -> None:
        """Forget the previous solution (the next solve starts cold)."""
        self._prev = None


@dataclass
class ClosedLoopResult:
    """A closed-loop run on the plant, on the plant's step.

    Attributes
    ----------
    name : str
    time : pandas.DatetimeIndex, length N + 1
        Sample times; inputs of row ``k`` act from ``time[k]`` to ``time[k + 1]``.
    zones : list of str
    T : ndarray, shape (N + 1, n_zones)
        True zone temperatures of the plant [°C].
    ms, Ts : ndarray, shape (N, n_zones)
        Applied supply flow [kg/s] and supply temperature [°C].
    T_out, T_c : ndarray, shape (N,)
        Outdoor and cold-deck temperature [°C].
    solve_time : list of float
        Wall time of each controller call [s] (empty for the baseline).
    cpu_time : list of float
        CPU time of each controller call [s].
    failures : int
        Controller calls whose solver did not report success.
    extra : dict
    """

    name: str
    time: pd.DatetimeIndex
    zones: list
    T: np.ndarray
    ms: np.ndarray
    Ts: np.ndarray
    T_out: np.ndarray
    T_c: np.ndarray
    solve_time: list = field(default_factory=list)
    cpu_time: list = field(default_factory=list)
    failures: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def dt(self) -> float:
        """Plant step [s]."""
        return float((self.time[1] - self.time[0]).total_seconds())


def kpis(res: ClosedLoopResult, hvac: HVACModel, band: ComfortBand, comfort_zones) -> dict:
    """Energy [kWh], discomfort [K·h] and solve-time KPIs of one run.

    Energy integrates the step powers (inputs held over each step); discomfort sums
    ``violation · dt`` over the steps, each scored by its starting sample against the band
    in force then (left rectangle rule), and over ``comfort_zones``.
    """
    p = hvac.powers(res.ms, res.Ts, res.T[:-1], res.T_out, res.T_c)
    e = {k: float(np.sum(v) * res.dt / J_PER_KWH) for k, v in p.items()}
    site = float(np.sum(hvac.site_power(p)) * res.dt / J_PER_KWH)
    cz = [res.zones.index(z) for z in comfort_zones]
    viol = band.violation(res.T[:-1, cz], res.time[:-1])
    st = np.asarray(res.solve_time, dtype=float)
    ct = np.asarray(res.cpu_time, dtype=float)
    return {
        "fan [kWh]": e["fan"], "heating [kWh]": e["heating"], "cooling [kWh]": e["cooling"],
        "site energy [kWh]": site,
        "discomfort [K·h]": float(viol.sum() * res.dt / 3600.0),
        "max violation [K]": float(viol.max(initial=0.0)),
        "solve median [s]": float(np.median(st)) if st.size else math.nan,
        "solve max [s]": float(st.max()) if st.size else math.nan,
        "CPU median [s]": float(np.median(ct)) if ct.size else math.nan,
        "failures": int(res.failures),
    }


def kpi_table(results, hvac: HVACModel, band: ComfortBand, comfort_zones) -> pd.DataFrame:
    """One row of :func:`kpis` per run, indexed by run name."""
    rows = {r.name: kpis(r, hvac, band, comfort_zones) for r in results}
    return pd.DataFrame.from_dict(rows, orient="index")


def format_table(df: pd.DataFrame) -> str:
    """Fixed-width text table: integers as such, times 3 decimals, other numbers 2."""
    def cell(col, v):
        if isinstance(v, (int, np.integer)):
            return f"{v:d}"
        if isinstance(v, (float, np.floating)):
            if math.isnan(v):
                return "-"
            return f"{v:.3f}" if "[s]" in col else f"{v:.2f}"
        return str(v)

    cols = [df.index.name or "controller"] + [str(c) for c in df.columns]
    rows = [[str(i)] + [cell(c, v) for c, v in zip(df.columns, r)]
            for i, r in zip(df.index, df.itertuples(index=False))]
    w = [max(len(cols[j]), *(len(r[j]) for r in rows)) for j in range(len(cols))]

    def line(r):
        return "  ".join(x.ljust(w[0]) if j == 0 else x.rjust(w[j]) for j, x in enumerate(r))

    return "\n".join([line(cols), line(["-" * n for n in w])] + [line(r) for r in rows])


def plot_closed_loop(results, band: ComfortBand, comfort_zones, path, title: str = ""):
    """Figure: zone temperatures of each run against the band, supply flow, heating/cooling.

    One temperature panel per run (comfort zones, band shaded), then total supply flow
    [kg/s] and site HVAC power [kW] of all runs. Written to ``path`` (PNG).
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(results)
    fig, axes = plt.subplots(n + 3, 1, figsize=(11, 2.3 * (n + 3)), sharex=True)
    t0 = results[0].time
    lo, hi = band.bounds(t0)
    for ax, r in zip(axes, results):
        ax.fill_between(t0, lo, hi, step="post", color="tab:green", alpha=0.12, lw=0,
                        label="comfort band")
        for z in comfort_zones:
            ax.plot(r.time, r.T[:, r.zones.index(z)], lw=0.9, label=z)
        ax.set_ylabel("T [°C]")
        ax.set_title(r.name, fontsize=9, loc="left")
    axes[0].legend(ncol=min(8, len(comfort_zones) + 1), fontsize=7, loc="upper right")
    ax_ms, ax_ts, ax_p = axes[n], axes[n + 1], axes[n + 2]
    for r in results:
        t = r.time[:-1]
        ax_ms.step(t, r.ms.sum(axis=1), where="post", lw=0.9, label=r.name)
        sup = r.ms.sum(axis=1) > 0
        ts_mean = np.where(sup, (r.ms * r.Ts).sum(axis=1) / np.where(sup, r.ms.sum(axis=1), 1.0),
                           np.nan)
        ax_ts.step(t, ts_mean, where="post", lw=0.9, label=r.name)
        p = r.extra.get("site_power")
        if p is not None:
            ax_p.step(t, p / 1e3, where="post", lw=0.9, label=r.name)
    ax_ts.plot(t0[:-1], results[0].T_out, color="0.5", lw=0.7, ls="--", label="outdoor")
    ax_ms.set_ylabel("Σ ṁ [kg/s]")
    ax_ts.set_ylabel("mean Ts [°C]")
    ax_p.set_ylabel("site power [kW]")
    for ax in (ax_ms, ax_ts, ax_p):
        ax.legend(fontsize=7, loc="upper right")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def save_outputs(out_dir, stem: str, table: pd.DataFrame, meta: dict) -> dict:
    """Write ``<stem>.csv``, ``<stem>.txt`` (the printed table) and ``<stem>.json`` (settings)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"csv": out / f"{stem}.csv", "txt": out / f"{stem}.txt", "json": out / f"{stem}.json"}
    table.to_csv(paths["csv"], index_label="controller")
    paths["txt"].write_text(format_table(table) + "\n")
    paths["json"].write_text(json.dumps(meta, indent=2, default=str))
    return paths


def example_parser(description: str) -> argparse.ArgumentParser:
    """Command-line options shared by the examples."""
    p = argparse.ArgumentParser(description=description,
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--hours", type=float, default=72.0,
                   help="closed-loop length [h] (fast mode: --hours 3)")
    p.add_argument("--model", default="identified",
                   help="the MPC's internal model(s), comma-separated: identified (thermctl's "
                        "default identification), paper (the paper's pipeline), true, "
                        "conduction-only (e.g. identified,true for the cost of model error)")
    p.add_argument("--warmup", type=float, default=48.0,
                   help="hours of the BAS log the Kalman filter replays before it takes over "
                        "(0: start from the first reading with guessed wall states)")
    p.add_argument("--order", type=int, default=None,
                   help="reduce the MPC's model to this many states (structure-preserving: "
                        "zone temperatures stay states); default: the full model")
    p.add_argument("--zones", type=int, default=7,
                   help="7: Pugh Hall section; more: testbed corridor floor of about this size")
    p.add_argument("--seed", type=int, default=0, help="testbed seed")
    p.add_argument("--step", type=float, default=10.0,
                   help="MPC step [min] (at 15 min, people leaving between two steps cost "
                        "more discomfort; docs/mpc.md)")
    p.add_argument("--horizon", type=float, default=6.0, help="prediction horizon [h]")
    p.add_argument("--backoff", type=float, default=0.35,
                   help="the MPC keeps this far inside the comfort band [K]: sensor offsets "
                        "(about 0.1 K) and what happens between two MPC steps (people leave)")
    p.add_argument("--start-day", type=int, default=None,
                   help="day of the testbed run to start on (default: the first Monday after "
                        "the identification days)")
    p.add_argument("--start-hour", type=float, default=0.0,
                   help="hour of the start day the control period starts at [h]")
    p.add_argument("--out", type=Path, default=Path("mpc-output"), help="output directory")
    p.add_argument("--no-figure", action="store_true", help="skip the figure")
    p.add_argument("--no-band-baseline", action="store_true",
                   help="skip the baseline run with its set points moved to the comfort band")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress")
    return p
