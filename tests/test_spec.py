"""Building spec: parsing, derived values, and every validation message."""

from __future__ import annotations

import json
import math
import re
import warnings

import numpy as np
import pytest

from thermctl import rc
from thermctl.errors import SpecError, SpecWarning
from thermctl.spec import (RHO_AIR, BuildingSpec, cp_moist_air, load_spec, spec_from_dict)

CP = 1006.0 + 1860.0 * 0.0074  # paper's W_s; written out here, not taken from the module


# ---------------------------------------------------------------------------------------------
# valid specs
# ---------------------------------------------------------------------------------------------
def test_small_spec_contents(small_spec):
    assert small_spec.zone_names == ["r1", "r2", "r3", "hallway"]
    assert small_spec.measured_zones == ["r1", "r2", "r3"]
    assert small_spec.boundary == ("outside", "ground")
    assert len(small_spec.walls) == 9
    assert small_spec.capacity_multiplier == 1.0
    assert small_spec.cp == pytest.approx(CP, rel=1e-15)
    assert cp_moist_air(0.0) == 1006.0


def test_u_value_wall_gets_pi2_split(small_spec):
    w = small_spec.walls[2]  # r2-outside: area 10, u 0.5, heat_capacity 2e5
    R, C = rc.homogeneous_split(1 / (0.5 * 10.0), 2.0e5 * 10.0)
    np.testing.assert_allclose(w.R, R, rtol=1e-15)
    np.testing.assert_allclose(w.C, C, rtol=1e-15)
    assert w.area == 10.0
    assert w.alpha == pytest.approx(np.pi**2, rel=1e-12)


def test_rc_wall_kept_as_given(small_spec):
    w = small_spec.walls[0]
    assert (w.a, w.b, w.R, w.C, w.area, w.name) == (
        "r1", "outside", (0.02, 0.06, 0.02), (2.0e6, 2.0e6), 12.0, "r1-ext")


def test_zone_capacitance_default_is_air_only(small_spec_dict):
    spec = spec_from_dict(small_spec_dict)
    assert spec.zone_capacitance("r1") == pytest.approx(RHO_AIR * CP * 60.0, rel=1e-14)
    assert RHO_AIR == 1.2
    assert spec.zone_capacitance("r3") == 5.0e5  # explicit capacitance wins
    small_spec_dict["capacity_multiplier"] = 5
    spec5 = spec_from_dict(small_spec_dict)
    assert spec5.zone_capacitance("r1") == pytest.approx(5 * 1.2 * CP * 60.0, rel=1e-14)
    assert spec5.zone_capacitance("r3") == 5.0e5


def test_w_s_changes_cp(small_spec_dict):
    small_spec_dict["w_s"] = 0.01
    spec = spec_from_dict(small_spec_dict)
    assert spec.cp == pytest.approx(1006.0 + 18.6, rel=1e-15)


def test_distance_lookup_is_symmetric(small_spec):
    assert small_spec.distance("r1", "r3") == 9.0
    assert small_spec.distance("r3", "r1") == 9.0
    assert small_spec.distance("r2", "hallway") is None


def test_alphas_per_wall_and_median(small_spec):
    alphas = small_spec.alphas()
    assert list(alphas)[:3] == ["r1-ext", "r1-window", "walls[2] r2-outside"]
    for w in small_spec.walls:
        R, C = np.array(w.R), np.array(w.C)
        tau = -1 / np.linalg.eigvals(rc.state_matrices(R, C)[0]).real.max()
        assert w.alpha == pytest.approx(R.sum() * C.sum() / tau, rel=1e-12)
    assert small_spec.alpha() == pytest.approx(float(np.median(list(alphas.values()))), rel=1e-15)


def test_alpha_without_walls_is_an_error():
    with pytest.warns(SpecWarning):
        spec = spec_from_dict({"zones": {"a": {"volume": 1}}, "boundary": ["o"], "walls": []})
    with pytest.raises(SpecError, match="no walls, cannot compute alpha"):
        spec.alpha()
    with pytest.raises(SpecError, match=r"no zone named 'b'; zones are \['a'\]"):
        spec.zone("b")


