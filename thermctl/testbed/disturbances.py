"""What the building does not control: weather, neighbouring spaces, people and equipment.

Everything is generated on the control grid (one value per control step, held over it)
from a seeded :class:`numpy.random.Generator`:

* **outdoor temperature** — hourly "weather station" values (daily mean as an AR(1)
  process from day to day, a daily cycle with its minimum at 07:00 and maximum at 15:00
  whose amplitude shrinks on cloudy days, hourly noise), linearly interpolated; the air
  the building sees adds fast AR(1) fluctuations the hourly station does not record.
  Defaults: Gainesville, FL, late January (normal daily range about 5–20 °C).
* **solar irradiance** on a south-facing wall: clear-sky shape times a daily clearness.
* **measured neighbouring spaces** (boundary nodes that are not outdoors): held near their
  own set point in occupied hours, floating slowly towards a mix of outdoor and building
  core temperature otherwise, with their own random fluctuations.
* **heat gains** per zone: occupants arriving, leaving and going to lunch at random
  times, equipment (standby plus per person, a per-zone factor), lighting on when someone
  is in, sun through south windows; halls get lighting on the building schedule.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.signal import lfilter

from ..errors import ModelError
from ..spec import OUTDOOR_NAMES  # boundary nodes that get the weather

__all__ = ["WeatherSettings", "OccupancySettings", "Disturbances", "make_disturbances",
           "occupied_mode", "OUTDOOR_NAMES", "GAIN_MODELS", "GAIN_NOISE_SD", "HOURLY_LEVEL",
           "EQUIPMENT_ROOM"]

GAIN_MODELS = ("arrivals", "hourly")
"""Occupancy models of :func:`make_disturbances`."""

HOURLY_LEVEL = (0.2, 1.0)
"""``gains_model="hourly"``: range of the per-day presence probability of an occupant [-]
(weekdays; a tenth of it on weekends)."""

HOURLY_WEEKEND = 0.1
"""``gains_model="hourly"``: weekend presence level as a fraction of the weekday one [-]."""

HOURLY_HOURS = (8.0, 18.0)
"""``gains_model="hourly"``: the hours [h local time] in which occupants may be present."""

GAIN_NOISE_SD = 30.0
"""``gains_model="hourly"``: white noise of every office's gain per control step [W]."""

EQUIPMENT_ROOM = (25.0, 0.3)
"""Zones of kind ``equipment`` (copy or server room): base load [W/m²] and its extra
fraction in building hours [-]."""


@dataclass(frozen=True)
class WeatherSettings:
    """Outdoor temperature and sun.

    Attributes
    ----------
    mean : float
        Long-run daily mean outdoor temperature [°C]. Default 12.5: Gainesville, FL,
        late January (NOAA 1981–2010 normals: mean low 5, mean high 20 °C).
    mean_sd : float
        Standard deviation of the daily mean [K] (cold fronts).
    mean_corr : float
        Day-to-day correlation of the daily mean [-].
    amplitude : float
        Half the daily range on a clear day [K].
    hourly_sd : float
        Hourly noise of the station values [K].
    fast_sd : float
        Fluctuation of the real air around the interpolated hourly values [K]
        (correlation time 20 min), not seen by the station.
    solar_peak : float
        Clear-sky irradiance on a south wall at solar noon [W/m²] (about 650 at 30 °N
        in January).
    """

    mean: float = 12.5
    mean_sd: float = 3.5
    mean_corr: float = 0.6
    amplitude: float = 7.5
    hourly_sd: float = 0.4
    fast_sd: float = 0.3
    solar_peak: float = 650.0


@dataclass(frozen=True)
class OccupancySettings:
    """Occupants, equipment and lighting of offices; lighting of halls.

    Attributes
    ----------
    occupants : tuple of int
        Possible occupant counts per office (drawn per office). The paper's offices have a
        design occupancy of 2.
    presence : float
        Probability that an occupant comes in on a weekday [-].
    weekend_presence : float
        The same on weekends [-].
    arrival, departure : tuple of float
        Mean and standard deviation of arrival / departure time [h].
    lunch : float
        Probability of leaving for lunch (around 12:10, 30–60 min) [-].
    person : float
        Sensible heat per person [W] (ASHRAE: seated office work, about 75 W).
    equipment_standby : float
        Equipment heat with nobody in [W per office].
    equipment_person : float
        Additional equipment heat per person present [W].
    equipment_spread : float
        Per-office equipment factor is uniform in ``1 ± equipment_spread`` [-].
    lighting : float
        Office lighting when anyone is in [W/m²].
    hall_lighting : float
        Hall lighting in building hours [W/m²] (30 % of it at other times).
    """

    occupants: tuple = (1, 2)
    presence: float = 0.85
    weekend_presence: float = 0.05
    arrival: tuple = (8.5, 0.75)
    departure: tuple = (17.25, 1.0)
    lunch: float = 0.6
    person: float = 75.0
    equipment_standby: float = 40.0
    equipment_person: float = 100.0
    equipment_spread: float = 0.4
    lighting: float = 9.0
    hall_lighting: float = 6.0


