"""A broader family of testbed buildings: rings, L-shapes, open plans, random walls, hidden zones.

The layouts of :mod:`thermctl.testbed.buildings` are a corridor with offices on both sides.
Real floors are not all like that. This module adds

* :func:`ring_layout` — offices in a ring around an unmeasured core (a circulation hall,
  a conditioned interior space whose thermostat is not logged, or a copy/server room);
* :func:`l_shape_layout` — two office wings at right angles, each along its own corridor,
  meeting at a glazed lobby (corridors and lobby unmeasured);
* :func:`open_plan_layout` — an open office split into thermostat zones with no walls
  between them (air paths between every pair of neighbours, several per zone), two
  enclosed offices and an unmeasured copy room;

and transforms of any :class:`~thermctl.testbed.buildings.Layout`:

* :func:`add_floor_above` — a measured floor above: a slab from every zone to a boundary
  node ``up-<zone>`` (offices) or ``up-common`` (unmeasured zones);
* :func:`random_walls` — every wall's construction drawn at random (area, U-value,
  areal heat capacity) and split 25/50/25 % in resistance, halves in capacity; returns the
  plant's spec and the spec a user would write (the homogeneous-slab split of the same
  wall, or the plant's own values);
* :func:`hide_offices` — offices whose thermostat is not logged (they keep their VAV box
  and occupants: hidden *conditioned* zones).

Zone kinds (``Layout.kind``) decide gains and HVAC: ``office`` (occupants, VAV box;
unmeasured: a hidden conditioned zone), ``hall`` (lighting), ``lobby`` (lighting and sun
through large glazing), ``equipment`` (a constant-ish load: copier, server closet).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SpecError
from ..spec import cp_moist_air, spec_from_dict
from .buildings import (CAPACITY_MULTIPLIER, SHGC_EFFECTIVE, WALL_TYPES, Layout, _hall_capacitance,
                        _pick_edges)

__all__ = ["ring_layout", "l_shape_layout", "open_plan_layout", "add_floor_above",
           "random_walls", "hide_offices", "WALL_RANGES", "RESISTANCE_SPLIT", "CORE_KINDS"]

CORE_KINDS = ("hall", "office", "equipment")
"""What the unmeasured core of :func:`ring_layout` is: circulation, a conditioned space
with an unlogged thermostat, or a copy/server room."""

RESISTANCE_SPLIT = (0.25, 0.5, 0.25)
"""Resistance split of the random walls' 3R2C elements [-] (capacity in halves)."""

WALL_RANGES = {
    # kind: (U-value range [W/(m² K)], areal heat capacity range [J/(m² K)])
    "exterior": ((0.25, 0.9), (4e4, 3.0e5)),
    "window": ((1.6, 5.0), (1.0e4, 3.0e4)),
    "partition": ((0.8, 3.0), (1.5e4, 1.2e5)),
    "hall": ((1.0, 3.0), (1.5e4, 1.2e5)),
    "door": ((2.0, 4.0), (1.0e4, 3.0e4)),
    "slab": ((0.8, 2.0), (1.5e5, 4.5e5)),
    "roof": ((0.2, 0.6), (1.0e5, 4.0e5)),
}
"""Ranges of the random wall constructions (drawn log-uniformly per wall)."""

AREA_SPREAD = 0.25
"""Random wall areas are the layout's area times a factor uniform in ``1 ± AREA_SPREAD``."""

_HEIGHT, _FLOOR_H = 3.0, 3.6


def _wall(a, b, kind, area, name):
    u, hc = WALL_TYPES[kind]
    return {"between": [a, b], "area": round(float(area), 3), "u_value": u, "heat_capacity": hc,
            "name": name}


class _Floor:
    """Accumulates zones, walls, distances and kinds of a layout."""

    def __init__(self):
        self.zones, self.walls, self.area, self.aperture, self.kind = {}, [], {}, {}, {}

    def office(self, name, width, depth, glass_side=None, sun=False):
        self.zones[name] = {"volume": round(width * depth * _HEIGHT, 3)}
        self.area[name] = width * depth
        self.kind[name] = "office"
        if glass_side is not None:
            glass = (glass_side - 1.0) * 1.5
            self.wall(name, "outside", "exterior", glass_side * _FLOOR_H - glass, f"{name}:ext")
            self.wall(name, "outside", "window", glass, f"{name}:window")
            if sun:
                self.aperture[name] = SHGC_EFFECTIVE * glass

    def hidden(self, name, area, kind, mult=None):
        vol = area * _HEIGHT
        entry = {"volume": round(vol, 3), "measured": False}
        if kind in ("hall", "lobby"):
            entry["capacitance"] = round(_hall_capacitance(vol, cp_moist_air()), 1)
        self.zones[name] = entry
        self.area[name] = area
        self.kind[name] = kind

    def wall(self, a, b, kind, area, name):
        self.walls.append(_wall(a, b, kind, area, name))

    def spec(self, name, boundary, distances):
        return spec_from_dict({"name": name, "capacity_multiplier": CAPACITY_MULTIPLIER,
                               "zones": self.zones, "boundary": boundary, "walls": self.walls,
                               "distances": distances}, source=name)


