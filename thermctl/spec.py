"""Building spec: YAML/JSON → validated dataclasses.

The format (see ``docs/model.md``)::

    name: pugh-hall-2f
    capacity_multiplier: 5          # optional: zone C = multiplier · rho · cp · volume
    zones:      {r240: {volume: 60}, hallway: {volume: 150, measured: false}}
    boundary:   [outside, r200]
    walls:      [{between: [r240, r241], R: [r1, r2, r3], C: [c1, c2], area: 14.2}]
    distances:  [{between: [r240, r243], d: 9.0}]    # air path lengths [m]

A wall gives either ``R``/``C`` (3R2C values [K/W], [J/K]) or ``area``,
``u_value`` [W/(m² K)] and ``heat_capacity`` [J/(m² K)], which get the
homogeneous-slab split of :func:`thermctl.rc.homogeneous_split`. Several walls
may join the same two nodes (a wall and a window, say): they stay separate edges.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import networkx as nx
import yaml

from . import rc
from .errors import SpecError, SpecWarning

__all__ = [
    "Zone", "Wall", "Distance", "Flow", "BuildingSpec", "load_spec", "spec_from_dict",
    "CONSTRUCTIONS",
    "RHO_AIR", "cp_moist_air", "OUTDOOR_NAMES", "is_outdoor",
]

RHO_AIR = 1.2
"""Air density [kg/m³] used for zone capacitance and volumetric flow."""

W_S_DEFAULT = 0.0074
"""Supply-air humidity ratio [kg/kg] measured on site by Goyal et al."""


def cp_moist_air(w_s: float = W_S_DEFAULT) -> float:
    """Specific heat of moist air, ``1006 + 1860·w_s`` [J/(kg K)]."""
    return 1006.0 + 1860.0 * w_s


OUTDOOR_NAMES = ("outside", "outdoor", "outdoors", "ambient", "out", "exterior")
"""Boundary node names (lower case) that mean the outdoor air; every other boundary node
is an indoor neighbouring space. The testbed gives these nodes the weather; the grey-box
model's ``boundary_noise="outdoor"`` puts its error on them."""


def is_outdoor(name: str) -> bool:
    """Whether boundary node ``name`` is the outdoor air (:data:`OUTDOOR_NAMES`, any case)."""
    return name.lower() in OUTDOOR_NAMES


WALL_CLASSES = ("exterior", "partition", "boundary")
"""Classes of walls by what they join (:func:`wall_class`)."""


def wall_class(a: str, b: str, zones) -> str:
    """Class of a wall between nodes ``a`` and ``b`` (``zones``: the zone names).

    ``exterior``: one end is an outdoor boundary node (:func:`is_outdoor`); ``partition``:
    both ends are zones; ``boundary``: one end is another boundary node (cellar, attic,
    floor above, a neighbour's space).
    """
    if is_outdoor(a) or is_outdoor(b):
        return "exterior"
    if a in zones and b in zones:
        return "partition"
    return "boundary"


_TOP_KEYS = {"name", "capacity_multiplier", "w_s", "zones", "boundary", "walls", "distances",
             "flows", "constructions"}
_ZONE_KEYS = {"volume", "measured", "capacitance", "storey"}
_WALL_KEYS = {"between", "R", "C", "area", "u_value", "heat_capacity", "name", "construction"}
_CONSTRUCTION_KEYS = {"u_value", "heat_capacity"}

