"""Figures of parameter estimation (paper Fig. 4) and of its identifiability report.

Every function returns a :class:`matplotlib.figure.Figure` built without ``pyplot``
(save it with ``fig.savefig``).
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from ..errors import EstimationError

__all__ = ["plot_cost_vs_rbar", "plot_profiles"]


def plot_cost_vs_rbar(grid, tau0=None, fit=None, logy: bool = True, figsize=(7.0, 4.5)) -> Figure:
    """J against rbar_v for a few values of tau0 = rbar_v·c_v, like paper Fig. 4.

    Parameters
    ----------
    grid : GridResult
        From :func:`thermctl.estimate.grid_search`.
    tau0 : sequence of float, optional
        Which rows to draw [s/m] (the nearest grid values); default: up to five spread
        over the range, always including the row of the minimum.
    fit : EstimationResult, optional
        An NLP estimate to mark (its J at its rbar_v; for per-edge fits nothing is drawn).
    logy : bool
        Logarithmic J axis (J spans decades over the rbar_v range).
    figsize : tuple of float
        [in]

    Returns
    -------
    matplotlib.figure.Figure
    """
    J = np.asarray(grid.J, dtype=float)
    taus = np.asarray(grid.tau0, dtype=float)
    if J.shape != (len(taus), len(grid.rbar_v)):
        raise EstimationError(f"grid.J has shape {J.shape}, expected ({len(taus)}, "
                              f"{len(grid.rbar_v)}) (tau0 × rbar_v)")
    if tau0 is None:
        rows = sorted(set(np.linspace(0, len(taus) - 1, min(5, len(taus))).round().astype(int))
                      | {grid.best_index[0]})
    else:
        rows = sorted({int(np.argmin(np.abs(taus - t))) for t in np.atleast_1d(tau0)})
    fig = Figure(figsize=figsize)
    ax = fig.subplots()
    for i in rows:
        ax.plot(grid.rbar_v, J[i], "-", lw=1.3, label=f"τ0 = {taus[i]:.3g} s/m")
    ax.plot(grid.best_rbar_v, grid.best_J, "ko", ms=6,
            label=f"grid minimum (R̄v = {grid.best_rbar_v:.3g}, Cv = {grid.best_c_v:.3g})")
    if fit is not None and np.ndim(fit.rbar_v) == 0:
        ax.plot(fit.rbar_v, fit.J, "r*", ms=11,
                label=f"NLP ({fit.method.replace('_', ' ')}): R̄v = {fit.rbar_v:.3g}, "
                      f"Cv = {fit.c_v:.3g}, τ0 = {fit.tau0:.3g}")
    ax.set_xscale("log")
    if logy and np.all(J[rows] > 0):
        ax.set_yscale("log")
    ax.set_xlabel("R̄v [K/(W m)]")
    ax.set_ylabel("J [K²]")
    title = f"prediction cost J (paper eq. 3), initial state '{grid.initial_state}'"
    if grid.active_bounds:
        title += " — minimum on a bound"
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_profiles(report, figsize=(7.0, 3.5)) -> Figure:
    """Profiles of J along each parameter (the identifiability report), one panel each.

    Parameters
    ----------
    report : thermctl.estimate.simulation.ProfileReport
        From :func:`thermctl.estimate.identifiability_report` (or ``result.identifiability``).
    figsize : tuple of float
        [in]
    """
    profs = list(report.profiles.values())
    if not profs:
        raise EstimationError("the identifiability report has no profiles")
    fig = Figure(figsize=(figsize[0], figsize[1]))
    axes = np.atleast_1d(fig.subplots(1, len(profs), sharey=True))
    for ax, p in zip(axes, profs):
        f = np.append(p.factors, 1.0)
        J = np.append(p.J, report.J)
        order = np.argsort(f)
        ax.plot(f[order], J[order], "o-", ms=4)
        ax.plot(1.0, report.J, "r*", ms=10)
        ax.set_xscale("log")
        ax.set_title(f"{p.name}: {p.verdict}", fontsize=9)
        ax.set_xlabel("multiple of the estimate [-]")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("profiled J [K²]")
    fig.tight_layout()
    return fig
