"""Brick models in: a Brick/REC/BOT Turtle file → a building spec and a column map.

:func:`read_brick` reads the spaces of a Brick model as thermctl's nodes, their volumes,
which spaces share a wall (Brick itself has no adjacency relation, Brick issue 626: the
REC and BOT relations are read, ``rec:adjacentElement``, ``bot:adjacentElement`` and
``bot:adjacentZone``), the exterior exposure, and the points of each zone, which become
the column map a user applies to a BAS export (``thermctl identify --columns``).

The rules (``docs/brick.md`` has them with an example):

* **Nodes.** Every ``brick:HVAC_Zone`` is one node (its rooms, ``brick:hasPart`` or
  ``brick:isPartOf``, belong to it; a zone of one room takes the room's name), and so is
  every space (``brick:Space``, ``rec:Room``, ``bot:Space`` and their subclasses) in no
  HVAC zone. A node is named by the local name of its IRI. The outdoor air is the node
  ``outside`` (a ``brick:Outside`` location, or the far side of an exterior element).
* **Zones and boundary nodes.** Every node is a zone unless it is typed ``tc:Boundary``
  (a measured neighbouring space outside the modelled section) or named in
  ``boundary=``. A zone with a ``Zone_Air_Temperature_Sensor`` is measured.
* **Volumes.** ``brick:volume`` of the zone, else the sum of its rooms'; else their
  ``brick:area`` (``grossArea``, ``netArea``) times ``height``. Units ``unit:M3``/``unit:FT3``,
  ``unit:M2``/``unit:FT2`` (no unit: SI).
* **Storeys.** A zone whose spaces are parts of one ``brick:Floor`` (``brick:hasPart`` or
  ``brick:isPartOf``) or spaces of one ``bot:Storey`` (``bot:hasSpace``) gets that storey:
  zones on different storeys share slabs, not doors, and no air-path candidate joins
  them unless ``tc:airPath`` names one (a stair).
* **Walls.** An element (``rec:Wall``, ``rec:Window``, any object of ``rec:adjacentElement``
  or ``bot:adjacentElement``) adjacent to two nodes is a wall between them; adjacent to one
  node only, or to it and ``brick:Outside``, it is an exterior element. Its area is its
  ``brick:area``; its construction ``tc:uValue`` [W/(m² K)] and ``tc:arealHeatCapacity``
  [J/(m² K)] where the model gives them, else the class ``tc:construction`` of
  :data:`CONSTRUCTIONS`, else the class its type implies (window, door, roof, slab; else
  exterior or partition). Its name is its ``rdfs:label``, else its local name.
  ``bot:adjacentZone`` without an element gives a partition of estimated area
  ``height·sqrt(smaller floor area)`` (with a note).
* **Points → columns.** A point of a node is one with ``brick:isPointOf``/``brick:hasPoint``
  or ``brick:hasLocation`` to one of the node's members, or a point of the equipment that
  ``brick:feeds`` a member (a VAV box): ``Zone_Air_Temperature_Sensor`` → ``T:<node>``,
  ``Supply_Air_Flow_Sensor`` → ``ms:<zone>`` (unit ``KiloGM-PER-SEC``) or ``vs:<zone>`` (any
  other unit), ``Supply_Air_Temperature_Sensor`` → ``Ts:<zone>`` (the ``Discharge_Air_``
  classes too), ``Outside_Air_Temperature_Sensor`` → ``T:outside``,
  ``Solar_Irradiance_Sensor`` → ``solar:<name>``. The BAS column of a point is its
  ``ref:hasExternalReference/ref:hasTimeseriesId``, else its local name.
* **thermctl extension** (namespace ``tc: <urn:thermctl:>``, for what Brick cannot say):
  ``tc:Boundary``, ``tc:construction``, ``tc:uValue``, ``tc:arealHeatCapacity``,
  ``tc:capacitance`` [J/K] of a space, ``tc:capacityMultiplier`` of the building, and the
  air-path lengths ``tc:airPath [tc:to <space>; tc:length <m>]``.

Examples
--------
>>> from thermctl.brick import example_model, read_brick
>>> imp = read_brick(example_model("pugh-hall-2f"))           # doctest: +SKIP
>>> imp.spec.zone_names                                       # doctest: +SKIP
['r240', 'r241', 'r242', 'r243', 'r244', 'r247', 'hallway']
>>> imp.columns["PUGH.2F.R240.ZN-T"]                          # doctest: +SKIP
'T:r240'
"""

