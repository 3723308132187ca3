"""The do-mpc side: the identified model as a ready do-mpc model, bilinear in the supply
flow, and its linearization at an operating point (:func:`to_do_mpc`, :class:`DoMpcModels`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..errors import ModelError
from ..model import OperatingPoint, ThermalModel
from .disturbances import disturbances
from .point import _ON, ExportPoint

__all__ = ["DoMpcModels", "to_do_mpc"]


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
