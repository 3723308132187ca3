"""The closed loop: testbed plant, baseline BAS, MPC with a Kalman filter, and the example runner.

Protocol (the same for every controller):

1. :func:`thermctl.testbed.generate` simulates the building under its baseline BAS for
   the identification days plus the control period; the controller model is identified
   from the data logged *before* the control period only.
2. Every controller then drives a fresh :class:`thermctl.testbed.Plant` over the control
   period: the true model, the same disturbances (weather, neighbours, gains), the same
   start state (the true state the baseline left at that time), the same sensor offsets
   and noise level. The plant steps at the testbed's control step (1 min); the MPC acts
   every ``--step`` minutes and holds its input in between; the VAV box never delivers
   air colder than the cold deck.
3. KPIs (:func:`mpc_examples.common.kpis`) are computed from the plant's true
   temperatures and the applied inputs, with the same energy model for everyone.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd

from thermctl.testbed import Plant, VAVController, generate

from .common import (ClosedLoopResult, ComfortBand, Forecast, HVACModel, example_parser,
                     format_table, kpi_table, plot_closed_loop, save_outputs)
from .model import GainKalmanFilter, controller_model, reduced_model

__all__ = ["Scenario", "make_scenario", "run_baseline", "band_baseline", "make_controller",
           "run_mpc", "run_example"]

log = logging.getLogger(__name__)

ID_DAYS = 14
"""Days of baseline data the controller model is identified from (SIN needs >= n + 2)."""


@dataclass
class Scenario:
    """One control experiment on a testbed building.

    Attributes
    ----------
    tb : thermctl.testbed.TestbedResult
    k0 : int
        Index of the first control step into ``tb.disturbances``.
    n_steps : int
        Plant steps of the run.
    hvac : HVACModel
    band : ComfortBand
    comfort_zones : list of str
        Measured zones with a VAV box.
    """

    tb: object
    k0: int
    n_steps: int
    hvac: HVACModel
    band: ComfortBand
    comfort_zones: list

    @property
    def dt(self) -> float:
        """Plant step [s]."""
        return float(self.tb.disturbances.dt)

    @property
    def start(self):
        return self.tb.disturbances.time[self.k0]

    def plant(self, seed: int = 1) -> Plant:
        """A fresh plant at the start of the control period (true state, same sensors)."""
        tb = self.tb
        r = int(round(tb.settings["step_minutes"] * 60.0 / self.dt))
        if self.k0 % r:
            raise ValueError("the control period must start on a data time stamp")
        noise = tb.settings.get("noise") or {}
        d = tb.disturbances.window(self.k0)
        return Plant(tb.model, d, x0=tb.states[self.k0 // r], sensor_sd=noise.get("T_sd", 0.0),
                     sensor_bias=tb.sensor_bias, seed=tb.truth.seed + seed)

    def forecast(self, k: int, N: int, every: int, gains, T_c: float, steps=None) -> Forecast:
        """What the MPC knows at plant step ``k`` of the run for ``N`` steps of ``every`` plant steps.

        Boundary temperatures: the logged values, averaged over each MPC step (perfect
        forecast of what the BAS records). Gains: ``gains`` [W] per zone held (the
        Kalman filter's estimate). Cold deck: the current reading held. Comfort band at the end of
        each step; occupied mode at its start. ``steps`` (N ints, optional): a non-uniform
        grid, step ``j`` lasting ``steps[j] · every`` plant steps (``LinearMPC(steps=...)``).
        """
        d = self.tb.disturbances
        a = self.k0 + k
        lengths = every * (np.ones(N, int) if steps is None else np.asarray(steps, int))
        ends = np.cumsum(lengths)
        starts = ends - lengths
        if a + ends[-1] - 1 >= len(d):
            raise ValueError(f"the testbed's disturbances end {a + ends[-1] - len(d)} plant steps "
                             "before the horizon does: generate more days")
        Tb = np.add.reduceat(d.T_boundary_logged[a: a + ends[-1]], starts, axis=0) / lengths[:, None]
        out = d.boundary.index(_outdoor(d.boundary))
        lo, hi = self.band.bounds(d.time[a + ends])
        return Forecast(T_boundary=Tb, gains=np.tile(np.asarray(gains, float), (N, 1)),
                        T_out=Tb[:, out], T_c=np.full(N, float(T_c)),
                        hvac_on=np.asarray(d.occupied[a + starts]), lo=lo, hi=hi)


def _outdoor(boundary):
    from thermctl.testbed.disturbances import OUTDOOR_NAMES
    for b in boundary:
        if b.lower() in OUTDOOR_NAMES:
            return b
    raise ValueError(f"no outdoor boundary node among {boundary}")


def make_scenario(zones: int = 7, seed: int = 0, hours: float = 72.0, horizon_hours: float = 8.0,
                  start_day: int | None = None, start_hour: float = 0.0,
                  band: ComfortBand = ComfortBand()) -> Scenario:
    """Generate the testbed and fix the control period.

    Parameters
    ----------
    zones : int
        7: Pugh Hall section (the paper's building); otherwise the corridor floor with about
        this many zones.
    seed : int
    hours : float
        Length of the control period [h].
    horizon_hours : float
        Longest prediction horizon that will be used [h] (the disturbances must cover it).
    start_day : int, optional
        Day index (from the testbed's first day) the control period starts on, at
        midnight. Default: the first Monday on or after day :data:`ID_DAYS`.
    start_hour : float
        Hour of that day the control period starts [h] (a multiple of the data step).
    band : ComfortBand
    """
    start = "2011-01-21"  # the paper's first day (a Friday)
    first = pd.Timestamp(start)
    if start_day is None:
        start_day = ID_DAYS + (7 - (first + pd.Timedelta(days=ID_DAYS)).day_of_week) % 7
    if start_day < 0:
        raise ValueError(f"start_day must be >= 0, found {start_day}")
    days = start_day + math.ceil((start_hour + hours + horizon_hours) / 24.0 + 1e-9)
    building = "pugh-hall" if zones == 7 else "corridor"
    tb = generate(building, days=days, seed=seed, start=start,
                  zones=None if zones == 7 else zones)
    dt = float(tb.disturbances.dt)
    k0 = int(round((start_day * 86400.0 + start_hour * 3600.0) / dt))
    n_steps = int(round(hours * 3600.0 / dt))
    boxes = tb.truth.details["vav_boxes"]
    zones_all = tb.network.zones
    ms_min = np.array([boxes[z]["ms_min"] if z in boxes else 0.0 for z in zones_all])
    ms_max = np.array([boxes[z]["ms_max"] if z in boxes else 0.0 for z in zones_all])
    hvac = HVACModel(cp=tb.spec.cp, ms_min=ms_min, ms_max=ms_max,
                     Ts_max=float(tb.controller.settings.Ts_max))
    comfort = [z for z in tb.spec.measured_zones if z in boxes]
    return Scenario(tb, k0, n_steps, hvac, band, comfort)


def _result(name, scn, plant, T, ms, Ts, n, solve_time=(), cpu_time=(), failures=0, extra=None):
    d = scn.tb.disturbances
    idx = scn.k0 + np.arange(n)
    out = d.boundary.index(_outdoor(d.boundary))
    time_ = d.time[scn.k0: scn.k0 + n + 1]
    res = ClosedLoopResult(name, time_, list(plant.network.zones), np.asarray(T), np.asarray(ms),
                           np.asarray(Ts), d.T_boundary[idx, out], d.T_ahu[idx],
                           list(solve_time), list(cpu_time), failures, dict(extra or {}))
    p = scn.hvac.powers(res.ms, res.Ts, res.T[:-1], res.T_out, res.T_c)
    res.extra["site_power"] = scn.hvac.site_power(p)
    return res


def run_baseline(scn: Scenario, controller: VAVController | None = None,
                 name: str = "baseline (testbed BAS)") -> ClosedLoopResult:
    """The testbed's VAV controller (or ``controller``) on a fresh plant."""
    ctrl = scn.tb.controller if controller is None else controller
    ctrl.reset()
    plant = scn.plant()
    T, ms_rec, Ts_rec = [plant.T_zones], [], []

    def record(meas, ms, Ts, plant_):
        ms_rec.append(np.array(ms, float))
        Ts_rec.append(np.array(Ts, float))

    meas = plant.measure()
    for _ in range(scn.n_steps):
        ms, Ts = ctrl(meas)
        record(meas, ms, Ts, plant)
        meas = plant.step(ms, Ts)
        T.append(plant.T_zones)
    return _result(name, scn, plant, T, ms_rec, Ts_rec, scn.n_steps)


def band_baseline(scn: Scenario, margin: float = 0.5) -> VAVController:
    """The baseline BAS with its set points moved to the comfort band (``margin`` inside).

    The testbed's own set points (about 21.7 / 22.8 °C ± per-zone offsets) are narrower than
    the band; giving the baseline the band the MPC gets makes the comparison fair.
    """
    tb = scn.tb
    boxes = {z: (b["ms_min"], b["ms_max"], b["ms_heat_max"])
             for z, b in tb.truth.details["vav_boxes"].items()}
    lo, hi = scn.band.occupied
    return VAVController(tb.network.zones, boxes, {z: lo + margin for z in boxes},
                         {z: hi - margin for z in boxes}, tb.spec.measured_zones,
                         tb.controller.settings, scn.dt)


def box_inputs(ms_cmd, Ts_cmd, supplied, T_ahu: float):
    """What the VAV boxes apply of a plan's input: flow and supply temperature where a box
    is (``supplied``: its zone indices), no flow elsewhere, and a supply temperature never
    below the air-handling unit's ``T_ahu`` [°C] (a box can only reheat).

    Returns
    -------
    ms : ndarray
        [kg/s] per zone.
    Ts : ndarray
        [°C] per zone (``T_ahu`` where no box).
    """
    n = len(ms_cmd)
    ms = np.zeros(n)
    ms[supplied] = np.asarray(ms_cmd)[supplied]
    Ts = np.full(n, float(T_ahu))
    Ts[supplied] = np.maximum(np.asarray(Ts_cmd)[supplied], T_ahu)
    return ms, Ts


def run_mpc(scn: Scenario, mpc, model, name: str, backoff: float = 0.35,
            warmup_hours: float = 48.0,
            progress: bool = False) -> ClosedLoopResult:
    """Receding-horizon MPC with a :class:`GainKalmanFilter` on a fresh plant.

    Parameters
    ----------
    scn : Scenario
    mpc : EconomicMPC or LinearMPC
        Has ``dt`` [s], ``N`` and ``solve(x0, forecast) -> MPCSolution``.
    model : ThermalModel
        The MPC's model (for the Kalman filter).
    name : str
    backoff : float
        The MPC's band is the comfort band narrowed by this much on both sides [K].
    warmup_hours : float
        The filter first replays this much of the BAS log before the control period [h]
        (:meth:`GainKalmanFilter.run`): the controller takes over a running building with
        its wall states and gains already estimated. 0: start from the first reading
        (edges at the mean of their ends, gains 0).
    """
    plant = scn.plant()
    net = model.network
    if net.zones != plant.network.zones or net.boundary != plant.network.boundary:
        raise ValueError("the controller model and the plant must share zones and boundary nodes")
    every = int(round(mpc.dt / scn.dt))
    if abs(every * scn.dt - mpc.dt) > 1e-6:
        raise ValueError(f"the MPC step ({mpc.dt} s) must be a multiple of the plant step ({scn.dt} s)")
    measured = list(net.measured_zones)
    # the filter runs at the MPC step: inputs averaged over it (the supply is held anyway)
    kf = GainKalmanFilter(model, mpc.dt, measured)
    meas = plant.measure()
    if warmup_hours > 0:
        data = scn.tb.data
        kf.run(data.loc[(data.index >= scn.start - pd.Timedelta(hours=warmup_hours))
                        & (data.index < scn.start)])   # ends predicted to the start
        kf.update(meas.T)
    else:
        kf.reset(meas.T, meas.T_boundary)
    sl = net.input_slices()
    sup = scn.hvac.supplied
    T, ms_rec, Ts_rec, times, cpu, fails = [plant.T_zones], [], [], [], [], 0
    u_sum = np.zeros(net.n_inputs)
    t_run = time.perf_counter()
    for k in range(scn.n_steps):
        if k % every == 0:
            if k > 0:
                kf.predict(u_sum / every)
                kf.update(meas.T)
                u_sum[:] = 0.0
            fc = scn.forecast(k, mpc.N, every, kf.gains_all_zones(), meas.T_ahu,
                              steps=getattr(mpc, "steps", None))
            fc.lo, fc.hi = fc.lo + backoff, fc.hi - backoff
            sol = mpc.solve(kf.x, fc)
            times.append(sol.solve_time)
            cpu.append(sol.cpu_time)
            fails += not sol.success
            ms_cmd, Ts_cmd = sol.ms[0].copy(), sol.Ts[0].copy()
            if progress and (k // every) % 16 == 0:
                log.info("%s: %s, step %d/%d, solve %.3f s (%s)", name, fc.hvac_on[0],
                         k // every, scn.n_steps // every, sol.solve_time, sol.status)
        ms, Ts = box_inputs(ms_cmd, Ts_cmd, sup, meas.T_ahu)
        u_sum[sl["ms"]] += ms
        u_sum[sl["Ts"]] += Ts
        u_sum[sl["T"]] += meas.T_boundary
        ms_rec.append(ms)
        Ts_rec.append(Ts)
        meas = plant.step(ms, Ts)
        T.append(plant.T_zones)
    log.info("%s: %d steps in %.1f s", name, scn.n_steps, time.perf_counter() - t_run)
    return _result(name, scn, plant, T, ms_rec, Ts_rec, scn.n_steps, times, cpu, fails)


def run_example(kind: str, cls, argv=None):
    """Command-line entry of both examples: baseline(s) and MPC(s), table, figure.

    ``cls`` is the controller class (``EconomicMPC`` or ``LinearMPC``): the example modules
    pass themselves in, so this module never imports them (no import cycle).
    """
    parser = example_parser("Economic (nonlinear) MPC" if kind == "economic" else "Linear MPC (QP)")
    if kind == "economic":
        parser.add_argument("--transcription", choices=["implicit", "euler", "explicit"],
                            default="implicit",
                            help="the shooting gaps: Radau, sparse (implicit) or through its dense "
                                 "solve (explicit), same optimum; or implicit Euler (one-hop rows)")
    else:
        parser.add_argument("--qp-solver", choices=["piqp", "osqp", "qpoases", "highs"],
                            default="piqp",
                            help="QP solver plugin of casadi.conic")
        parser.add_argument("--transcription", choices=["zoh", "euler", "radau", "radau-dense"],
                            default="zoh",
                            help="step rows: the exported dense StateSpace, or sparse implicit "
                                 "steps of the continuous model (mpc_examples.sparse)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(message)s")
    N = int(round(args.horizon * 60.0 / args.step))
    scn = make_scenario(args.zones, args.seed, args.hours, args.horizon, args.start_day,
                        args.start_hour)
    kinds = [m.strip() for m in args.model.split(",") if m.strip()]
    print(f"{scn.tb.spec.name}: {len(scn.tb.network.zones)} zones, "
          f"{scn.tb.network.n_states} states; control from {scn.start:%a %Y-%m-%d %H:%M} "
          f"for {args.hours:g} h; MPC step {args.step:g} min, horizon {args.horizon:g} h")
    results = [run_baseline(scn)]
    if not args.no_band_baseline:
        results.append(run_baseline(scn, band_baseline(scn), "baseline (band set points)"))
    meta = {"example": kind, "args": vars(args), "building": scn.tb.spec.name,
            "start": str(scn.start), "models": {}}
    for mk in kinds:
        full = controller_model(scn.tb, mk, end=scn.start)
        model = reduced_model(scn.tb, full, args.order) if args.order else full
        mpc = make_controller(cls, model, scn, args.step, N,
                              **({"transcription": args.transcription} if kind == "economic"
                                 else {"solver": args.qp_solver,
                                       "transcription": args.transcription}))
        label = f"{'economic NMPC' if kind == 'economic' else 'linear MPC'} ({mk} model)"
        if args.order:
            label = label[:-1] + f", {model.network.n_states} states)"
        opts = (getattr(full, "meta", None) or {}).get("options", {})
        meta["models"][mk] = {"edges": [(e.a, e.b) for e in full.network.convection_edges],
                              "identification": {k: opts[k] for k in ("criterion", "selection")
                                                 if k in opts} or None,
                              "rbar_v": np.asarray(full.rbar_v).tolist(),
                              "c_v": np.asarray(full.c_v).tolist(),
                              "states": model.network.n_states,
                              "build_time_s": getattr(mpc, "build_time", None),
                              "n_variables": getattr(mpc, "n_variables", None)}
        results.append(run_mpc(scn, mpc, model, label, args.backoff,
                               warmup_hours=args.warmup, progress=args.verbose))
    table = kpi_table(results, scn.hvac, scn.band, scn.comfort_zones)
    stem = f"{kind}_mpc"
    print(format_table(table))
    paths = save_outputs(args.out, stem, table, meta)
    if not args.no_figure:
        paths["png"] = plot_closed_loop(results, scn.band, scn.comfort_zones,
                                        args.out / f"{stem}.png",
                                        title=f"{'economic NMPC' if kind == 'economic' else 'linear MPC'}"
                                              f" vs baseline — {scn.tb.spec.name}")
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return table


def make_controller(cls, model, scn: Scenario, step_minutes: float, N: int, **options):
    """The example's MPC for ``scn``.

    Parameters
    ----------
    cls : type
        :class:`~mpc_examples.economic_mpc.EconomicMPC` or
        :class:`~mpc_examples.linear_mpc.LinearMPC` (given by the caller: the simulator does
        not import the controllers, which import it for their ``main``).
    model : ThermalModel or ReducedNetwork
    scn : Scenario
    step_minutes : float
        MPC step [min].
    N : int
        Horizon [steps].
    **options
        Passed to ``cls`` (e.g. ``transcription`` for the economic MPC, ``solver`` for the
        linear one).
    """
    return cls(model, scn.hvac, scn.comfort_zones, dt=step_minutes * 60.0, horizon=N, **options)
