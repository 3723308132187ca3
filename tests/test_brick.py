"""Brick models in: the shipped Pugh Hall model gives the testbed's hand-written spec, its
points the testbed's columns, and identification the same model; bad models fail in one
line naming the file and the node or element."""

from __future__ import annotations

import dataclasses
import json
import textwrap
import warnings

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

pytest.importorskip("brickschema")

from thermctl.brick import (CONSTRUCTIONS, apply_column_map, example_model,  # noqa: E402
                            load_column_map, read_brick)
from thermctl.cli import app  # noqa: E402
from thermctl.data import read_measurements  # noqa: E402
from thermctl.errors import DataError, DataWarning, SpecError  # noqa: E402
from thermctl.identify import (EstimationOptions, IdentifyOptions, SplitOptions,  # noqa: E402
                               StructureOptions, identify)
from thermctl.io import model_to_dict  # noqa: E402
from thermctl.model import ThermalModel  # noqa: E402
from thermctl.network import ThermalNetwork  # noqa: E402
from thermctl.spec import load_spec  # noqa: E402
from thermctl.testbed import generate  # noqa: E402
from thermctl.testbed.buildings import WALL_TYPES, pugh_hall_spec  # noqa: E402

runner = CliRunner()


@pytest.fixture(scope="module")
def pugh():
    return read_brick(example_model("pugh-hall-2f"))


def _walls(spec):
    return sorted(((w.name, frozenset((w.a, w.b)), w.R, w.C, w.area) for w in spec.walls),
                  key=str)


def test_constructions_are_the_testbed_wall_types():
    """The classes a Brick wall gets are the testbed's (two tables, one set of values)."""
    assert CONSTRUCTIONS == WALL_TYPES


def test_pugh_hall_model_gives_the_handwritten_spec(pugh):
    hand, _ = pugh_hall_spec()
    spec = pugh.spec
    assert spec.name == hand.name == "pugh-hall-2f"
    # names, order, volumes, measured, C; the model also says the storey (brick:Floor)
    assert [dataclasses.replace(z, storey=None) for z in spec.zones] == list(hand.zones)
    assert {z.storey for z in spec.zones} == {"floor-2"}
    assert spec.capacity_multiplier == hand.capacity_multiplier == 6.0
    assert set(spec.boundary) == set(hand.boundary) and spec.boundary[0] == "outside"
    assert _walls(spec) == _walls(hand)             # names, ends, R, C, area: exact
    assert len(spec.walls) == 21
    dist = lambda s: {(frozenset((d.a, d.b)), d.d) for d in s.distances}  # noqa: E731
    assert dist(spec) == dist(hand) and len(spec.distances) == 11


def test_pugh_hall_model_gives_the_same_dynamics(pugh):
    """Same network up to the order of the wall states: same eigenvalues, same steady state."""
    hand, edges = pugh_hall_spec()
    ms = {}
    for name, spec in (("hand", hand), ("brick", pugh.spec)):
        model = ThermalModel(ThermalNetwork(spec, edges), 3.36e-4, 1.19e3)
        op = model.operating_point(ms=0.05, Ts=14.0, T={"outside": -5.0, "*": 21.0})
        A, _ = model.jacobians(op)
        ms[name] = (np.sort(np.linalg.eigvals(A).real), op.x[:len(spec.zones)])
    np.testing.assert_allclose(ms["brick"][0], ms["hand"][0], rtol=1e-9)
    np.testing.assert_allclose(ms["brick"][1], ms["hand"][1], rtol=1e-12)


def test_points_become_the_testbed_columns(pugh):
    cols = pugh.columns
    assert cols["PUGH.2F.R240.ZN-T"] == "T:r240"
    assert cols["PUGH.2F.R240.VAV.SA-F"] == "ms:r240"      # unit:KiloGM-PER-SEC
    assert cols["PUGH.2F.R247.VAV.SA-T"] == "Ts:r247"
    assert cols["PUGH.OAT"] == "T:outside"
    assert cols["PUGH.2F.CORRIDOR.ZN-T"] == "T:corridor"
    tb_cols = {c for c in generate("pugh-hall", days=0.25, seed=0).data.columns}
    assert set(cols.values()) == tb_cols                     # every testbed column, no other
    assert pugh.units == "si"
    assert any("hallway" in n and "unmeasured" in n for n in pugh.notes)