@pytest.mark.parametrize("suffix", [".yaml", ".yml", ".json"])
def test_dump_load_round_trip(small_spec, tmp_path, suffix):
    path = tmp_path / f"b{suffix}"
    small_spec.dump(path)
    back = load_spec(path)
    assert back == small_spec  # dataclass equality, every field but `source`
    assert back.source == str(path)


def test_yaml_and_json_give_the_same_spec(small_spec_dict, write_spec):
    a = load_spec(write_spec(small_spec_dict, "b.yaml"))
    b = load_spec(write_spec(small_spec_dict, "b.json"))
    assert a == b
    assert isinstance(a, BuildingSpec)


def test_name_defaults_to_file_stem(small_spec_dict, write_spec):
    del small_spec_dict["name"]
    assert load_spec(write_spec(small_spec_dict, "pugh-hall.yaml")).name == "pugh-hall"


def test_numeric_zone_names_become_strings(write_spec):
    text = """
zones: {101: {volume: 30}, 102: {volume: 40}}
boundary: [outside]
walls:
  - {between: [101, outside], R: [1, 2, 1], C: [5, 5]}
  - {between: [101, 102], R: [1, 2, 1], C: [5, 5]}
distances: [{between: [101, 102], d: 3}]
"""
    spec = load_spec(write_spec(text))
    assert spec.zone_names == ["101", "102"]
    assert spec.distance("102", "101") == 3.0


def test_parallel_walls_stay_separate(small_spec):
    pair = [w for w in small_spec.walls if {w.a, w.b} == {"r1", "outside"}]
    assert [w.name for w in pair] == ["r1-ext", "r1-window"]


def test_real_house_spec(twinhouse_spec_path):
    spec = load_spec(twinhouse_spec_path)
    assert len(spec.zones) == 7 and spec.boundary == ("outside", "attic", "cellar")
    assert len(spec.walls) == 44 and len(spec.distances) == 9
    pairs = [frozenset((w.a, w.b)) for w in spec.walls]
    assert len(set(pairs)) < len(pairs)  # parallel walls (wall + window, wall + door)
    # every element there is a homogeneous split
    np.testing.assert_allclose(list(spec.alphas().values()), np.pi**2, rtol=1e-4)


# ---------------------------------------------------------------------------------------------
# validation: every message
# ---------------------------------------------------------------------------------------------
def _wall(d, i):
    return d["walls"][i]


ALLOWED = {
    "top": r"\['boundary', 'capacity_multiplier', 'constructions', 'distances', 'flows', 'name', 'w_s', 'walls', 'zones'\]",
    "zone": r"\['capacitance', 'measured', 'storey', 'volume'\]",
    "wall": r"\['C', 'R', 'area', 'between', 'construction', 'heat_capacity', 'name', 'u_value'\]",
    "distance": r"\['between', 'd'\]",
}