@dataclass
class Disturbances:
    """Inputs the controller does not choose, on the control grid (held over each step).

    Attributes
    ----------
    time : pandas.DatetimeIndex, length N
        Start of each control step (tz-aware).
    dt : float
        Control step [s].
    boundary, zones : list of str
        Column names of ``T_boundary`` and ``gains``.
    T_boundary : ndarray, shape (N, n_boundary)
        True boundary temperatures [°C].
    T_boundary_logged : ndarray, shape (N, n_boundary)
        What the BAS records before sensor noise [°C]: outdoors the interpolated hourly
        station values, indoors the true temperature.
    gains : ndarray, shape (N, n_zones)
        Unmeasured heat gains [W].
    occupied : ndarray of bool, shape (N,)
        HVAC occupied mode (supply on).
    T_ahu : ndarray, shape (N,)
        Cold-deck supply air temperature from the air handler [°C].
    solar : ndarray, shape (N,)
        Irradiance on a south-facing wall [W/m²].
    info : dict
        Per-node and per-zone random draws (set points of neighbours, occupant counts,
        equipment factors), for the truth file.
    """

    time: pd.DatetimeIndex
    dt: float
    boundary: list
    zones: list
    T_boundary: np.ndarray
    T_boundary_logged: np.ndarray
    gains: np.ndarray
    occupied: np.ndarray
    T_ahu: np.ndarray
    solar: np.ndarray
    info: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.time)

    def window(self, start: int, stop: int | None = None) -> "Disturbances":
        """The same disturbances from control step ``start`` to ``stop``."""
        s = slice(start, stop)
        return Disturbances(self.time[s], self.dt, self.boundary, self.zones, self.T_boundary[s],
                            self.T_boundary_logged[s], self.gains[s], self.occupied[s],
                            self.T_ahu[s], self.solar[s], self.info)


def _ar1(rng, n, sd, corr, size=None):
    """Stationary AR(1) sequence(s) of length n with marginal sd and lag-one correlation."""
    shape = (n,) if size is None else (n, size)
    e = rng.standard_normal(shape)
    s = sd * np.sqrt(1.0 - corr * corr)
    # start in the stationary distribution: y[0] = sd·e[0]
    zi = (corr * sd * e[0])[None] if size is not None else np.array([corr * sd * e[0]])
    y = lfilter([s], [1.0, -corr], e[1:], axis=0, zi=zi)[0] if n > 1 else np.empty((0,) + shape[1:])
    return np.concatenate([sd * e[:1], y], axis=0)


def _diurnal(hour):
    """Daily temperature shape in [-1, 1]: minimum at 07:00, maximum at 15:00."""
    rise = (hour >= 7.0) & (hour < 15.0)
    return np.where(rise, -np.cos(np.pi * (hour - 7.0) / 8.0),
                    np.cos(np.pi * np.mod(hour - 15.0, 24.0) / 16.0))


def _local_clock(time: pd.DatetimeIndex):
    hour = np.asarray(time.hour + time.minute / 60.0 + time.second / 3600.0, dtype=float)
    wall = time.tz_localize(None) if time.tz is not None else time  # local wall clock
    days = np.asarray((wall.normalize() - wall[0].normalize()).days, dtype=int)  # DST-proof
    weekday = np.asarray(time.day_of_week) < 5
    return hour, days, weekday


def _hourly_people(rng, n_occ, hour, day, weekday_of_day, n_days):
    """People present per control step: a per-day level, presence redrawn every hour."""
    lo, hi = HOURLY_LEVEL
    level = rng.uniform(lo, hi, n_days) * np.where(weekday_of_day, 1.0, HOURLY_WEEKEND)
    slot = day * 24 + np.floor(hour).astype(int)
    open_hours = (hour >= HOURLY_HOURS[0]) & (hour < HOURLY_HOURS[1])
    people = np.zeros(len(hour))
    for _ in range(n_occ):
        present = rng.random(n_days * 24) < np.repeat(level, 24)
        people += present[slot] & open_hours
    return people


