"""Figures of model reduction: Hankel singular values, step responses, error vs order.

Every function returns a :class:`matplotlib.figure.Figure` built without ``pyplot``
(save it with ``fig.savefig`` or :func:`thermctl.report.save_figure`).
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from ..errors import ModelError
from ..reduce import step_responses

__all__ = ["plot_hsv", "plot_step_responses", "plot_error_vs_order", "default_channels"]

_H = 3600.0


def plot_hsv(hsv, order: int | None = None, n_zones: int | None = None, figsize=(7.0, 4.0)) -> Figure:
    """Hankel singular values (log scale) and the a-priori bound ``2 Σ_{i>r} σ_i`` vs order.

    Parameters
    ----------
    hsv : array_like
        Hankel singular values of the scaled system, descending [K per scaled input unit].
    order : int, optional
        The chosen order: marked with a vertical line.
    n_zones : int, optional
        Adds a secondary axis in states per zone.
    figsize : tuple of float
        [in]
    """
    hsv = np.asarray(hsv, dtype=float)
    if hsv.ndim != 1 or hsv.size == 0:
        raise ModelError("hsv: expected a non-empty 1-D array of Hankel singular values")
    pos = hsv > 0
    r = np.arange(1, hsv.size + 1)
    bound = 2.0 * np.cumsum(hsv[::-1])[::-1]  # bound[k] = 2 Σ_{i>k} σ_i for order k
    fig = Figure(figsize=figsize)
    ax = fig.subplots()
    ax.semilogy(r[pos], hsv[pos], ".", ms=4, label="Hankel singular value σ_i")
    ok = np.append(bound[1:], 0.0) > 0
    ax.semilogy(r[ok], np.append(bound[1:], 0.0)[ok], "-", lw=1.2, label="bound 2 Σ_{i>r} σ_i at order r")
    if order is not None:
        ax.axvline(order, color="k", ls="--", lw=1, label=f"order {order}")
    ax.set_xlabel("index i / order r")
    ax.set_ylabel("K per scaled input unit")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    if n_zones:
        sec = ax.secondary_xaxis("top", functions=(lambda x: x / n_zones, lambda x: x * n_zones))
        sec.set_xlabel("states per zone")
    fig.tight_layout()
    return fig


def default_channels(sys, n: int = 2):
    """A few telling (input, output) pairs: own-zone heat, neighbour heat, first boundary node."""
    zones = [o[2:-1] for o in sys.output_labels if o.startswith("T[")]
    inputs = list(sys.input_labels)
    pairs = []
    for z in zones[:n]:
        if f"Q[{z}]" in inputs:
            pairs.append((f"Q[{z}]", f"T[{z}]"))
    if len(zones) > 1 and f"Q[{zones[0]}]" in inputs:
        pairs.append((f"Q[{zones[0]}]", f"T[{zones[1]}]"))
    boundary = [i for i in inputs if i.startswith("T[")]
    if boundary and zones:
        pairs.append((boundary[0], f"T[{zones[-1]}]"))
    return pairs


def plot_step_responses(full, reduced: dict, channels=None, t_end: float = 48 * _H,
                        capacitances=None, n_points: int = 200, figsize=None) -> Figure:
    """Step responses of the full model and reduced ones, channel by channel.

    Parameters
    ----------
    full : control.StateSpace
        The full continuous model.
    reduced : dict of str → control.StateSpace
        Reduced models with the same signals, keyed by legend label.
    channels : list of (input, output), optional
        Default :func:`default_channels`.
    t_end : float
        [s]
    capacitances : array_like, optional
        State capacitances of the full model [J/K] (speeds up the full responses).
    n_points : int
    figsize : tuple of float, optional
        [in]
    """
    channels = default_channels(full) if channels is None else list(channels)
    if not channels:
        raise ModelError("no channels to plot: pass channels=[(input, output), ...]")
    t = np.linspace(0.0, t_end, n_points)
    ncol = min(2, len(channels))
    nrow = int(np.ceil(len(channels) / ncol))
    fig = Figure(figsize=figsize or (5.5 * ncol, 3.2 * nrow))
    axes = np.atleast_1d(fig.subplots(nrow, ncol, squeeze=False)).ravel()
    ins = list(dict.fromkeys(c[0] for c in channels))
    outs = list(dict.fromkeys(c[1] for c in channels))
    Yf = step_responses(full, t, ins, outs, capacitances=capacitances)
    Yr = {k: step_responses(s, t, ins, outs) for k, s in reduced.items()}
    for ax, (i, o) in zip(axes, channels):
        a, b = outs.index(o), ins.index(i)
        unit = 1000.0 if i.startswith("Q[") else 1.0  # per kW rather than per W
        ax.plot(t / _H, Yf[:, a, b] * unit, "k-", lw=2, label=f"full ({full.nstates})")
        for k, Y in Yr.items():
            ax.plot(t / _H, Y[:, a, b] * unit, "--", lw=1.3, label=f"{k} ({reduced[k].nstates})")
        ax.set_title(f"{i} → {o}", fontsize=9)
        ax.set_xlabel("time [h]")
        ax.set_ylabel("K per kW" if unit != 1.0 else "K per unit")
        ax.grid(True, alpha=0.3)
    for ax in axes[len(channels):]:
        ax.set_visible(False)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def plot_error_vs_order(table, figsize=(7.0, 4.0)) -> Figure:
    """Step-response error at 1, 6, 24 h vs states per zone, one line style per method.

    Parameters
    ----------
    table : pandas.DataFrame
        From :func:`thermctl.reduce.error_vs_order` (several methods concatenated).
    figsize : tuple of float
        [in]
    """
    cols = [c for c in table.columns if c.startswith("err_")]
    if not cols or table.empty:
        raise ModelError("table: expected rows from error_vs_order with err_* columns")
    fig = Figure(figsize=figsize)
    ax = fig.subplots()
    styles = ["-o", "--s", ":^", "-.v", "-x"]
    colors = ["C0", "C1", "C2", "C3"]
    for k, (method, df) in enumerate(table.groupby("method", sort=False)):
        df = df.sort_values("states_per_zone")
        for j, c in enumerate(cols):
            ax.semilogy(df.states_per_zone, df[c].clip(lower=1e-6) * 100, styles[k % len(styles)],
                        color=colors[j % len(colors)], ms=4,
                        label=f"{method}, {c[4:]}")
    ax.axhline(1.0, color="grey", lw=0.8)
    ax.axhline(0.1, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("states per zone")
    ax.set_ylabel("step-response error [%]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return fig