# (id, mutation of a fresh copy of the small spec dict -> dict to validate, message regex)
ERROR_CASES = [
    # structure and unknown keys at every level
    ("top-not-mapping", lambda d: [d], r"small\.yaml: expected a mapping, found list"),
    ("unknown-top-key", lambda d: {**d, "zonez": {}},
     r"small\.yaml: unknown key\(s\) \['zonez'\]; allowed keys are " + ALLOWED["top"]),
    ("unknown-zone-key", lambda d: d["zones"]["r1"].update(volumen=3) or d,
     r"zones\.r1: unknown key\(s\) \['volumen'\]; allowed keys are " + ALLOWED["zone"]),
    ("unknown-wall-key", lambda d: _wall(d, 0).update(U=1) or d,
     r"walls\[0\]: unknown key\(s\) \['U'\]; allowed keys are " + ALLOWED["wall"]),
    ("unknown-distance-key", lambda d: d["distances"][1].update(length=3) or d,
     r"distances\[1\]: unknown key\(s\) \['length'\]; allowed keys are " + ALLOWED["distance"]),
    ("missing-zones", lambda d: d.pop("zones") and d, r"missing required key 'zones'"),
    ("missing-boundary", lambda d: d.pop("boundary") and d, r"missing required key 'boundary'"),
    ("missing-walls", lambda d: d.pop("walls") and d, r"missing required key 'walls'"),
    # top-level numbers
    ("capacity-multiplier-zero", lambda d: {**d, "capacity_multiplier": 0},
     r"capacity_multiplier: must be finite and > 0 \[-\], found 0"),
    ("capacity-multiplier-text", lambda d: {**d, "capacity_multiplier": "five"},
     r"capacity_multiplier: expected a number \[-\], found 'five'"),
    ("w_s-out-of-range", lambda d: {**d, "w_s": 0.2},
     r"w_s must be a humidity ratio in \[0, 0\.1\) \[kg/kg\], found 0\.2"),
    # zones
    ("zones-empty", lambda d: {**d, "zones": {}}, r"'zones' must be a non-empty mapping"),
    ("zones-list", lambda d: {**d, "zones": ["r1"]}, r"'zones' must be a non-empty mapping"),
    ("zone-not-mapping", lambda d: d["zones"].update(r1=60) or d,
     r"zones\.r1: expected a mapping, found int"),
    ("zone-missing-volume", lambda d: d["zones"]["r2"].pop("volume") and d,
     r"zones\.r2: missing 'volume' \[m³\]"),
    ("volume-zero", lambda d: d["zones"]["r2"].update(volume=0) or d,
     r"zones\.r2\.volume: must be finite and > 0 \[m³\], found 0"),
    ("volume-negative", lambda d: d["zones"]["r2"].update(volume=-5.0) or d,
     r"zones\.r2\.volume: must be finite and > 0 \[m³\], found -5\.0"),
    ("volume-nan", lambda d: d["zones"]["r2"].update(volume=math.nan) or d,
     r"zones\.r2\.volume: must be finite and > 0 \[m³\], found nan"),
    ("volume-text", lambda d: d["zones"]["r2"].update(volume="big") or d,
     r"zones\.r2\.volume: expected a number \[m³\], found 'big'"),
    ("capacitance-zero", lambda d: d["zones"]["r3"].update(capacitance=0) or d,
     r"zones\.r3\.capacitance: must be finite and > 0 \[J/K\], found 0"),
    ("measured-not-bool", lambda d: d["zones"]["hallway"].update(measured="no") or d,
     r"zones\.hallway\.measured: expected true or false, found 'no'"),
    # boundary
    ("boundary-not-list", lambda d: {**d, "boundary": "outside"},
     r"'boundary' must be a list of node names, found 'outside'"),
    ("boundary-listed-twice", lambda d: {**d, "boundary": ["outside", "ground", "outside"]},
     r"boundary node 'outside' is listed twice"),
    ("zone-also-boundary", lambda d: {**d, "boundary": ["outside", "ground", "r2"]},
     r"\['r2'\] named both as zone and as boundary node"),
    # walls
    ("walls-not-list", lambda d: {**d, "walls": {"a": 1}}, r"'walls' must be a list"),
    ("wall-not-mapping", lambda d: d["walls"].append("r1-r2") or d,
     r"walls\[9\]: expected a mapping, found str"),
    ("wall-unknown-zone", lambda d: _wall(d, 7).update(between=["r1", "r9"]) or d,
     r"walls\[7\]: unknown node 'r9'; known nodes are \['ground', 'hallway', 'outside', 'r1', "
     r"'r2', 'r3'\]"),
    ("wall-between-missing", lambda d: _wall(d, 7).pop("between") and d,
     r"walls\[7\]: 'between' must list exactly 2 nodes, found None"),
    ("wall-between-three", lambda d: _wall(d, 7).update(between=["r1", "r2", "r3"]) or d,
     r"walls\[7\]: 'between' must list exactly 2 nodes, found \['r1', 'r2', 'r3'\]"),
    ("wall-names-node-twice", lambda d: _wall(d, 7).update(between=["r1", "r1"]) or d,
     r"walls\[7\]: 'between' names node 'r1' twice"),
    ("wall-between-boundaries", lambda d: _wall(d, 7).update(between=["outside", "ground"]) or d,
     r"walls\[7\]: joins two boundary nodes 'outside' and 'ground'; it affects no zone"),
    ("wall-rc-and-u-value", lambda d: _wall(d, 0).update(u_value=0.5) or d,
     r"walls\[0\]: give either R/C or area/u_value/heat_capacity, not both"),
    ("wall-u-value-and-C", lambda d: _wall(d, 2).update(C=[1.0, 1.0]) or d,
     r"walls\[2\]: give either R/C or area/u_value/heat_capacity, not both"),
    ("wall-missing-C", lambda d: _wall(d, 3).pop("C") and d,
     r"walls\[3\]: needs R \(3 values \[K/W\]\) and C \(2 values \[J/K\]\), "
     r"or area/u_value/heat_capacity"),
    ("wall-nothing", lambda d: {**d, "walls": [{"between": ["r1", "outside"], "area": 3}]},
     r"walls\[0\]: needs R \(3 values"),
    ("wall-R-length-2", lambda d: _wall(d, 3).update(R=[0.1, 0.1]) or d,
     r"walls\[3\]\.R: expected a list of 3 resistances \[K/W\], found \[0\.1, 0\.1\]"),
    ("wall-R-scalar", lambda d: _wall(d, 3).update(R=0.3) or d,
     r"walls\[3\]\.R: expected a list of 3 resistances \[K/W\], found 0\.3"),
    ("wall-C-length-3", lambda d: _wall(d, 3).update(C=[1.0, 1.0, 1.0]) or d,
     r"walls\[3\]\.C: expected a list of 2 capacitances \[J/K\], found \[1\.0, 1\.0, 1\.0\]"),
    ("wall-R-zero", lambda d: _wall(d, 3).update(R=[0.03, 0, 0.03]) or d,
     r"walls\[3\]\.R\[1\]: must be finite and > 0 \[K/W\], found 0"),
    ("wall-R-negative", lambda d: _wall(d, 3).update(R=[-0.03, 0.1, 0.03]) or d,
     r"walls\[3\]\.R\[0\]: must be finite and > 0 \[K/W\], found -0\.03"),
    ("wall-C-zero", lambda d: _wall(d, 3).update(C=[1e6, 0.0]) or d,
     r"walls\[3\]\.C\[1\]: must be finite and > 0 \[J/K\], found 0\.0"),
    ("wall-C-negative", lambda d: _wall(d, 3).update(C=[-1e6, 1e6]) or d,
     r"walls\[3\]\.C\[0\]: must be finite and > 0 \[J/K\], found -1000000\.0"),
    ("wall-area-zero", lambda d: _wall(d, 2).update(area=0) or d,
     r"walls\[2\]\.area: must be finite and > 0 \[m²\], found 0"),
    ("wall-u-value-negative", lambda d: _wall(d, 2).update(u_value=-0.5) or d,
     r"walls\[2\]\.u_value: must be finite and > 0 \[W/\(m² K\)\], found -0\.5"),
    ("wall-heat-capacity-zero", lambda d: _wall(d, 2).update(heat_capacity=0) or d,
     r"walls\[2\]\.heat_capacity: must be finite and > 0 \[J/\(m² K\)\], found 0"),
    ("wall-missing-heat-capacity", lambda d: _wall(d, 2).pop("heat_capacity") and d,
     r"walls\[2\]: missing 'heat_capacity' \(needed with u_value/heat_capacity\)"),
    ("wall-missing-area", lambda d: _wall(d, 2).pop("area") and d,
     r"walls\[2\]: missing 'area' \(needed with u_value/heat_capacity\)"),
    ("duplicate-wall-name", lambda d: _wall(d, 1).update(name="r1-ext") or d,
     r"walls\[1\]: duplicate wall name 'r1-ext'"),
    # distances
    ("distances-not-list", lambda d: {**d, "distances": {"r1": 3}}, r"'distances' must be a list"),
    ("distance-unknown-zone", lambda d: d["distances"][0].update(between=["r1", "kitchen"]) or d,
     r"distances\[0\]: unknown node 'kitchen'; known nodes are"),
    ("distance-names-node-twice", lambda d: d["distances"][0].update(between=["r2", "r2"]) or d,
     r"distances\[0\]: 'between' names node 'r2' twice"),
    ("distance-to-boundary", lambda d: d["distances"][0].update(between=["r1", "outside"]) or d,
     r"distances\[0\]: 'outside' is a boundary node; air paths join zones"),
    ("distance-missing-d", lambda d: d["distances"][0].pop("d") and d,
     r"distances\[0\]: missing 'd' \[m\]"),
    ("distance-d-zero", lambda d: d["distances"][0].update(d=0) or d,
     r"distances\[0\]\.d: must be finite and > 0 \[m\], found 0"),
    ("distance-d-negative", lambda d: d["distances"][0].update(d=-4.0) or d,
     r"distances\[0\]\.d: must be finite and > 0 \[m\], found -4\.0"),
    ("distance-given-twice",
     lambda d: d["distances"].append({"between": ["r3", "r1"], "d": 7.0}) or d,
     r"distances\[5\]: distance between 'r3' and 'r1' given twice"),
]