def _candidates(spec_walls, doors, path, max_distance):
    """Office pairs without a wall between them, door-to-door length ``path(a, b)`` [m]."""
    walled = {frozenset(w["between"]) for w in spec_walls}
    names = list(doors)
    out = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if frozenset((a, b)) in walled:
                continue
            d = round(path(a, b), 2)
            if d <= max_distance:
                out.append((a, b, d))
    return out


def ring_layout(n_per_side: int = 3, core: str = "hall", seed: int = 0, *,
                p_edge: float = 0.5, max_edge_distance: float = 10.0,
                max_distance: float = 15.0) -> Layout:
    """Offices in a ring around an unmeasured core, on a measured floor ``below``.

    North and south rows of ``n_per_side`` offices (4 m × 5 m; south windows get sun), one
    office at each end (6 m wide × 5 m), each with an exterior wall and window,
    partitions to its ring neighbours and a wall to the ``core`` (``4 n`` m × 6 m). Doors
    open onto the core; an air path runs door to door across it (straight line + 1 m).

    Parameters
    ----------
    n_per_side : int
        Offices per long side (>= 2); ``2 n + 2`` offices in all.
    core : {"hall", "office", "equipment"}
        The core's kind (:data:`CORE_KINDS`): circulation with lighting, a conditioned
        space with occupants and a VAV box whose thermostat is not logged, or a copy/server
        room.
    seed : int
        Door positions and true air paths.
    p_edge, max_edge_distance, max_distance : float
        Probability that an office gets an air-path partner [-]; longest true air path
        [m]; longest candidate written to the spec [m].

    Returns
    -------
    Layout
    """
    if int(n_per_side) != n_per_side or n_per_side < 2:
        raise SpecError(f"ring: n_per_side must be an integer >= 2, found {n_per_side!r}")
    if core not in CORE_KINDS:
        raise SpecError(f"ring: core must be one of {list(CORE_KINDS)}, found {core!r}")
    n = int(n_per_side)
    rng = np.random.default_rng(seed)
    w, depth, core_w = 4.0, 5.0, 6.0
    length = n * w
    f = _Floor()
    f.hidden("core", length * core_w, core)
    north = [f"n{i}" for i in range(n)]
    south = [f"s{i}" for i in range(n)]
    doors = {}
    for i, z in enumerate(north):
        f.office(z, w, depth, glass_side=w)
        doors[z] = ((i + 0.5) * w + rng.uniform(-1.0, 1.0), core_w)
    for i, z in enumerate(south):
        f.office(z, w, depth, glass_side=w, sun=True)
        doors[z] = ((i + 0.5) * w + rng.uniform(-1.0, 1.0), 0.0)
    for z, x in (("west", 0.0), ("east", length)):
        f.office(z, core_w, depth, glass_side=core_w + 2 * depth)
        doors[z] = (x, core_w / 2 + rng.uniform(-1.5, 1.5))
    ring = ["west"] + north + ["east"] + south[::-1]
    for a, b in zip(ring, ring[1:] + ring[:1]):
        f.wall(a, b, "partition", depth * _HEIGHT, f"{a}|{b}")
    for z in ring:
        side = core_w if z in ("west", "east") else w
        f.wall(z, "core", "hall", side * _HEIGHT, f"{z}|core")
    for z in list(f.zones):
        f.wall("below", z, "slab", f.area[z], f"below|{z}")

    def path(a, b):
        (xa, ya), (xb, yb) = doors[a], doors[b]
        return math.hypot(xa - xb, ya - yb) + 1.0

    cand = _candidates(f.walls, doors, path, max_distance)
    edges = _pick_edges(rng, ring, cand, p_edge, max_edge_distance)
    spec = f.spec(f"ring-{2 * n + 2}-{core}", ["outside", "below"],
                  [{"between": [a, b], "d": d} for a, b, d in cand])
    return Layout(spec, edges, f.area, f.aperture, f.kind)


