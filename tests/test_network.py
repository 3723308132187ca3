"""ThermalNetwork: edges, ordering and names, links, errors."""

from __future__ import annotations

import numpy as np
import pytest

from thermctl.errors import ModelError, SpecError
from thermctl.network import ThermalNetwork
from thermctl.spec import load_spec, spec_from_dict

WALL_NAMES = ["r1-ext", "r1-window", "r2-outside", "r3-outside", "r1-hallway", "r2-hallway",
              "r3-hallway", "r1-r2", "hallway-ground"]


def test_edges_in_spec_order_then_convection(small_network):
    net = small_network
    assert [e.name for e in net.edges] == WALL_NAMES + ["air:r1-r3"]
    assert [e.kind for e in net.edges] == ["conduction"] * 9 + ["convection"]
    conv = net.convection_edges[0]
    assert (conv.a, conv.b, conv.d, conv.R, conv.C) == ("r1", "r3", 9.0, None, None)
    assert net.convection_pairs == [("r1", "r3", 9.0)]
    assert len(net.conduction_edges) == 9
    for e, w in zip(net.conduction_edges, net.spec.walls):
        assert (e.a, e.b, e.R, e.C) == (w.a, w.b, w.R, w.C)


def test_state_input_output_names_documented_order(small_network):
    net = small_network
    zones = ["r1", "r2", "r3", "hallway"]
    states = [f"T[{z}]" for z in zones]
    for e in WALL_NAMES + ["air:r1-r3"]:
        states += [f"x[{e},1]", f"x[{e},2]"]
    assert net.state_names == states
    assert net.n_states == 4 + 2 * 10 == len(states)
    inputs = ([f"ms[{z}]" for z in zones] + [f"Ts[{z}]" for z in zones]
              + ["T[outside]", "T[ground]"] + [f"Q[{z}]" for z in zones])
    assert net.input_names == inputs
    assert net.n_inputs == len(inputs) == 14
    assert net.output_names == [f"T[{z}]" for z in zones]
    sl = net.input_slices()
    for group in ("ms", "Ts", "T", "Q"):
        names = net.input_names[sl[group]]
        assert all(n.startswith(group + "[") for n in names)
    assert sl["Q"].stop == net.n_inputs


def test_convection_distance_explicit_and_sorted_ends(small_spec):
    net = ThermalNetwork(small_spec, convection=[("r3", "r2"), ("r1", "r2", 6.5)])
    assert [(e.name, e.a, e.b, e.d) for e in net.convection_edges] == [
        ("air:r2-r3", "r2", "r3", 5.0), ("air:r1-r2", "r1", "r2", 6.5)]


def test_parallel_walls_get_distinct_edges(small_spec_dict):
    for w in small_spec_dict["walls"]:
        w.pop("name", None)
    net = ThermalNetwork(spec_from_dict(small_spec_dict))
    assert [e.name for e in net.edges][:2] == ["r1-outside", "r1-outside#2"]
    assert len(set(net.state_names)) == net.n_states
    assert net.neighbours("r1") == ["hallway", "outside", "r2"]


def test_real_house_parallel_walls(twinhouse_spec_path):
    spec = load_spec(twinhouse_spec_path)
    net = ThermalNetwork(spec, [(d.a, d.b) for d in spec.distances])
    names = [e.name for e in net.edges]
    assert len(set(names)) == len(names) == 44 + 9
    assert "living-outside#2" in names
    assert net.n_states == 7 + 2 * 53
    assert len(set(net.state_names)) == net.n_states
    # a parallel pair is two independent chains: 6 links with the two walls' own R
    ends, R, conv = net.links()
    k = names.index("living-outside#2")
    np.testing.assert_allclose(R[3 * k:3 * k + 3], spec.walls[1].R)


def test_links_and_capacitances(small_network):
    net = small_network
    ends, R, conv = net.links()
    assert ends.shape == (3 * 10, 2) and R.shape == conv.shape == (30,)
    nz, ns = 4, net.n_states
    # first wall: r1 -> s1 -> s2 -> outside (boundary node 0 has index n_states)
    np.testing.assert_array_equal(ends[:3], [[0, nz], [nz, nz + 1], [nz + 1, ns]])
    np.testing.assert_allclose(R[:3], [0.02, 0.06, 0.02])
    # hallway-ground: hallway (3) -> ... -> ground (boundary 1)
    np.testing.assert_array_equal(ends[3 * 8 + 2], [nz + 17, ns + 1])
    # the convection edge: r1 (0) ... r3 (2), resistance NaN (parameter), edge index 0
    np.testing.assert_array_equal(ends[27:], [[0, nz + 18], [nz + 18, nz + 19], [nz + 19, 2]])
    assert np.isnan(R[27:]).all() and (conv[27:] == 0).all() and (conv[:27] == -1).all()
    cap = net.fixed_capacitances()
    assert cap[2] == 5.0e5
    np.testing.assert_allclose(cap[nz:nz + 2], [2.0e6, 2.0e6])
    assert np.isnan(cap[-2:]).all() and np.isfinite(cap[:-2]).all()
    np.testing.assert_array_equal(net.conv_state_edge(), [-1] * 22 + [0, 0])


