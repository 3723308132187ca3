r"""A task where the model matters: tariff, peak charge, a demand-response event, a small box.

Run from the repository root::

    python -m mpc_examples.demand_response                  # 24 h, four internal models
    python -m mpc_examples.demand_response --model true,conduction-only --hours 12
    python -m mpc_examples.demand_response --small-load 1200 --start-hour 5 --hours 15

The energy/comfort task of the other examples barely separates the models (the gain
filter absorbs a missing air path). This one makes the controller *plan through the
building's dynamics*:

* **Time-of-use electricity** (fan and chiller): 0.08 $/kWh off-peak, 0.24 $/kWh on-peak
  (weekdays 12:00–18:00); boiler fuel 0.035 $/kWh.
* **Peak-demand charge** 15 $/kW on the highest 15-min electric power (a month's charge,
  set by this day).
* **Demand-response event** 14:00–16:00: electric power capped at 1.1 × what ventilation
  alone needs (fans and coil at the boxes' minimum flows, offices at 24 °C, the event's
  outdoor temperature): every extra cooling flow shed; soft, 2 $/kWh above the cap. Cooling
  the offices *before* the event, through the walls' mass, is what pays.
* **An undersized box**: office r240's box delivers 35 % of its design flow (its minimum
  stays). r240 has a true air path to r243 (2.8 m): when r240 overheats, over-cooling r243
  moves heat out of r240 through the air path — a model without that path cannot plan it.
  In the testbed's February weather it only binds with extra heat in r240
  (``--small-load``, e.g. 1200 W: docs/mpc.md).

The controller is the linear MPC (:class:`~mpc_examples.linear_mpc.LinearMPC` with
``tariff=True``: cost instead of energy, a peak variable, the event's cap) with each
internal model and the Kalman filter of :mod:`mpc_examples.model`; the plant is the
testbed's true building. KPIs in BOPTEST's units: thermal discomfort per zone [K·h/zone],
energy [kWh/m²], cost [$/m²], peak electric power [kW/m²] (15-min mean), plus the
event's excess energy [kWh] and the small-box zone's discomfort.

The MPC charges every horizon for its own peak (no memory of the day's peak so far):
conservative, and the same for every model.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from .common import J_PER_KWH, ComfortBand, Tariff, example_parser, format_table, save_outputs
from .linear_mpc import LinearMPC
from .model import controller_model
from .simulator import Scenario, make_scenario, run_baseline, run_mpc

__all__ = ["TariffSettings", "DRScenario", "make_dr_scenario", "dr_kpis", "main"]

log = logging.getLogger(__name__)

SMALL_BOX_ZONE = "r240"
"""The office whose box is undersized (true air path to r243)."""


@dataclass(frozen=True)
class TariffSettings:
    """Prices and the event (defaults: a US commercial time-of-use rate, order of magnitude).

    Attributes
    ----------
    off_peak, on_peak : float
        Electricity [$/kWh].
    peak_hours : (float, float)
        On-peak window, weekdays [h local time].
    fuel : float
        Boiler fuel [$/kWh].
    demand : float
        Demand charge [$/kW] on the highest 15-min mean electric power.
    event : (float, float)
        Demand-response event [h local time] (on the control period's first weekday).
    cap_factor : float
        Event cap as a multiple of the ventilation-only electric power [-].
    cap_penalty : float
        [$/kWh] above the cap.
    """

    off_peak: float = 0.08
    on_peak: float = 0.24
    peak_hours: tuple = (12.0, 18.0)
    fuel: float = 0.035
    demand: float = 15.0
    event: tuple = (14.0, 16.0)
    cap_factor: float = 1.1
    cap_penalty: float = 2.0


@dataclass
class DRScenario(Scenario):
    """A :class:`~mpc_examples.simulator.Scenario` whose forecasts carry the tariff."""

    tariff: TariffSettings = TariffSettings()
    cap_kw: float = math.inf
    area: float = 1.0

    def prices(self, time: pd.DatetimeIndex):
        """Electricity and fuel price [$/kWh] and electric cap [kW] at each time stamp."""
        ts = self.tariff
        h = np.asarray(time.hour + time.minute / 60.0, float)
        wd = np.asarray(time.day_of_week) < 5
        on = wd & (h >= ts.peak_hours[0]) & (h < ts.peak_hours[1])
        event = (wd & (h >= ts.event[0]) & (h < ts.event[1])
                 & (np.asarray(time.normalize()) == np.asarray(self.start.normalize())))
        return (np.where(on, ts.on_peak, ts.off_peak), np.full(len(h), ts.fuel),
                np.where(event, self.cap_kw, np.inf))

    def forecast(self, k, N, every, gains, T_c, steps=None):
        fc = super().forecast(k, N, every, gains, T_c, steps=steps)
        d = self.tb.disturbances
        lengths = every * (np.ones(N, int) if steps is None else np.asarray(steps, int))
        starts = np.cumsum(lengths) - lengths
        a = self.k0 + k
        # prices at every plant step of the horizon: a long (coarse-grid) step pays their
        # mean, and its cap is the tightest one inside it (a 2-h event within a 60-min step)
        el, fuel, cap = (np.asarray(v, float) for v in self.prices(d.time[a: a + lengths.sum()]))
        fc.tariff = Tariff(elec=np.add.reduceat(el, starts) / lengths,
                           heat=np.add.reduceat(fuel, starts) / lengths,
                           demand=self.tariff.demand, elec_cap=np.minimum.reduceat(cap, starts),
                           cap_penalty=self.tariff.cap_penalty)
        return fc


def make_dr_scenario(seed: int = 0, hours: float = 24.0, horizon_hours: float = 6.0,
                     start_day=None, start_hour: float = 0.0, small_fraction: float = 0.35,
                     tariff: TariffSettings = TariffSettings(),
                     small_load: float = 0.0) -> DRScenario:
    """Pugh Hall with the undersized box and the tariff (see the module docstring).

    ``small_load`` [W]: extra heat in the small-box office in occupied hours from the
    control period's start on (equipment switched on that morning: the log before it, which
    the Kalman filter replays and the identification used, does not have it). Neither the
    controller nor its filter is told; the filter's gain estimate picks it up.
    """
    scn = make_scenario(7, seed, hours, horizon_hours, start_day, start_hour, ComfortBand())
    hv = scn.hvac
    zones = list(scn.tb.network.zones)
    j = zones.index(SMALL_BOX_ZONE)
    if small_load:
        d = scn.tb.disturbances
        gains = np.array(d.gains, float)
        on = np.asarray(d.occupied, bool) & (np.arange(len(d)) >= scn.k0)
        gains[on, list(d.zones).index(SMALL_BOX_ZONE)] += float(small_load)
        scn = replace(scn, tb=replace(scn.tb, disturbances=replace(d, gains=gains)))
    ms_max = np.array(hv.ms_max, float)
    ms_max[j] *= small_fraction
    ms_min = np.minimum(np.array(hv.ms_min, float), ms_max)
    hvac = replace(hv, ms_min=ms_min, ms_max=ms_max)
    # the cap: what ventilation alone needs during the event — fans and coil at the minimum
    # flows with the offices at the band's top and the event's mean outdoor temperature;
    # any extra cooling flow is shed
    d = scn.tb.disturbances
    h = np.asarray(d.time.hour + d.time.minute / 60.0, float)
    day = np.asarray(d.time.normalize()) == np.asarray(scn.start.normalize())
    ev = day & (h >= tariff.event[0]) & (h < tariff.event[1])
    from .simulator import _outdoor
    T_o = float(d.T_boundary[ev, d.boundary.index(_outdoor(d.boundary))].mean())
    ms = np.asarray(ms_min)[None, :]
    T_c = float(scn.tb.controller.settings.T_ahu)
    p = hvac.powers(ms, np.full_like(ms, T_c), np.full_like(ms, scn.band.occupied[1]),
                    np.array([T_o]), np.array([T_c]))
    base_kw = float(p["fan"][0] + p["cooling"][0] / hvac.cop_cool) / 1e3
    area = sum(z.volume for z in scn.tb.spec.zones) / 3.0     # 3 m rooms [m²]
    return DRScenario(scn.tb, scn.k0, scn.n_steps, hvac, scn.band, scn.comfort_zones,
                      tariff=tariff, cap_kw=tariff.cap_factor * base_kw, area=area)


def small_box_baseline(scn: DRScenario, margin: float = 0.5):
    """The band-set-point BAS (:func:`~mpc_examples.simulator.band_baseline`) with the small box."""
    from thermctl.testbed import VAVController

    tb = scn.tb
    zones = list(tb.network.zones)
    boxes = {}
    for z, b in tb.truth.details["vav_boxes"].items():
        j = zones.index(z)
        mx = float(scn.hvac.ms_max[j])
        boxes[z] = (float(scn.hvac.ms_min[j]), mx, min(b["ms_heat_max"], mx))
    lo, hi = scn.band.occupied
    return VAVController(tb.network.zones, boxes, {z: lo + margin for z in boxes},
                         {z: hi - margin for z in boxes}, tb.spec.measured_zones,
                         tb.controller.settings, scn.dt)


def dr_kpis(res, scn: DRScenario) -> dict:
    """Cost, peak, event excess and discomfort of one run (BOPTEST units where they apply)."""
    hv = scn.hvac
    p = hv.powers(res.ms, res.Ts, res.T[:-1], res.T_out, res.T_c)
    elec = (p["fan"] + p["cooling"] / hv.cop_cool) / 1e3                      # [kW]
    fuel = p["heating"] / hv.eta_heat / 1e3
    el_price, fuel_price, cap = scn.prices(res.time[:-1])
    h = res.dt / 3600.0
    per15 = max(1, int(round(900.0 / res.dt)))
    n15 = len(elec) // per15
    peak = float(elec[: n15 * per15].reshape(n15, per15).mean(axis=1).max())
    energy_cost = float(np.sum(el_price * elec + fuel_price * fuel) * h)
    demand_cost = scn.tariff.demand * peak
    excess = float(np.sum(np.maximum(elec - cap, 0.0)) * h)
    cz = [res.zones.index(z) for z in scn.comfort_zones]
    viol = scn.band.violation(res.T[:-1, cz], res.time[:-1]) * h                # [K·h]
    small = scn.comfort_zones.index(SMALL_BOX_ZONE)
    total_kwh = float(np.sum(elec + fuel) * h)
    A = scn.area
    st = np.asarray(res.solve_time, float)
    return {"cost [$]": energy_cost + demand_cost, "energy cost [$]": energy_cost,
            "demand cost [$]": demand_cost, "peak [kW]": peak,
            "event excess [kWh]": excess, "site energy [kWh]": total_kwh,
            "discomfort [K·h/zone]": float(viol.sum() / len(cz)),
            f"{SMALL_BOX_ZONE} discomfort [K·h]": float(viol[:, small].sum()),
            "energy [kWh/m²]": total_kwh / A, "cost [$/m²]": (energy_cost + demand_cost) / A,
            "peak [W/m²]": 1e3 * peak / A,     # BOPTEST's kW/m² × 1000 (legible at 2 decimals)
            "solve median [s]": float(np.median(st)) if st.size else math.nan,
            "failures": int(res.failures)}


def main(argv=None):
    """Baselines and the linear MPC with each internal model on the DR day; print and save."""
    p = example_parser("Demand-response day: tariff, peak charge, 2-h event, small box")
    p.set_defaults(hours=24.0, model="identified,paper,true,conduction-only")
    p.add_argument("--transcription", default="zoh",
                   help="the linear MPC's step rows (mpc_examples.sparse.TRANSCRIPTIONS)")
    p.add_argument("--small-fraction", type=float, default=0.35,
                   help="the small box's maximum flow as a fraction of its design [-]")
    p.add_argument("--small-load", type=float, default=0.0,
                   help=f"extra heat in {SMALL_BOX_ZONE} in occupied hours from the start [W] "
                        "(equipment the log before does not have): the small box cannot cool "
                        "it alone")
    p.add_argument("--cap-factor", type=float, default=TariffSettings.cap_factor,
                   help="event cap as a multiple of the ventilation-only electric power [-] "
                        "(below 1: the zones must be cooler than the band's top in the event)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(message)s")
    N = int(round(args.horizon * 60.0 / args.step))
    scn = make_dr_scenario(args.seed, args.hours, args.horizon, args.start_day, args.start_hour,
                           args.small_fraction, TariffSettings(cap_factor=args.cap_factor),
                           args.small_load)
    print(f"{scn.tb.spec.name}: control from {scn.start:%a %Y-%m-%d %H:%M} for {args.hours:g} h; "
          f"{SMALL_BOX_ZONE}'s box at {args.small_fraction:.0%}"
          + (f" with {args.small_load:g} W more heat" if args.small_load else "")
          + f"; event cap {scn.cap_kw:.2f} kW; "
          f"floor area {scn.area:.0f} m²")
    results = [run_baseline(scn, small_box_baseline(scn), "baseline (band set points)")]
    meta = {"example": "demand_response", "args": vars(args), "start": str(scn.start),
            "cap_kw": scn.cap_kw, "area_m2": scn.area, "tariff": vars(scn.tariff), "models": {}}
    for mk in [m.strip() for m in args.model.split(",") if m.strip()]:
        model = controller_model(scn.tb, mk, end=scn.start)
        mpc = LinearMPC(model, scn.hvac, scn.comfort_zones, dt=args.step * 60.0, horizon=N,
                        tariff=True, transcription=args.transcription)
        meta["models"][mk] = {"edges": [(e.a, e.b) for e in model.network.convection_edges],
                              "rbar_v": np.asarray(model.rbar_v).tolist()}
        results.append(run_mpc(scn, mpc, model, f"linear MPC ({mk} model)", args.backoff,
                               warmup_hours=args.warmup, progress=args.verbose))
    table = pd.DataFrame.from_dict({r.name: dr_kpis(r, scn) for r in results}, orient="index")
    print(format_table(table))
    paths = save_outputs(args.out, "demand_response", table, meta)
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return table


if __name__ == "__main__":
    main()
