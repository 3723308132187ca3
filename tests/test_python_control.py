"""python-control, idiomatically: exported and reduced systems are used by signal name, and
``thermctl.load_statespace`` gives a StateSpace that prints its operating point."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest
from typer.testing import CliRunner

import thermctl
from thermctl.cli import app
from thermctl.errors import ModelError
from thermctl.export import OperatingStateSpace, input_signals, statespace
from thermctl.io import save_model
from thermctl.model import ThermalModel
from thermctl.network import ThermalNetwork
from thermctl.reduce import balanced_reduction, kron, lumped, structured
from thermctl.testbed.buildings import pugh_hall_spec

OP = dict(ms={"*": 0.05, "hallway": 0.0}, Ts=30.0, T={"*": 21.0, "outside": -5.0})
DAY = 86400.0


@pytest.fixture(scope="module")
def pugh():
    spec, edges = pugh_hall_spec()
    model = ThermalModel(ThermalNetwork(spec, edges), 3.36e-4, 1.19e3)
    op = model.operating_point(**OP)
    sys_, _ = statespace(model, op)
    return model, op, sys_


def _outside_dc(model):
    """Independent reference: steady state at T[outside] + 1 K minus the one at op [K/K]."""
    up = model.operating_point(**{**OP, "T": {"*": 21.0, "outside": -4.0}}).x
    return up - model.operating_point(**OP).x


def test_export_carries_the_signal_names(pugh):
    model, _, sys_ = pugh
    net = model.network
    assert sys_.state_labels == net.state_names and sys_.nstates == 55
    assert sys_.input_labels == net.input_names and sys_.input_labels[0] == "ms[r240]"
    assert sys_.output_labels == [f"T[{z}]" for z in net.zones]
    assert sys_.dt == 0


def test_step_response_by_name(pugh):
    """``sys[output, input]`` picks signals by name; its DC gain and 20-day step equal the
    steady-state change of the nonlinear model for +1 K outside."""
    model, _, sys_ = pugh
    ref = _outside_dc(model)[0]                     # T[r240]
    sub = sys_["T[r240]", "T[outside]"]
    assert sub.input_labels == ["T[outside]"] and sub.output_labels == ["T[r240]"]
    np.testing.assert_allclose(ct.dcgain(sub), ref, rtol=1e-9)
    resp = ct.step_response(sub, np.linspace(0, 20 * DAY, 401))
    np.testing.assert_allclose(resp.outputs[-1], ref, rtol=1e-6)   # 20 days: settled
    assert 0.05 < ref < 0.5


def test_forced_response_with_inputs_by_name(pugh):
    """``input_signals`` builds U from names; the response to a 1 K outside step equals the
    step response of the same channel, and to_pandas() labels the columns by name."""
    _, _, sys_ = pugh
    T = np.linspace(0, 2 * DAY, 97)
    U = input_signals(sys_, T, {"T[outside]": 1.0})
    assert U.shape == (sys_.ninputs, T.size) and U[sys_.input_labels.index("T[outside]")].min() == 1
    forced = ct.forced_response(sys_, T, U)
    step = ct.step_response(sys_["T[r243]", "T[outside]"], T)
    i = sys_.output_labels.index("T[r243]")
    np.testing.assert_allclose(forced.outputs[i], step.outputs, rtol=1e-9, atol=1e-12)
    df = forced.to_pandas()
    assert "T[r243]" in df.columns and "T[outside]" in df.columns
    with pytest.raises(ModelError, match=r"unknown input\(s\) \['T\[moon\]'\]"):
        input_signals(sys_, T, {"T[moon]": 1.0})
    with pytest.raises(ModelError, match=r"ms\[r240\] has shape \(3,\), expected \(97,\)"):
        input_signals(sys_, T, {"ms[r240]": [1.0, 2.0, 3.0]})


@pytest.mark.parametrize("reduce", [
    lambda m, op: structured(m, op, order=14),
    lambda m, op: kron(m, op),
    lambda m, op: lumped(m, op),
    lambda m, op: balanced_reduction(m, op, order=10),
], ids=["structured", "kron", "lumped", "balanced"])
def test_reduced_models_keep_the_names(pugh, reduce):
    """Every reduction keeps the inputs and outputs by name, so the same by-name code runs on
    it; all four are exact at DC (lumped by construction: the Kron conductances)."""
    model, op, sys_ = pugh
    red = reduce(model, op).sys
    assert red.input_labels == sys_.input_labels and red.output_labels == sys_.output_labels
    assert red.nstates < sys_.nstates
    gain = ct.dcgain(red["T[r240]", "T[outside]"])
    np.testing.assert_allclose(gain, _outside_dc(model)[0], rtol=1e-6)


def test_load_statespace_prints_its_operating_point(tmp_path, pugh):
    model, _, _ = pugh
    save_model(model, tmp_path / "model.json")
    res = CliRunner().invoke(app, ["export", str(tmp_path / "model.json"), "--statespace",
                                   str(tmp_path / "ss.npz"), "--op", "ms=0.05", "--op",
                                   "ms[hallway]=0", "--op", "Ts=30", "--op", "T=21", "--op",
                                   "T[outside]=-5", "--dt", "600"])
    assert res.exit_code == 0, res.output
    sys_ = thermctl.load_statespace(tmp_path / "ss.npz")
    assert isinstance(sys_, OperatingStateSpace) and isinstance(sys_, ct.StateSpace)
    assert sys_.dt == 600.0 and sys_.input_labels[0] == "ms[r240]"
    text = str(sys_)
    assert "operating point (the model is in deviations from it):" in text
    assert "ms[r240] = 0.05 kg/s (given)" in text and "T[outside] = -5 °C (given)" in text
    assert "T[r240] = " in text and "wall and air-path states" in text
    op = sys_.operating_point()
    np.testing.assert_allclose(op["T[r240]"], model.operating_point(**OP).x[0], rtol=1e-12)
    # still a StateSpace: discrete step by name, DC gain = the continuous one
    np.testing.assert_allclose(ct.dcgain(sys_["T[r240]", "T[outside]"]), _outside_dc(model)[0],
                               rtol=1e-7)


def test_docs_snippet_runs(docs_snippets, tmp_path):
    ns = docs_snippets("python-control.md")
    assert (tmp_path / "ss.npz").is_file() and ns["loaded"].nstates == 55
