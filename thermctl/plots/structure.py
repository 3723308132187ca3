"""Figures of structure identification (paper Figs. 3 and 7).

Every function takes a fitted :class:`~thermctl.structure.StructureIdentifier` and
returns a :class:`matplotlib.figure.Figure` built without ``pyplot`` (no global state,
no display needed: save it with ``fig.savefig``).
"""

from __future__ import annotations

import networkx as nx
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle
from matplotlib.textpath import TextPath

from ..errors import DataError

__all__ = ["plot_network", "plot_scores", "plot_correlations"]


def _check_fitted(sid):
    if not hasattr(sid, "network_"):    # set last by either identifier's fit
        raise DataError("the StructureIdentifier is not fitted; call fit(data, network) first")


def _node_sizes(labels, square: bool = False, fontsize: float = 7.0, pad: float = 3.0,
                smallest: float = 22.0, largest: float = 40.0) -> tuple[float, dict]:
    """Marker size [pt] that holds every label, and each label's font size [pt].

    A circle's diameter is the diagonal of the widest label's box plus a margin, a
    square's side the box's width plus a margin, between ``smallest`` and ``largest``; a
    label still too wide at ``largest`` gets a smaller font.
    """
    def need(label):
        ext = TextPath((0, 0), label, size=fontsize).get_extents()
        w, h = ext.width, max(ext.height, 0.75 * fontsize)
        return (w if square else float(np.hypot(w, h))) + 2 * pad

    needs = {lab: need(lab) for lab in labels}
    d = min(largest, max([smallest, *needs.values()]))
    fonts = {lab: fontsize if n <= d else fontsize * (d - 2 * pad) / (n - 2 * pad)
             for lab, n in needs.items()}
    return d, fonts


def plot_network(sid, seed: int = 0, figsize=(7.0, 5.5), network=None, title=None) -> Figure:
    """The thermal network with conduction (solid) and convection (dashed) edges.

    Like paper Fig. 3: zones are circles (hollow if unmeasured), boundary nodes grey
    squares, both sized so that their names fit inside; each convection edge is labelled
    with its score.

    Parameters
    ----------
    sid : StructureIdentifier
        Fitted; its ``network_`` is drawn.
    seed : int
        Seed of the layout (used only if the Kamada-Kawai layout fails).
    figsize : tuple of float
        Figure size [in].
    network : ThermalNetwork, optional
        Draw this network instead of ``sid.network_`` (e.g. the model-based selection's),
        labelling its convection edges with their SIN scores.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_fitted(sid)
    net = sid.network_ if network is None else network
    g = nx.Graph()
    g.add_nodes_from(net.zones + net.boundary)
    g.add_edges_from((e.a, e.b) for e in net.edges)
    try:
        pos = nx.kamada_kawai_layout(g)
    except Exception:  # disconnected or degenerate graphs: fall back to a seeded layout
        pos = nx.spring_layout(g, seed=seed)
    fig = Figure(figsize=figsize)
    ax = fig.subplots()
    drawn = set()
    for e in net.conduction_edges:
        key = frozenset((e.a, e.b))
        if key in drawn:  # parallel walls (wall + window) drawn once
            continue
        drawn.add(key)
        (x0, y0), (x1, y1) = pos[e.a], pos[e.b]
        ax.plot([x0, x1], [y0, y1], "-", color="0.35", lw=1.5, zorder=1, gid="conduction")
    score = {frozenset(p): v for p, v in sid.scores_.items()}
    for e in net.convection_edges:
        (x0, y0), (x1, y1) = pos[e.a], pos[e.b]
        ax.plot([x0, x1], [y0, y1], "--", color="tab:red", lw=2.0, zorder=2, gid="convection")
        s = score.get(frozenset((e.a, e.b)))
        if s is not None:
            ax.text((x0 + x1) / 2, (y0 + y1) / 2, f"{s:.2f}", color="tab:red", fontsize=8,
                    ha="center", va="center", zorder=4,
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.8))
    d, fonts = _node_sizes([str(z) for z in net.zones])
    side, box_fonts = _node_sizes([str(b) for b in net.boundary], square=True)
    fonts.update(box_fonts)
    for node in g.nodes:
        x, y = pos[node]
        if node in net.boundary:
            ax.scatter([x], [y], s=side ** 2, marker="s", c="0.8", edgecolors="0.3",
                       zorder=3, gid=f"node:{node}")
        else:
            measured = node in net.measured_zones
            ax.scatter([x], [y], s=d ** 2, marker="o", c="tab:blue" if measured else "white",
                       edgecolors="tab:blue", linewidths=1.5, zorder=3, gid=f"node:{node}")
        ax.text(x, y, node, fontsize=fonts[str(node)], ha="center", va="center", zorder=5,
                color="white" if node in net.measured_zones else "black", gid=f"label:{node}")
    ax.legend(handles=[Line2D([], [], color="0.35", lw=1.5, label="conduction"),
                       Line2D([], [], color="tab:red", ls="--", lw=2, label="convection (score)")],
              loc="best", fontsize=8)
    ax.set_title(title or f"{net.spec.name}: identified thermal network ({sid.method}, rule={sid.rule})")
    ax.set_axis_off()
    ax.margins(0.12)
    return fig


def plot_scores(sid, figsize=None) -> Figure:
    """Score matrix: fraction of times of day with each edge, for every zone pair.

    Pairs joined by a wall are hatched (they are removed unless ``allow_parallel``);
    selected convection edges are outlined in red.

    Parameters
    ----------
    sid : StructureIdentifier
        Fitted.
    figsize : tuple of float, optional
        Figure size [in]; grows with the number of zones by default.

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_fitted(sid)
    zones, M = sid.zones_, sid.score_matrix_
    n = len(zones)
    side = min(12.0, 3.0 + 0.45 * n)
    fig = Figure(figsize=figsize or (side + 1.2, side))
    ax = fig.subplots()
    im = ax.imshow(np.where(np.eye(n, dtype=bool), np.nan, M), vmin=0, vmax=1, cmap="viridis")
    fig.colorbar(im, ax=ax, label="score $s_{ij}$ [-]")
    ax.set_xticks(range(n), zones, rotation=90, fontsize=8)
    ax.set_yticks(range(n), zones, fontsize=8)
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            if frozenset((zones[i], zones[j])) in sid.conduction_pairs_:
                ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="//",
                                       ec="white", lw=0, gid="wall"))
            if n <= 15:
                ax.text(j, i, f"{M[i, j]:.2f}", ha="center", va="center", fontsize=7,
                        color="white" if M[i, j] < 0.6 else "black")
    for e in sid.edges_:
        i, j = sid.pair_index(e.a, e.b)
        for r, c in ((i, j), (j, i)):
            ax.add_patch(Rectangle((c - 0.5, r - 0.5), 1, 1, fill=False, ec="red", lw=2,
                                   gid="selected"))
    ax.set_title(f"edge scores ({sid.method}); hatched: wall, red: selected")
    return fig