def _bas(tb, columns):
    """The testbed's data as a BAS would export them: its point names, not thermctl's."""
    inverse = {v: k for k, v in columns.items()}
    df = tb.data.rename(columns=inverse)
    df.insert(0, "time", [t.isoformat() for t in df.index])
    return df.reset_index(drop=True)


_FAST = ["--criterion", "simulation", "--selection", "scores", "--method", "glasso",
         "--no-grid"]


def test_brick_round_trip_identifies_the_same_model(tmp_path, pugh):
    """TTL → spec + column map → identify on the BAS export = identify on the hand-written
    spec and the testbed's own columns (7 days: glasso needs 5 complete days)."""
    tb = generate("pugh-hall", days=7, seed=0)
    tb.write(tmp_path / "tb")
    res = runner.invoke(app, ["spec", "from-brick", str(example_model()), "--out",
                              str(tmp_path / "b" / "building.yaml"), "--columns-out",
                              str(tmp_path / "b" / "map.yaml")])
    assert res.exit_code == 0, res.output
    # the Brick model also names the storey (brick:Floor), the testbed's spec does not
    assert [dataclasses.replace(z, storey=None) for z in
            load_spec(tmp_path / "b" / "building.yaml").zones] == list(tb.spec.zones)
    cmap = load_column_map(tmp_path / "b" / "map.yaml")
    assert cmap == pugh.columns
    _bas(tb, cmap).to_csv(tmp_path / "bas.csv", index=False)
    res = runner.invoke(app, ["identify", str(tmp_path / "bas.csv"), "-b",
                              str(tmp_path / "b" / "building.yaml"), "--columns",
                              str(tmp_path / "b" / "map.yaml"), "--out", str(tmp_path / "o"),
                              *_FAST])
    assert res.exit_code == 0, res.output
    brick = json.loads((tmp_path / "o" / "model.json").read_text())
    opts = IdentifyOptions(structure=StructureOptions(method="glasso"),
                           estimation=EstimationOptions(criterion="simulation", grid=False))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hand = model_to_dict(identify(read_measurements(tmp_path / "tb" / "data.csv", tb.spec),
                                      opts).model)
    conv = lambda m: sorted((tuple(sorted((c["a"], c["b"]))), c["d"])  # noqa: E731
                            for c in m["convection"])
    assert conv(brick) == conv(hand) and len(conv(hand)) == 3
    for p in ("rbar_v", "c_v"):
        # the same problem with the walls in another order: equal to rounding
        np.testing.assert_allclose(brick["parameters"][p], hand["parameters"][p], rtol=1e-6)


def test_spec_from_brick_cli_writes_spec_and_map(tmp_path):
    res = runner.invoke(app, ["spec", "from-brick", str(example_model()), "-o",
                              str(tmp_path / "building.yaml")])
    assert res.exit_code == 0, res.output
    assert "7 zones (6 measured)" in res.output and "columns.yaml" in res.output
    text = (tmp_path / "columns.yaml").read_text()
    assert text.startswith("# thermctl column map") and "PUGH.OAT: T:outside" in text
    assert load_spec(tmp_path / "building.yaml").measured_zones == \
        ["r240", "r241", "r242", "r243", "r244", "r247"]


_HEAD = """\
@prefix brick: <https://brickschema.org/schema/Brick#> .
@prefix rec: <https://w3id.org/rec#> .
@prefix bot: <https://w3id.org/bot#> .
@prefix unit: <http://qudt.org/vocab/unit/> .
@prefix tc: <urn:thermctl:> .
@prefix : <http://example.org/b#> .
:b a brick:Building .
"""


def _ttl(tmp_path, body, name="m.ttl"):
    p = tmp_path / name
    p.write_text(_HEAD + textwrap.dedent(body))
    return p


