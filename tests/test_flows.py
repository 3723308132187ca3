"""Directed air flows (ventilation air passed on from room to room, issue 20)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from thermctl.data.inputs import network_inputs
from thermctl.errors import DataError, SpecError
from thermctl.local import local_problems
from thermctl.model import ThermalModel
from thermctl.network import ThermalNetwork
from thermctl.spec import Flow, spec_from_dict

R_WALL = (0.01, 0.02, 0.01)         # [K/W]: UA = 25 W/K
C_WALL = (1e5, 1e5)


def _spec(flows=None):
    d = {"zones": {"a": {"volume": 50.0}, "b": {"volume": 30.0}, "c": {"volume": 20.0}},
         "boundary": ["outside"],
         "walls": [{"between": [z, "outside"], "R": list(R_WALL), "C": list(C_WALL)}
                   for z in ("a", "b", "c")] + [{"between": ["a", "b"], "R": [0.1, 0.1, 0.1],
                                                 "C": [1e4, 1e4]}],
         "distances": [{"between": ["a", "b"], "d": 3.0}]}
    if flows is not None:
        d["flows"] = flows
    return spec_from_dict(d)


def test_spec_reads_checks_and_writes_flows():
    s = _spec([{"from": "a", "to": "b", "of": "a"},
               {"from": "b", "to": "c", "fraction": 0.5, "column": "vent"}])
    assert s.flows == (Flow("a", "b", 1.0, "a", None), Flow("b", "c", 0.5, None, "vent"))
    assert spec_from_dict(s.to_dict()).flows == s.flows
    for bad, match in [({"from": "x", "to": "b", "of": "a"}, "unknown node 'x'"),
                       ({"from": "a", "to": "outside", "of": "a"}, "is not a zone"),
                       ({"from": "a", "to": "b"}, "exactly one"),
                       ({"from": "a", "to": "b", "of": "a", "column": "v"}, "exactly one"),
                       ({"from": "a", "to": "b", "of": "a", "fraction": -1}, "fraction"),
                       ({"from": "a", "to": "a", "of": "a"}, "both 'a'"),
                       ({"to": "b", "of": "a"}, "missing 'from'")]:
        with pytest.raises(SpecError, match=match):
            _spec([bad])


def _frame(n=5):
    idx = pd.date_range("2024-01-01", periods=n, freq="5min")
    return pd.DataFrame({"T:a": 21.0, "T:b": 19.0, "T:c": 18.0, "T:outside": 0.0,
                         "ms:a": 0.04, "Ts:a": 30.0, "ms:b": 0.01, "Ts:b": 16.0,
                         "vent": 0.02}, index=idx)


def test_flows_join_the_zones_supply_air_at_the_mixed_temperature():
    s = _spec([{"from": "a", "to": "b", "of": "a", "fraction": 0.5},
               {"from": "b", "to": "c", "column": "vent"}])
    net = ThermalNetwork(s)
    col = dict(zip(net.input_names, network_inputs(_frame(), net)[0]))
    # b: its own 0.01 kg/s at 16 °C and half of a's 0.04 kg/s at a's 21 °C
    assert col["ms[b]"] == pytest.approx(0.03)
    assert col["Ts[b]"] == pytest.approx((0.01 * 16.0 + 0.02 * 21.0) / 0.03)
    # c: no supply of its own, 0.02 kg/s of b's air at 19 °C
    assert col["ms[c]"] == pytest.approx(0.02) and col["Ts[c]"] == pytest.approx(19.0)
    # a keeps its own supply (the air it passes on leaves at its temperature)
    assert col["ms[a]"] == pytest.approx(0.04) and col["Ts[a]"] == pytest.approx(30.0)
    # without flows: the same columns give b its own supply only
    col0 = dict(zip(net.input_names, network_inputs(_frame(), ThermalNetwork(_spec()))[0]))
    assert col0["ms[b]"] == pytest.approx(0.01) and col0["Ts[b]"] == pytest.approx(16.0)


def test_steady_state_matches_the_hand_balance():
    """a supplied with 0.04 kg/s at 30 °C passes it all to b: in steady state
    b's balance is UA_b (T_o − T_b) + UA_ab (T_a − T_b) + ṁ cp (T_a − T_b) = 0."""
    s = _spec([{"from": "a", "to": "b", "of": "a"}])
    net = ThermalNetwork(s)
    model = ThermalModel(net)
    f = _frame()
    f["ms:b"] = 0.0
    # T_a is an input of b's flow: take the value the steady state gives a
    U = network_inputs(f, net)
    x = model.steady_state(U[0])
    ta = x[net.zones.index("a")]
    f["T:a"] = ta
    x = model.steady_state(network_inputs(f, net)[0])
    tb, ta2 = x[net.zones.index("b")], x[net.zones.index("a")]
    ua, ua_ab, mcp = 1 / sum(R_WALL), 1 / 0.3, 0.04 * s.cp
    # the wall sees a's state, the flow carries the measured (input) T_a
    expect = (ua * 0.0 + ua_ab * ta2 + mcp * ta) / (ua + ua_ab + mcp)
    assert tb == pytest.approx(expect, abs=1e-9)
    assert tb > ta2 * ua_ab / (ua + ua_ab) + 5.0     # the flow warms b by several K


def test_missing_columns_and_local_problems():
    s = _spec([{"from": "a", "to": "b", "column": "vent"}])
    f = _frame().drop(columns=["vent"])
    with pytest.raises(DataError, match="'vent' missing"):
        network_inputs(f, ThermalNetwork(s))
    p = [p for p in local_problems(s, _frame().columns) if p.zone == "b"][0]
    assert p.spec.flows == s.flows and "vent" in p.columns and "T:a" in p.columns


def test_export_operating_point_sees_the_flows():
    from thermctl.data import read_measurements
    from thermctl.export.point import supply_zones, typical_inputs
    s = _spec([{"from": "b", "to": "c", "of": "a", "fraction": 0.5}])
    f = _frame(n=24).reset_index(names="time").drop(columns=["vent"])
    meas = read_measurements(f, s, name="flows")
    assert supply_zones(meas) == ["a", "b", "c"]
    op = typical_inputs(meas, ThermalNetwork(s))
    assert op["ms"]["c"] == pytest.approx(0.02) and op["Ts"]["c"] == pytest.approx(19.0)
