"""Testbed buildings: specs with known convection edges.

Two layouts:

* :func:`pugh_hall_spec` — the paper's case (Goyal, Liao & Barooah, Fig. 2): six offices
  on both sides of an unmeasured hallway on the 2nd floor of Pugh Hall (Gainesville, FL),
  north walls to the outside, measured neighbouring spaces as boundary nodes, floor and
  roof neglected as in the paper.
* :func:`corridor_floor_spec` — ``n`` offices on each side of a corridor, several floors
  stacked (slabs between floors, roof, a measured space below), to scale up to hundreds
  of zones.

Both return ``(spec, edges)``: a :class:`~thermctl.spec.BuildingSpec` without convection
edges (walls and air-path distances only, what a user would write) and the true
convection edges ``[(a, b, d)]``. The true edges always join zones with no wall between
them (the paper's rule excludes conduction pairs), and their ``d`` is in the spec.

Wall data (U-values include surface films; areal heat capacities of the layers on the
room side of the insulation):

==================  ================  ===================  ==========================
element             U [W/(m² K)]      heat cap. [J/(m² K)]  source / reasoning
==================  ================  ===================  ==========================
exterior wall       0.45              1.2e5                 insulated masonry, ASHRAE 90.1-2007 zone 2
window              2.8               2.0e4                 double glazing, aluminium frame
office partition    1.8               2.5e4                 steel stud, 2 × gypsum
office–hallway      2.0               2.2e4                 partition with door
hallway door        3.0               1.5e4                 double door leaf
floor slab          1.2               3.0e5                 150 mm concrete, carpet, ceiling
roof                0.3               3.0e5                 insulated concrete deck
==================  ================  ===================  ==========================
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import SpecError
from ..spec import RHO_AIR, BuildingSpec, cp_moist_air, spec_from_dict

__all__ = ["pugh_hall_spec", "corridor_floor_spec", "Layout", "WALL_TYPES"]

WALL_TYPES = {
    # name: (u_value [W/(m² K)], heat_capacity [J/(m² K)])
    "exterior": (0.45, 1.2e5),
    "window": (2.8, 2.0e4),
    "partition": (1.8, 2.5e4),
    "hall": (2.0, 2.2e4),
    "door": (3.0, 1.5e4),
    "slab": (1.2, 3.0e5),
    "roof": (0.3, 3.0e5),
}
"""U-value and areal heat capacity of the wall types used by the testbed layouts."""

SHGC_EFFECTIVE = 0.35
"""Solar aperture per m² of window [-]: SHGC 0.4 of the glass times a 0.87 glazed fraction."""

CAPACITY_MULTIPLIER = 6.0
"""Zone capacitance over air capacitance for furnished offices [-] (furniture, paper, the
surface layers of floor and ceiling; 5–10 is typical)."""

HALL_MULTIPLIER = 3.0
"""The same for hallways and corridors [-] (little furniture)."""


@dataclass
class Layout:
    """A testbed building: spec, true air paths and what the generator needs beyond the spec.

    Attributes
    ----------
    spec : BuildingSpec
    edges : list of (str, str, float)
        True convection edges ``(a, b, d)``, ``d`` [m].
    floor_area : dict
        Floor area per zone [m²] (lighting and equipment gains scale with it).
    solar_aperture : dict
        Effective solar aperture per zone [m²] of south-facing glazing (0 or absent: none).
    kind : dict
        ``"office"`` (VAV box, occupants) or ``"hall"`` (no supply air, lighting only).
    """

    spec: BuildingSpec
    edges: list
    floor_area: dict = field(default_factory=dict)
    solar_aperture: dict = field(default_factory=dict)
    kind: dict = field(default_factory=dict)

    @classmethod
    def from_spec(cls, spec: BuildingSpec, edges=(), height: float = 3.0) -> "Layout":
        """Layout of a user spec: measured zones are offices, unmeasured ones halls, no sun.

        Parameters
        ----------
        spec : BuildingSpec
        edges : iterable of (a, b) or (a, b, d)
            True convection edges; ``d`` [m] defaults to the spec's distance.
        height : float
            Room height [m] used to get floor areas from volumes.
        """
        out = []
        for item in edges:
            if len(item) not in (2, 3):
                raise SpecError(f"true convection edge must be (a, b) or (a, b, d), found {item!r}")
            a, b = str(item[0]), str(item[1])
            d = item[2] if len(item) == 3 else spec.distance(a, b)
            if d is None:
                raise SpecError(f"true convection edge {a}-{b}: {spec.source} gives no distance "
                                "for this pair; add it under 'distances' or pass (a, b, d)")
            out.append((a, b, float(d)))
        kind = {z.name: "office" if z.measured else "hall" for z in spec.zones}
        area = {z.name: z.volume / height for z in spec.zones}
        return cls(spec, out, area, {}, kind)


def _wall(a, b, kind, area, name):
    u, hc = WALL_TYPES[kind]
    return {"between": [a, b], "area": round(float(area), 3), "u_value": u, "heat_capacity": hc,
            "name": name}


def _hall_capacitance(volume, cp):
    return HALL_MULTIPLIER * RHO_AIR * cp * volume


def _pick_edges(rng, offices, cand, p_edge, max_edge):
    """Open-door pairs ``(a, b, d)``, sorted: each office in at most one, a partner within
    ``max_edge`` [m] drawn with probability ∝ 1/d, an office tried with probability ``p_edge``."""
    free, edges = set(offices), []
    for a in rng.permutation(offices):
        if a not in free or rng.random() >= p_edge:
            continue
        opts = [(b if x == a else x, d) for x, b, d in cand
                if a in (x, b) and d <= max_edge and (b if x == a else x) in free]
        if not opts:
            continue
        w = np.array([1.0 / d for _, d in opts])
        b, d = opts[rng.choice(len(opts), p=w / w.sum())]
        free -= {a, b}
        edges.append((*sorted((str(a), str(b))), d))
    return sorted(edges)


def pugh_hall_layout() -> Layout:
    """The :func:`pugh_hall_spec` building with floor areas and zone kinds (no sun: north walls)."""
    height, hall_w, floor_h = 3.0, 2.0, 3.6
    # (name, x_left [m], width [m], door x [m]) — north row over the outside wall, south row
    # across the hallway. Door positions decide the air-path lengths.
    north = [("r240", 0.0, 4.0, 2.6), ("r241", 4.0, 3.6, 5.8), ("r242", 7.6, 4.4, 10.8)]
    south = [("r243", 0.0, 4.2, 1.8), ("r244", 4.2, 3.8, 6.4), ("r247", 8.0, 4.6, 9.6)]
    depth = 5.0
    hall_len = 14.0
    zones, walls, area = {}, [], {}
    for row in (north, south):
        for name, _, width, _ in row:
            zones[name] = {"volume": round(width * depth * height, 3)}
            area[name] = width * depth
    hall_vol = hall_len * hall_w * height
    zones["hallway"] = {"volume": hall_vol, "measured": False,
                        "capacitance": round(_hall_capacitance(hall_vol, cp_moist_air()), 1)}
    area["hallway"] = hall_len * hall_w
    for name, _, width, _ in north:
        glass = (width - 1.0) * 1.5
        walls.append(_wall(name, "outside", "exterior", width * floor_h - glass, f"{name}:ext"))
        walls.append(_wall(name, "outside", "window", glass, f"{name}:window"))
    for row, west, east in ((north, "r200", "r210"), (south, "r230", "r248")):
        names = [r[0] for r in row]
        walls.append(_wall(west, names[0], "partition", depth * height, f"{west}|{names[0]}"))
        for a, b in zip(names, names[1:]):
            walls.append(_wall(a, b, "partition", depth * height, f"{a}|{b}"))
        walls.append(_wall(names[-1], east, "partition", depth * height, f"{names[-1]}|{east}"))
        for name, _, width, _ in row:
            walls.append(_wall(name, "hallway", "hall", width * height, f"{name}|hallway"))
    walls.append(_wall("hallway", "corridor", "door", hall_w * height, "hallway|corridor"))
    door = {r[0]: r[3] for r in north + south}
    pairs = [("r240", "r242")] + [("r243", "r247")] + [(a[0], b[0]) for a in north for b in south]
    distances = [{"between": [a, b], "d": round(abs(door[a] - door[b]) + hall_w, 2)}
                 for a, b in pairs]
    spec = spec_from_dict({
        "name": "pugh-hall-2f",
        "capacity_multiplier": CAPACITY_MULTIPLIER,
        "zones": zones,
        "boundary": ["outside", "r200", "r210", "r230", "r248", "corridor"],
        "walls": walls,
        "distances": distances,
    }, source="pugh-hall-2f")
    # Open doors pairing each office with one across the hallway: one straight across,
    # two diagonal (air paths follow pressure differences, not the shortest route).
    truth = [("r240", "r243"), ("r241", "r247"), ("r242", "r244")]
    edges = [(a, b, spec.distance(a, b)) for a, b in truth]
    kind = {z: "office" for z in spec.measured_zones}
    kind["hallway"] = "hall"
    return Layout(spec, edges, area, {}, kind)


def pugh_hall_spec():
    """The paper's building: Pugh Hall, 2nd floor section (Goyal, Liao & Barooah, Fig. 2).

    Six measured offices (``r240``–``r242`` on the north side with north walls and windows
    to the outside; ``r243``, ``r244``, ``r247`` across an unmeasured ``hallway``), measured
    neighbouring spaces ``r200``, ``r210``, ``r230``, ``r248`` and ``corridor`` as boundary
    nodes with ``outside``. Floor and roof are neglected as in the paper. Offices are
    3.6–4.6 m × 5 m × 3 m; the hallway 14 m × 2 m. Air-path lengths are door-to-door
    through the hallway.

    Returns
    -------
    spec : BuildingSpec
        Walls and distances, no convection edges.
    edges : list of (str, str, float)
        True convection edges ``(a, b, d)`` [m]: ``r240–r243`` (2.8 m), ``r241–r247``
        (5.8 m), ``r242–r244`` (6.4 m).

    Examples
    --------
    >>> spec, edges = pugh_hall_spec()
    >>> spec.measured_zones
    ['r240', 'r241', 'r242', 'r243', 'r244', 'r247']
    >>> edges[0]
    ('r240', 'r243', 2.8)
    """
    lay = pugh_hall_layout()
    return lay.spec, list(lay.edges)


def corridor_layout(n_per_side: int, floors: int = 1, seed: int = 0, *, office_width: float = 4.0,
                    depth: float = 5.0, height: float = 3.0, corridor_width: float = 2.0,
                    p_edge: float = 0.35, max_edge_distance: float = 8.0,
                    max_distance: float = 15.0) -> Layout:
    """:func:`corridor_floor_spec` with floor areas, solar apertures and zone kinds."""
    if int(n_per_side) != n_per_side or n_per_side < 2:
        raise SpecError(f"n_per_side must be an integer >= 2, found {n_per_side!r}")
    if int(floors) != floors or floors < 1:
        raise SpecError(f"floors must be an integer >= 1, found {floors!r}")
    if not 0.0 <= p_edge <= 1.0:
        raise SpecError(f"p_edge must be in [0, 1], found {p_edge}")
    n, floors = int(n_per_side), int(floors)
    rng = np.random.default_rng(seed)
    floor_h = height + 0.6
    hall_len = n * office_width
    zones, walls, distances, area, aperture, kind = {}, [], [], {}, {}, {}
    edges = []
    for f in range(1, floors + 1):
        rows = {side: [f"f{f}{side}{i:02d}" for i in range(n)] for side in "ns"}
        hall = f"f{f}hall"
        hall_vol = hall_len * corridor_width * height
        for side, names in rows.items():
            for i, z in enumerate(names):
                zones[z] = {"volume": round(office_width * depth * height, 3), "storey": f}
                area[z] = office_width * depth
                kind[z] = "office"
                glass = (office_width - 1.0) * 1.5
                walls.append(_wall(z, "outside", "exterior", office_width * floor_h - glass, f"{z}:ext"))
                walls.append(_wall(z, "outside", "window", glass, f"{z}:window"))
                if side == "s":
                    aperture[z] = SHGC_EFFECTIVE * glass
                walls.append(_wall(z, hall, "hall", office_width * height, f"{z}|{hall}"))
            for a, b in zip(names, names[1:]):
                walls.append(_wall(a, b, "partition", depth * height, f"{a}|{b}"))
            for end in (names[0], names[-1]):
                walls.append(_wall(end, "outside", "exterior", depth * floor_h, f"{end}:end"))
        zones[hall] = {"volume": hall_vol, "measured": False, "storey": f,
                       "capacitance": round(_hall_capacitance(hall_vol, cp_moist_air()), 1)}
        area[hall] = hall_len * corridor_width
        kind[hall] = "hall"
        walls.append(_wall(hall, "outside", "door", 2 * corridor_width * floor_h, f"{hall}:ends"))
        for z in rows["n"] + rows["s"] + [hall]:
            a = area[z]
            below = "below" if f == 1 else z.replace(f"f{f}", f"f{f - 1}", 1)
            if f == 1:
                walls.append(_wall(z, "below", "slab", a, f"{z}:floor"))
            else:
                walls.append(_wall(below, z, "slab", a, f"{below}|{z}"))
            if f == floors:
                walls.append(_wall(z, "outside", "roof", a, f"{z}:roof"))
        # Doors at the office centre, jittered: air-path lengths are door to door via the corridor.
        door = {}
        for side, names in rows.items():
            for i, z in enumerate(names):
                door[z] = (i + 0.5) * office_width + rng.uniform(-0.3, 0.3) * office_width
        offices = rows["n"] + rows["s"]
        walled = {frozenset(p) for names in rows.values() for p in zip(names, names[1:])}
        cand = []
        for i, a in enumerate(offices):
            for b in offices[i + 1:]:
                if frozenset((a, b)) in walled:
                    continue
                d = round(abs(door[a] - door[b]) + corridor_width, 2)
                if d <= max_distance:
                    distances.append({"between": [a, b], "d": d})
                    cand.append((a, b, d))
        # Open-door pairs: each office joins at most one air path; partners within
        # max_edge_distance, nearer ones likelier.
        edges += _pick_edges(rng, offices, cand, p_edge, max_edge_distance)
    spec = spec_from_dict({
        "name": f"corridor-{floors}x{n}x2",
        "capacity_multiplier": CAPACITY_MULTIPLIER,
        "zones": zones,
        "boundary": ["outside", "below"],
        "walls": walls,
        "distances": distances,
    }, source=f"corridor-{floors}x{n}x2")
    edges.sort()
    return Layout(spec, edges, area, aperture, kind)


def corridor_floor_spec(n_per_side: int, floors: int = 1, seed: int = 0, **kwargs):
    """A corridor office floor (or several stacked): ``n`` offices per side, for scaling.

    Per floor ``f``: offices ``f{f}n00…`` (north) and ``f{f}s00…`` (south, with sun on
    their windows), each ``office_width`` × ``depth`` × ``height``, with exterior wall and
    window, partitions to their neighbours and a wall to the unmeasured corridor
    ``f{f}hall``; end offices have end walls, the corridor glazed end doors. Floors are
    joined by slabs; the first floor sits on a measured space ``below``, the top floor has a
    roof. Distances are given for every pair of offices on a floor without a wall between
    them and within ``max_distance`` door to door. True air paths pair offices (each in at
    most one) with probability ``p_edge``, partners within ``max_edge_distance``.

    Parameters
    ----------
    n_per_side : int
        Offices on each side of the corridor per floor (>= 2).
    floors : int
        Number of floors (>= 1). Zones: ``floors · (2 n + 1)``.
    seed : int
        Seed of the door positions and the true air paths.
    **kwargs
        Geometry passed to :func:`corridor_layout`: ``office_width``, ``depth``,
        ``height`` (office size [m], defaults 4, 5, 3), ``corridor_width`` [m] (2),
        ``p_edge`` (probability that an office gets an air path partner [-], 0.35),
        ``max_edge_distance`` (longest true air path [m], 8), ``max_distance`` (longest
        candidate air path written to the spec [m], 15).

    Returns
    -------
    spec : BuildingSpec
    edges : list of (str, str, float)
        True convection edges ``(a, b, d)`` [m].

    Examples
    --------
    >>> spec, edges = corridor_floor_spec(25, floors=4)
    >>> len(spec.zones)
    204
    """
    lay = corridor_layout(n_per_side, floors, seed, **kwargs)
    return lay.spec, list(lay.edges)


def corridor_for_zones(zones: int, seed: int = 0) -> Layout:
    """A corridor layout with about ``zones`` zones (at most 25 offices per side per floor)."""
    if int(zones) != zones or zones < 5:
        raise SpecError(f"zones must be an integer >= 5 for the corridor building, found {zones!r}")
    floors = max(1, int(np.ceil(zones / 51)))
    n = max(2, int(round((zones / floors - 1) / 2)))
    return corridor_layout(n, floors, seed)