from __future__ import annotations

import functools
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from .errors import DataError, DataWarning, SpecError
from .spec import BuildingSpec, spec_from_dict

__all__ = ["BrickImport", "CONSTRUCTIONS", "DEFAULT_HEIGHT", "TC", "read_brick",
           "example_model", "load_column_map", "apply_column_map", "write_column_map"]

TC = "urn:thermctl:"
"""Namespace of thermctl's extension terms (``@prefix tc: <urn:thermctl:> .``)."""

CONSTRUCTIONS = {
    # name: (U-value [W/(m² K)], areal heat capacity [J/(m² K)]), surface films included
    "exterior": (0.45, 1.2e5),     # insulated masonry, ASHRAE 90.1-2007 climate zone 2
    "window": (2.8, 2.0e4),        # double glazing, aluminium frame
    "partition": (1.8, 2.5e4),     # steel stud, 2 x gypsum
    "hall": (2.0, 2.2e4),          # office-corridor partition with a door
    "door": (3.0, 1.5e4),          # double door leaf
    "slab": (1.2, 3.0e5),          # 150 mm concrete, carpet, ceiling
    "roof": (0.3, 3.0e5),          # insulated concrete deck
}
"""Construction classes of walls whose U-value and heat capacity the model does not give."""

DEFAULT_HEIGHT = 3.0
"""Room height [m] for volumes from floor areas (an office floor-to-ceiling height)."""

_FT3, _FT2 = 0.3048 ** 3, 0.3048 ** 2
_NODE_CLASSES = ("brick:Space", "rec:Room")
_POINTS = {
    # column prefix: point classes (with their subclasses)
    "T": ("brick:Zone_Air_Temperature_Sensor",),
    "flow": ("brick:Supply_Air_Flow_Sensor", "brick:Discharge_Air_Flow_Sensor"),
    "Ts": ("brick:Supply_Air_Temperature_Sensor", "brick:Discharge_Air_Temperature_Sensor"),
    "outside": ("brick:Outside_Air_Temperature_Sensor",),
    "solar": ("brick:Solar_Irradiance_Sensor", "brick:Solar_Radiance_Sensor"),
}
_ELEMENT_KINDS = (("rec:Window", "window"), ("rec:Door", "door"), ("rec:Roof", "roof"),
                  ("rec:Slab", "slab"))


@dataclass
class BrickImport:
    """What :func:`read_brick` read from a Brick model.

    Attributes
    ----------
    spec_dict : dict
        The building spec in the file format (walls as ``area``, ``u_value``,
        ``heat_capacity``), ready for ``yaml.safe_dump``.
    spec : BuildingSpec
        ``spec_dict`` validated.
    columns : dict
        ``{BAS column: thermctl column}`` (``T:r240``, ``ms:r240``...).
    units : str or None
        ``"si"`` or ``"imperial"`` when the points' units say so (all °C/kg/s/m³/s or all
        °F/CFM), else ``None``.
    notes : list of str
        What was estimated or left out (a wall area from the floor areas, a zone
        without points...).
    source : str
    """

    spec_dict: dict
    spec: BuildingSpec
    columns: dict
    units: str | None = None
    notes: list = field(default_factory=list)
    source: str = "<brick>"


