"""The identified Kalman filter of an export: the likelihood's noise model (random-walk
gains, process and sensor noise) at an operating point, and at a sample time its exact
discretisation and stationary gain (:func:`kalman_filter`, :class:`KalmanFilter`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ModelError
from ..estimate.likelihood.kalman import dare_np, process_noise_np
from ..model import OperatingPoint, ThermalModel, zoh
from .disturbances import disturbances, greybox_params
from .point import DESCRIBE_NODES

__all__ = ["KalmanFilter", "kalman_filter", "augment_noise", "has_noise_model",
           "KALMAN_DT_MAX_STATES"]

KALMAN_DT_MAX_STATES = 2000
"""Filter states above which ``thermctl export --dt`` leaves out the stationary gain (the
``max_states`` it gives :func:`kalman_filter`): its dense exponentials and Riccati equation
cost ~n³. Measured at 707 states (49 zones): 5.4 s CPU (exponential 2.2 s, process noise
1.3 s, Riccati 1.8 s); about 2 min at 2 000 states and an hour at 6 231 (490 zones)."""


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
    note : str
        Why the discrete filter was left out although a sample time was asked for.
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
    note: str = ""

    def describe_noise(self, max_nodes: int = DESCRIBE_NODES) -> str:
        """The noise parameters in one line: a group with more than ``max_nodes`` values
        (one per zone of a large building) as its count, range and median."""
        groups = {}
        for k, v in self.params.items():
            groups.setdefault(k.split("[")[0], []).append((k, float(v)))
        parts = []
        for g, items in groups.items():
            if len(items) > max_nodes:
                v = np.array([x for _, x in items])
                parts.append(f"{g}: {len(v)} values, {v.min():.3g} to {v.max():.3g} (median "
                             f"{np.median(v):.3g})")
            else:
                parts += [f"{k}={x:.3g}" for k, x in items]
        return ", ".join(parts)

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


def has_noise_model(params: dict) -> bool:
    """Whether grey-box parameters hold a noise model (a sensor noise ``sigma_v``)."""
    return any(k == "sigma_v" or k.startswith("sigma_v[") for k in params)


def augment_noise(params: dict, A0, cz, zones, measured):
    """The grey-box noise model on a network's state matrix: augmented ``A``, ``C``, ``Qc``, ``R``.

    The state is the network's (``n_net`` states, zones first) followed by one random-walk
    heat gain ``d[z]`` [W] per measured zone if ``sigma_phi`` is given, the AR(1) sensor
    errors ``e[z]`` [K] if ``sigma_e`` and ``tau_e`` are, the fast (first-order) gains
    ``g[z]`` [W] if ``sigma_g`` and ``tau_g`` are, and the common gains ``c1``, ``c2``… [-]
    (unit variance, heating zone z by ``loading[z,ck]`` [W]) if ``tau_c`` is. Shared by
    :func:`kalman_filter` (at an operating point) and by filters whose network block changes
    with the supply flow (the MPC examples'), so the noise model is written once.

    Parameters
    ----------
    params : dict
        Grey-box parameters (``sigma_q`` [W s^0.5], ``sigma_phi`` [W/s^0.5], ``sigma_v`` [K],
        ``sigma_e`` [K], ``tau_e`` [s]), each shared or per zone (``sigma_q[r1]``).
    A0 : ndarray, shape (n_net, n_net)
        The network's state matrix [1/s].
    cz : ndarray, shape (n_zones,)
        Zone capacitances [J/K].
    zones : list of str
        The network's zones (the first states).
    measured : list of str
        Measured zones: the outputs, and the zones that get a gain and a sensor error.

    Returns
    -------
    A : ndarray, shape (n, n)
        [1/s]; the network block is ``A0``.
    C : ndarray, shape (n_measured, n)
    Qc : ndarray, shape (n, n)
        Process noise intensity [K²/s for temperatures, W²/s for gains].
    R : ndarray, shape (n_measured, n_measured)
        Sensor noise covariance [K²].
    extra : list of str
        Names of the states after the network's (``d[z]``, then ``e[z]``, then ``g[z]``,
        then ``c1``…).
    """
    p = params
    if any(k.startswith(("sigma_b", "tau_b")) for k in p):
        raise ModelError("model.json meta greybox.params: boundary-noise states (sigma_b, tau_b) "
                         "are not exported; their boundary nodes are not recorded in the model")
    zones = list(zones)
    nz, n_net = len(zones), A0.shape[0]
    mi = [zones.index(z) for z in measured]
    ny = len(measured)
    has_d = any(k == "sigma_phi" or k.startswith("sigma_phi[") for k in p)
    has_e = "sigma_e" in p and "tau_e" in p
    has_g = "sigma_g" in p and "tau_g" in p
    nd, ne, ng = (ny if has_d else 0), (ny if has_e else 0), (ny if has_g else 0)
    nc = 0
    if "tau_c" in p:
        while any(k.startswith("loading[") and k.endswith(f",c{nc + 1}]") for k in p):
            nc += 1
    n = n_net + nd + ne + ng + nc
    A = np.zeros((n, n))
    A[:n_net, :n_net] = A0
    Qc = np.zeros((n, n))
    sq = _per(p, "sigma_q", zones, "every zone")
    Qc[np.arange(nz), np.arange(nz)] = (sq / cz) ** 2
    extra = []
    if nd:
        sphi = _per(p, "sigma_phi", measured, "every measured zone")
        for j, i in enumerate(mi):
            A[i, n_net + j] = 1.0 / cz[i]
            Qc[n_net + j, n_net + j] = sphi[j] ** 2
        extra += [f"d[{z}]" for z in measured]
    C = np.zeros((ny, n))
    C[np.arange(ny), mi] = 1.0
    if ne:
        tau_e, sig_e = float(p["tau_e"]), float(p["sigma_e"])
        k = n_net + nd + np.arange(ne)
        A[k, k] = -1.0 / tau_e
        Qc[k, k] = 2.0 * sig_e ** 2 / tau_e
        C[np.arange(ny), k] = 1.0
        extra += [f"e[{z}]" for z in measured]
    if ng:
        # the fast gain g[z] [W]: first order, stationary standard deviation σ_g
        tau_g, sig_g = float(p["tau_g"]), float(p["sigma_g"])
        k = n_net + nd + ne + np.arange(ng)
        A[mi, k] = 1.0 / cz[mi]
        A[k, k] = -1.0 / tau_g
        Qc[k, k] = 2.0 * sig_g ** 2 / tau_g
        extra += [f"g[{z}]" for z in measured]
    if nc:
        # common gains c_k: first order, unit variance; zone z gets loading[z,ck]·c_k [W]
        tau_c = float(p["tau_c"])
        for k in range(nc):
            j = n_net + nd + ne + ng + k
            for i, z in zip(mi, measured):
                A[i, j] = float(p.get(f"loading[{z},c{k + 1}]", 0.0)) / cz[i]
            A[j, j] = -1.0 / tau_c
            Qc[j, j] = 2.0 / tau_c
        extra += [f"c{k + 1}" for k in range(nc)]
    R = np.diag(_per(p, "sigma_v", measured, "every measured zone") ** 2)
    return A, C, Qc, R, extra


def kalman_filter(model: ThermalModel, op: OperatingPoint, dt: float | None = None,
                  max_states: int | None = None):
    """The grey-box noise model of ``model.json`` at ``op`` (``None`` if it has none).

    Built from ``model.meta["greybox"]["params"]`` (:func:`augment_noise`): ``sigma_q``
    (heat noise per zone [W s^0.5], intensity ``(σ_q/C_z)²`` on ``T[z]``), ``sigma_phi``
    (random-walk gain per measured zone [W/s^0.5]), ``sigma_v`` (sensor noise [K]) and, if
    identified, the AR(1) sensor error ``sigma_e`` [K], ``tau_e`` [s], the fast gains
    (``sigma_g`` [W], ``tau_g`` [s]) and the common gains (``tau_c`` [s], ``loading[z,ck]``
    [W]). Each noise level is shared or per zone (``sigma_q[r1]``). Models identified with
    ``--criterion simulation`` have no noise model.

    Parameters
    ----------
    model : ThermalModel
    op : OperatingPoint
    dt : float, optional
        Sample time [s]: also the exact discretisation (:func:`~thermctl.model.zoh`,
        :func:`~thermctl.estimate.likelihood.kalman.process_noise_np`) and the stationary
        filter (:func:`~thermctl.estimate.likelihood.kalman.dare_np`).
    max_states : int or None
        Above this many filter states the discrete filter is left out (dense, ~n³; the
        command line uses :data:`KALMAN_DT_MAX_STATES`) and :attr:`KalmanFilter.note` says
        so. None (default): no limit.

    Returns
    -------
    KalmanFilter or None
    """
    p = greybox_params(model)
    if not has_noise_model(p):
        return None
    net = model.network
    n_net = net.n_states
    measured = [z for z in net.spec.measured_zones if z in net.zones]
    cz = 1.0 / np.asarray(model.sym.inv_cz, float)
    dist = disturbances(model)
    A0, B0 = model.jacobians(op)
    B0 = np.hstack([B0, dist.E])
    A, C, Qc, R, extra = augment_noise(p, A0, cz, net.zones, measured)
    B = np.zeros((A.shape[0], B0.shape[1]))
    B[:n_net] = B0
    used = {k: float(v) for k, v in p.items()
            if k.startswith(("sigma_", "tau_e", "tau_g", "tau_c", "loading["))}
    kf = KalmanFilter(states=list(net.state_names) + extra, inputs=net.input_names + dist.names,
                      outputs=[f"T[{z}]" for z in measured], A=A, B=B, C=C, Qc=Qc, R=R,
                      params=used)
    if dt is not None and not dt > 0:
        raise ModelError(f"dt must be > 0 [s], found {dt}")
    if dt is not None and max_states is not None and A.shape[0] > max_states:
        kf.note = (f"no stationary gain at dt={dt:g} s: the filter has {A.shape[0]} states "
                   f"(> {max_states}; dense exponentials and Riccati equation, ~n³); the "
                   f"continuous noise model (Qc, R) is exported")
    elif dt is not None:
        Phi, GamB = zoh(A, dt, B)
        Qd = process_noise_np(A, Qc, dt)
        try:
            P, _ = dare_np(Phi, C, Qd, R)
        except (np.linalg.LinAlgError, FloatingPointError) as exc:
            raise ModelError(f"stationary Kalman filter at dt={dt:g} s: the Riccati equation "
                             f"has no stabilising solution ({exc})") from None
        K = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
        kf.dt, kf.Phi, kf.Gamma, kf.Qd, kf.P, kf.K = float(dt), Phi, GamB, Qd, P, K
    return kf