def l_shape_layout(seed: int = 0, *, p_edge: float = 0.6, max_edge_distance: float = 14.0,
                   max_distance: float = 22.0) -> Layout:
    """Two office wings at right angles, each on its own corridor, joined by a glazed lobby.

    Wing A runs east from the 6 m × 6 m ``lobby`` along corridor ``hall-a`` (12 m × 2 m):
    offices ``a0``–``a2`` on its north side (4 m wide), ``a3``, ``a4`` on its south side
    (6 m wide, sun). Wing B runs north along ``hall-b``: ``b0``, ``b1`` on its east and
    ``b2``, ``b3`` on its west side (6 m wide). Offices are 5 m deep. The lobby has a
    glazed south-west façade (sun). An air path runs door to door along the corridors,
    across the lobby (6 m) when the wings differ. Combine with :func:`add_floor_above` for
    the case of a measured floor above.

    Parameters
    ----------
    seed : int
        Door positions and true air paths.
    p_edge, max_edge_distance, max_distance : float
        As :func:`ring_layout`.

    Returns
    -------
    Layout
    """
    rng = np.random.default_rng(seed)
    depth, hall_w, lobby = 5.0, 2.0, 6.0
    f = _Floor()
    f.hidden("lobby", lobby * lobby, "lobby")
    glass = 2 * lobby * 2.5
    f.wall("lobby", "outside", "window", glass, "lobby:glass")
    f.aperture["lobby"] = SHGC_EFFECTIVE * glass / 2      # half of it faces south
    doors = {}  # office → (wing, distance of the door from the lobby along the corridor)
    for wing, rows in (("a", ((("a0", 4.0), ("a1", 4.0), ("a2", 4.0)), (("a3", 6.0), ("a4", 6.0)))),
                       ("b", ((("b0", 6.0), ("b1", 6.0)), (("b2", 6.0), ("b3", 6.0))))):
        hall = f"hall-{wing}"
        f.hidden(hall, 12.0 * hall_w, "hall")
        f.wall(hall, "lobby", "door", hall_w * _HEIGHT, f"{hall}|lobby")
        f.wall(hall, "outside", "door", hall_w * _FLOOR_H, f"{hall}:end")
        for r, row in enumerate(rows):
            s = 0.0
            names = [z for z, _ in row]
            for z, width in row:
                sun = wing == "a" and r == 1
                f.office(z, width, depth, glass_side=width, sun=sun)
                f.wall(z, hall, "hall", width * _HEIGHT, f"{z}|{hall}")
                doors[z] = (wing, s + width / 2 + rng.uniform(-1.0, 1.0))
                s += width
            for a, b in zip(names, names[1:]):
                f.wall(a, b, "partition", depth * _HEIGHT, f"{a}|{b}")
            f.wall(names[0], "lobby", "partition", depth * _HEIGHT, f"{names[0]}|lobby")
            f.wall(names[-1], "outside", "exterior", depth * _FLOOR_H, f"{names[-1]}:end")

    def path(a, b):
        (wa, sa), (wb, sb) = doors[a], doors[b]
        if wa == wb:
            return abs(sa - sb) + hall_w
        return sa + sb + lobby + hall_w

    cand = _candidates(f.walls, doors, path, max_distance)
    edges = _pick_edges(rng, list(doors), cand, p_edge, max_edge_distance)
    spec = f.spec("l-shape", ["outside"], [{"between": [a, b], "d": d} for a, b, d in cand])
    return Layout(spec, edges, f.area, f.aperture, f.kind)