def example_model(name: str = "pugh-hall-2f") -> Path:
    """Path of a Brick model shipped with thermctl.

    Parameters
    ----------
    name : str
        ``"pugh-hall-2f"``: the testbed's 7-zone Pugh Hall section.
    """
    path = Path(__file__).with_name("brick_models") / f"{name}.ttl"
    if not path.is_file():
        have = sorted(p.stem for p in path.parent.glob("*.ttl"))
        raise SpecError(f"no shipped Brick model {name!r}; shipped: {have}")
    return path


# ---------------------------------------------------------------------------- RDF helpers
def _brickschema():
    try:
        import brickschema
    except ImportError:
        raise SpecError("reading Brick models needs brickschema: pip install "
                        "'thermctl[brick]'") from None
    return brickschema


@functools.lru_cache(maxsize=1)
def _ontology():
    """Brick (with REC) as shipped by brickschema: for the subclass closures."""
    return _brickschema().Graph(load_brick=True)


@functools.lru_cache(maxsize=None)
def _subclasses(curie: str) -> frozenset:
    from rdflib import RDFS, URIRef

    onto = _ontology()
    root = URIRef(_expand(curie))
    seen, todo = {root}, [root]
    while todo:
        for sub in onto.subjects(RDFS.subClassOf, todo.pop()):
            if sub not in seen:
                seen.add(sub)
                todo.append(sub)
    return frozenset(seen)


_PREFIXES = {"brick": "https://brickschema.org/schema/Brick#",
             "rec": "https://w3id.org/rec#", "bot": "https://w3id.org/bot#",
             "ref": "https://brickschema.org/schema/Brick/ref#",
             "unit": "http://qudt.org/vocab/unit/", "tc": TC}


def _expand(curie: str) -> str:
    prefix, _, local = curie.partition(":")
    return _PREFIXES[prefix] + local


def _u(curie: str):
    from rdflib import URIRef
    return URIRef(_expand(curie))


def _local(iri) -> str:
    """The local name of an IRI: after the last ``#``, else ``/``, else ``:``."""
    s = str(iri)
    for sep in ("#", "/", ":"):
        if sep in s and s.rsplit(sep, 1)[1]:
            return s.rsplit(sep, 1)[1]
    return s


def _natural(name: str):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name)]


def _number(g, node, pred, where, unit_scale=None):
    """A number given as a literal or a Brick QuantityValue ``[brick:value; brick:hasUnit]``."""
    from rdflib import Literal

    vals = list(g.objects(node, pred))
    if not vals:
        return None
    v = vals[0]
    unit = None
    if not isinstance(v, Literal):
        unit = next(iter(g.objects(v, _u("brick:hasUnit"))), None)
        v = next(iter(g.objects(v, _u("brick:value"))), None)
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise SpecError(f"{where}: {_local(pred)} is not a number: {v!r}") from None
    if not math.isfinite(x) or x <= 0:
        raise SpecError(f"{where}: {_local(pred)} must be > 0, found {x}")
    if unit is not None and unit_scale is not None:
        scale = unit_scale.get(_local(unit))
        if scale is None:
            raise SpecError(f"{where}: {_local(pred)} in unit {_local(unit)}; expected one of "
                            f"{sorted(unit_scale)}")
        x *= scale
    return x