def test_bot_adjacency_areas_and_imperial_points(tmp_path):
    """BOT: a zone of two rooms, volumes from floor areas in ft², a wall estimated from
    bot:adjacentZone, CFM flows → vs: columns and the imperial units noted."""
    p = _ttl(tmp_path, """\
        :z1 a brick:HVAC_Zone ; brick:hasPart :a, :b .
        :a a brick:Room ; brick:area [ brick:value 200 ; brick:hasUnit unit:FT2 ] .
        :b a brick:Room ; brick:area [ brick:value 100 ; brick:hasUnit unit:FT2 ] .
        :c a brick:Room ; brick:volume [ brick:value 30 ; brick:hasUnit unit:M3 ] .
        :a bot:adjacentZone :c .
        :a bot:adjacentElement :ext .
        :ext a rec:Wall ; brick:area 10 .
        :t a brick:Zone_Air_Temperature_Sensor ; brick:isPointOf :z1 ; brick:hasUnit unit:DEG_F .
        :vav a brick:VAV ; brick:feeds :z1 ; brick:hasPoint :f, :s .
        :f a brick:Supply_Air_Flow_Sensor ; brick:hasUnit unit:FT3-PER-MIN .
        :s a brick:Discharge_Air_Temperature_Sensor ; brick:hasUnit unit:DEG_F .
        :oat a brick:Outside_Air_Temperature_Sensor ; brick:hasUnit unit:DEG_F .
        """)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")    # zone c has no wall to a boundary node
        imp = read_brick(p, height=2.5)
    spec = imp.spec
    assert spec.zone_names == ["z1", "c"]
    ft2 = 0.3048 ** 2
    np.testing.assert_allclose(spec.zone("z1").volume, 300 * ft2 * 2.5, rtol=1e-12)
    assert not spec.zone("c").measured
    part = next(w for w in spec.walls if {w.a, w.b} == {"z1", "c"})
    np.testing.assert_allclose(part.area, round(2.5 * np.sqrt(30 / 2.5), 3), rtol=1e-12)
    ext = next(w for w in spec.walls if "outside" in (w.a, w.b))
    assert ext.name == "ext" and ext.area == 10
    assert imp.columns == {"t": "T:z1", "f": "vs:z1", "s": "Ts:z1", "oat": "T:outside"}
    assert imp.units == "imperial"
    assert any("merged" in n for n in imp.notes) and any("estimated" in n for n in imp.notes)


def test_storeys_from_brick_floors_and_bot_storeys(tmp_path):
    """A zone on a brick:Floor or a bot:Storey gets it; the slab between storeys proposes no
    air path, a tc:airPath (a stair) does; a zone on two storeys gets none, with a note."""
    from thermctl.structure.search import candidate_pairs
    p = _ttl(tmp_path, """\
        :b brick:hasPart :f1 .
        :f1 a brick:Floor ; brick:hasPart :a, :b1 .
        :f2 a bot:Storey ; bot:hasSpace :c, :d .
        :atrium a brick:HVAC_Zone ; brick:hasPart :e1, :e2 .
        :e1 a brick:Room ; brick:volume 40 ; brick:isPartOf :f1 .
        :e2 a brick:Room ; brick:volume 40 ; brick:isPartOf :f2 .
        :a a brick:Room ; brick:volume 50 .
        :b1 a brick:Room ; brick:volume 50 .
        :c a brick:Room ; brick:volume 50 .
        :d a brick:Room ; brick:volume 50 .
        :a bot:adjacentZone :b1, :c, :e1 .
        :b1 bot:adjacentZone :d .
        :c bot:adjacentZone :d, :e2 .
        :a tc:airPath [ tc:to :d ; tc:length 7.5 ] .
        """)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")    # no wall to a boundary node in this sketch
        imp = read_brick(p)
    spec = imp.spec
    assert {z.name: z.storey for z in spec.zones} == {"a": "f1", "b1": "f1", "c": "f2",
                                                     "d": "f2", "atrium": None}
    assert any("atrium" in n and "storeys ['f1', 'f2']" in n for n in imp.notes)
    pairs = {c.pair for c in candidate_pairs(spec)}
    # walls: a–b1, c–d (same storey: doors possible), a–c and b1–d (slabs: none), the atrium
    # with a and c (no storey: possible); the stair a–d by its given length
    assert pairs == {("a", "b1"), ("c", "d"), ("a", "atrium"), ("atrium", "c"), ("a", "d")}


_ROOM = ":r1 a brick:Room ; brick:volume 50 ; rec:adjacentElement :w1 .\n:w1 a rec:Wall ; brick:area 10 .\n"


