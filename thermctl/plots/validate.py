"""Validation figures: open-loop traces (paper Fig. 5/6) and the step-response matrix."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

__all__ = ["plot_open_loop", "plot_step_responses"]

_STYLE = {"identified": ("tab:blue", "-"), "conduction-only": ("tab:red", "--"),
          "truth": ("tab:green", ":")}


def plot_open_loop(vr, zone: str, figsize=(8.0, 3.6)) -> Figure:
    """Measured vs predicted temperature of one zone over the validation window."""
    fig = Figure(figsize=figsize)
    ax = fig.add_subplot()
    first = next(iter(vr.open_loop.values()))
    k = first.zones.index(zone)
    n = first.measured.shape[0]
    t = pd.date_range(vr.window[0], periods=n, freq=pd.Timedelta(vr.window_step_s, "s")) \
        if hasattr(vr, "window_step_s") else np.arange(n)
    conv = vr.to_data_units
    offset = 32.0 if vr.units == "°F" else 0.0
    ax.plot(t, conv(first.measured[:, k]) + offset, color="k", lw=1.2, label="measured")
    for name, r in vr.open_loop.items():
        c, ls = _STYLE.get(name, ("tab:gray", "-"))
        ax.plot(t, conv(r.predicted[:, k]) + offset, color=c, ls=ls, lw=1.2,
                label=f"{name} (RMSE {float(conv(r.rmse[zone])):.2f})")
    ax.set_ylabel(f"{zone} temperature [{vr.units}]")
    ax.set_xlabel("time" if hasattr(vr, "window_step_s") else "sample")
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    fig.autofmt_xdate()
    return fig


def plot_step_responses(vr, figsize=None) -> Figure:
    """Heat-step response matrices, one panel per horizon, models side by side."""
    names = list(vr.step_responses)
    H = len(vr.horizons_h)
    n = len(vr.zones)
    fig = Figure(figsize=figsize or (3.2 * len(names), 2.9 * H))
    vmax = max(float(np.max(g)) for g in vr.step_responses.values())
    for h in range(H):
        for j, name in enumerate(names):
            ax = fig.add_subplot(H, len(names), h * len(names) + j + 1)
            im = ax.imshow(vr.step_responses[name][h], vmin=0, vmax=vmax, cmap="viridis")
            ax.set_title(f"{name}, {vr.horizons_h[h]:g} h", fontsize=9)
            ax.set_xticks(range(n), vr.zones, rotation=90, fontsize=6)
            ax.set_yticks(range(n), vr.zones, fontsize=6)
            if j == 0:
                ax.set_ylabel("temperature of zone", fontsize=8)
            if h == H - 1:
                ax.set_xlabel("heat into zone", fontsize=8)
    fig.colorbar(im, ax=fig.axes, shrink=0.6, label="K per 100 W")
    return fig