CONSTRUCTIONS = {
    # name: (U [W/(m² K)] with surface films, areal heat capacity [J/(m² K)], layers).
    # Computed from typical layers (λ, ρ, c of EN ISO 10456 tables; films 0.13 + 0.04
    # exterior, 0.13 + 0.13 interior, 0.17 + 0.17 floors): a floor plan's first guess,
    # right within about ±50 %. With --wall-factors the UA of each wall class is fitted
    # within [0.2, 5] × these values.
    "exterior-masonry-insulated": (0.30, 370e3, "240 mm brick, 100 mm insulation, plaster"),
    "exterior-masonry": (1.50, 370e3, "240 mm brick, plaster, no insulation"),
    "exterior-timber-frame": (0.25, 35e3, "gypsum, 160 mm mineral wool in studs, OSB"),
    "partition-light": (1.90, 22e3, "gypsum stud wall, 2 × 12.5 mm boards, cavity"),
    "partition-heavy": (2.10, 210e3, "115 mm brick, plaster both sides"),
    "floor-concrete": (2.30, 460e3, "200 mm concrete slab, no insulation"),
    "floor-concrete-insulated": (0.35, 460e3, "200 mm concrete slab, 100 mm insulation"),
    "roof-insulated": (0.20, 30e3, "timber rafters, 200 mm mineral wool, gypsum"),
    "window-double": (2.80, 15e3, "double glazing, air fill, frame included"),
    "window-triple": (1.00, 20e3, "triple glazing, low-e, argon, frame included"),
    "door-internal": (1.80, 30e3, "40 mm wooden leaf"),
}
"""Built-in wall constructions a spec names with ``construction:`` (see docs/model.md)."""
_DIST_KEYS = {"between", "d"}
_FLOW_KEYS = {"from", "to", "fraction", "of", "column"}


@dataclass(frozen=True)
class Zone:
    """A well-mixed air volume whose temperature is a state.

    Attributes
    ----------
    name : str
    volume : float
        Air volume [m³].
    measured : bool
        Whether its temperature is in the data (a hallway often is not).
    capacitance : float or None
        Heat capacity [J/K]; ``None`` means ``capacity_multiplier·ρ·cp·volume``.
    storey : str or None
        The storey (floor level) the zone is on, e.g. ``"1"`` or ``"ground"``; ``None``:
        not said. Two zones on different storeys exchange no air through the slab
        between them: the wall they share gives them no air-path candidate
        (:meth:`BuildingSpec.air_path_length`); a stair or shaft between them is an
        explicit ``distances`` entry.
    """

    name: str
    volume: float
    measured: bool = True
    capacitance: float | None = None
    storey: str | None = None


@dataclass(frozen=True)
class Wall:
    """A conduction path (wall, floor, window, door leaf) modelled as 3R2C.

    Attributes
    ----------
    a, b : str
        End nodes (zone or boundary).
    R : tuple of 3 float
        [K/W]
    C : tuple of 2 float
        [J/K]
    area : float or None
        [m²], informative.
    name : str or None
    construction : str or None
        The construction it was built from (:data:`CONSTRUCTIONS` or the spec's
        ``constructions``), informative.
    """

    a: str
    b: str
    R: tuple[float, float, float]
    C: tuple[float, float]
    area: float | None = None
    name: str | None = None
    construction: str | None = None

    @property
    def alpha(self) -> float:
        """alpha of this wall's 3R2C element [-] (see :func:`thermctl.rc.alpha`)."""
        return rc.alpha(self.R, self.C)


@dataclass(frozen=True)
class Distance:
    """Length of the most likely air path between two zones [m]."""

    a: str
    b: str
    d: float


@dataclass(frozen=True)
class Flow:
    """A directed air flow of known rate from one node into a zone.

    Ventilation air passed on from room to room (supplied to a living room, through the
    corridor, extracted in the bath): the receiving zone gains ``ṁ·cp·(T_src − T_dst)``,
    one way, beside any symmetric air-path edge. Air leaves every zone at that zone's
    temperature, as much as enters it (the spec does not check the mass balance).

    Attributes
    ----------
    src, dst : str
        The node the air comes from (a zone with a measured temperature, or a boundary
        node) and the zone it enters.
    fraction : float
        Multiplies the rate [-].
    of : str or None
        The rate is ``fraction`` × this zone's supply flow (its ``ms:`` column) [kg/s].
    column : str or None
        Or ``fraction`` × this data column [kg/s].
    """

    src: str
    dst: str
    fraction: float = 1.0
    of: str | None = None
    column: str | None = None

    @property
    def rate_column(self) -> str:
        """The data column whose value times ``fraction`` is the rate [kg/s]."""
        return f"ms:{self.of}" if self.of is not None else str(self.column)