@pytest.mark.parametrize("mutate, match", [c[1:] for c in ERROR_CASES],
                         ids=[c[0] for c in ERROR_CASES])
def test_spec_errors(small_spec_dict, mutate, match):
    data = mutate(small_spec_dict)
    with pytest.raises(SpecError, match=match) as info:
        spec_from_dict(data, source="small.yaml")
    # every message names the file it came from
    assert str(info.value).startswith("small.yaml")


def test_w_s_not_a_number(small_spec_dict):
    small_spec_dict["w_s"] = "humid"
    with pytest.raises(SpecError, match=r"small\.yaml: w_s"):
        spec_from_dict(small_spec_dict, source="small.yaml")


@pytest.mark.parametrize("level, mutate", [
    ("top", lambda d: {**d, "bogus": 1}),
    ("zone", lambda d: d["zones"]["r2"].update(bogus=1) or d),
    ("wall", lambda d: _wall(d, 4).update(bogus=1) or d),
    ("distance", lambda d: d["distances"][2].update(bogus=1) or d),
], ids=["top", "zone", "wall", "distance"])
def test_unknown_key_error_lists_every_allowed_key(small_spec_dict, level, mutate):
    with pytest.raises(SpecError) as info:
        spec_from_dict(mutate(small_spec_dict))
    listed = re.search(r"allowed keys are \[(.*)\]", str(info.value)).group(1)
    expected = {"top": {"name", "capacity_multiplier", "w_s", "zones", "boundary", "walls",
                        "distances", "flows", "constructions"},
                "zone": {"volume", "measured", "capacitance", "storey"},
                "wall": {"between", "R", "C", "area", "u_value", "heat_capacity", "name",
                         "construction"},
                "distance": {"between", "d"}}[level]
    assert {k.strip(" '") for k in listed.split(",")} == expected
    if level == "top":  # every BuildingSpec field (but the file name) can be set from a file
        # ('constructions' only resolves walls: no field of its own)
        assert set(BuildingSpec.__dataclass_fields__) - {"source"} == expected - {"constructions"}


