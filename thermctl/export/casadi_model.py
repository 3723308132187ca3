"""The CasADi side: the identified model as saved CasADi functions with the parameters built
in, ``f(x, u) -> xdot`` and the Radau step ``F(x, u, dt) -> x_next``, and the document that
names their signals (:func:`casadi_functions`)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..model import ThermalModel

__all__ = ["casadi_functions"]


def casadi_functions(model: ThermalModel, substeps: int, info: dict | None = None,
                     dist=None, kf=None):
    """``f(x, u)`` and ``F(x, u, dt)`` of ``model`` with ``p`` built in, and their document.

    Parameters
    ----------
    model : ThermalModel
    substeps : int
        Radau substeps of ``F`` per call (:meth:`ThermalModel.to_casadi`).
    info : dict, optional
        Added to the document as is (``thermctl export`` puts the operating point there).
    dist : Disturbances, optional
        Its input matrix is stored as ``E`` [K/s per unit].
    kf : KalmanFilter, optional
        Its noise model (diagonals of ``Qc`` and ``R``) is stored as ``noise``.

    Returns
    -------
    f : casadi.Function
        ``f(x, u) -> xdot`` [°C/s].
    F : casadi.Function
        ``F(x, u, dt) -> x_next`` [°C], ``dt`` [s].
    doc : dict
        Signal and parameter names, ``p``, ``substeps``, the signature, ``info``, ``E`` and
        ``noise`` (JSON-ready).
    """
    cm = model.to_casadi(substeps=substeps)
    x, u = ca.SX.sym("x", len(cm.state_names)), ca.SX.sym("u", len(cm.input_names))
    f = ca.Function("f", [x, u], [cm.f(x, u, cm.p_value)], ["x", "u"], ["xdot"])
    xm, um, dtm = ca.MX.sym("x", x.numel()), ca.MX.sym("u", u.numel()), ca.MX.sym("dt")
    F = ca.Function("F", [xm, um, dtm], [cm.F(xm, um, cm.p_value, dtm)], ["x", "u", "dt"],
                    ["x_next"])
    doc = {"states": cm.state_names, "inputs": cm.input_names, "parameters": cm.param_names,
           "p": np.asarray(cm.p_value).tolist(), "substeps": substeps,
           "signature": "f(x, u) -> xdot and F(x, u, dt) -> x_next, p built in; "
                        "ThermalModel.to_casadi() gives f(x, u, p), F(x, u, p, dt)",
           **(info or {})}
    if dist is not None:
        doc["E"] = dist.E.tolist()
    if kf is not None:
        doc["noise"] = {"states": kf.states, "Qc_diag": np.diag(kf.Qc).tolist(),
                        "R_diag": np.diag(kf.R).tolist(), "params": kf.params,
                        "meaning": "augmented state x, then d[z] (heat gain [W], random "
                                   "walk, dT[z]/dt += d[z]/C_z); Qc continuous intensity"}
    return f, F, doc