def test_graph_and_neighbours(small_network):
    net = small_network
    assert net.neighbours("r1") == ["hallway", "outside", "r2", "r3"]  # r3 via the air path
    assert net.neighbours("hallway") == ["ground", "r1", "r2", "r3"]
    assert net.graph.number_of_edges("r1", "outside") == 2
    assert net.graph.nodes["hallway"] == {"kind": "zone", "measured": False}
    assert net.graph.nodes["ground"]["kind"] == "boundary"


def test_with_convection_and_conduction_only(small_network):
    net2 = small_network.with_convection([("r2", "r3")])
    assert [e.name for e in net2.convection_edges] == ["air:r2-r3"]
    assert net2.spec is small_network.spec
    net0 = small_network.conduction_only()
    assert net0.convection_edges == [] and net0.n_states == 4 + 18
    assert [e.name for e in small_network.convection_edges] == ["air:r1-r3"]  # unchanged
    assert "1 convection" in repr(small_network) and "24 states" in repr(small_network)


def test_input_vector(small_network):
    net = small_network
    u = net.input_vector(ms={"r2": 0.1}, Ts=14.0, T={"outside": -3.0, "ground": 9.0},
                         Q={"hallway": 250.0})
    expected = dict.fromkeys(net.input_names, 0.0)
    expected.update({"ms[r2]": 0.1, "T[outside]": -3.0, "T[ground]": 9.0, "Q[hallway]": 250.0})
    expected.update({f"Ts[{z}]": 14.0 for z in net.zones})
    np.testing.assert_array_equal(u, [expected[n] for n in net.input_names])
    np.testing.assert_array_equal(net.input_vector(T=4.0)[8:10], [4.0, 4.0])


@pytest.mark.parametrize("kwargs, match", [
    ({"ms": {"r9": 0.1}}, r"ms: unknown node\(s\) \['r9'\]; expected \['r1', 'r2', 'r3', "
                          r"'hallway'\]"),
    ({"T": {"outside": 1.0}}, r"T: missing value\(s\) for \['ground'\]"),
    ({"T": {"outside": 1.0, "ground": 2.0, "attic": 3.0}}, r"T: unknown node\(s\) \['attic'\]"),
], ids=["unknown-zone", "missing-boundary", "unknown-boundary"])
def test_input_vector_errors(small_network, kwargs, match):
    with pytest.raises(ModelError, match=match):
        small_network.input_vector(**kwargs)


@pytest.mark.parametrize("convection, match", [
    ([("r2", "hallway")], r"convection edge hallway-r2: small\.yaml gives no distance for this "
                          r"pair; add it under 'distances' or pass d"),
    ([("r1", "r7")], r"convection edge r1-r7: 'r7' is not a zone of small\.yaml; zones are "
                     r"\['r1', 'r2', 'r3', 'hallway'\]"),
    ([("outside", "ground", 3.0)], r"'ground' is not a zone of small\.yaml"),
    ([("r1", "r3"), ("r3", "r1")], r"convection edge r1-r3 given twice"),
    ([("r1", "r2"), ("r1", "r2", 5.0)], r"convection edge r1-r2 given twice"),
    ([("r2", "r2", 3.0)], r"convection edge names zone 'r2' twice"),
    ([("r1", "r2", 0.0)], r"convection edge r1-r2: distance must be > 0 \[m\], found 0\.0"),
    ([("r1", "r2", -2.0)], r"convection edge r1-r2: distance must be > 0 \[m\], found -2\.0"),
    ([("r1",)], r"convection edge must be \(a, b\) or \(a, b, d\), found \('r1',\)"),
], ids=["no-distance", "unknown-zone", "boundary-node", "twice", "twice-with-d",
        "same-zone", "d-zero", "d-negative", "bad-tuple"])
def test_network_errors(small_spec, convection, match):
    with pytest.raises(SpecError, match=match):
        ThermalNetwork(small_spec, convection=convection)


def test_air_path_to_a_boundary_node_needs_a_length(small_spec):
    """A local problem's measured neighbour is a boundary node: an air path to it is
    allowed with its length given, refused without."""
    net = ThermalNetwork(small_spec, [("r1", "outside", 3.0)])
    e = net.convection_edges[0]
    assert (e.a, e.b, e.d) == ("outside", "r1", 3.0)
    assert net.n_states == small_network_states(small_spec) + 2
    with pytest.raises(SpecError, match="'outside' is not a zone"):
        ThermalNetwork(small_spec, [("r1", "outside")])


def small_network_states(spec):
    return ThermalNetwork(spec).n_states