def occupied_mode(time: pd.DatetimeIndex, hours=(6.0, 19.0), weekdays_only: bool = True):
    """HVAC occupied mode per time stamp: within ``hours`` [h local time], weekdays only."""
    hour, _, weekday = _local_clock(time)
    on = (hour >= hours[0]) & (hour < hours[1])
    return on & weekday if weekdays_only else on


def make_disturbances(layout, time: pd.DatetimeIndex, dt: float, rng: np.random.Generator,
                      weather: WeatherSettings = WeatherSettings(),
                      occupancy: OccupancySettings = OccupancySettings(),
                      hours=(6.0, 19.0), weekdays_only: bool = True,
                      T_ahu: float = 12.8, *, gains_model: str = "arrivals",
                      gain_noise: float | None = None, neighbour_noise: float = 0.0,
                      rng_extra: np.random.Generator | None = None) -> Disturbances:
    """Draw weather, neighbouring-space temperatures and heat gains for a layout.

    Parameters
    ----------
    layout : thermctl.testbed.buildings.Layout
    time : pandas.DatetimeIndex
        Start of every control step, tz-aware (local clock drives schedules).
    dt : float
        Control step [s].
    rng : numpy.random.Generator
    weather : WeatherSettings
    occupancy : OccupancySettings
    hours : (float, float)
        Occupied-mode hours [h local time].
    weekdays_only : bool
    T_ahu : float
        Mean cold-deck supply air temperature [°C] (12.8 °C = 55 °F); it wanders by about
        ±0.3 K.
    gains_model : {"arrivals", "hourly"}
        Offices: occupants arriving, lunching and leaving at random times, or a per-day
        presence level (:data:`HOURLY_LEVEL`) with presence redrawn every hour plus white
        noise (:data:`GAIN_NOISE_SD`).
    gain_noise : float, optional
        White noise of every office's gain per control step [W]; default
        :data:`GAIN_NOISE_SD` with ``gains_model="hourly"``, 0 otherwise.
    neighbour_noise : float
        White noise on indoor boundary temperatures per control step [K] (the plant feels
        it and the BAS logs it).
    rng_extra : numpy.random.Generator, optional
        Draws of the neighbours' noise (kept apart from ``rng`` so that the default
        disturbances do not change). Default: ``rng``.

    Returns
    -------
    Disturbances
    """
    spec = layout.spec
    n = len(time)
    if n < 2:
        raise ModelError("make_disturbances: need at least 2 control steps")
    hour, day, weekday = _local_clock(time)
    n_days = int(day[-1]) + 1
    occ_mode = occupied_mode(time, hours, weekdays_only)

    # --- outdoor: hourly station values, linearly interpolated ------------------
    w = weather
    day_mean = w.mean + _ar1(rng, n_days + 2, w.mean_sd, w.mean_corr)
    cloud = rng.beta(1.2, 1.2, n_days + 2)  # 0 clear, 1 overcast
    amp = w.amplitude * (1.0 - 0.6 * cloud)
    t0 = time[0].normalize()
    t_sec = np.asarray((time - t0).total_seconds(), dtype=float)
    hours_grid = np.arange(0.0, np.ceil(t_sec[-1] / 3600.0) + 2.0)
    hd = (hours_grid / 24.0)
    # daily mean and amplitude change smoothly through the day (fronts take hours)
    mean_h = np.interp(hd - 0.5, np.arange(n_days + 2), day_mean)
    amp_h = np.interp(hd - 0.5, np.arange(n_days + 2), amp)
    station = mean_h + amp_h * _diurnal(np.mod(hours_grid, 24.0)) \
        + _ar1(rng, len(hours_grid), w.hourly_sd, 0.5)
    t_out_logged = np.interp(t_sec / 3600.0, hours_grid, station)
    corr_fast = np.exp(-dt / 1200.0)
    t_out = t_out_logged + _ar1(rng, n, w.fast_sd, corr_fast)

    # --- sun on a south wall ------------------------------------------------------
    sunrise, sunset = 7.3, 17.9
    shape = np.clip(np.sin(np.pi * (hour - sunrise) / (sunset - sunrise)), 0.0, None) ** 1.5
    clear = 1.0 - 0.8 * cloud[day]
    solar = w.solar_peak * shape * clear

    # --- indoor neighbouring spaces ----------------------------------------------
    nb = len(spec.boundary)
    T_b = np.empty((n, nb))
    info = {"neighbours": {}, "offices": {}}
    t_core = 20.0  # building core temperature the neighbours float towards [°C]
    indoor = [j for j, b in enumerate(spec.boundary) if b.lower() not in OUTDOOR_NAMES]
    for j, b in enumerate(spec.boundary):
        if j not in indoor:
            T_b[:, j] = t_out
    if indoor:
        m = len(indoor)
        sp = 22.2 + rng.normal(0.0, 0.5, m)
        mix = rng.uniform(0.1, 0.35, m)      # weight of outdoor air in the float target
        tau_float = rng.uniform(8.0, 16.0, m) * 3600.0
        tau_on = rng.uniform(0.5, 1.0, m) * 3600.0
        wiggle = _ar1(rng, n, 0.25, np.exp(-dt / 3600.0), size=m)
        on = occ_mode[:, None]
        target = np.where(on, sp, mix * t_out_logged[:, None] + (1.0 - mix) * t_core)
        keep = np.exp(-dt / np.where(on, tau_on, tau_float))
        x = np.empty((n, m))
        x[0] = target[0]
        for k in range(1, n):
            x[k] = target[k - 1] + (x[k - 1] - target[k - 1]) * keep[k - 1]
        T_b[:, indoor] = x + wiggle
        for q, j in enumerate(indoor):
            info["neighbours"][spec.boundary[j]] = {
                "set_point": round(float(sp[q]), 3), "outdoor_mix": round(float(mix[q]), 3),
                "tau_float_h": round(float(tau_float[q]) / 3600.0, 3)}
    if neighbour_noise > 0 and indoor:
        extra = rng if rng_extra is None else rng_extra
        T_b[:, indoor] += extra.normal(0.0, neighbour_noise, (n, len(indoor)))
    T_b_logged = T_b.copy()
    for j, b in enumerate(spec.boundary):
        if b.lower() in OUTDOOR_NAMES:
            T_b_logged[:, j] = t_out_logged

    # --- heat gains ----------------------------------------------------------------
    o = occupancy
    zones = spec.zone_names
    gains = np.zeros((n, len(zones)))
    building_hours = (hour >= 6.5) & (hour < 20.0) & weekday
    wd = np.zeros(n_days, dtype=bool)
    wd[day] = weekday
    for i, z in enumerate(zones):
        kind = layout.kind.get(z, "office")
        area = layout.floor_area.get(z, 0.0)
        if kind in ("hall", "lobby"):
            gains[:, i] = o.hall_lighting * area * np.where(building_hours, 1.0, 0.3)
            if kind == "lobby":
                gains[:, i] += layout.solar_aperture.get(z, 0.0) * solar
            continue
        if kind == "equipment":
            base, extra_day = EQUIPMENT_ROOM
            gains[:, i] = base * area * np.where(building_hours, 1.0 + extra_day, 1.0)
            continue
        n_occ = int(rng.choice(o.occupants))
        eq = 1.0 + rng.uniform(-o.equipment_spread, o.equipment_spread)
        people = np.zeros(n)
        if gains_model == "hourly":
            people = _hourly_people(rng, n_occ, hour, day, wd, n_days)
            sd = GAIN_NOISE_SD if gain_noise is None else gain_noise
            noise = sd * rng.standard_normal(n)     # drawn at any sd: same occupants
            gains[:, i] = (o.person * people
                           + eq * (o.equipment_standby + o.equipment_person * people)
                           + o.lighting * area * (people > 0)
                           + layout.solar_aperture.get(z, 0.0) * solar + noise)
            info["offices"][z] = {"occupants": n_occ, "equipment_factor": round(eq, 4)}
            continue
        for _ in range(n_occ):
            p_in = np.where(wd, o.presence, o.weekend_presence)
            present = rng.random(n_days) < p_in
            arr = np.clip(rng.normal(*o.arrival, n_days), 6.5, 11.0)
            dep = np.clip(rng.normal(*o.departure, n_days), arr + 2.0, 21.0)
            goes = rng.random(n_days) < o.lunch
            l0 = rng.normal(12.2, 0.3, n_days)
            l1 = l0 + rng.uniform(0.5, 1.0, n_days)
            here = present[day] & (hour >= arr[day]) & (hour < dep[day]) \
                & ~(goes[day] & (hour >= l0[day]) & (hour < l1[day]))
            people += here
        gains[:, i] = (o.person * people + eq * (o.equipment_standby + o.equipment_person * people)
                       + o.lighting * area * (people > 0)
                       + layout.solar_aperture.get(z, 0.0) * solar)
        if gain_noise:
            gains[:, i] += (rng if rng_extra is None else rng_extra).normal(0.0, gain_noise, n)
        info["offices"][z] = {"occupants": n_occ, "equipment_factor": round(eq, 4)}

    ahu = T_ahu + _ar1(rng, n, 0.3, np.exp(-dt / 7200.0))
    return Disturbances(time, float(dt), list(spec.boundary), list(zones), T_b, T_b_logged, gains,
                        occ_mode, ahu, solar, info)