# ---------------------------------------------------------------------------------------------
# isolated zones
# ---------------------------------------------------------------------------------------------
def test_zone_without_path_to_boundary_warns(small_spec_dict):
    small_spec_dict["walls"] = [w for w in small_spec_dict["walls"]
                                if "r3" not in w["between"]]
    with pytest.warns(SpecWarning, match=r"small\.yaml: zone\(s\) \['r3'\] have no wall path "
                      r"to any boundary node"):
        spec = spec_from_dict(small_spec_dict, source="small.yaml")
    assert spec.zone_names == ["r1", "r2", "r3", "hallway"]  # still a valid spec


def test_isolated_cluster_and_no_boundary_warn(small_spec_dict):
    # r1 and r2 only see each other and the hallway, which only sees them
    small_spec_dict["walls"] = [w for w in small_spec_dict["walls"]
                                if not {"outside", "ground"} & set(w["between"])
                                and "r3" not in w["between"]]
    small_spec_dict["walls"].append({"between": ["r3", "ground"], "R": [1, 1, 1], "C": [1, 1]})
    with pytest.warns(SpecWarning, match=r"\['r1', 'r2', 'hallway'\] have no wall path"):
        spec_from_dict(small_spec_dict)
    small_spec_dict["boundary"] = []
    small_spec_dict["walls"].pop()
    small_spec_dict["distances"] = []
    with pytest.warns(SpecWarning, match=r"\['r1', 'r2', 'r3', 'hallway'\] have no wall path"):
        spec_from_dict(small_spec_dict)


