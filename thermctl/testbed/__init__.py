"""Synthetic testbed: multi-zone buildings with known air exchange, operated like a real BAS.

The demo, the tests and the benchmarks need data whose truth is known. :func:`generate`
simulates a building whose thermal model is known exactly — walls (3R2C), zone
capacitances and true convection edges (``rbar_v·d``, ``c_v``) — under realistic
operation, and returns the data a building automation system would log:

* occupied hours (weekdays 06:00–19:00) with closed-loop VAV zone control: PI loops on
  supply flow (minimum 30 % of maximum) and reheat (dual maximum), per-zone set points;
* nights and weekends with the supply off: the zones float;
* unmeasured heat gains — occupants arriving, leaving and lunching at random, equipment,
  lighting, sun through south windows — that differ by zone and day;
* outdoor temperature with a daily cycle and day-to-day weather (Gainesville in late
  January by default), measured neighbouring spaces with their own set points and drift;
* sensor offsets and noise, flow calibration errors, 0.1 °F / 1 CFM export rounding,
  optional missing samples.

The plant is the true :class:`~thermctl.model.ThermalModel` itself, integrated with an
L-stable Radau IIA step at the control step (1 min by default; the controller acts there
too), so the convection edges' time constants of seconds do no harm. The data are logged at
``step_minutes``: temperatures as sampled sensor readings, supply flow and temperature as
the command in force at the time stamp.

Examples
--------
>>> from thermctl.testbed import generate
>>> tb = generate("pugh-hall", days=26, seed=0)           # doctest: +SKIP
>>> tb.data.filter(like="T:r24").describe()               # doctest: +SKIP
>>> tb.truth.edges                                        # doctest: +SKIP
[('r240', 'r243', 2.8), ('r241', 'r247', 5.8), ('r242', 'r244', 6.4)]
>>> tb.write("testbed-out", units="imperial")             # doctest: +SKIP
"""

from __future__ import annotations

import json
import logging
import math
import time as _time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from .. import rc
from ..errors import SpecError
from ..model import C_V_PAPER, RBAR_V_PAPER, ThermalModel
from ..network import ThermalNetwork
from ..spec import BuildingSpec
from .buildings import (Layout, corridor_floor_spec, corridor_for_zones, pugh_hall_layout,
                        pugh_hall_spec)
from .disturbances import (GAIN_MODELS, Disturbances, OccupancySettings, WeatherSettings,
                           make_disturbances)
from .family import (add_floor_above, hide_offices, l_shape_layout, open_plan_layout,
                     random_walls, ring_layout)
from .fdplant import FD_NODES, FDPlant
from .output import (SensorNoise, Truth, bas_export, json_ready, load_truth, to_imperial,
                     write_data_csv)
from .plant import (HvacSettings, Measurement, PadeZoneStepper, Plant, VAVController,
                    run_closed_loop, single_thread_blas)

__all__ = [
    "generate", "TestbedResult", "Truth", "load_truth",
    "pugh_hall_spec", "corridor_floor_spec", "Layout",
    "Plant", "FDPlant", "Measurement", "VAVController", "run_closed_loop", "PadeZoneStepper",
    "single_thread_blas",
    "Disturbances", "make_disturbances",
    "HvacSettings", "WeatherSettings", "OccupancySettings", "SensorNoise",
    "BUILDINGS", "PLANTS", "T_MIN", "T_MAX",
]

log = logging.getLogger(__name__)

BUILDINGS = ("pugh-hall", "corridor", "ring", "ring-office", "ring-equipment", "l-shape",
             "open-plan")
"""Names accepted by :func:`generate`."""

PLANTS = ("rc", "rc-exact", "fd")
"""Plants accepted by :func:`generate`: the 3R2C model on the Radau step (default), the
3R2C model with exact zero-order hold of every control step, finite-volume walls
(:class:`FDPlant`)."""

_FAMILY_DEFAULTS = {"plant": "rc", "walls": "types", "wall_spec": "u_value", "gains": "arrivals",
                    "gain_noise": None, "neighbour_noise": 0.0, "hide": 0, "floor_above": False,
                    "fd_nodes": FD_NODES, "internal_mass": None, "wall_factor": None}

T_MIN, T_MAX = 4.0, 20.0
"""The paper's bounds on the convection time constant per unit distance [s/m]."""

