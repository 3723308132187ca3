"""ConvectionParameters: the one place parameter names are spelled and read (issue 18)."""

import numpy as np
import pytest

from thermctl.model import ConvectionParameters as CP


@pytest.mark.parametrize("key, kind, edge, rbar, per_edge", [
    ("rbar_v", "rbar_v", None, True, False),
    ("rbar_v[air:a-b]", "rbar_v", "air:a-b", True, True),
    ("c_v[air:a-b]", "c_v", "air:a-b", False, False),
    ("tau0", "tau0", None, False, False),
    ("sigma_q[r1]", "sigma_q", "r1", False, False),
])
def test_names_are_read_back(key, kind, edge, rbar, per_edge):
    assert CP.kind_of(key) == kind and CP.edge_of(key) == edge
    assert CP.is_rbar(key) is rbar
    assert CP.is_rbar(key, per_edge=True) is (rbar and per_edge)
    assert CP.is_rbar(key, per_edge=False) is (rbar and not per_edge)


def test_keys_round_trip_and_tau0():
    cp = CP.from_tau0(("air:a-b", "air:b-c"), [2.0, 4.0], 8.0)
    np.testing.assert_allclose(cp.c_v, [4.0, 2.0])
    d = cp.as_dict(("rbar_v", "tau0"))
    assert all(CP.edge_of(k) in cp.edges for k in d)
    assert [k for k in d if CP.is_rbar(k, per_edge=True)] == [CP.key(e) for e in cp.edges]