def test_connected_spec_does_not_warn(small_spec_dict):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        spec_from_dict(small_spec_dict)


# ---------------------------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------------------------
FILE_CASES = [
    ("empty-file", "b.yaml", "", r"b\.yaml: building spec is empty"),
    ("whitespace-file", "b.yaml", "  \n\n", r"b\.yaml: building spec is empty"),
    ("comment-only-file", "b.yaml", "# nothing yet\n", r"b\.yaml: building spec is empty \(only comments\)"),
    ("invalid-yaml", "b.yaml", "zones: {r1: {volume: 3}\nboundary: [", r"b\.yaml: not valid YAML"),
    ("invalid-json", "b.json", '{"zones": ', r"b\.json: not valid JSON"),
    ("duplicate-yaml-zone", "b.yaml",
     "zones:\n  r1: {volume: 3}\n  r1: {volume: 4}\nboundary: [o]\nwalls: []\n",
     r"b\.yaml: duplicate key 'r1' at line 3"),
    ("duplicate-yaml-top-key", "b.yaml",
     "zones: {r1: {volume: 3}}\nboundary: [o]\nwalls: []\nboundary: [p]\n",
     r"b\.yaml: duplicate key 'boundary' at line 4"),
    ("duplicate-yaml-key-in-wall", "b.yaml",
     "zones: {r1: {volume: 3}}\nboundary: [o]\n"
     "walls: [{between: [r1, o], R: [1, 1, 1], R: [2, 2, 2], C: [1, 1]}]\n",
     r"b\.yaml: duplicate key 'R' at line 3"),
    ("duplicate-json-zone", "b.json",
     '{"zones": {"r1": {"volume": 3}, "r1": {"volume": 4}}, "boundary": [], "walls": []}',
     r"b\.json: duplicate key 'r1'"),
    ("json-error-names-file", "b.json",
     '{"zones": {"r1": {"volume": -3}}, "boundary": ["o"], "walls": []}',
     r"b\.json: zones\.r1\.volume: must be finite and > 0"),
]


@pytest.mark.parametrize("name, text, match", [c[1:] for c in FILE_CASES],
                         ids=[c[0] for c in FILE_CASES])
def test_file_errors(write_spec, name, text, match):
    path = write_spec(text, name)
    with pytest.raises(SpecError, match=match) as info:
        load_spec(path)
    assert str(path.parent) in str(info.value)  # the full path, not just the name


def test_missing_file(tmp_path):
    with pytest.raises(SpecError, match=r"nope\.yaml: building spec not found"):
        load_spec(tmp_path / "nope.yaml")
    with pytest.raises(SpecError, match="building spec not found"):
        load_spec(tmp_path)  # a directory is not a spec file


def test_uppercase_json_suffix_error_says_json(write_spec):
    path = write_spec('{"zones": ', "B.JSON")
    with pytest.raises(SpecError, match="not valid JSON"):
        load_spec(path)


def test_spec_error_is_a_value_error():
    assert issubclass(SpecError, ValueError)
    with pytest.raises(ValueError):
        spec_from_dict({"zones": {}, "boundary": [], "walls": []})


def test_json_dump_is_plain_json(small_spec, tmp_path):
    path = tmp_path / "b.json"
    small_spec.dump(path)
    data = json.loads(path.read_text())
    assert data["walls"][2]["R"] == list(small_spec.walls[2].R)
    assert "u_value" not in data["walls"][2]


def test_air_path_length_given_estimated_or_none(small_spec):
    # given in `distances` (also for a pair with a wall): the spec's value, not estimated
    assert small_spec.air_path_length("r1", "r2") == (4.0, False)
    assert small_spec.air_path_length("r3", "r1") == (9.0, False)
    # r2–hallway share a wall but have no length: two cubes' centres, (V_a^⅓ + V_b^⅓) / 2
    d, est = small_spec.air_path_length("hallway", "r2")
    assert est and d == pytest.approx(0.5 * (45.0 ** (1 / 3) + 120.0 ** (1 / 3)), rel=1e-12)
    assert d == pytest.approx(4.2447, abs=1e-4)
    # a zone and a boundary node, or two zones with neither wall nor length: nothing
    assert small_spec.air_path_length("r2", "outside") == (None, False)
    assert frozenset(("r1", "r2")) in small_spec.wall_pairs()
    assert frozenset(("r1", "outside")) not in small_spec.wall_pairs()   # boundary walls