# ---------------------------------------------------------------------------- reading
def read_brick(path, *, boundary=(), height: float = DEFAULT_HEIGHT,
               capacity_multiplier: float | None = None) -> BrickImport:
    """Read a Brick model (Turtle) into a building spec and a column map.

    Parameters
    ----------
    path : str or Path
        Turtle file (``.ttl``; other RDF syntaxes by their suffix).
    boundary : iterable of str, optional
        Nodes to take as boundary nodes (measured neighbouring spaces), beside those
        typed ``tc:Boundary``.
    height : float, default :data:`DEFAULT_HEIGHT`
        Room height [m]: volumes from floor areas, estimated wall areas.
    capacity_multiplier : float, optional
        Zone capacitance over air capacitance [-]; default the building's
        ``tc:capacityMultiplier``, else the spec default 1.

    Returns
    -------
    BrickImport

    Raises
    ------
    SpecError
        The file is missing or not RDF, a zone has no volume or area, an element
        joins three nodes...: one line naming the file and the node or element.
    """
    from rdflib import RDF, RDFS, Literal

    bs = _brickschema()
    path = Path(path)
    src = str(path)
    if not path.is_file():
        raise SpecError(f"{src}: Brick model not found")
    if not height > 0:
        raise SpecError(f"height must be > 0 [m], found {height}")
    g = bs.Graph()
    try:
        g.parse(str(path), format="turtle" if path.suffix.lower() in (".ttl", ".n3", "") else None)
    except Exception as exc:  # rdflib raises many parser types
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise SpecError(f"{src}: not a readable RDF/Turtle file: {msg}") from None
    notes = []

    def typed(cls_curies):
        classes = frozenset().union(*(_subclasses(c) for c in cls_curies))
        return {s for s, c in g.subject_objects(RDF.type) if c in classes}

    def related(x, fwd, inv):
        return set(g.objects(x, _u(fwd))) | set(g.subjects(_u(inv), x))

    # nodes and their members
    hvac = sorted(typed(("brick:HVAC_Zone",)), key=str)
    spaces = typed(_NODE_CLASSES) | {s for s, c in g.subject_objects(RDF.type) if c == _u("bot:Space")}
    outside_iris = typed(("brick:Outside",))
    spaces -= outside_iris
    members, node_of = {}, {}
    for z in hvac:
        rooms = sorted(related(z, "brick:hasPart", "brick:isPartOf") & spaces, key=str)
        name = _local(rooms[0]) if len(rooms) == 1 else _local(z)
        members.setdefault(name, set()).update([z, *rooms])
    in_zone = set().union(*members.values()) if members else set()
    for s in sorted(spaces - in_zone, key=str):
        members.setdefault(_local(s), set()).add(s)
    # storeys: a brick:Floor's parts, a bot:Storey's spaces (zones on different storeys
    # share slabs, not doors: no air-path candidate between them)
    storey_of = {}
    storeys = typed(("brick:Floor",)) | {s for s, c in g.subject_objects(RDF.type)
                                         if c == _u("bot:Storey")}
    for fl in sorted(storeys, key=str):
        for m in (related(fl, "brick:hasPart", "brick:isPartOf")
                  | set(g.objects(fl, _u("bot:hasSpace")))):
            storey_of[m] = _local(fl)
    for name, ms in members.items():
        iris = {str(m) for m in ms}
        for m in ms:
            if m in node_of and node_of[m] != name:
                raise SpecError(f"{src}: {_local(m)} belongs to two HVAC zones "
                                f"({node_of[m]}, {name})")
            node_of[m] = name
        if len(iris) > 1 and len({_local(m) for m in ms if m not in hvac}) > 1:
            notes.append(f"zone {name}: rooms {sorted(_local(m) for m in ms if m not in hvac)} "
                         "merged (one HVAC zone, one air temperature)")
    if not members:
        raise SpecError(f"{src}: no brick:HVAC_Zone and no space (brick:Space, rec:Room, "
                        "bot:Space) found")
    if "outside" in members:
        raise SpecError(f"{src}: a space is named 'outside', the name of the outdoor node")
    for o in outside_iris:
        node_of[o] = "outside"

    marked = {node_of[s] for s in g.subjects(RDF.type, _u("tc:Boundary")) if s in node_of}
    unknown = sorted(set(boundary) - set(members))
    if unknown:
        raise SpecError(f"{src}: boundary node(s) {unknown} are not spaces of the model; "
                        f"spaces are {sorted(members, key=_natural)}")
    bnodes = marked | set(boundary)

    # points
    def points_of(ms):
        found = set()
        for m in ms:
            found |= related(m, "brick:hasPoint", "brick:isPointOf")
            found |= related(m, "brick:isLocationOf", "brick:hasLocation")
            for eq in related(m, "brick:isFedBy", "brick:feeds"):
                found |= related(eq, "brick:hasPoint", "brick:isPointOf")
        return found

    def column_name(p):
        for ref in g.objects(p, _u("ref:hasExternalReference")):
            for ts in g.objects(ref, _u("ref:hasTimeseriesId")):
                return str(ts)
        for ts in g.objects(p, _u("brick:timeseries")):
            for tid in g.objects(ts, _u("brick:hasTimeseriesId")):
                return str(tid)
        return _local(p)

    kinds = {k: typed(v) for k, v in _POINTS.items()}
    columns, units_seen = {}, set()

    def add(point, col, where):
        bas = column_name(point)
        if bas in columns and columns[bas] != col:
            raise SpecError(f"{src}: point {bas} maps to both {columns[bas]} and {col}")
        if col in columns.values() and columns.get(bas) != col:
            other = next(k for k, v in columns.items() if v == col)
            raise SpecError(f"{src}: {where} has two {col.partition(':')[0]} points, {other} and "
                            f"{bas}; map one of them")
        columns[bas] = col
        for unit in g.objects(point, _u("brick:hasUnit")):
            units_seen.add(_local(unit))
        return bas

    measured = {}
    for name in sorted(members, key=_natural):
        pts = points_of(members[name])
        t = sorted(pts & kinds["T"], key=str)
        measured[name] = bool(t)
        for p in t[:1]:
            add(p, f"T:{name}", f"zone {name}")
        if len(t) > 1:
            notes.append(f"zone {name}: {len(t)} zone air temperature sensors; mapped "
                         f"{column_name(t[0])}")
        if name in bnodes:
            if not t:
                raise SpecError(f"{src}: boundary node {name} has no Zone_Air_Temperature_Sensor; "
                                "a boundary node needs a measured temperature")
            continue
        for p in sorted(pts & kinds["flow"], key=str):
            unit = next(iter(g.objects(p, _u("brick:hasUnit"))), None)
            prefix = "ms" if unit is not None and _local(unit) == "KiloGM-PER-SEC" else "vs"
            add(p, f"{prefix}:{name}", f"zone {name}")
        for p in sorted(pts & kinds["Ts"], key=str):
            add(p, f"Ts:{name}", f"zone {name}")
        has_flow = any(v in (f"ms:{name}", f"vs:{name}") for v in columns.values())
        if has_flow != (f"Ts:{name}" in columns.values()):
            notes.append(f"zone {name}: a supply air flow or temperature point without the other; "
                         "the data need both (ms/vs and Ts) for a zone with supply air")
    oat = sorted(kinds["outside"], key=str)
    if oat:
        add(oat[0], "T:outside", "the outdoor air")
        if len(oat) > 1:
            notes.append(f"{len(oat)} outside air temperature sensors; mapped {column_name(oat[0])}")
    for p in sorted(kinds["solar"], key=str):
        add(p, f"solar:{_local(p)}", "the building")

    # volumes, capacitances
    vol_units, area_units = {"M3": 1.0, "FT3": _FT3}, {"M2": 1.0, "FT2": _FT2}
    zones_dict, floor_area = {}, {}
    order = sorted((n for n in members if n not in bnodes),
                   key=lambda n: (not measured[n], _natural(n)))
    for name in order:
        where = f"{src}: zone {name}"
        ms = sorted(members[name], key=lambda m: (m not in hvac, str(m)))
        vols = [_number(g, m, _u("brick:volume"), where, vol_units) for m in ms]
        vol = vols[0] if vols[0] is not None else (sum(v for v in vols if v) or None)
        areas = []
        for m in ms:
            a = None
            for prop in ("brick:area", "brick:grossArea", "brick:netArea"):
                a = a or _number(g, m, _u(prop), where, area_units)
            areas.append(a)
        area = areas[0] if areas[0] is not None else (sum(a for a in areas if a) or None)
        if vol is None and area is None:
            raise SpecError(f"{where}: no brick:volume or brick:area on the zone or its rooms; "
                            "add one (e.g. brick:volume [brick:value 60; brick:hasUnit unit:M3])")
        if vol is None:
            vol = area * height
            notes.append(f"zone {name}: volume {vol:.4g} m³ from floor area × height {height:g} m")
        floor_area[name] = area if area is not None else vol / height
        entry = {"volume": _clean(vol)}
        if not measured[name]:
            entry["measured"] = False
        caps = [_number(g, m, _u("tc:capacitance"), where) for m in ms]
        if any(c is not None for c in caps):
            entry["capacitance"] = _clean(next(c for c in caps if c is not None))
        on = sorted({storey_of[m] for m in ms if m in storey_of})
        if len(on) == 1:
            entry["storey"] = on[0]
        elif on:
            notes.append(f"zone {name}: its spaces are on storeys {on}: no storey (air paths "
                         "to zones on every storey are candidates)")
        zones_dict[name] = entry
        if not measured[name]:
            notes.append(f"zone {name}: no Zone_Air_Temperature_Sensor: an unmeasured zone")
    if not zones_dict:
        raise SpecError(f"{src}: every space is a boundary node; no zone left to model")

    # walls
    adj_preds = (_u("rec:adjacentElement"), _u("bot:adjacentElement"))
    sides = {}
    for pred in adj_preds:
        for s, e in g.subject_objects(pred):
            if s in node_of:
                sides.setdefault(e, set()).add(node_of[s])
    elem_kind = {}
    for curie, kind in _ELEMENT_KINDS:
        for e in typed((curie,)):
            elem_kind[e] = kind
    walls = []
    for e in sorted(sides, key=str):
        nodes = sorted(sides[e], key=_natural)
        label = next(iter(g.objects(e, RDFS.label)), None)
        wname = str(label) if isinstance(label, Literal) else _local(e)
        where = f"{src}: element {wname}"
        if len(nodes) == 1:
            if nodes[0] == "outside":
                raise SpecError(f"{where}: adjacent to the outside only; it bounds no space")
            nodes = [nodes[0], "outside"]
        if len(nodes) > 2:
            raise SpecError(f"{where}: adjacent to {len(nodes)} spaces {nodes}; an element "
                            "joins two (split it into one element per pair)")
        if all(n in bnodes or n == "outside" for n in nodes):
            continue      # between two boundary nodes: affects no zone
        area = None
        for prop in ("brick:area", "brick:grossArea", "brick:netArea"):
            area = area or _number(g, e, _u(prop), where, area_units)
        if area is None:
            raise SpecError(f"{where}: no brick:area; give the element's area [m²]")
        u = _number(g, e, _u("tc:uValue"), where)
        hc = _number(g, e, _u("tc:arealHeatCapacity"), where)
        cls = next(iter(g.objects(e, _u("tc:construction"))), None)
        if cls is not None and str(cls) not in CONSTRUCTIONS:
            raise SpecError(f"{where}: tc:construction {str(cls)!r} unknown; expected one of "
                            f"{sorted(CONSTRUCTIONS)}")
        kind = str(cls) if cls is not None else elem_kind.get(
            e, "exterior" if "outside" in nodes else "partition")
        u = u if u is not None else CONSTRUCTIONS[kind][0]
        hc = hc if hc is not None else CONSTRUCTIONS[kind][1]
        walls.append({"between": nodes, "area": _clean(area), "u_value": u, "heat_capacity": hc,
                      "name": wname})
    joined = {frozenset(w["between"]) for w in walls}
    for a, b in g.subject_objects(_u("bot:adjacentZone")):
        if a not in node_of or b not in node_of or node_of[a] == node_of[b]:
            continue
        pair = sorted({node_of[a], node_of[b]}, key=_natural)
        if frozenset(pair) in joined or all(n in bnodes or n == "outside" for n in pair):
            continue
        joined.add(frozenset(pair))
        known = [floor_area[n] for n in pair if n in floor_area]
        area = height * math.sqrt(min(known))
        u, hc = CONSTRUCTIONS["exterior" if "outside" in pair else "partition"]
        walls.append({"between": pair, "area": _clean(round(area, 3)), "u_value": u,
                      "heat_capacity": hc})
        notes.append(f"wall {pair[0]}-{pair[1]} (bot:adjacentZone, no element): area "
                     f"{area:.3g} m² estimated as height × sqrt(floor area)")

    # air paths
    distances, seen = [], set()
    for s in sorted(node_of, key=str):
        for ap in g.objects(s, _u("tc:airPath")):
            to = next(iter(g.objects(ap, _u("tc:to"))), None)
            where = f"{src}: tc:airPath of {node_of[s]}"
            if to not in node_of:
                raise SpecError(f"{where}: tc:to {to} is not a space of the model")
            d = _number(g, ap, _u("tc:length"), where)
            if d is None:
                raise SpecError(f"{where}: no tc:length [m]")
            pair = sorted((node_of[s], node_of[to]), key=_natural)
            key = frozenset(pair)
            if key in seen:
                raise SpecError(f"{where}: the path {pair[0]}-{pair[1]} is given twice")
            seen.add(key)
            distances.append({"between": pair, "d": _clean(d)})
    distances.sort(key=lambda d: [_natural(n) for n in d["between"]])

    # the building
    buildings = sorted(typed(("brick:Building",)), key=str)
    bname = _local(buildings[0]) if buildings else path.stem
    mult = capacity_multiplier
    if mult is None and buildings:
        mult = _number(g, buildings[0], _u("tc:capacityMultiplier"), f"{src}: {bname}")
    used_bnd = {n for w in walls for n in w["between"] if n not in zones_dict}
    bnd = sorted(used_bnd, key=lambda n: (n != "outside", _natural(n)))
    unused = sorted(bnodes - used_bnd, key=_natural)
    if unused:
        notes.append(f"boundary node(s) {unused} share no wall with a zone: left out")
        for n in unused:
            columns = {k: v for k, v in columns.items() if v != f"T:{n}"}
    if "outside" not in used_bnd and "T:outside" in columns.values():
        columns = {k: v for k, v in columns.items() if v != "T:outside"}
        notes.append("an outside air temperature point but no exterior element: not mapped")
    if "outside" in used_bnd and "T:outside" not in columns.values():
        notes.append("no Outside_Air_Temperature_Sensor: the data need a T:outside column")
    spec_dict = {"name": bname}
    if mult is not None:
        spec_dict["capacity_multiplier"] = _clean(mult)
    spec_dict.update(zones=zones_dict, boundary=bnd, walls=walls, distances=distances)
    spec = spec_from_dict(spec_dict, source=src)
    return BrickImport(spec_dict, spec, columns, _units(units_seen), notes, src)