TIMEZONE = "America/New_York"
"""Local time of the default building (Gainesville, FL): schedules follow its clock."""


@dataclass
class TestbedResult:
    """A generated testbed: the building, its truth, and the data a BAS would log.

    Attributes
    ----------
    spec : BuildingSpec
        Walls and distances, no convection edges (what a user would write).
    data : pandas.DataFrame
        SI, tz-aware DatetimeIndex at ``step_minutes``; columns ``T:<node>`` [°C] for
        measured zones and boundary nodes (unmeasured zones absent), ``Ts:<zone>`` [°C] and
        ``ms:<zone>`` [kg/s] for zones with a VAV box, ``solar:south`` [W/m²] if any zone
        has south windows. Quantised and noisy as exported; NaN where missing.
    truth : Truth
        True edges, parameters, alpha, seed and every setting.
    network : ThermalNetwork
        Spec plus the true convection edges.
    model : ThermalModel
        The true model (the plant).
    gains : pandas.DataFrame
        Unmeasured heat gains per zone [W] (columns: zone names), mean over each data
        step, same index as ``data``.
    states : ndarray, shape (n_steps, n_states)
        True full state at each data time stamp [°C] (before any sensor).
    inputs : ndarray, shape (n_steps, n_inputs)
        True model inputs in force at each time stamp (``network.input_names`` order).
    disturbances : Disturbances
        Boundary temperatures and gains on the control grid for the data period.
    layout : Layout
    controller : VAVController
        The baseline controller that produced the data (its boxes and set points); call
        ``reset()`` before driving :meth:`plant` with it again.
    settings : dict
        Every generator setting (also in ``truth.settings``).
    sensor_bias : ndarray, shape (n_measured,)
        Constant offsets of the zone sensors [K] (also in ``truth.details``).
    """

    spec: BuildingSpec
    data: pd.DataFrame
    truth: Truth
    network: ThermalNetwork
    model: ThermalModel
    gains: pd.DataFrame
    states: np.ndarray
    inputs: np.ndarray
    disturbances: Disturbances
    layout: Layout
    controller: VAVController
    settings: dict = field(default_factory=dict)
    sensor_bias: np.ndarray | None = None

    __test__ = False  # not a pytest test class despite the name

    def plant(self, seed: int | None = None) -> Plant:
        """A fresh :class:`Plant` at the first data time stamp, with the same disturbances.

        Other controllers (MPC) can drive it for the data period; its sensors have the
        same offsets and noise level as the generated data.
        """
        noise = self.settings.get("noise") or {}
        fam = {**_FAMILY_DEFAULTS, **self.settings.get("family", {})}
        kw = dict(sensor_sd=noise.get("T_sd", 0.0), sensor_bias=self.sensor_bias,
                  seed=self.truth.seed + 1 if seed is None else seed,
                  sensed=self.controller_sensed)
        if fam["plant"] == "fd":
            return FDPlant(self.model, self.disturbances, x0=self.states[0],
                           nodes=fam["fd_nodes"], **kw)
        return Plant(self.model, self.disturbances, x0=self.states[0],
                     method="exact" if fam["plant"] == "rc-exact" else "radau", **kw)

    @property
    def controller_sensed(self) -> list:
        """Zones whose thermostats the controller reads: measured, then unlogged ones."""
        return list(self.spec.measured_zones) + list(self.truth.details.get("sensed_unlogged", []))

    def write(self, outdir, units: str = "si") -> dict:
        """Write ``building.yaml``, ``data.csv``, ``truth.json`` and ``gains.csv``.

        Parameters
        ----------
        outdir : str or Path
            Created if needed.
        units : {"si", "imperial"}
            ``imperial`` writes ``data.csv`` as a BAS would: ``T:``/``Ts:`` in °F and
            ``vs:<zone>`` in CFM (the spec, truth and gains stay SI).

        Returns
        -------
        dict
            File role → path.
        """
        if units not in ("si", "imperial"):
            raise SpecError(f"units must be 'si' or 'imperial', found {units!r}")
        out = Path(outdir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {k: out / f for k, f in (("building", "building.yaml"), ("data", "data.csv"),
                                         ("truth", "truth.json"), ("gains", "gains.csv"))}
        self.spec.dump(paths["building"])
        write_data_csv(self.data, paths["data"], units=units)
        truth = self.truth.to_dict()
        truth["settings"] = {**truth["settings"], "units": units}
        paths["truth"].write_text(json.dumps(json_ready(truth), indent=2) + "\n")
        g = self.gains.round(2)
        g.columns = [f"Q:{z}" for z in g.columns]
        g.insert(0, "time", [t.isoformat() for t in g.index])
        g.to_csv(paths["gains"], index=False, lineterminator="\n")
        return paths

    def data_imperial(self) -> pd.DataFrame:
        """``data`` in BAS units: °F and CFM (``vs:<zone>``)."""
        return to_imperial(self.data)


def _resolve(building, zones, seed) -> Layout:
    if isinstance(building, Layout):
        return building
    if isinstance(building, str):
        key = building.lower().replace("_", "-")
        if key in ("pugh-hall", "pugh", "pugh-hall-2f"):
            if zones not in (None, 7):
                raise SpecError(f"building 'pugh-hall' has 7 zones; --zones {zones} is for "
                                "the 'corridor' building")
            return pugh_hall_layout()
        if key == "corridor":
            return corridor_for_zones(50 if zones is None else zones, seed=seed)
        if key in ("ring", "ring-hall", "ring-office", "ring-equipment"):
            core = key.partition("-")[2] or "hall"
            return ring_layout(3 if zones is None else _ring_side(zones), core=core, seed=seed)
        if key in ("l-shape", "l"):
            return l_shape_layout(seed=seed)
        if key == "open-plan":
            return open_plan_layout(seed=seed)
        raise SpecError(f"unknown testbed building {building!r}; choose from {list(BUILDINGS)} "
                        "or pass (spec, edges)")
    if isinstance(building, BuildingSpec):
        return Layout.from_spec(building)
    if isinstance(building, (tuple, list)) and len(building) == 2 \
            and isinstance(building[0], BuildingSpec):
        return Layout.from_spec(building[0], building[1])
    raise SpecError(f"building must be a name {list(BUILDINGS)}, a BuildingSpec or "
                    f"(BuildingSpec, edges); found {type(building).__name__}")


def _ring_side(zones):
    if int(zones) != zones or zones < 7 or (zones - 3) % 2:
        raise SpecError(f"zones must be an odd integer >= 7 for the ring building (2 n + 2 "
                        f"offices and the core), found {zones!r}")
    return (int(zones) - 3) // 2


def _choice(name, value, allowed):
    if value not in allowed:
        raise SpecError(f"{name} must be one of {list(allowed)}, found {value!r}")
    return value


def _check(name, value, unit, lo=0.0, hi=None, positive=True):
    """A finite number > 0 (``positive``) or in [lo, hi)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SpecError(f"{name}: expected a number {unit}, found {value!r}") from None
    if positive:
        if not (math.isfinite(v) and v > 0):
            raise SpecError(f"{name} must be finite and > 0 {unit}, found {value!r}")
    elif not (math.isfinite(v) and lo <= v and (hi is None or v < hi)):
        where = f"[{lo}, {hi})" if hi is not None else f">= {lo}"
        raise SpecError(f"{name} must be in {where} {unit}, found {value!r}")
    return v


def generate(building="pugh-hall", *, days: float = 26, step_minutes: float = 5,
             start: str = "2011-01-21", rbar_v=RBAR_V_PAPER, c_v=C_V_PAPER, seed: int = 0,
             zones: int | None = None, control_minutes: float = 1.0, burn_in_days: float = 3,
             missing: float = 0.0, noise: SensorNoise | None = SensorNoise(),
             hvac: HvacSettings = HvacSettings(), weather: WeatherSettings = WeatherSettings(),
             occupancy: OccupancySettings = OccupancySettings(), timezone: str = TIMEZONE,
             plant: str = "rc", walls: str = "types", wall_spec: str = "u_value",
             gains: str = "arrivals", gain_noise: float | None = None,
             neighbour_noise: float = 0.0, hide: int = 0,
             floor_above: bool = False, fd_nodes: int = FD_NODES,
             internal_mass=None, wall_factor=None, progress=None) -> TestbedResult:
    """Simulate a building with known convection edges operated by a VAV BAS.

    Parameters
    ----------
    building : str, BuildingSpec, (BuildingSpec, edges) or Layout
        ``"pugh-hall"`` (the paper's 7-zone section, default), ``"corridor"`` (about
        ``zones`` zones, see :func:`corridor_floor_spec`), a spec without air paths, or a
        spec with true edges ``[(a, b)]`` / ``[(a, b, d)]``. For a user spec, measured zones
        get a VAV box and occupants, unmeasured zones neither.
    days : float
        Length of the data [days], > 0. The paper: 26.
    step_minutes : float
        Data step [min]; a multiple of ``control_minutes``. The paper: 5.
    start : str
        First time stamp, local time (``timezone``). The paper: 2011-01-21.
    rbar_v : float or sequence
        True convection resistance per unit distance [K/(W m)], shared or one per true
        edge. Default: the paper's 3.36e-4.
    c_v : float or sequence
        True convection capacitance [J/K]. Default: the paper's 1.19e3.
    seed : int
        Seeds everything (weather, people, boxes, sensors, gaps; corridor air paths).
    zones : int, optional
        Number of zones of the ``"corridor"`` building (default 50).
    control_minutes : float
        Control and integration step [min] (default 1: the controller acts between data
        samples, as a real BAS does). Equal to ``step_minutes`` makes the logged inputs
        exactly the plant's zero-order-hold inputs.
    burn_in_days : float
        Simulated before ``start`` and discarded, so walls start in a realistic state.
    missing : float
        Fraction of missing samples in [0, 1) (sensor dropouts and export outages).
    noise : SensorNoise or None
        Sensor imperfections; ``None`` logs the plant's true values.
    hvac : HvacSettings
    weather : WeatherSettings
    occupancy : OccupancySettings
    timezone : str
        IANA name for the local clock that drives schedules.
    plant : {"rc", "rc-exact", "fd"}
        ``rc``: the true 3R2C model on the Radau IIA step (default); ``rc-exact``: the same
        model with exact zero-order hold of each control step; ``fd``: walls resolved by
        ``2 fd_nodes`` finite volumes each and an independent L-stable SDIRK integrator
        (:class:`FDPlant`) — a plant that is not the identification model. ``model`` stays
        the 3R2C description in every case.
    walls : {"types", "random"}
        ``types``: the layout's wall types (:data:`buildings.WALL_TYPES`, homogeneous-slab
        split); ``random``: every wall's area, U-value and heat capacity drawn at random,
        split 25/50/25 % in resistance (:func:`family.random_walls`).
    wall_spec : {"u_value", "plant"}
        With ``walls="random"``: the spec returned (and written) lists each wall's area,
        U-value and heat capacity (homogeneous split, as a user would write it; default) or
        the plant's own 3R2C values.
    gains : {"arrivals", "hourly"}
        Occupancy model: ``arrivals`` (occupants arrive, lunch and leave at random times;
        default) or ``hourly`` (a per-day presence level, presence redrawn every hour, plus
        white noise of :data:`disturbances.GAIN_NOISE_SD` per control step).
    gain_noise : float, optional
        White noise on every office's gain per control step [W]; default 30 W with
        ``gains="hourly"``, none with ``"arrivals"``.
    neighbour_noise : float
        White noise on the true temperature of indoor boundary nodes (conditioned
        neighbours) per control step [K]; 0 for none.
    hide : int
        Offices whose thermostat the BAS does not log (outside the true air paths; they keep
        their VAV box and occupants).
    floor_above : bool
        Put a measured floor above the layout (:func:`family.add_floor_above`).
    fd_nodes : int
        Finite volumes per wall layer of ``plant="fd"``.
    internal_mass : float or dict, optional
        Mass the spec omits: the plant's zone capacitance is this factor [-] (>= 1) times
        the published spec's (one number for every zone, or ``{zone: factor}``); the spec
        returned keeps the published value, ``truth.details["zone_capacitance"]`` holds
        the plant's. Every plant (``rc``, ``rc-exact``, ``fd``) uses it. Default: none.
    wall_factor : dict, optional
        Walls of uncertain construction: ``{class: f}`` (classes ``exterior``,
        ``partition``, ``boundary`` of :func:`thermctl.spec.wall_class`)
        multiplies the plant's conductances of every wall of that class by f (all three
        resistances ``R/f``, capacities kept); the spec returned keeps the published walls.
        Every plant uses it. Default: none.
    progress : callable, optional
        ``progress(done, total)`` called as the simulation advances (control steps).

    Returns
    -------
    TestbedResult

    Raises
    ------
    SpecError
        On an unknown building or invalid settings (the message names the setting).
    ModelError
        If ``rbar_v`` or ``c_v`` has the wrong number of values for the true edges.

    Examples
    --------
    >>> tb = generate(days=2, seed=1)
    >>> list(tb.data.columns[:2])
    ['T:r240', 'T:r241']
    >>> len(tb.data), tb.states.shape[0]
    (576, 576)
    """
    t_start = _time.perf_counter()
    days = _check("days", days, "[days]")
    step_minutes = _check("step_minutes", step_minutes, "[min]")
    control_minutes = _check("control_minutes", control_minutes, "[min]")
    burn_in_days = _check("burn_in_days", burn_in_days, "[days]", positive=False)
    missing = _check("missing", missing, "[-]", 0.0, 1.0, positive=False)
    ratio = step_minutes / control_minutes
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise SpecError(f"step_minutes ({step_minutes}) must be a whole multiple of "
                        f"control_minutes ({control_minutes})")
    r = int(round(ratio))
    n_data = days * 1440.0 / step_minutes
    if abs(n_data - round(n_data)) > 1e-9:
        raise SpecError(f"days ({days}) must hold a whole number of {step_minutes}-min steps")
    n_data = int(round(n_data))
    n_burn = int(round(burn_in_days * 1440.0 / step_minutes)) * r
    n_ctrl = n_burn + n_data * r
    seed = int(seed)

    _choice("plant", plant, PLANTS)
    _choice("walls", walls, ("types", "random"))
    _choice("wall_spec", wall_spec, ("u_value", "plant"))
    _choice("gains", gains, GAIN_MODELS)
    neighbour_noise = _check("neighbour_noise", neighbour_noise, "[K]", positive=False)
    if gain_noise is not None:
        gain_noise = _check("gain_noise", gain_noise, "[W]", positive=False)
    family = {k: v for k, v in (("plant", plant), ("walls", walls), ("wall_spec", wall_spec),
                                ("gains", gains), ("gain_noise", gain_noise),
                                ("neighbour_noise", neighbour_noise),
                                ("hide", hide), ("floor_above", floor_above),
                                ("fd_nodes", fd_nodes), ("internal_mass", internal_mass),
                                ("wall_factor", wall_factor))
              if v != _FAMILY_DEFAULTS[k]}
    # the family's draws come from their own stream: the default buildings stay bit-for-bit
    rng_family = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(24,)))

    layout = _resolve(building, zones, seed)
    if floor_above:
        layout = add_floor_above(layout)
    layout = hide_offices(layout, hide, rng_family)
    wall_draws = {}
    if walls == "random":
        layout, spec, wall_draws = random_walls(layout, rng_family, wall_spec)
    else:
        spec = layout.spec
    plant_spec = layout.spec if internal_mass is None else _with_internal_mass(layout.spec,
                                                                              internal_mass)
    if wall_factor is not None:
        plant_spec = _with_wall_factor(plant_spec, wall_factor)
    net = ThermalNetwork(plant_spec, layout.edges)
    model = ThermalModel(net, rbar_v=rbar_v, c_v=c_v)
    p = model.p  # validates rbar_v / c_v against the number of edges

    streams = np.random.SeedSequence(seed).spawn(4)
    rng_dist, rng_hvac, rng_sensor, rng_gaps = (np.random.default_rng(s) for s in streams)
    try:
        t0 = pd.Timestamp(start)
    except (ValueError, TypeError):
        raise SpecError(f"start: not a date/time {start!r} (use e.g. 2011-01-21)") from None
    t0 = t0.tz_localize(timezone) if t0.tzinfo is None else t0.tz_convert(timezone)
    dt = control_minutes * 60.0
    first = t0 - pd.Timedelta(seconds=n_burn * dt)
    time = pd.date_range(first, periods=n_ctrl, freq=pd.Timedelta(seconds=dt))
    dist = make_disturbances(layout, time, dt, rng_dist, weather, occupancy, hvac.hours,
                             hvac.weekdays_only, hvac.T_ahu, gains_model=gains,
                             gain_noise=gain_noise, neighbour_noise=neighbour_noise,
                             rng_extra=rng_family)
    if noise is None:
        dist.T_boundary_logged = dist.T_boundary.copy()

    # VAV boxes and set points
    boxes, heat_sp, cool_sp = {}, {}, {}
    for z in spec.zone_names:
        if layout.kind.get(z) != "office":     # hidden offices keep their box
            continue
        size = 1.0 + rng_hvac.uniform(-hvac.flow_spread, hvac.flow_spread)
        ms_max = hvac.flow_per_area * layout.floor_area[z] * size
        boxes[z] = (hvac.min_fraction * ms_max, ms_max, hvac.heat_max_fraction * ms_max)
        off = rng_hvac.normal(0.0, hvac.setpoint_sd)
        heat_sp[z], cool_sp[z] = hvac.heat_setpoint + off, hvac.cool_setpoint + off
    # thermostats the BAS does not log (hidden conditioned zones) come after the logged ones
    sensed = list(spec.measured_zones) + [z for z in spec.zone_names
                                          if z in boxes and z not in spec.measured_zones]
    ctrl = VAVController(spec.zone_names, boxes, heat_sp, cool_sp, sensed, hvac, dt)

    nm = len(spec.measured_zones)
    if noise is not None:
        bias = rng_sensor.normal(0.0, noise.T_bias_sd, nm)
        flow_gain = 1.0 + rng_sensor.normal(0.0, noise.flow_gain_sd, len(spec.zone_names))
        if len(sensed) > nm:
            bias = np.concatenate([bias, rng_family.normal(0.0, noise.T_bias_sd, len(sensed) - nm)])
    else:
        bias, flow_gain = np.zeros(len(sensed)), np.ones(len(spec.zone_names))
    plant_kw = dict(sensor_sd=0.0 if noise is None else noise.T_sd, sensor_bias=bias,
                    seed=rng_sensor, sensed=sensed)
    if plant == "fd":
        the_plant = FDPlant(model, dist, nodes=fd_nodes, **plant_kw)
    else:
        the_plant = Plant(model, dist, method="exact" if plant == "rc-exact" else "radau",
                          **plant_kw)

    nz, nb = net.n_zones, len(net.boundary)
    T_rec = np.empty((n_data, nm))
    Tb_rec = np.empty((n_data, nb))
    ms_rec = np.empty((n_data, nz))
    Ts_rec = np.empty((n_data, nz))
    X = np.empty((n_data, the_plant.n_states))
    U = np.empty((n_data, net.n_inputs))
    meas = the_plant.measure()
    report = max(1, n_ctrl // 200)
    with single_thread_blas():
        for k in range(n_ctrl):
            ms, Ts = ctrl(meas)
            j, rem = divmod(k - n_burn, r)
            if k >= n_burn and rem == 0:
                T_rec[j], Tb_rec[j], ms_rec[j], Ts_rec[j] = meas.T[:nm], meas.T_boundary, ms, Ts
                X[j] = the_plant.x
                U[j] = the_plant.inputs(ms, Ts, k)
            meas = the_plant.step(ms, Ts)
            if progress is not None and (k % report == 0 or k == n_ctrl - 1):
                progress(k + 1, n_ctrl)

    rec = {"T": T_rec, "Tb": Tb_rec, "ms": ms_rec, "Ts": Ts_rec, "x": X}
    data, gains = bas_export(layout, net, dist, rec, n_burn=n_burn, every=r, flow_gain=flow_gain,
                             noise=noise, boxes=boxes, missing=missing, rng=rng_sensor,
                             rng_gaps=rng_gaps, step_minutes=step_minutes)
    alpha = spec.alpha()
    rc = np.asarray(rbar_v, float) * np.asarray(c_v, float)
    settings = {
        "building": building if isinstance(building, str) else spec.name, "spec_name": spec.name,
        "zones": zones, "days": days, "step_minutes": step_minutes, "start": t0.isoformat(),
        "timezone": timezone, "control_minutes": control_minutes, "burn_in_days": burn_in_days,
        "missing": missing, "noise": None if noise is None else asdict(noise),
        "hvac": asdict(hvac), "weather": asdict(weather), "occupancy": asdict(occupancy),
    }
    if family:  # only what differs from the default (the default truth files stay as they were)
        settings["family"] = family
    details = {
        "rbar_v_c_v": rc.tolist() if rc.ndim else float(rc),
        "rbar_v_c_v_bounds": [T_MIN / alpha, T_MAX / alpha],
        "convection_time_constants_s": {f"{a}-{b}": float(t) for (a, b, _), t in zip(
            layout.edges, _conv_time_constants(model, p))},
        "zone_capacitance": dict(zip(net.zones, map(float, model.capacitances()[:nz]))),
        "sensor_bias": dict(zip(spec.measured_zones, map(float, bias))),
        "flow_gain": {z: float(g) for z, g in zip(net.zones, flow_gain) if z in boxes},
        "vav_boxes": {z: {"ms_min": b[0], "ms_max": b[1], "ms_heat_max": b[2],
                          "heat_setpoint": heat_sp[z], "cool_setpoint": cool_sp[z]}
                      for z, b in boxes.items()},
        "solar_aperture": dict(layout.solar_aperture),
        "unmeasured_zones": [z for z in net.zones if z not in spec.measured_zones],
        **dist.info,
    }
    if family:
        details["zone_kinds"] = dict(layout.kind)
        details["sensed_unlogged"] = sensed[nm:]
        if wall_draws:
            details["walls"] = wall_draws
            details["plant_walls"] = {w.name: {"R": list(w.R), "C": list(w.C)}
                                      for w in layout.spec.walls}
        if plant == "fd":
            details["fd"] = {"nodes_per_layer": fd_nodes, "states": the_plant.n_states,
                             "substeps": the_plant.substeps}
    truth = Truth(list(layout.edges), _plain(rbar_v), _plain(c_v), alpha, spec.alphas(), seed,
                  json_ready(settings), json_ready(details))
    log.info("testbed %s: %d zones, %d states, %d days in %.2f s", spec.name, nz, net.n_states,
             days, _time.perf_counter() - t_start)
    return TestbedResult(spec, data, truth, net, model, gains, X, U,
                         dist.window(n_burn), layout, ctrl, settings, bias)


def _with_internal_mass(spec: BuildingSpec, factor) -> BuildingSpec:
    """``spec`` with zone capacitances times ``factor`` (a number or ``{zone: factor}``)."""
    names = spec.zone_names
    if isinstance(factor, dict):
        bad = sorted(set(factor) - set(names))
        if bad:
            raise SpecError(f"internal_mass: {bad} are not zones ({names})")
        f = {z: _check(f"internal_mass[{z}]", v, "[-]") for z, v in factor.items()}
    else:
        f = dict.fromkeys(names, _check("internal_mass", factor, "[-]"))
    low = {z: v for z, v in f.items() if v < 1.0}
    if low:
        raise SpecError(f"internal_mass must be >= 1 (mass added to the spec's), found {low}")
    zones = tuple(replace(z, capacitance=f[z.name] * spec.zone_capacitance(z.name))
                  if z.name in f else z for z in spec.zones)
    return replace(spec, zones=zones)


def _with_wall_factor(spec: BuildingSpec, factor) -> BuildingSpec:
    """``spec`` with the walls of each class in ``factor`` (``{class: f}``) at ``R/f``."""
    from ..spec import WALL_CLASSES, wall_class

    if not isinstance(factor, dict):
        raise SpecError(f"wall_factor: expected {{class: factor}} with classes {WALL_CLASSES}, "
                        f"found {factor!r}")
    bad = sorted(set(factor) - set(WALL_CLASSES))
    if bad:
        raise SpecError(f"wall_factor: {bad} are not wall classes {WALL_CLASSES}")
    f = {c: _check(f"wall_factor[{c}]", v, "[-]") for c, v in factor.items()}
    zones = set(spec.zone_names)
    walls = tuple(replace(w, R=tuple(r / f[c] for r in w.R))
                  if (c := wall_class(w.a, w.b, zones)) in f else w for w in spec.walls)
    return replace(spec, walls=walls)


def _plain(v):
    a = np.asarray(v, dtype=float)
    return float(a) if a.ndim == 0 else a.tolist()


def _conv_time_constants(model, p):
    m = len(model.network.convection_edges)
    out = []
    for e, rb, cv in zip(model.network.convection_edges, p[:m], p[m:]):
        R = rb * e.d
        out.append(rc.time_constant([R] * 3, [cv] * 2))
    return out
