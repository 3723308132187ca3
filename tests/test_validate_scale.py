"""Validation measures at building scale: step responses without dense n × n exponentials."""

import numpy as np
import pytest

from thermctl import validate as V
from thermctl.errors import ModelError
from thermctl.model import ThermalModel, zoh
from thermctl.network import ThermalNetwork
from thermctl.testbed.buildings import corridor_floor_spec

H = (0.5, 1.0, 6.0, 24.0)


@pytest.fixture(scope="module")
def corridor_model():
    """A 2-floor corridor building (26 zones, 4 offices a side), its true air paths."""
    spec, edges = corridor_floor_spec(6, floors=2, seed=3)
    model = ThermalModel(ThermalNetwork(spec, edges))
    ms = np.linspace(0.0, 0.05, model.network.n_zones)     # some zones without supply air
    return model, ms


def _zoh_reference(model, ms, horizons_h, power=100.0):
    """The step responses the way they were computed before: ``Γ`` of the 2n-square ``zoh``."""
    net = model.network
    A_u, _ = model.affine(net.input_vector(ms=dict(zip(net.zones, ms))))
    nz = net.n_zones
    BQ = np.zeros((net.n_states, nz))
    BQ[np.arange(nz), np.arange(nz)] = model.sym.inv_cz
    return np.stack([(zoh(A_u, 3600.0 * t)[1] @ BQ)[:nz] * power for t in horizons_h])


def test_exact_equals_the_zoh_formula(corridor_model):
    model, ms = corridor_model
    G = V.step_response_matrix(model, ms, H, method="exact")
    ref = _zoh_reference(model, ms, H)
    assert G.shape == (len(H), model.network.n_zones, model.network.n_zones)
    np.testing.assert_allclose(G, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    # heat into a zone warms that zone most, and more the longer it is on
    diag = np.einsum("hii->hi", G)
    assert np.all(diag > 0) and np.all(np.diff(diag, axis=0) > 0)


def test_radau_agrees_with_the_exponential(corridor_model):
    model, ms = corridor_model
    ex = V.step_response_matrix(model, ms, H, method="exact")
    ra = V.step_response_matrix(model, ms, H, method="radau")
    err = V.relative_error(ra, ex)
    # measured on this building: 7e-6, 7e-7, 7e-6, 1e-7 at 0.5, 1, 6, 24 h (5-min sub-steps
    # over the first hour instead of 2-min: 1e-4 at 0.5 h)
    assert np.all(err < 5e-5), err
    # unsorted and repeated horizons come back in the order asked
    ra2 = V.step_response_matrix(model, ms, (6.0, 1.0, 6.0), method="radau")
    np.testing.assert_allclose(ra2[[1, 0, 2]], ra[[1, 2, 2]], rtol=1e-12)


def test_auto_integrates_above_the_limit(corridor_model, monkeypatch):
    model, ms = corridor_model
    calls = []
    real = V._responses_radau
    monkeypatch.setattr(V, "_responses_radau", lambda *a, **k: calls.append(1) or real(*a, **k))
    V.step_response_matrix(model, ms, (1.0,))
    assert not calls                        # 26 zones: exact
    monkeypatch.setattr(V, "EXACT_LIMIT", 10)
    V.step_response_matrix(model, ms, (1.0,))
    assert calls


def test_unknown_method_is_refused(corridor_model):
    model, ms = corridor_model
    with pytest.raises(ModelError, match="method"):
        V.step_response_matrix(model, ms, (1.0,), method="euler")