def _clean(x: float):
    """An int if the value is one (``60`` rather than ``60.0`` in the YAML)."""
    x = float(x)
    return int(x) if x.is_integer() and abs(x) < 2 ** 53 else x


_SI_UNITS = {"DEG_C", "KiloGM-PER-SEC", "M3-PER-SEC", "W-PER-M2", "L-PER-SEC"}
_IMPERIAL_UNITS = {"DEG_F", "FT3-PER-MIN"}


def _units(seen: set) -> str | None:
    if seen and seen <= _SI_UNITS | {"W-PER-M2"} and not seen <= {"W-PER-M2"}:
        return "si" if not seen & {"L-PER-SEC"} else None
    if seen and seen <= _IMPERIAL_UNITS | {"W-PER-M2"} and seen & _IMPERIAL_UNITS:
        return "imperial"
    return None


# ---------------------------------------------------------------------------- column maps
def write_column_map(columns: dict, path, source: str | None = None,
                     units: str | None = None) -> None:
    """Write a column map as YAML: ``columns: {BAS column: thermctl column}``.

    Parameters
    ----------
    columns : dict
    path : str or Path
    source : str, optional
        The Brick model it came from (a comment).
    units : {"si", "imperial"}, optional
        The points' units (a comment: the ``--units`` to read the data with).
    """
    head = ["# thermctl column map: BAS export column -> thermctl column"]
    if source:
        head.append(f"# from {source}")
    if units:
        head.append(f"# the points are in {units} units: read the data with --units {units}")
    head.append("# use: thermctl identify DATA.csv -b building.yaml --columns THIS_FILE")
    body = yaml.safe_dump({"columns": dict(columns)}, sort_keys=False, allow_unicode=True)
    Path(path).write_text("\n".join(head) + "\n" + body)


