"""The thermal network: zones and boundary nodes joined by 3R2C edges.

State ordering (stable, documented in ``docs/model.md``):

1. ``T[z]`` for every zone, in spec order;
2. ``x[e,1]``, ``x[e,2]`` for every edge: conduction edges in spec order, then
   convection edges in the order they were added.

Input ordering: ``ms[z]`` (supply mass flow [kg/s]) for every zone, ``Ts[z]``
(supply temperature [°C]) for every zone, ``T[b]`` for every boundary node,
``Q[z]`` (heat input [W]) for every zone. Outputs: ``T[z]`` for every zone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Mapping

import networkx as nx
import numpy as np

from .errors import ModelError, SpecError
from .spec import BuildingSpec

__all__ = ["Edge", "ThermalNetwork", "air_path_name"]


def air_path_name(a: str, b: str) -> str:
    """Name of the air path (convection edge) between nodes ``a`` and ``b``: ``air:a-b``
    with the ends sorted, the one spelling every module uses."""
    a, b = sorted((str(a), str(b)))
    return f"air:{a}-{b}"

CONDUCTION = "conduction"
CONVECTION = "convection"


@dataclass(frozen=True)
class Edge:
    """One 3R2C edge of the network.

    Attributes
    ----------
    name : str
        Unique name, used in state names ``x[name,1]``.
    a, b : str
        End nodes.
    kind : {"conduction", "convection"}
    R : tuple of 3 float or None
        Resistances [K/W] of a conduction edge (None for convection: from ``rbar_v·d``).
    C : tuple of 2 float or None
        Capacitances [J/K] of a conduction edge (None for convection: ``c_v``).
    d : float or None
        Air path length [m] of a convection edge.
    """

    name: str
    a: str
    b: str
    kind: str
    R: tuple | None = None
    C: tuple | None = None
    d: float | None = None


class ThermalNetwork:
    """Zones, boundary nodes and typed 3R2C edges, with a fixed state ordering.

    Parameters
    ----------
    spec : BuildingSpec
        Gives the zones, boundary nodes and conduction edges (walls).
    convection : iterable of (a, b) or (a, b, d), optional
        Convection edges between zones. ``d`` [m] defaults to the spec's distance
        for that pair; a pair with no known distance is an error.

    Examples
    --------
    >>> net = ThermalNetwork(spec, convection=[("r240", "r243")])  # doctest: +SKIP
    >>> net.state_names[:2]  # doctest: +SKIP
    ['T[r240]', 'T[r241]']
    """

    def __init__(self, spec: BuildingSpec, convection: Iterable = ()):
        self.spec = spec
        self.zones = list(spec.zone_names)
        self.boundary = list(spec.boundary)
        self.measured_zones = list(spec.measured_zones)
        edges = []
        used = set()
        for w in spec.walls:
            base = w.name or f"{w.a}-{w.b}"
            name, k = base, 2
            while name in used:
                name, k = f"{base}#{k}", k + 1
            used.add(name)
            edges.append(Edge(name, w.a, w.b, CONDUCTION, tuple(w.R), tuple(w.C)))
        for item in convection:
            a, b, d = self._convection_entry(item)
            name = air_path_name(a, b)
            if name in used:
                raise SpecError(f"convection edge {a}-{b} given twice")
            used.add(name)
            edges.append(Edge(name, a, b, CONVECTION, d=d))
        self.edges = edges
        self.graph = nx.MultiGraph()
        for z in self.zones:
            self.graph.add_node(z, kind="zone", measured=z in self.measured_zones)
        for b in self.boundary:
            self.graph.add_node(b, kind="boundary")
        for e in edges:
            self.graph.add_edge(e.a, e.b, key=e.name, kind=e.kind, edge=e)

    def _convection_entry(self, item):
        if len(item) == 2:
            a, b = item
            d = None
        elif len(item) == 3:
            a, b, d = item
        else:
            raise SpecError(f"convection edge must be (a, b) or (a, b, d), found {item!r}")
        a, b = sorted((str(a), str(b)))
        # one end may be a boundary node when the length is given: in a local problem
        # (thermctl.local) a measured neighbour zone is a boundary node, and the air path
        # to it is still an air path
        for n in (a, b):
            if n not in self.zones and not (d is not None and n in self.boundary
                                            and (a in self.zones or b in self.zones)):
                raise SpecError(f"convection edge {a}-{b}: {n!r} is not a zone of "
                                f"{self.spec.source}; zones are {self.zones}")
        if a == b:
            raise SpecError(f"convection edge names zone {a!r} twice")
        if d is None:
            d = self.spec.distance(a, b)
            if d is None:
                raise SpecError(f"convection edge {a}-{b}: {self.spec.source} gives no distance "
                                "for this pair; add it under 'distances' or pass d")
        d = float(d)
        if not np.isfinite(d) or d <= 0:
            raise SpecError(f"convection edge {a}-{b}: distance must be > 0 [m], found {d}")
        return a, b, d

    # ---- derived networks --------------------------------------------------
    @property
    def convection_edges(self) -> list[Edge]:
        return [e for e in self.edges if e.kind == CONVECTION]

    @property
    def conduction_edges(self) -> list[Edge]:
        return [e for e in self.edges if e.kind == CONDUCTION]

    @property
    def convection_pairs(self) -> list[tuple[str, str, float]]:
        return [(e.a, e.b, e.d) for e in self.convection_edges]

    def with_convection(self, convection: Iterable) -> "ThermalNetwork":
        """A new network with the same spec and these convection edges (replacing any)."""
        return ThermalNetwork(self.spec, convection)

    def conduction_only(self) -> "ThermalNetwork":
        """The same network without convection edges."""
        return ThermalNetwork(self.spec, ())

    # ---- sizes and names ---------------------------------------------------
    @property
    def n_zones(self) -> int:
        return len(self.zones)

    @property
    def n_states(self) -> int:
        return len(self.zones) + 2 * len(self.edges)

    @property
    def n_inputs(self) -> int:
        return 3 * len(self.zones) + len(self.boundary)

    @property
    def state_names(self) -> list[str]:
        names = [f"T[{z}]" for z in self.zones]
        for e in self.edges:
            names += [f"x[{e.name},1]", f"x[{e.name},2]"]
        return names

    @property
    def input_names(self) -> list[str]:
        return ([f"ms[{z}]" for z in self.zones] + [f"Ts[{z}]" for z in self.zones]
                + [f"T[{b}]" for b in self.boundary] + [f"Q[{z}]" for z in self.zones])

    @property
    def output_names(self) -> list[str]:
        return [f"T[{z}]" for z in self.zones]

    def input_slices(self) -> dict[str, slice]:
        """Where each input group sits in the input vector."""
        nz, nb = len(self.zones), len(self.boundary)
        return {"ms": slice(0, nz), "Ts": slice(nz, 2 * nz),
                "T": slice(2 * nz, 2 * nz + nb), "Q": slice(2 * nz + nb, 3 * nz + nb)}

    def input_vector(self, ms=0.0, Ts=20.0, T=10.0, Q=0.0) -> np.ndarray:
        """Build an input vector from scalars (broadcast) or dicts keyed by node name.

        Parameters
        ----------
        ms : float or mapping
            Supply mass flow per zone [kg/s]; missing zones get 0.
        Ts : float or mapping
            Supply air temperature per zone [°C]; missing zones get 20.
        T : float or mapping
            Boundary node temperatures [°C]; every boundary node must be given if a mapping.
        Q : float or mapping
            Heat input per zone [W]; missing zones get 0.
        """
        def fill(val, names, default, what, require=False):
            if isinstance(val, Mapping):
                unknown = sorted(set(val) - set(names))
                if unknown:
                    raise ModelError(f"{what}: unknown node(s) {unknown}; expected {names}")
                if require:
                    missing = [n for n in names if n not in val]
                    if missing:
                        raise ModelError(f"{what}: missing value(s) for {missing}")
                return [float(val.get(n, default)) for n in names]
            return [float(val)] * len(names)

        return np.array(fill(ms, self.zones, 0.0, "ms") + fill(Ts, self.zones, 20.0, "Ts")
                        + fill(T, self.boundary, 10.0, "T", require=True)
                        + fill(Q, self.zones, 0.0, "Q"))

    # ---- linear-network structure -----------------------------------------
    def links(self):
        """Resistive links of the network.

        Returns
        -------
        ends : ndarray of int, shape (L, 2)
            Node indices; nodes ``0..n_states-1`` are states, ``n_states + j`` is
            boundary node ``j``.
        R : ndarray, shape (L,)
            Resistance [K/W] of conduction links; NaN for convection links.
        conv_edge : ndarray of int, shape (L,)
            Index of the convection edge of each link (into ``convection_edges``), or -1.
        """
        nz = len(self.zones)
        index = {z: i for i, z in enumerate(self.zones)}
        index.update({b: self.n_states + j for j, b in enumerate(self.boundary)})
        ends, R, conv = [], [], []
        k_conv = 0
        for k, e in enumerate(self.edges):
            s1, s2 = nz + 2 * k, nz + 2 * k + 1
            chain = [(index[e.a], s1), (s1, s2), (s2, index[e.b])]
            ends += chain
            if e.kind == CONDUCTION:
                R += list(e.R)
                conv += [-1, -1, -1]
            else:
                R += [np.nan] * 3
                conv += [k_conv] * 3
                k_conv += 1
        return np.array(ends, dtype=int).reshape(-1, 2), np.array(R), np.array(conv, dtype=int)

    def fixed_capacitances(self) -> np.ndarray:
        """Capacitance of every state [J/K]; NaN for convection edge states (``c_v``)."""
        cap = [self.spec.zone_capacitance(z) for z in self.zones]
        for e in self.edges:
            cap += list(e.C) if e.kind == CONDUCTION else [np.nan, np.nan]
        return np.array(cap)

    def conv_state_edge(self) -> np.ndarray:
        """Index of the convection edge of every state, or -1."""
        idx = [-1] * len(self.zones)
        k_conv = 0
        for e in self.edges:
            if e.kind == CONVECTION:
                idx += [k_conv, k_conv]
                k_conv += 1
            else:
                idx += [-1, -1]
        return np.array(idx, dtype=int)

    def neighbours(self, node: str) -> list[str]:
        return sorted(set(self.graph.neighbors(node)))

    def __repr__(self):
        return (f"ThermalNetwork({self.spec.name!r}: {len(self.zones)} zones, "
                f"{len(self.boundary)} boundary nodes, {len(self.conduction_edges)} conduction "
                f"and {len(self.convection_edges)} convection edges, {self.n_states} states)")
