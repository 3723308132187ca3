"""Walls from a floor plan: area + construction class instead of R and C (issue 20)."""

import pytest

from thermctl import rc
from thermctl.errors import SpecError
from thermctl.spec import CONSTRUCTIONS, spec_from_dict


def _spec(walls, constructions=None):
    d = {"zones": {"a": {"volume": 40.0}, "b": {"volume": 30.0}}, "boundary": ["outside"],
         "walls": walls}
    if constructions is not None:
        d["constructions"] = constructions
    return spec_from_dict(d)


def test_a_construction_gives_the_u_value_walls_rc():
    s = _spec([{"between": ["a", "outside"], "area": 12.0,
                "construction": "exterior-masonry-insulated"},
               {"between": ["a", "b"], "area": 9.0, "construction": "partition-light"}])
    u, k, _ = CONSTRUCTIONS["exterior-masonry-insulated"]
    R, C = rc.from_u_value(12.0, u, k)
    w = s.walls[0]
    assert w.R == pytest.approx(R) and w.C == pytest.approx(C)
    assert 1.0 / sum(w.R) == pytest.approx(0.30 * 12.0)            # UA [W/K]
    assert sum(w.C) == pytest.approx(370e3 * 12.0)                   # [J/K]
    assert w.construction == "exterior-masonry-insulated"
    assert 1.0 / sum(s.walls[1].R) == pytest.approx(1.90 * 9.0)


def test_own_constructions_and_overrides():
    s = _spec([{"between": ["a", "outside"], "area": 10.0, "construction": "my-wall"},
               {"between": ["b", "outside"], "area": 10.0, "construction": "partition-heavy",
                "u_value": 1.0}],
              constructions={"my-wall": {"u_value": 0.5, "heat_capacity": 1e5}})
    assert 1.0 / sum(s.walls[0].R) == pytest.approx(5.0)
    assert sum(s.walls[0].C) == pytest.approx(1e6)
    # a given u_value wins over the construction's; its heat capacity stays
    assert 1.0 / sum(s.walls[1].R) == pytest.approx(10.0)
    assert sum(s.walls[1].C) == pytest.approx(210e3 * 10.0)


@pytest.mark.parametrize("wall, cons, match", [
    ({"between": ["a", "outside"], "area": 5.0, "construction": "straw"}, None,
     "unknown construction 'straw'"),
    ({"between": ["a", "outside"], "construction": "partition-light"}, None, "missing 'area'"),
    ({"between": ["a", "outside"], "area": 5.0, "construction": "partition-light",
      "R": [1, 1, 1], "C": [1, 1]}, None, "not both"),
    ({"between": ["a", "outside"], "area": 5.0, "construction": "x"},
     {"x": {"u_value": 1.0}}, "constructions.x: missing 'heat_capacity'"),
    ({"between": ["a", "outside"], "area": 5.0, "construction": "x"},
     {"x": {"u_value": -1.0, "heat_capacity": 1.0}}, "u_value"),
])
def test_construction_errors_name_the_entry(wall, cons, match):
    with pytest.raises(SpecError, match=match):
        _spec([wall], cons)


def test_the_table_is_physical():
    for name, (u, k, layers) in CONSTRUCTIONS.items():
        assert 0.1 <= u <= 6.0, name            # [W/(m² K)] with films
        assert 5e3 <= k <= 1e6, name            # [J/(m² K)]
        assert layers
