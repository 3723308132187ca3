"""The identified Kalman filter of an export: the likelihood's noise model (random-walk
gains, process and sensor noise) at an operating point, and at a sample time its exact
discretisation and stationary gain (:func:`kalman_filter`, :class:`KalmanFilter`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ..errors import ModelError
from ..model import OperatingPoint, ThermalModel, zoh
from .disturbances import disturbances, greybox_params

__all__ = ["KalmanFilter", "kalman_filter"]


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
    p = greybox_params(model)
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