@pytest.mark.parametrize("body, match", [
    (":r1 a brick:Room ; rec:adjacentElement :w1 .\n:w1 a rec:Wall ; brick:area 10 .\n",
     r"zone r1: no brick:volume or brick:area"),
    (_ROOM + ":r2 a brick:Room ; brick:volume 5 ; rec:adjacentElement :w1 .\n"
     ":r3 a brick:Room ; brick:volume 5 ; rec:adjacentElement :w1 .\n",
     r"element w1: adjacent to 3 spaces"),
    (_ROOM + ':w1 tc:construction "straw" .\n', r"element w1: tc:construction 'straw' unknown"),
    (_ROOM.replace("brick:area 10", "brick:volume 1"), r"element w1: no brick:area"),
    (_ROOM + ":r2 a brick:Room, tc:Boundary ; rec:adjacentElement :w2 .\n"
             ":r1 rec:adjacentElement :w2 .\n:w2 a rec:Wall ; brick:area 3 .\n",
     r"boundary node r2 has no Zone_Air_Temperature_Sensor"),
    (":b brick:hasPart :f .\n:f a brick:Floor .\n", r"no brick:HVAC_Zone and no space"),
    (_ROOM.replace("brick:volume 50", "brick:volume -1"), r"zone r1: volume must be > 0"),
    (_ROOM.replace("brick:volume 50", "brick:volume [ brick:value 5 ; brick:hasUnit unit:L ]"),
     r"zone r1: volume in unit L; expected one of \['FT3', 'M3'\]"),
    ("this is not turtle", r"m\.ttl: not a readable RDF/Turtle file"),
], ids=["no-volume", "three-sides", "unknown-class", "no-area", "boundary-unmeasured",
        "no-space", "negative-volume", "bad-unit", "not-turtle"])
def test_bad_models_fail_naming_file_and_node(tmp_path, body, match):
    p = _ttl(tmp_path, body)
    with pytest.raises(SpecError, match=match) as exc:
        read_brick(p)
    assert str(p) in str(exc.value) and "\n" not in str(exc.value)


def test_unknown_boundary_option_and_missing_file(tmp_path):
    p = _ttl(tmp_path, _ROOM)
    with pytest.raises(SpecError, match=r"boundary node\(s\) \['r9'\] are not spaces"):
        read_brick(p, boundary=["r9"])
    with pytest.raises(SpecError, match=r"nope\.ttl: Brick model not found"):
        read_brick(tmp_path / "nope.ttl")


def test_column_map_renames_and_reports():
    df = pd.DataFrame({"time": ["2011-01-21T00:00"], "A.T": [20.0], "other": [1.0]})
    with pytest.warns(DataWarning, match=r"1 column\(s\) of the column map not in the data: \['B'\]"):
        out = apply_column_map(df, {"A.T": "T:r1", "B": "T:r2"}, "bas.csv")
    assert list(out.columns) == ["time", "T:r1", "other"] and list(df.columns)[1] == "A.T"
    with pytest.raises(DataError, match=r"bas.csv: after the column map, column\(s\) \['other'\]"):
        apply_column_map(df, {"A.T": "other"}, "bas.csv")


@pytest.mark.parametrize("text, match", [
    ("columns: [a, b]", r"expected a mapping"),
    ("columns: {a: T:r1, b: T:r1}", r"T:r1 is the target of two columns"),
    ("a: 3", r"entry 'a': 3 must map a column name to a name"),
], ids=["list", "twice", "number"])
def test_bad_column_maps(tmp_path, text, match):
    p = tmp_path / "map.yaml"
    p.write_text(text)
    with pytest.raises(DataError, match=match):
        load_column_map(p)


def test_docs_snippet_runs(docs_snippets):
    ns = docs_snippets("brick.md")
    assert ns["imp"].columns["PUGH.2F.R240.VAV.SA-F"] == "ms:r240"


@pytest.mark.slow
def test_brick_round_trip_greybox_default(tmp_path, pugh):
    """The default identification (grey-box likelihood, BIC selection) on 4 testbed days:
    the Brick spec and the hand-written spec give the same air paths and R̄_v per path."""
    tb = generate("pugh-hall", days=4, seed=0)
    opts = IdentifyOptions(estimation=EstimationOptions(intervals="none"),
                           split=SplitOptions(scale="global"))
    models = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bas = _bas(tb, pugh.columns)
        for name, spec, frame in (("hand", tb.spec, tb.data),
                                  ("brick", pugh.spec, apply_column_map(bas, pugh.columns))):
            models[name] = model_to_dict(identify(read_measurements(frame, spec), opts).model)
    conv = lambda m: sorted((tuple(sorted((c["a"], c["b"]))), round(c["d"], 9))  # noqa: E731
                            for c in m["convection"])
    assert conv(models["brick"]) == conv(models["hand"])
    # the same likelihood with the walls in another order: equal to the optimiser's tolerance
    np.testing.assert_allclose(models["brick"]["parameters"]["rbar_v"],
                               models["hand"]["parameters"]["rbar_v"], rtol=1e-4)