def load_column_map(path) -> dict:
    """Read a column map: YAML or JSON, ``{columns: {BAS: thermctl}}`` or the bare mapping.

    Raises
    ------
    DataError
        Missing file, not a mapping of names to names, a thermctl column given twice.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: column map not found")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise DataError(f"{path}: column map is not valid YAML: "
                        f"{str(exc).splitlines()[0]}") from None
    if isinstance(data, dict) and set(data) == {"columns"}:
        data = data["columns"]
    if not isinstance(data, dict) or not data:
        raise DataError(f"{path}: expected a mapping 'BAS column: thermctl column' (under "
                        f"'columns:'), found {type(data).__name__}")
    out = {}
    for k, v in data.items():
        if not isinstance(v, str) or not str(k).strip():
            raise DataError(f"{path}: entry {k!r}: {v!r} must map a column name to a name")
        if v in out.values():
            raise DataError(f"{path}: {v} is the target of two columns")
        out[str(k).strip()] = v.strip()
    return out


def apply_column_map(frame, columns: dict, source: str = "<data>"):
    """Rename the columns of a BAS export by a column map.

    Columns the map does not name are kept as they are; mapped columns missing from the
    data are reported with a :class:`~thermctl.errors.DataWarning` (the data reader then
    says which thermctl columns a zone lacks).

    Parameters
    ----------
    frame : pandas.DataFrame
    columns : dict
        ``{BAS column: thermctl column}``.
    source : str
        Name of the data in messages.

    Returns
    -------
    pandas.DataFrame
        A renamed copy.
    """
    names = [str(c).strip() for c in frame.columns]
    missing = [c for c in columns if c not in names]
    if missing:
        warnings.warn(f"{source}: {len(missing)} column(s) of the column map not in the data: "
                      f"{missing[:5]}{' ...' if len(missing) > 5 else ''}", DataWarning,
                      stacklevel=2)
    new = [columns.get(c, c) for c in names]
    dupes = sorted({c for c in new if new.count(c) > 1})
    if dupes:
        raise DataError(f"{source}: after the column map, column(s) {dupes} appear more than "
                        "once (a mapped column and an unmapped one of the same name)")
    out = frame.copy()
    out.columns = new
    return out


def read_mapped_table(path, columns: dict, sep: str = ","):
    """A CSV or parquet BAS export read as a table and renamed by ``columns``.

    Parameters
    ----------
    path : str or Path
    columns : dict
        ``{BAS column: thermctl column}`` (:func:`load_column_map`).
    sep : str, default ","
        CSV field separator (``";"``: decimal commas too).
    """
    import pandas as pd

    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: data file not found")
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            df = pd.read_parquet(path)
            if "time" not in df.columns and df.index.name is not None:
                df = df.reset_index()
        else:
            df = pd.read_csv(path, encoding="utf-8-sig", skipinitialspace=True, sep=sep,
                             decimal="," if sep == ";" else ".")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, OSError,
            ValueError) as exc:
        raise DataError(f"{path}: not a readable data file: "
                        f"{str(exc).strip().splitlines()[0] if str(exc).strip() else exc}") from None
    return apply_column_map(df, columns, str(path))