def _default_pairs(sid):
    zones = sid.zones_
    a = sid.edges_[0].a if sid.edges_ else zones[0]
    i = zones.index(a)
    others = sorted((j for j in range(len(zones)) if j != i),
                    key=lambda j: -sid.score_matrix_[i, j])
    return [(a, zones[j]) for j in others[:4]]


def plot_correlations(sid, pairs=None, figsize=(8.0, 6.0)) -> Figure:
    """Marginal and partial correlation over the day for some zone pairs (paper Fig. 7).

    Marginal correlations mostly show the operation of the building (all zones
    drifting together at night); partial correlations show direct interaction.
    Dots on the lower panel mark the times at which the pair is an edge of the graph.

    Parameters
    ----------
    sid : StructureIdentifier
        Fitted.
    pairs : list of (str, str), optional
        Measured-zone pairs; default: the first selected edge's first zone with its
        four highest-scoring partners.
    figsize : tuple of float
        Figure size [in].

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_fitted(sid)
    pairs = _default_pairs(sid) if pairs is None else list(pairs)
    hours = sid.times_ / 3600.0
    fig = Figure(figsize=figsize)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    for a, b in pairs:
        i, j = sid.pair_index(a, b)
        (line,) = ax1.plot(hours, sid.correlations_[:, i, j], label=f"({a}, {b})")
        ax2.plot(hours, sid.partial_correlations_[:, i, j], color=line.get_color())
        on = sid.graphs_[:, i, j]
        ax2.plot(hours[on], sid.partial_correlations_[on, i, j], ".", color=line.get_color(),
                 ms=4)
    ax1.set_ylabel("marginal correlation [-]")
    ax2.set_ylabel("partial correlation [-]")
    ax2.set_xlabel("time of day [h]")
    for ax in (ax1, ax2):
        ax.set_ylim(-1.05, 1.05)
        ax.axhline(0, color="0.6", lw=0.8)
        ax.grid(alpha=0.3)
    ax2.set_xlim(0, 24)
    ax1.legend(fontsize=8, ncol=2)
    ax1.set_title(f"correlations over the day ({len(sid.days_used_)} days; dots: edge in graph)")
    return fig