def open_plan_layout(seed: int = 0, *, cols: int = 3, zone_width: float = 6.0,
                     zone_depth: float = 5.0) -> Layout:
    """An open office split into thermostat zones, with enclosed offices and a copy room.

    A ``2 × cols`` grid of zones ``p<row><col>`` (``zone_width`` × ``zone_depth``, no walls
    between them; the south row gets sun) under a roof, on a measured floor ``below``. True
    air paths join every pair of grid neighbours (a zone is in up to four), their length
    the distance between zone centres. West of the grid two enclosed offices ``o0``,
    ``o1`` (4 m × 5 m, walls to the grid, doors to ``p00``/``p10``); east the unmeasured
    ``copy`` room (equipment) with walls to the grid's east column.

    Parameters
    ----------
    seed : int
        Jitters the door positions of the enclosed offices.
    cols : int
        Columns of the grid (>= 2).
    zone_width, zone_depth : float
        Size of a thermostat zone [m].

    Returns
    -------
    Layout
    """
    if int(cols) != cols or cols < 2:
        raise SpecError(f"open-plan: cols must be an integer >= 2, found {cols!r}")
    rng = np.random.default_rng(seed)
    f = _Floor()
    grid = [[f"p{r}{c}" for c in range(int(cols))] for r in range(2)]
    centre = {}
    for r, row in enumerate(grid):
        for c, z in enumerate(row):
            f.office(z, zone_width, zone_depth, glass_side=zone_width, sun=r == 1)
            centre[z] = ((c + 0.5) * zone_width, (1.5 - r) * zone_depth)
    for r, z in enumerate(("o0", "o1")):
        f.office(z, 4.0, zone_depth, glass_side=4.0 + zone_depth, sun=r == 1)
        f.wall(z, grid[r][0], "partition", zone_depth * _HEIGHT, f"{z}|{grid[r][0]}")
        centre[z] = (-0.5 + rng.uniform(-0.3, 0.3), (1.5 - r) * zone_depth)
    f.wall("o0", "o1", "partition", 4.0 * _HEIGHT, "o0|o1")
    f.hidden("copy", 3.0 * 2 * zone_depth, "equipment")
    for r in range(2):
        f.wall(grid[r][-1], "copy", "partition", zone_depth * _HEIGHT, f"{grid[r][-1]}|copy")
    f.wall("copy", "outside", "exterior", 2 * zone_depth * _FLOOR_H, "copy:ext")
    for z in list(f.zones):
        f.wall("below", z, "slab", f.area[z], f"below|{z}")
        f.wall(z, "outside", "roof", f.area[z], f"{z}:roof")
    names = list(centre)

    def dist(a, b):
        (xa, ya), (xb, yb) = centre[a], centre[b]
        return math.hypot(xa - xb, ya - yb)

    walled = {frozenset(w["between"]) for w in f.walls}
    distances, edges = [], []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if frozenset((a, b)) in walled:
                continue
            d = round(dist(a, b) + (1.0 if a[0] == "o" or b[0] == "o" else 0.0), 2)
            distances.append({"between": [a, b], "d": d})
            ra, ca = (int(a[1]), int(a[2])) if a[0] == "p" else (None, None)
            rb, cb = (int(b[1]), int(b[2])) if b[0] == "p" else (None, None)
            if ra is not None and rb is not None and abs(ra - rb) + abs(ca - cb) == 1:
                edges.append((a, b, d))
    spec = f.spec(f"open-plan-2x{int(cols)}", ["outside", "below"], distances)
    return Layout(spec, sorted(edges), f.area, f.aperture, f.kind)


def add_floor_above(layout: Layout) -> Layout:
    """The same floor under a measured floor: a slab from each zone to the space above it.

    Offices get their own boundary node ``up-<zone>`` (the office above, logged by the
    BAS); unmeasured zones share ``up-common``. Roofs (walls to ``outside`` of kind
    ``roof``) are dropped: the floor is no longer the top one.
    """
    data = layout.spec.to_dict()
    walls = [w for w in data["walls"] if not ("outside" in w["between"] and _kind(w) == "roof")]
    boundary = list(data["boundary"])
    for z in layout.spec.zones:
        up = f"up-{z.name}" if z.measured else "up-common"
        if up not in boundary:
            boundary.append(up)
        R, C = _slab_rc(layout.floor_area[z.name])
        walls.append({"between": [z.name, up], "R": R, "C": C,
                      "area": round(layout.floor_area[z.name], 3), "name": f"{z.name}|{up}"})
    data["walls"], data["boundary"] = walls, boundary
    data["name"] = f"{data['name']}+above"
    spec = spec_from_dict(data, source=data["name"])
    return Layout(spec, list(layout.edges), dict(layout.floor_area), dict(layout.solar_aperture),
                  dict(layout.kind))


def _slab_rc(area):
    from .. import rc

    u, hc = WALL_TYPES["slab"]
    R, C = rc.from_u_value(area, u, hc)
    return list(R), list(C)


def _kind(wall: dict) -> str:
    """The :data:`WALL_TYPES` kind of a layout's wall (R/C form), by its U-value and capacity."""
    area = wall.get("area") or 1.0
    u = 1.0 / (sum(wall["R"]) * area)
    hc = sum(wall["C"]) / area
    return min(WALL_TYPES, key=lambda k: abs(math.log(u / WALL_TYPES[k][0]))
               + abs(math.log(hc / WALL_TYPES[k][1])))


