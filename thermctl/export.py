"""What an MPC designer needs beside the linear model: its operating point, the disturbance
inputs and the identified state estimator.

* :func:`export_point` chooses the operating point explicitly: per-node values given by
  the user, else the data's typical values (supply flow of the zones that have supply air,
  supply temperature, boundary temperatures), else stated defaults — and says which is
  which (:meth:`ExportPoint.describe`, :meth:`ExportPoint.to_dict`).
* :func:`disturbances` turns the identified solar apertures and time-of-day gains of
  ``model.meta["greybox"]`` into extra inputs of the state equation.
* :func:`kalman_filter` builds the grey-box model's noise model (the one the likelihood
  was computed with): the state augmented with one random-walk heat gain per measured
  zone, continuous process-noise intensity, sensor-noise variance and, at a sample time,
  the stationary Kalman gain.

``thermctl export`` writes all three into the exported files. For control toolboxes:

* :func:`to_do_mpc` builds do-mpc models (bilinear, and linear at the operating point);
* :func:`load_statespace` reads an exported state space as an :class:`OperatingStateSpace`,
  a ``control.StateSpace`` that prints its operating point; :func:`input_signals` makes a
  ``forced_response`` input array from signals given by name.

Examples
--------
>>> model = load_model("out/model.json")                                  # doctest: +SKIP
>>> point = export_point(model, {"T": {"*": 21.0, "outside": -5.0}}, data=meas)  # doctest: +SKIP
>>> print(point.describe())                                               # doctest: +SKIP
>>> sys, dist = statespace(model, point.op, dt=600.0)                     # doctest: +SKIP
>>> kf = kalman_filter(model, point.op, dt=600.0)                         # doctest: +SKIP
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca
import control as ct
import numpy as np
import scipy.linalg as sla

from .errors import ModelError
from .model import OperatingPoint, ThermalModel, zoh

__all__ = ["ExportPoint", "Disturbances", "KalmanFilter", "supply_zones", "typical_inputs",
           "export_point", "disturbances", "statespace", "kalman_filter", "DoMpcModels",
           "to_do_mpc", "OperatingStateSpace", "load_statespace", "input_signals"]

_ON = 1e-6          # [kg/s]: a box "supplies air" above this flow (logged zeros are 0.0 or tiny)
_DEFAULTS = {"ms": 0.0, "Ts": 20.0, "T": 10.0, "Q": 0.0}   # ThermalNetwork.input_vector's
_UNITS = {"ms": "kg/s", "Ts": "°C", "T": "°C", "Q": "W"}


# ---------------------------------------------------------------------------- operating point
def supply_zones(meas) -> list[str]:
    """Zones whose data have supply air: an ``ms:`` column with some flow above zero.

    Parameters
    ----------
    meas : thermctl.data.Measurements
    """
    f = meas.frame
    return [z for z in meas.spec.zone_names
            if f"ms:{z}" in f and np.nanmax(np.r_[f[f"ms:{z}"].to_numpy(), 0.0]) > _ON]


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

    def describe(self) -> str:
        """A few lines for the terminal: every value with its source, then the notes."""
        tag = {"given": "given", "data": "data", "default": "DEFAULT"}  # loud: nothing known
        lines = ["operating point (the linear model is in deviations from it):"]
        for name in ("ms", "Ts", "Q", "T"):
            vals, srcs = self.values[name], self.sources[name]
            # Q = 0 is the natural point (unmeasured gains are the disturbances): no alarm
            parts = [f"{n}={v:.4g} ({'default' if name == 'Q' else tag[srcs[n]]})"
                     for n, v in vals.items()]
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


# ---------------------------------------------------------------------------- disturbances
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


def _greybox_params(model) -> dict:
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
    for name, value in _greybox_params(model).items():
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


def statespace(model: ThermalModel, op: OperatingPoint, dt: float | None = None):
    """The linearized model with the disturbance inputs appended to its inputs.

    Parameters
    ----------
    model : ThermalModel
    op : OperatingPoint
    dt : float, optional
        Sample time [s]: exact ZOH discretisation (disturbances held over the step too).

    Returns
    -------
    sys : control.StateSpace
        Inputs ``ms[z]``, ``Ts[z]``, ``T[b]``, ``Q[z]`` then :attr:`Disturbances.names`.
    dist : Disturbances
    """
    net = model.network
    dist = disturbances(model)
    A, B = model.jacobians(op)
    B = np.hstack([B, dist.E])
    C = np.zeros((net.n_zones, net.n_states))
    C[np.arange(net.n_zones), np.arange(net.n_zones)] = 1.0
    D = np.zeros((net.n_zones, B.shape[1]))
    if dt is not None:
        if not dt > 0:
            raise ModelError(f"dt must be > 0 [s], found {dt}")
        Phi, Gamma = zoh(A, dt)
        A, B = Phi, Gamma @ B
    sys = ct.ss(A, B, C, D, dt=0 if dt is None else dt, states=net.state_names,
                inputs=net.input_names + dist.names, outputs=net.output_names,
                name=net.spec.name)
    return sys, dist


# ---------------------------------------------------------------------------- Kalman filter
@dataclass
class KalmanFilter:
    """The identified stochastic model at an operating point, and its stationary filter.

    Continuous model (deviation variables, ``w`` white with the given intensity)::

        dx/dt = A x + B u + w,   E[w wᵀ] = Qc δ(t − s)
        y_k   = C x_k + v_k,     E[v vᵀ] = R

    ``x`` is the model's state followed by one heat gain ``d[z]`` [W] per measured zone (a
    random walk, the offset-free disturbance model of MPC: it absorbs unmeasured gains
    and model error), and, with an AR(1) sensor-error model, ``e[z]`` [K]. ``y`` are the
    measured zone temperatures.

    Attributes
    ----------
    states, inputs, outputs : list of str
    A, B, C : ndarray
        [1/s], [per input unit per s], [-].
    Qc : ndarray, shape (n, n)
        Process noise intensity [K²/s for temperatures, W²/s for gains].
    R : ndarray, shape (ny, ny)
        Measurement noise covariance [K²].
    dt : float or None
        Sample time [s] of the discrete filter below.
    Phi, Gamma, Qd : ndarray or None
        Exact discretisation at ``dt``: ``x⁺ = Phi x + Gamma u + w_d``, ``cov(w_d) = Qd``.
    P : ndarray or None
        Stationary one-step prediction covariance (discrete Riccati equation).
    K : ndarray or None
        Stationary filter gain: ``x̂_{k|k} = x̂_{k|k-1} + K (y_k − C x̂_{k|k-1})``.
    params : dict
        The noise parameters it was built from (``sigma_v`` [K], ``sigma_q`` [W s^0.5],
        ``sigma_phi`` [W/s^0.5]...).
    """

    states: list
    inputs: list
    outputs: list
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    Qc: np.ndarray
    R: np.ndarray
    params: dict
    dt: float | None = None
    Phi: np.ndarray | None = None
    Gamma: np.ndarray | None = None
    Qd: np.ndarray | None = None
    P: np.ndarray | None = None
    K: np.ndarray | None = None

    def arrays(self) -> dict:
        """Every matrix and name list, for ``save_statespace(kalman=...)``."""
        out = {k: getattr(self, k) for k in ("states", "inputs", "outputs", "A", "B", "C", "Qc", "R")}
        if self.dt is not None:
            out.update(dt=self.dt, Phi=self.Phi, Gamma=self.Gamma, Qd=self.Qd, P=self.P, K=self.K)
        return out


def _per(params, group, names, what):
    """Values of a noise group for these nodes: shared ``group`` or per node ``group[node]``."""
    if group in params:
        return np.full(len(names), float(params[group]))
    try:
        return np.array([float(params[f"{group}[{n}]"]) for n in names])
    except KeyError as exc:
        raise ModelError(f"model.json meta greybox.params: no {group} (shared) and no "
                         f"{exc.args[0]} for {what}") from None


def _noise_discretize(A, Qc, dt):
    """``Qd = ∫₀^dt e^{As} Qc e^{Aᵀs} ds`` by Van Loan at a short step, then doubling.

    Van Loan's block exponential at the full step holds ``e^{-A dt}``, which overflows for
    the convection edges (time constants of seconds against a step of minutes), so it is
    taken at ``h = dt/2^s`` with ``‖A‖₁ h ≤ 1/4`` and doubled exactly:
    ``Q(2h) = Φ(h) Q(h) Φ(h)ᵀ + Q(h)``, ``Φ(2h) = Φ(h)²``.
    """
    n = A.shape[0]
    norm = float(np.abs(A).sum(axis=0).max()) * dt
    s = max(0, int(np.ceil(np.log2(max(norm, 1e-300) / 0.25)))) if norm > 0.25 else 0
    h = dt / 2.0 ** s
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A * h
    M[:n, n:] = Qc * h
    M[n:, n:] = A.T * h
    E = sla.expm(M)
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    for _ in range(s):
        Qd = Phi @ Qd @ Phi.T + Qd
        Phi = Phi @ Phi
    return 0.5 * (Qd + Qd.T)


def kalman_filter(model: ThermalModel, op: OperatingPoint, dt: float | None = None):
    """The grey-box noise model of ``model.json`` at ``op`` (``None`` if it has none).

    Built from ``model.meta["greybox"]["params"]``: ``sigma_q`` (heat noise per zone
    [W s^0.5], intensity ``(σ_q/C_z)²`` on ``T[z]``), ``sigma_phi`` (random-walk gain per
    measured zone [W/s^0.5]), ``sigma_v`` (sensor noise [K]) and, if identified, the AR(1)
    sensor error ``sigma_e`` [K], ``tau_e`` [s]. Each is shared or per zone (``sigma_q[r1]``).
    Models identified with ``--criterion simulation`` have no noise model.

    Parameters
    ----------
    model : ThermalModel
    op : OperatingPoint
    dt : float, optional
        Sample time [s]: also the exact discretisation and the stationary filter.

    Returns
    -------
    KalmanFilter or None
    """
    p = _greybox_params(model)
    if not any(k == "sigma_v" or k.startswith("sigma_v[") for k in p):
        return None
    if any(k.startswith(("sigma_b", "tau_b")) for k in p):
        raise ModelError("model.json meta greybox.params: boundary-noise states (sigma_b, tau_b) "
                         "are not exported; their boundary nodes are not recorded in the model")
    net = model.network
    nz, n_net = net.n_zones, net.n_states
    measured = [z for z in net.spec.measured_zones if z in net.zones]
    mi = [net.zones.index(z) for z in measured]
    ny = len(measured)
    cz = 1.0 / np.asarray(model.sym.inv_cz, float)
    has_d = any(k == "sigma_phi" or k.startswith("sigma_phi[") for k in p)
    has_e = "sigma_e" in p and "tau_e" in p
    nd, ne = (ny if has_d else 0), (ny if has_e else 0)
    n = n_net + nd + ne
    dist = disturbances(model)
    A0, B0 = model.jacobians(op)
    B0 = np.hstack([B0, dist.E])
    A = np.zeros((n, n))
    A[:n_net, :n_net] = A0
    B = np.zeros((n, B0.shape[1]))
    B[:n_net] = B0
    Qc = np.zeros((n, n))
    sq = _per(p, "sigma_q", net.zones, "every zone")
    Qc[np.arange(nz), np.arange(nz)] = (sq / cz) ** 2
    states = list(net.state_names)
    if nd:
        sphi = _per(p, "sigma_phi", measured, "every measured zone")
        for j, i in enumerate(mi):
            A[i, n_net + j] = 1.0 / cz[i]
            Qc[n_net + j, n_net + j] = sphi[j] ** 2
        states += [f"d[{z}]" for z in measured]
    C = np.zeros((ny, n))
    C[np.arange(ny), mi] = 1.0
    if ne:
        tau_e, sig_e = float(p["tau_e"]), float(p["sigma_e"])
        k = n_net + nd + np.arange(ne)
        A[k, k] = -1.0 / tau_e
        Qc[k, k] = 2.0 * sig_e ** 2 / tau_e
        C[np.arange(ny), k] = 1.0
        states += [f"e[{z}]" for z in measured]
    R = np.diag(_per(p, "sigma_v", measured, "every measured zone") ** 2)
    used = {k: float(v) for k, v in p.items() if k.startswith(("sigma_", "tau_e"))}
    kf = KalmanFilter(states=states, inputs=net.input_names + dist.names,
                      outputs=[f"T[{z}]" for z in measured], A=A, B=B, C=C, Qc=Qc, R=R,
                      params=used)
    if dt is not None:
        if not dt > 0:
            raise ModelError(f"dt must be > 0 [s], found {dt}")
        Phi, Gam = zoh(A, dt)
        Qd = _noise_discretize(A, Qc, dt)
        try:
            P = sla.solve_discrete_are(Phi.T, C.T, Qd, R)
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise ModelError(f"stationary Kalman filter at dt={dt:g} s: the Riccati equation "
                             f"has no stabilising solution ({exc})") from None
        P = 0.5 * (P + P.T)
        K = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
        kf.dt, kf.Phi, kf.Gamma, kf.Qd, kf.P, kf.K = float(dt), Phi, Gam @ B, Qd, P, K
    return kf


# ---------------------------------------------------------------------------- do-mpc
@dataclass
class DoMpcModels:
    """The identified model as do-mpc models: bilinear, and linear at an operating point.

    Both are continuous and have the same variable names: states ``T[z]``, ``x[e,1]``...
    (:attr:`ThermalNetwork.state_names`), inputs ``ms[z]`` [kg/s] and ``Ts[z]`` [°C] of the
    zones with supply air, time-varying parameters ``T[b]`` [°C] (boundary temperatures),
    ``Q[z]`` [W] (measured heat) and the identified disturbances :attr:`Disturbances.names`
    (``solar[...]`` [W/m²], ``gain[...]`` [-]).

    Attributes
    ----------
    model : do_mpc.model.Model
        ``dT/dt = f(x, u, tvp)``: bilinear in supply flow and temperatures, set up.
    linear : do_mpc.model.LinearModel or None
        ``d(Δx)/dt = A Δx + B Δu + B_tvp Δtvp`` in deviations from :attr:`op` (every variable
        is the deviation from its value at ``op``, as in do-mpc's own ``linearize``), set up;
        ``None`` without an operating point.
    states, inputs, tvp : list of str
    op : OperatingPoint or None
    x_op, u_op, tvp_op : dict
        Values at ``op`` by name [°C, kg/s, W; disturbances 0].
    """

    model: object
    linear: object
    states: list
    inputs: list
    tvp: list
    op: OperatingPoint | None = None
    x_op: dict = field(default_factory=dict)
    u_op: dict = field(default_factory=dict)
    tvp_op: dict = field(default_factory=dict)

    def tvp_fun(self, user, values: Mapping | None = None):
        """A ``tvp_fun`` for a do-mpc MPC or Simulator built on :attr:`model` or :attr:`linear`.

        Parameters
        ----------
        user : do_mpc.controller.MPC or do_mpc.simulator.Simulator
            Set up far enough to have ``get_tvp_template`` (``set_param`` called).
        values : mapping, optional
            ``{tvp name: value or callable(t [s]) -> value}`` in absolute units [°C, W,
            W/m², -]; names not given keep :attr:`tvp_op`. For :attr:`linear` the deviation
            from :attr:`tvp_op` is passed on.

        Returns
        -------
        callable
            ``tvp_fun(t_now)`` to give to ``user.set_tvp_fun``.
        """
        values = dict(values or {})
        unknown = sorted(set(values) - set(self.tvp))
        if unknown:
            raise ModelError(f"tvp_fun: unknown time-varying parameter(s) {unknown}; the model "
                             f"has {self.tvp}")
        linear = getattr(user, "model", None) is self.linear and self.linear is not None
        tpl = user.get_tvp_template()
        horizon = getattr(user, "settings", None)
        n = getattr(horizon, "n_horizon", None)
        dt = getattr(horizon, "t_step", None)

        def value(name, t):
            v = values.get(name, self.tvp_op.get(name, 0.0))
            v = float(v(t)) if callable(v) else float(v)
            return v - self.tvp_op.get(name, 0.0) if linear else v

        def fun(t_now):
            for name in self.tvp:
                if n is None:                    # Simulator: one value
                    tpl[name] = value(name, t_now)
                else:                            # MPC: one value per step of the horizon
                    for k in range(n + 1):
                        tpl["_tvp", k, name] = value(name, t_now + k * dt)
            return tpl
        return fun


def _do_mpc():
    try:
        import do_mpc
    except ImportError:
        raise ImportError("thermctl.export.to_do_mpc needs do-mpc: pip install "
                          "'thermctl[do-mpc]'") from None
    return do_mpc


def to_do_mpc(model: ThermalModel, op=None, *, supply_zones=None) -> DoMpcModels:
    """The identified model as a ready do-mpc model, and its linearization at ``op``.

    .. math::

        \\dot T_z = \\frac{1}{C_z}\\Big(\\sum_j \\frac{T_j - T_z}{R_{zj}}
        + \\dot m_z c_p (T_{s,z} - T_z) + Q_z + \\sum_k h_{zk} d_k\\Big)

    with the wall and air-path states of the network, the supply flow ``ms[z]`` and
    temperature ``Ts[z]`` as inputs (the product makes the model bilinear) and the
    boundary temperatures, heat ``Q[z]`` and identified disturbances ``d`` (solar
    irradiance through the fitted apertures ``h`` [m²], time-of-day gains ``h`` [W]) as
    time-varying parameters. The parameters (R̄_v, C_v) are built in.

    Parameters
    ----------
    model : ThermalModel
    op : OperatingPoint or ExportPoint, optional
        Linearization point (:func:`export_point`); without it :attr:`DoMpcModels.linear`
        is ``None``.
    supply_zones : list of str, optional
        Zones whose ``ms``/``Ts`` are inputs (the others get no supply air). Default: the
        ``ExportPoint``'s zones with supply air when known, else the measured zones.

    Returns
    -------
    DoMpcModels

    Raises
    ------
    ImportError
        do-mpc is not installed (``pip install 'thermctl[do-mpc]'``).
    ModelError
        An unknown zone in ``supply_zones``.

    Examples
    --------
    >>> dm = to_do_mpc(model, export_point(model, {"ms": 0.05, "Ts": 30, "T": 21}))  # doctest: +SKIP
    >>> mpc = do_mpc.controller.MPC(dm.model)                                    # doctest: +SKIP
    """
    do_mpc = _do_mpc()
    net = model.network
    if isinstance(op, ExportPoint):
        fed = op.supply_zones if supply_zones is None else supply_zones
        op = op.op
    else:
        fed = supply_zones
    fed = list(net.spec.measured_zones if fed is None else fed)
    unknown = sorted(set(fed) - set(net.zones))
    if unknown:
        raise ModelError(f"supply_zones: {unknown} are not zones of the model {net.zones}")
    fed = [z for z in net.zones if z in fed]              # model order
    dist = disturbances(model)
    sl = net.input_slices()
    heat = np.zeros((net.n_zones, len(dist.names)))       # [W per unit of d]
    zi = {z: i for i, z in enumerate(net.zones)}
    for j, name in enumerate(dist.names):
        for z, h in dist.heat[name].items():
            heat[zi[z], j] = h
    inputs = [f"ms[{z}]" for z in fed] + [f"Ts[{z}]" for z in fed]
    tvp = [f"T[{b}]" for b in net.boundary] + [f"Q[{z}]" for z in net.zones] + list(dist.names)
    states = list(net.state_names)
    p = model.p

    def build(m, rhs_of):
        x = ca.vertcat(*[m.set_variable("_x", n) for n in states])
        u = {n: m.set_variable("_u", n) for n in inputs}
        w = {n: m.set_variable("_tvp", n) for n in tvp}
        xdot = rhs_of(x, u, w)
        for i, n in enumerate(states):
            m.set_rhs(n, xdot[i])
        m.setup()
        return m

    def full_u(u, w, zero):
        """The network's input vector from do-mpc's inputs and tvp (disturbances as heat)."""
        ms = [u.get(f"ms[{z}]", zero) for z in net.zones]
        Ts = [u.get(f"Ts[{z}]", zero) for z in net.zones]
        d = ca.vertcat(*[w[n] for n in dist.names]) if dist.names else None
        Q = [w[f"Q[{z}]"] + (ca.mtimes(ca.DM(heat[i:i + 1, :]), d) if d is not None else 0)
             for i, z in enumerate(net.zones)]
        parts = {"ms": ms, "Ts": Ts, "T": [w[f"T[{b}]"] for b in net.boundary], "Q": Q}
        out = [None] * net.n_inputs
        for key, vals in parts.items():
            for k, idx in enumerate(range(sl[key].start, sl[key].stop)):
                out[idx] = vals[k]
        return ca.vertcat(*out)

    f = model.sym.f
    bilinear = build(do_mpc.model.Model("continuous", "SX"),
                     lambda x, u, w: f(x, full_u(u, w, ca.SX(0)), p))
    out = DoMpcModels(bilinear, None, states, inputs, tvp)
    if op is None:
        return out
    ms_op = np.asarray(op.u, float)[sl["ms"]]
    stray = [z for z, v in zip(net.zones, ms_op) if v > _ON and z not in fed]
    if stray:
        raise ModelError(f"op: supply flow at zone(s) {stray}, which are not supply_zones {fed}; "
                         "add them to supply_zones or set their ms to 0")
    A, B = model.jacobians(op)
    idx = {n: i for i, n in enumerate(net.input_names)}
    Bu = B[:, [idx[n] for n in inputs]]
    Bw = np.hstack([B[:, [idx[n] for n in tvp[:len(net.boundary) + net.n_zones]]],
                    B[:, [idx[f"Q[{z}]"] for z in net.zones]] @ heat])

    def lin_rhs(x, u, w):
        du = ca.vertcat(*[u[n] for n in inputs]) if inputs else ca.SX(0, 1)
        dw = ca.vertcat(*[w[n] for n in tvp])
        return ca.mtimes(ca.DM(A), x) + ca.mtimes(ca.DM(Bu), du) + ca.mtimes(ca.DM(Bw), dw)

    out.linear = build(do_mpc.model.LinearModel("continuous", "SX"), lin_rhs)
    u_all = dict(zip(net.input_names, np.asarray(op.u, float)))
    out.op = op
    out.x_op = dict(zip(states, np.asarray(op.x, float).tolist()))
    out.u_op = {n: float(u_all[n]) for n in inputs}
    out.tvp_op = {n: float(u_all.get(n, 0.0)) for n in tvp}
    return out


# ---------------------------------------------------------------------------- python-control
_UNIT_OF = {"ms": "kg/s", "Ts": "°C", "T": "°C", "Q": "W", "solar": "W/m²", "gain": "-"}


class OperatingStateSpace(ct.StateSpace):
    """A ``control.StateSpace`` that knows the operating point it is linearized at.

    It is a ``StateSpace`` (``ct.step_response(sys)``, ``sys["T[r240]", "ms[r240]"]``...)
    in deviations from the operating point; ``print(sys)`` shows the matrices and then
    the operating point. Made by :func:`load_statespace`.

    Attributes
    ----------
    x_op : ndarray, shape (nstates,)
        State at the operating point [°C].
    u_op : ndarray, shape (ninputs,)
        Inputs at the operating point [kg/s, °C, W; disturbance inputs 0].
    info : dict
        What ``thermctl export`` stored: the operating point with the source of every
        value, the disturbance inputs.
    kalman : dict
        The identified Kalman filter's arrays, if exported.
    """

    def __init__(self, sys, x_op=None, u_op=None, info=None, kalman=None):
        super().__init__(sys)
        self.x_op = np.zeros(sys.nstates) if x_op is None else np.asarray(x_op, float)
        u = np.zeros(sys.ninputs)
        if u_op is not None:
            u[:len(u_op)] = np.asarray(u_op, float)     # disturbance inputs: 0 at the point
        self.u_op = u
        self.info = dict(info or {})
        self.kalman = dict(kalman or {})

    def operating_point(self) -> dict:
        """``{signal name: value}`` of the inputs and states at the operating point."""
        return {**dict(zip(self.input_labels, self.u_op.tolist())),
                **dict(zip(self.state_labels, self.x_op.tolist()))}

    def describe_operating_point(self) -> str:
        """The operating point as lines: inputs with unit and source, then zone temperatures."""
        src = (self.info.get("operating_point") or {}).get("source", {})
        lines = ["operating point (the model is in deviations from it):"]
        for name, v in zip(self.input_labels, self.u_op):
            kind, _, node = name.partition("[")
            node = node.rstrip("]")
            how = (src.get(kind) or {}).get(node)
            lines.append(f"  {name} = {v:.6g} {_UNIT_OF.get(kind, '')}"
                         + (f" ({how})" if how else ""))
        zones = [(n, v) for n, v in zip(self.state_labels, self.x_op) if n.startswith("T[")]
        lines.append("  state: " + ", ".join(f"{n} = {v:.4g} °C" for n, v in zones)
                     + f" (+ {self.nstates - len(zones)} wall and air-path states)")
        return "\n".join(lines)

    def __str__(self):
        return super().__str__() + "\n\n" + self.describe_operating_point()


def load_statespace(path) -> OperatingStateSpace:
    """Load a state-space file of ``thermctl export --statespace`` as a named system.

    Parameters
    ----------
    path : str or Path
        ``.npz`` written by ``thermctl export`` (or :func:`thermctl.io.save_statespace`).

    Returns
    -------
    OperatingStateSpace
        Signal names ``T[z]``, ``ms[z]``..., ``dt`` (0: continuous, else the sample time
        [s]), the operating point (printed with the system), the stored info and Kalman
        filter.

    Examples
    --------
    >>> sys = thermctl.load_statespace("ss.npz")                      # doctest: +SKIP
    >>> print(sys)                   # matrices, then the operating point  # doctest: +SKIP
    >>> ct.step_response(sys["T[r240]", "ms[r240]"], 6 * 3600)       # doctest: +SKIP
    """
    from .io import load_statespace as _load

    sys, extras = _load(path)
    return OperatingStateSpace(sys, extras.get("x_op"), extras.get("u_op"),
                               extras.get("info"), extras.get("kalman"))


def input_signals(sys, timepts, values: Mapping) -> np.ndarray:
    """An input array for ``control.forced_response`` from signals given by name.

    Parameters
    ----------
    sys : control.StateSpace
    timepts : array_like, shape (nt,)
        Time points [s].
    values : mapping
        ``{input name: number or array of shape (nt,)}`` in the system's units (for an
        exported model: deviations from the operating point); inputs not named are 0.

    Returns
    -------
    ndarray, shape (ninputs, nt)

    Examples
    --------
    >>> T = np.arange(0, 86400, 600.0)                                    # doctest: +SKIP
    >>> U = input_signals(sys, T, {"ms[r240]": 0.02, "T[outside]": -3.0})   # doctest: +SKIP
    >>> ct.forced_response(sys, T, U).to_pandas()                         # doctest: +SKIP
    """
    t = np.asarray(timepts, float)
    names = list(sys.input_labels)
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise ModelError(f"input_signals: unknown input(s) {unknown}; {sys.name} has {names}")
    U = np.zeros((len(names), t.size))
    for name, v in values.items():
        v = np.asarray(v, float)
        if v.ndim and v.shape != t.shape:
            raise ModelError(f"input_signals: {name} has shape {v.shape}, expected {t.shape} "
                             "(one value per time point) or a number")
        U[names.index(name)] = v
    return U