@dataclass(frozen=True)
class BuildingSpec:
    """A validated building spec. Build with :func:`load_spec` or :func:`spec_from_dict`."""

    name: str
    zones: tuple[Zone, ...]
    boundary: tuple[str, ...]
    walls: tuple[Wall, ...]
    distances: tuple[Distance, ...] = ()
    capacity_multiplier: float = 1.0
    w_s: float = W_S_DEFAULT
    source: str = field(default="<dict>", compare=False)
    flows: tuple = ()

    @property
    def zone_names(self) -> list[str]:
        return [z.name for z in self.zones]

    @property
    def measured_zones(self) -> list[str]:
        return [z.name for z in self.zones if z.measured]

    @property
    def cp(self) -> float:
        """Specific heat of the supply air [J/(kg K)]."""
        return cp_moist_air(self.w_s)

    def zone(self, name: str) -> Zone:
        for z in self.zones:
            if z.name == name:
                return z
        raise SpecError(f"{self.source}: no zone named {name!r}; zones are {self.zone_names}")

    def zone_capacitance(self, name: str) -> float:
        """Heat capacity of a zone [J/K]."""
        z = self.zone(name)
        if z.capacitance is not None:
            return z.capacitance
        return self.capacity_multiplier * RHO_AIR * self.cp * z.volume

    def distance(self, a: str, b: str) -> float | None:
        """Air path length between two zones [m], or None if the spec gives none."""
        return self.distance_table().get(frozenset((a, b)))

    def air_path_length(self, a: str, b: str) -> tuple[float | None, bool]:
        """Air path length for a candidate convection edge [m], and whether it is estimated.

        The spec's ``distances`` first. Zones that share a wall but have no given length
        (an open door beside a wall, which a spec author rarely lists) get the distance
        between the centres of two cubes of the zones' volumes,
        ``(V_a^(1/3) + V_b^(1/3)) / 2``: an air path through a door in the common wall.
        The estimate only scales that edge's resistance ``R̄_v·d``; with one R̄_v per edge
        it cancels. Zones on different storeys (:attr:`Zone.storey`, both given) share a
        slab, not a door: no estimate. Other pairs without a length: ``(None, False)``.
        """
        d = self.distance(a, b)
        if d is not None:
            return d, False
        if frozenset((a, b)) in self.wall_pairs() and not self.across_storeys(a, b):
            za, zb = self.zone(a), self.zone(b)
            return 0.5 * (za.volume ** (1.0 / 3.0) + zb.volume ** (1.0 / 3.0)), True
        return None, False

    def across_storeys(self, a: str, b: str) -> bool:
        """Whether zones ``a`` and ``b`` are on different storeys (both storeys given; a
        boundary node has none)."""
        storey = self.__dict__.get("_storeys")
        if storey is None:      # cached: called for every wall pair (frozen dataclass)
            storey = {z.name: z.storey for z in self.zones}
            object.__setattr__(self, "_storeys", storey)
        sa, sb = storey.get(a), storey.get(b)
        return sa is not None and sb is not None and sa != sb

    def wall_pairs(self) -> frozenset:
        """Zone pairs joined by at least one wall (cached)."""
        pairs = self.__dict__.get("_wall_pairs")
        if pairs is None:
            zones = set(self.zone_names)
            pairs = frozenset(frozenset((w.a, w.b)) for w in self.walls
                              if w.a in zones and w.b in zones)
            object.__setattr__(self, "_wall_pairs", pairs)
        return pairs

    def distance_table(self) -> dict:
        """``{frozenset((a, b)): d}`` for every given air path length [m] (cached)."""
        table = self.__dict__.get("_distance_table")
        if table is None:
            table = {frozenset((d.a, d.b)): d.d for d in self.distances}
            object.__setattr__(self, "_distance_table", table)  # frozen dataclass cache
        return table

    def alphas(self) -> dict[str, float]:
        """alpha of every wall, keyed by wall label."""
        return {_wall_label(w, i): w.alpha for i, w in enumerate(self.walls)}

    def alpha(self) -> float:
        """The alpha used for the convection bounds: the median over the walls [-]."""
        vals = sorted(self.alphas().values())
        if not vals:
            raise SpecError(f"{self.source}: no walls, cannot compute alpha")
        n = len(vals)
        return vals[n // 2] if n % 2 else 0.5 * (vals[n // 2 - 1] + vals[n // 2])

    def to_dict(self) -> dict:
        """Plain dict in the spec file format (R/C form for every wall)."""
        zones = {}
        for z in self.zones:
            entry = {"volume": z.volume}
            if not z.measured:
                entry["measured"] = False
            if z.capacitance is not None:
                entry["capacitance"] = z.capacitance
            if z.storey is not None:
                entry["storey"] = z.storey
            zones[z.name] = entry
        walls = []
        for w in self.walls:
            entry = {"between": [w.a, w.b], "R": list(w.R), "C": list(w.C)}
            if w.area is not None:
                entry["area"] = w.area
            if w.name is not None:
                entry["name"] = w.name
            walls.append(entry)
        return {
            "name": self.name,
            "capacity_multiplier": self.capacity_multiplier,
            "w_s": self.w_s,
            "zones": zones,
            "boundary": list(self.boundary),
            "walls": walls,
            "distances": [{"between": [d.a, d.b], "d": d.d} for d in self.distances],
        } | ({"flows": [{"from": f.src, "to": f.dst, "fraction": f.fraction}
                        | ({"of": f.of} if f.of is not None else {"column": f.column})
                        for f in self.flows]} if self.flows else {})

    def dump(self, path) -> None:
        """Write the spec as YAML (``.yaml``/``.yml``) or JSON (any other suffix)."""
        path = Path(path)
        data = self.to_dict()
        if path.suffix.lower() in (".yaml", ".yml"):
            path.write_text(yaml.safe_dump(data, sort_keys=False))
        else:
            path.write_text(json.dumps(data, indent=2))


def _wall_label(w: Wall, i: int) -> str:
    return w.name if w.name else f"walls[{i}] {w.a}-{w.b}"


class _UniqueKeyLoader(yaml.SafeLoader):
    """YAML loader that refuses duplicate mapping keys (a silent override in plain YAML)."""


def _construct_mapping(loader, node, deep=False):
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise SpecError(f"duplicate key {key!r} at line {key_node.start_mark.line + 1}")
        seen.add(key)
    return yaml.SafeLoader.construct_mapping(loader, node, deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def load_spec(path) -> BuildingSpec:
    """Load and validate a building spec from a YAML or JSON file.

    Parameters
    ----------
    path : str or Path
        ``.yaml``, ``.yml`` or ``.json`` file.

    Returns
    -------
    BuildingSpec

    Raises
    ------
    SpecError
        If the file is missing, unreadable or invalid; the message names the file and entry.

    Examples
    --------
    >>> spec = load_spec("building.yaml")  # doctest: +SKIP
    >>> spec.zone_names  # doctest: +SKIP
    ['r240', 'r241', 'hallway']
    """
    path = Path(path)
    if not path.is_file():
        raise SpecError(f"{path}: building spec not found")
    text = path.read_text()
    if not text.strip():
        raise SpecError(f"{path}: building spec is empty")
    is_json = path.suffix.lower() == ".json"
    try:
        if is_json:
            data = json.loads(text, object_pairs_hook=_json_unique)
        else:
            data = yaml.load(text, Loader=_UniqueKeyLoader)
    except SpecError as exc:
        raise SpecError(f"{path}: {exc}") from None
    except (yaml.YAMLError, json.JSONDecodeError) as exc:
        raise SpecError(f"{path}: not valid {'JSON' if is_json else 'YAML'}: {exc}") from None
    if data is None:
        raise SpecError(f"{path}: building spec is empty (only comments)")
    return spec_from_dict(data, source=str(path))


def _json_unique(pairs):
    out = {}
    for k, v in pairs:
        if k in out:
            raise SpecError(f"duplicate key {k!r}")
        out[k] = v
    return out


def _positive(value, where, unit):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SpecError(f"{where}: expected a number {unit}, found {value!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise SpecError(f"{where}: must be finite and > 0 {unit}, found {value!r}")
    return v


def _check_keys(entry, allowed, where):
    if not isinstance(entry, dict):
        raise SpecError(f"{where}: expected a mapping, found {type(entry).__name__}")
    unknown = sorted(set(entry) - allowed)
    if unknown:
        raise SpecError(f"{where}: unknown key(s) {unknown}; allowed keys are {sorted(allowed)}")


def _pair(entry, where, nodes):
    pair = entry.get("between")
    if not isinstance(pair, (list, tuple)) or len(pair) != 2:
        raise SpecError(f"{where}: 'between' must list exactly 2 nodes, found {pair!r}")
    a, b = (str(p) for p in pair)
    if a == b:
        raise SpecError(f"{where}: 'between' names node {a!r} twice")
    for n in (a, b):
        if n not in nodes:
            raise SpecError(f"{where}: unknown node {n!r}; known nodes are {sorted(nodes)}")
    return a, b


def spec_from_dict(data: dict, source: str = "<dict>") -> BuildingSpec:
    """Validate a spec given as a dict (the parsed file). See :func:`load_spec`."""
    src = source
    _check_keys(data, _TOP_KEYS, src)
    for key in ("zones", "boundary", "walls"):
        if key not in data:
            raise SpecError(f"{src}: missing required key {key!r}")
    name = str(data.get("name", Path(source).stem if source != "<dict>" else "building"))
    mult = _positive(data.get("capacity_multiplier", 1.0), f"{src}: capacity_multiplier", "[-]")
    w_s = data.get("w_s", W_S_DEFAULT)
    try:
        w_s = float(w_s)
    except (TypeError, ValueError):
        raise SpecError(f"{src}: w_s: expected a humidity ratio [kg/kg], found {w_s!r}") from None
    if not (0 <= w_s < 0.1):
        raise SpecError(f"{src}: w_s must be a humidity ratio in [0, 0.1) [kg/kg], found {w_s}")

    raw_zones = data["zones"]
    if not isinstance(raw_zones, dict) or not raw_zones:
        raise SpecError(f"{src}: 'zones' must be a non-empty mapping of zone name → {{volume: ...}}")
    zones = []
    for zname, entry in raw_zones.items():
        where = f"{src}: zones.{zname}"
        entry = {} if entry is None else entry
        _check_keys(entry, _ZONE_KEYS, where)
        if "volume" not in entry:
            raise SpecError(f"{where}: missing 'volume' [m³]")
        vol = _positive(entry["volume"], f"{where}.volume", "[m³]")
        cap = entry.get("capacitance")
        cap = None if cap is None else _positive(cap, f"{where}.capacitance", "[J/K]")
        measured = entry.get("measured", True)
        if not isinstance(measured, bool):
            raise SpecError(f"{where}.measured: expected true or false, found {measured!r}")
        storey = entry.get("storey")
        if storey is not None:
            if isinstance(storey, bool) or not isinstance(storey, (int, str)) or storey == "":
                raise SpecError(f"{where}.storey: expected a storey name or number (e.g. 1 or "
                                f"ground), found {storey!r}")
            storey = str(storey)
        zones.append(Zone(str(zname), vol, measured, cap, storey))

    boundary = data["boundary"] or []
    if not isinstance(boundary, (list, tuple)):
        raise SpecError(f"{src}: 'boundary' must be a list of node names, found {boundary!r}")
    boundary = [str(b) for b in boundary]
    seen = set()
    for b in boundary:
        if b in seen:
            raise SpecError(f"{src}: boundary node {b!r} is listed twice")
        seen.add(b)
    clash = sorted(set(boundary) & {z.name for z in zones})
    if clash:
        raise SpecError(f"{src}: {clash} named both as zone and as boundary node")
    nodes = {z.name for z in zones} | set(boundary)

    constructions = _constructions(data.get("constructions") or {}, src)
    walls = []
    raw_walls = data["walls"] or []
    if not isinstance(raw_walls, list):
        raise SpecError(f"{src}: 'walls' must be a list")
    wall_names = set()
    for i, entry in enumerate(raw_walls):
        where = f"{src}: walls[{i}]"
        _check_keys(entry, _WALL_KEYS, where)
        a, b = _pair(entry, where, nodes)
        if a in boundary and b in boundary:
            raise SpecError(f"{where}: joins two boundary nodes {a!r} and {b!r}; it affects no zone")
        has_rc = "R" in entry or "C" in entry
        cons = entry.get("construction")
        if cons is not None:
            if has_rc:
                raise SpecError(f"{where}: give either R/C or a construction, not both")
            if str(cons) not in constructions:
                raise SpecError(f"{where}.construction: unknown construction {cons!r}; known "
                                f"are {sorted(constructions)} (or define it under "
                                "'constructions')")
            if "area" not in entry:
                raise SpecError(f"{where}: missing 'area' [m²] (needed with a construction)")
            u0, k0 = constructions[str(cons)]
            entry = {"u_value": u0, "heat_capacity": k0} | dict(entry)   # given values win
        has_u = any(k in entry for k in ("u_value", "heat_capacity"))
        if has_rc and has_u:
            raise SpecError(f"{where}: give either R/C or area/u_value/heat_capacity, not both")
        area = entry.get("area")
        area = None if area is None else _positive(area, f"{where}.area", "[m²]")
        if has_u:
            for k in ("area", "u_value", "heat_capacity"):
                if k not in entry:
                    raise SpecError(f"{where}: missing {k!r} (needed with u_value/heat_capacity)")
            u = _positive(entry["u_value"], f"{where}.u_value", "[W/(m² K)]")
            hc = _positive(entry["heat_capacity"], f"{where}.heat_capacity", "[J/(m² K)]")
            R, C = rc.from_u_value(area, u, hc)
        else:
            R, C = entry.get("R"), entry.get("C")
            if R is None or C is None:
                raise SpecError(f"{where}: needs R (3 values [K/W]) and C (2 values [J/K]), "
                                "or area/u_value/heat_capacity")
            if not isinstance(R, (list, tuple)) or len(R) != 3:
                raise SpecError(f"{where}.R: expected a list of 3 resistances [K/W], found {R!r}")
            if not isinstance(C, (list, tuple)) or len(C) != 2:
                raise SpecError(f"{where}.C: expected a list of 2 capacitances [J/K], found {C!r}")
            R = tuple(_positive(r, f"{where}.R[{k}]", "[K/W]") for k, r in enumerate(R))
            C = tuple(_positive(c, f"{where}.C[{k}]", "[J/K]") for k, c in enumerate(C))
        wname = entry.get("name")
        if wname is not None:
            wname = str(wname)
            if wname in wall_names:
                raise SpecError(f"{where}: duplicate wall name {wname!r}")
            wall_names.add(wname)
        walls.append(Wall(a, b, R, C, area, wname, None if cons is None else str(cons)))

    distances = []
    raw_d = data.get("distances") or []
    if not isinstance(raw_d, list):
        raise SpecError(f"{src}: 'distances' must be a list")
    zone_set = {z.name for z in zones}
    seen_pairs = set()
    for i, entry in enumerate(raw_d):
        where = f"{src}: distances[{i}]"
        _check_keys(entry, _DIST_KEYS, where)
        a, b = _pair(entry, where, nodes)
        for n in (a, b):
            if n not in zone_set:
                raise SpecError(f"{where}: {n!r} is a boundary node; air paths join zones")
        if "d" not in entry:
            raise SpecError(f"{where}: missing 'd' [m]")
        d = _positive(entry["d"], f"{where}.d", "[m]")
        key = frozenset((a, b))
        if key in seen_pairs:
            raise SpecError(f"{where}: distance between {a!r} and {b!r} given twice")
        seen_pairs.add(key)
        distances.append(Distance(a, b, d))

    flows = _flows(data.get("flows") or [], src, zone_set, nodes)
    spec = BuildingSpec(name, tuple(zones), tuple(boundary), tuple(walls), tuple(distances),
                        mult, w_s, source, flows)
    _warn_isolated(spec)
    return spec


def _constructions(raw, src) -> dict:
    """The built-in :data:`CONSTRUCTIONS` plus the spec's own (which may override them):
    name → (U [W/(m² K)], areal heat capacity [J/(m² K)])."""
    out = {k: v[:2] for k, v in CONSTRUCTIONS.items()}
    if not isinstance(raw, dict):
        raise SpecError(f"{src}: 'constructions' must be a mapping of name → "
                        "{u_value: ..., heat_capacity: ...}")
    for name, entry in raw.items():
        where = f"{src}: constructions.{name}"
        _check_keys(entry, _CONSTRUCTION_KEYS, where)
        for k in _CONSTRUCTION_KEYS:
            if k not in entry:
                raise SpecError(f"{where}: missing {k!r}")
        out[str(name)] = (_positive(entry["u_value"], f"{where}.u_value", "[W/(m² K)]"),
                          _positive(entry["heat_capacity"], f"{where}.heat_capacity",
                                    "[J/(m² K)]"))
    return out


def _flows(raw, src, zones, nodes) -> tuple:
    """``flows:`` entries → :class:`Flow` objects (one-line errors naming the entry)."""
    if not isinstance(raw, list):
        raise SpecError(f"{src}: 'flows' must be a list")
    out = []
    for i, entry in enumerate(raw):
        where = f"{src}: flows[{i}]"
        _check_keys(entry, _FLOW_KEYS, where)
        for k in ("from", "to"):
            if k not in entry:
                raise SpecError(f"{where}: missing {k!r} (the node the air comes from and the "
                                "zone it enters)")
        a, b = str(entry["from"]), str(entry["to"])
        if a not in nodes:
            raise SpecError(f"{where}.from: unknown node {a!r}; known nodes are {sorted(nodes)}")
        if b not in zones:
            raise SpecError(f"{where}.to: {b!r} is not a zone; the air enters a zone "
                            f"(zones are {sorted(zones)})")
        if a == b:
            raise SpecError(f"{where}: 'from' and 'to' are both {a!r}")
        if ("of" in entry) == ("column" in entry):
            raise SpecError(f"{where}: give the rate as 'of: <zone>' (a fraction of that zone's "
                            "supply flow ms:<zone>) or 'column: <name>' [kg/s], exactly one")
        of = entry.get("of")
        if of is not None and str(of) not in zones:
            raise SpecError(f"{where}.of: {of!r} is not a zone (its ms: column gives the rate)")
        frac = _positive(entry.get("fraction", 1.0), f"{where}.fraction", "[-]")
        out.append(Flow(a, b, frac, None if of is None else str(of),
                        None if "column" not in entry else str(entry["column"])))
    return tuple(out)


def _warn_isolated(spec: BuildingSpec) -> None:
    g = nx.Graph()
    g.add_nodes_from(spec.zone_names)
    g.add_nodes_from(spec.boundary)
    g.add_edges_from((w.a, w.b) for w in spec.walls)
    reach = set()
    for b in spec.boundary:
        reach |= nx.node_connected_component(g, b)
    lonely = [z for z in spec.zone_names if z not in reach]
    if lonely:
        warnings.warn(f"{spec.source}: zone(s) {lonely} have no wall path to any boundary node; "
                      "their temperature is set by supply air and heat gains alone",
                      SpecWarning, stacklevel=3)