def random_walls(layout: Layout, rng: np.random.Generator, published: str = "u_value"):
    """Every wall's construction drawn at random, split 25/50/25 % in resistance.

    Per wall: area = the layout's area × U(1 ± :data:`AREA_SPREAD`); U-value and areal heat
    capacity log-uniform in the wall kind's :data:`WALL_RANGES`. The plant's 3R2C element
    is ``R = (0.25, 0.5, 0.25) / (U A)``, ``C = (hc A / 2, hc A / 2)``.

    Parameters
    ----------
    layout : Layout
    rng : numpy.random.Generator
    published : {"u_value", "plant"}
        The spec a user gets: ``u_value`` — each wall's area, U-value and heat capacity,
        hence the homogeneous-slab split (R 20/60/20 %), not the plant's; ``plant`` — the
        plant's own R and C.

    Returns
    -------
    plant : Layout
        The building as simulated.
    spec : BuildingSpec
        The spec handed to identification.
    draws : dict
        Wall name → ``{"area", "u_value", "heat_capacity"}``.
    """
    if published not in ("u_value", "plant"):
        raise SpecError(f"wall_spec must be 'u_value' or 'plant', found {published!r}")
    data = layout.spec.to_dict()
    plant_walls, user_walls, draws = [], [], {}
    for i, w in enumerate(data["walls"]):
        kind = _kind(w)
        (u_lo, u_hi), (c_lo, c_hi) = WALL_RANGES.get(kind, WALL_RANGES["partition"])
        base = w.get("area") or 10.0
        area = round(float(base * rng.uniform(1 - AREA_SPREAD, 1 + AREA_SPREAD)), 3)
        u = float(np.exp(rng.uniform(math.log(u_lo), math.log(u_hi))))
        hc = float(np.exp(rng.uniform(math.log(c_lo), math.log(c_hi))))
        r_tot, c_tot = 1.0 / (u * area), hc * area
        name = w.get("name") or f"wall{i}"
        draws[name] = {"area": area, "u_value": u, "heat_capacity": hc}
        common = {"between": w["between"], "area": area, "name": name}
        plant_walls.append({**common, "R": [s * r_tot for s in RESISTANCE_SPLIT],
                            "C": [c_tot / 2, c_tot / 2]})
        user_walls.append({**common, "u_value": u, "heat_capacity": hc})
    plant_spec = spec_from_dict({**data, "walls": plant_walls}, source=data["name"])
    user = plant_spec if published == "plant" else spec_from_dict({**data, "walls": user_walls},
                                                                  source=data["name"])
    plant = Layout(plant_spec, list(layout.edges), dict(layout.floor_area),
                   dict(layout.solar_aperture), dict(layout.kind))
    return plant, user, draws


def hide_offices(layout: Layout, count: int, rng: np.random.Generator) -> Layout:
    """``count`` measured offices become unmeasured (their thermostat is not logged).

    They keep their VAV box and occupants (a hidden conditioned zone). Offices outside the
    true air paths are hidden first; when there are too few, offices in an air path too
    (that air path then joins a hidden zone, which no method can see in the data).
    """
    if int(count) != count or count < 0:
        raise SpecError(f"hide must be an integer >= 0, found {count!r}")
    if count == 0:
        return layout
    in_edge = {z for a, b, _ in layout.edges for z in (a, b)}
    offices = [z for z in layout.spec.measured_zones if layout.kind.get(z) == "office"]
    free = [z for z in offices if z not in in_edge]
    paired = [z for z in offices if z in in_edge]
    if count >= len(offices):
        raise SpecError(f"hide={count}: {layout.spec.name} has {len(offices)} measured offices; "
                        "at least one must stay measured")
    chosen = list(rng.choice(free, size=min(int(count), len(free)), replace=False)) if free else []
    if len(chosen) < count:
        chosen += list(rng.choice(paired, size=int(count) - len(chosen), replace=False))
    chosen = {str(z) for z in chosen}
    data = layout.spec.to_dict()
    for z in chosen:
        data["zones"][z]["measured"] = False
    data["distances"] = [d for d in data["distances"] if not chosen & set(d["between"])]
    spec = spec_from_dict(data, source=data["name"])
    return Layout(spec, list(layout.edges), dict(layout.floor_area), dict(layout.solar_aperture),
                  dict(layout.kind))