def test_candidate_pairs_include_wall_pairs_without_length(small_spec):
    from thermctl.structure.search import candidate_pairs
    cands = {c.pair: c for c in candidate_pairs(small_spec)}
    assert cands[("hallway", "r2")].parallel and cands[("hallway", "r2")].unmeasured
    assert cands[("hallway", "r2")].d == pytest.approx(4.2447, abs=1e-4)
    assert cands[("r1", "r3")].d == 9.0 and not cands[("r1", "r3")].parallel
    assert ("hallway", "r2") not in {c.pair for c in candidate_pairs(small_spec, parallel=False)}


# ---------------------------------------------------------------------------------------------
# storeys: a slab between two zones is no air path
# ---------------------------------------------------------------------------------------------
def test_storey_parsed_as_text_and_round_trips(small_spec_dict):
    small_spec_dict["zones"]["r1"]["storey"] = 1
    small_spec_dict["zones"]["r2"]["storey"] = "ground"
    spec = spec_from_dict(small_spec_dict)
    assert [z.storey for z in spec.zones] == ["1", "ground", None, None]
    again = spec_from_dict(spec.to_dict())
    assert [z.storey for z in again.zones] == ["1", "ground", None, None]
    assert "storey" not in spec.to_dict()["zones"]["r3"]


@pytest.mark.parametrize("bad", [True, 1.5, "", [1]])
def test_storey_must_be_a_name_or_number(small_spec_dict, bad):
    small_spec_dict["zones"]["r2"]["storey"] = bad
    with pytest.raises(SpecError, match=r"zones\.r2\.storey: expected a storey name or number"):
        spec_from_dict(small_spec_dict, source="b.yaml")


def test_zones_on_different_storeys_share_a_slab_not_a_door(small_spec_dict):
    from thermctl.structure.search import as_candidates, candidate_pairs
    # r2 and the hallway share a wall and have no given length: a door is assumed...
    same = {c.pair for c in candidate_pairs(spec_from_dict(small_spec_dict))}
    assert ("hallway", "r2") in same
    # ...unless they are on different storeys; a given length (r1–r2: a stair) still counts,
    # and a zone without a storey is not restricted (r3–hallway)
    for z, s in (("r1", 1), ("r2", 2), ("hallway", 1)):
        small_spec_dict["zones"][z]["storey"] = s
    spec = spec_from_dict(small_spec_dict)
    assert spec.across_storeys("r2", "hallway") and not spec.across_storeys("r1", "hallway")
    assert not spec.across_storeys("r2", "r3") and not spec.across_storeys("r2", "outside")
    assert spec.air_path_length("hallway", "r2") == (None, False)
    assert spec.air_path_length("r1", "r2") == (4.0, False)
    cands = {c.pair for c in candidate_pairs(spec)}
    assert cands == same - {("hallway", "r2")}
    with pytest.raises(SpecError, match="different storeys and only a slab joins them"):
        as_candidates(spec, [("r2", "hallway")])


def test_corridor_testbed_has_no_candidate_through_a_slab():
    from thermctl.structure.search import candidate_pairs
    from thermctl.testbed.buildings import corridor_layout
    two = corridor_layout(6, floors=2, seed=3).spec
    assert {z.storey for z in two.zones} == {"1", "2"}
    cands = {c.pair for c in candidate_pairs(two)}
    assert all(a[:2] == b[:2] for a, b in cands)          # f1… with f1…, f2… with f2…
    # the same building without storeys: every slab (12 offices and the corridor, each
    # over the one below) is a candidate as well; nothing else changes
    raw = two.to_dict()
    for z in raw["zones"].values():
        del z["storey"]
    flat = {c.pair for c in candidate_pairs(spec_from_dict(raw))}
    slabs = {tuple(sorted((w.a, w.b))) for w in two.walls
             if w.a in two.zone_names and w.b in two.zone_names and w.a[:2] != w.b[:2]}
    assert len(slabs) == 13
    assert flat - cands == slabs and cands <= flat
