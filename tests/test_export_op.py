"""Issue 22, items 4, 7 and 8: the export's operating point, disturbance inputs and Kalman
filter; the first lines of Python in the README and quick start; the documentation."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from thermctl.cli import app
from thermctl.cli.export import parse_operating_point
from thermctl.errors import ModelError
from thermctl.io import load_statespace, save_model
from thermctl.model import ThermalModel

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()

# the grey-box noise model as `thermctl identify` stores it (meta.greybox.params)
PARAMS = {"rbar_v": 3.4e-4, "tau0": 2.0, "sigma_v": 0.05, "sigma_q": 7.0, "sigma_phi": 0.6,
          "aperture[r1,south]": 2.5, "aperture[r2,south]": 1.0}


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture
def data_csv(tmp_path):
    """Two days of 5-min data of the small building: supply air in r1 and r2 only."""
    t = pd.date_range("2024-01-08", periods=576, freq="5min", tz="Europe/Zurich")
    h = t.hour.to_numpy()
    on = (h >= 7) & (h < 19)
    df = pd.DataFrame({
        "time": t.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "T:r1": 21.0, "T:r2": 21.5, "T:r3": 20.5, "T:outside": 2.0 + (h - 12) / 6,
        "T:ground": 10.0,
        "ms:r1": np.where(on, 0.04, 0.0), "Ts:r1": np.where(on, 16.0, 21.0),
        "ms:r2": np.where(on, np.where(h < 12, 0.02, 0.06), 0.0), "Ts:r2": 14.0,
        "solar:south": np.clip(400 * np.sin((h - 6) / 12 * np.pi), 0, None),
    })
    path = tmp_path / "data.csv"
    df.to_csv(path, index=False)
    return path


@pytest.fixture
def model_json(small_network, tmp_path):
    path = tmp_path / "model.json"
    save_model(ThermalModel(small_network, meta={"greybox": {"params": dict(PARAMS)}}), path)
    return path


def _meas(small_network, path):
    from thermctl.data import read_measurements
    return read_measurements(path, small_network.spec)


# ------------------------------------------------------------------ item 4: operating point
def test_op_scalar_and_per_node_combine():
    assert parse_operating_point(["T=21", "T[outside]=-5"]) == {"T": {"*": 21.0, "outside": -5.0}}
    assert parse_operating_point(["T[outside]=-5", "T=21"]) == {"T": {"*": 21.0, "outside": -5.0}}
    assert parse_operating_point(["ms=0.05", "Ts=14"]) == {"ms": 0.05, "Ts": 14.0}


def test_operating_point_star_and_missing_boundary(small_model):
    net = small_model.network
    op = small_model.operating_point(T={"*": 21.0, "outside": -5.0})
    u = dict(zip(net.input_names, op.u))
    assert u["T[outside]"] == -5.0 and u["T[ground]"] == 21.0
    with pytest.raises(ModelError, match=r"ground.*'\*'"):
        small_model.operating_point(T={"outside": 5.0})


def test_cli_per_node_override_and_message_as_written(model_json, tmp_path):
    res = run("export", model_json, "--statespace", tmp_path / "ss.npz",
              "--op", "T=21", "--op", "T[outside]=-5")
    assert res.exit_code == 0, res.output
    sys, ex = load_statespace(tmp_path / "ss.npz")
    u = dict(zip(sys.input_labels, ex["u_op"]))
    assert u["T[outside]"] == -5.0 and u["T[ground]"] == 21.0
    assert ex["info"]["operating_point"]["inputs"]["T"] == {"outside": -5.0, "ground": 21.0}
    # rich markup must not eat "[outside]" out of an error message
    res = run("export", model_json, "--statespace", tmp_path / "ss2.npz",
              "--op", "T[outside]=1", "--op", "T[outside]=2")
    assert res.exit_code == 2 and "T[outside]=2" in res.output


def test_default_flow_only_where_the_data_have_supply_air(model_json, data_csv, tmp_path,
                                                          small_network):
    res = run("export", model_json, "--statespace", tmp_path / "ss.npz", "--data", data_csv)
    assert res.exit_code == 0, res.output
    assert "operating point" in res.output and "r1=0.04 (data)" in res.output
    sys, ex = load_statespace(tmp_path / "ss.npz")
    point = ex["info"]["operating_point"]
    ms = point["inputs"]["ms"]
    # mean while on: r2 runs 5 h at 0.02 and 7 h at 0.06 kg/s
    assert ms["r1"] == pytest.approx(0.04) and ms["r2"] == pytest.approx((5 * 0.02 + 7 * 0.06) / 12)
    assert ms["r3"] == 0.0 and ms["hallway"] == 0.0
    assert point["supply_zones"] == ["r1", "r2"] and point["source"]["ms"]["r1"] == "data"
    assert point["inputs"]["Ts"]["r1"] == pytest.approx(16.0)
    B = pd.DataFrame(sys.B, index=sys.state_labels, columns=sys.input_labels)
    assert B.loc["T[r1]", "Ts[r1]"] > 0 and B.loc["T[r2]", "Ts[r2]"] > 0
    assert B.loc["T[r3]", "Ts[r3]"] == 0 and B.loc["T[hallway]", "Ts[hallway]"] == 0
    # a single ms goes to the zones with supply air only
    res = run("export", model_json, "--statespace", tmp_path / "ss.npz", "--data", data_csv,
              "--op", "ms=0.05")
    assert res.exit_code == 0, res.output
    _, ex = load_statespace(tmp_path / "ss.npz")
    ms = ex["info"]["operating_point"]["inputs"]["ms"]
    assert (ms["r1"], ms["r2"], ms["r3"], ms["hallway"]) == (0.05, 0.05, 0.0, 0.0)
    assert any("only" in n for n in ex["info"]["operating_point"]["notes"])


def test_no_data_says_loudly_that_flow_is_zero(model_json, tmp_path):
    res = run("export", model_json, "--statespace", tmp_path / "ss.npz", "--op", "T=5")
    assert res.exit_code == 0, res.output
    assert "NOTE: ms = 0 kg/s in every zone" in res.output
    _, ex = load_statespace(tmp_path / "ss.npz")
    assert any("ms = 0 kg/s" in n for n in ex["info"]["operating_point"]["notes"])
    assert np.allclose(ex["u_op"][:4], 0.0)


# ------------------------------------------------------------------ item 4: disturbances, Kalman filter
def test_disturbance_inputs_and_kalman_filter_exported(model_json, data_csv, tmp_path,
                                                       small_network):
    from thermctl.estimate.likelihood.kalman import discretize_np

    res = run("export", model_json, "--statespace", tmp_path / "ss.npz", "--data", data_csv,
              "--dt", 600, "--casadi", tmp_path / "f.casadi")
    assert res.exit_code == 0, res.output
    sys, ex = load_statespace(tmp_path / "ss.npz")
    assert sys.input_labels[-1] == "solar[south]"
    cz = 1.0 / np.asarray(ThermalModel(small_network).sym.inv_cz)
    # continuous E column: aperture / C_z; the file holds the ZOH-discretised one
    from thermctl.export import disturbances
    E = disturbances(ThermalModel(small_network, meta={"greybox": {"params": PARAMS}})).E
    assert E[0, 0] == pytest.approx(2.5 / cz[0]) and E[1, 0] == pytest.approx(1.0 / cz[1])
    assert E[2, 0] == 0.0
    kf = ex["kalman"]
    meas = ["r1", "r2", "r3"]
    assert kf["states"][-3:] == [f"d[{z}]" for z in meas]
    assert kf["outputs"] == [f"T[{z}]" for z in meas]
    assert np.allclose(kf["R"], 0.05 ** 2 * np.eye(3))
    assert kf["Qc"][0, 0] == pytest.approx((7.0 / cz[0]) ** 2)
    assert kf["Qc"][-1, -1] == pytest.approx(0.6 ** 2)
    # exact noise discretisation (independent modal formula) and a stable filter
    _, _, Qd = discretize_np(kf["A"], kf["B"], kf["Qc"], 600.0)
    assert np.allclose(kf["Qd"], Qd, rtol=1e-8, atol=1e-12 * np.abs(Qd).max())
    F = kf["Phi"] - kf["Phi"] @ kf["K"] @ kf["C"]
    assert np.abs(np.linalg.eigvals(F)).max() < 1.0
    doc = json.loads((tmp_path / "f.casadi.json").read_text())
    assert doc["disturbances"]["names"] == ["solar[south]"]
    assert doc["noise"]["R_diag"] == pytest.approx([0.0025] * 3)
    assert doc["operating_point"]["inputs"]["ms"]["r1"] == pytest.approx(0.04)


def test_describe_summarises_a_long_input_and_lists_a_short_one(small_model):
    from thermctl.export import export_point
    from thermctl.export import point as P

    pt = export_point(small_model, {"ms": 0.05, "Ts": 14.0, "T": {"*": 10.0, "outside": -5.0}})
    full = pt.describe()
    nz = small_model.network.n_zones
    assert full.count("(given)") == 2 * nz + 2           # ms, Ts per zone, T per boundary node
    short = pt.describe(max_nodes=2)
    ms_line = next(line for line in short.splitlines() if line.startswith("  ms"))
    assert ms_line.startswith(f"  ms [kg/s]: {nz} nodes, 0.05 to 0.05 (median 0.05), {nz} given")
    assert ms_line.count("=") == 3 and "every value in the exported file" in ms_line
    t_line = next(line for line in short.splitlines() if line.startswith("  T "))
    assert t_line == "  T [°C]: outside=-5 (given), ground=10 (given)"   # 2 nodes: listed
    t_one = next(line for line in pt.describe(max_nodes=1).splitlines() if line.startswith("  T "))
    assert t_one.startswith("  T [°C]: 2 nodes, -5 to 10 (median 2.5), 2 given")
    assert P.DESCRIBE_NODES >= nz                       # a small building is listed in full
    assert pt.to_dict()["inputs"]["ms"] == {z: 0.05 for z in small_model.network.zones}


def test_model_without_noise_model_says_so(small_network, tmp_path):
    save_model(ThermalModel(small_network), tmp_path / "m.json")
    res = run("export", tmp_path / "m.json", "--statespace", tmp_path / "ss.npz", "--op", "T=5")
    assert res.exit_code == 0, res.output
    assert "no Kalman filter" in res.output
    assert "kalman" not in load_statespace(tmp_path / "ss.npz")[1]


# ------------------------------------------------------------------ item 7: first lines of Python
def _python_blocks(path):
    return re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.S)


def _demo_workdir(tmp_path, monkeypatch):
    """building.yaml of the demo building and an out/model.json identified-like from it."""
    from thermctl.network import ThermalNetwork
    from thermctl.testbed.buildings import pugh_hall_spec

    spec, _ = pugh_hall_spec()
    (tmp_path / "building.yaml").write_text(yaml.safe_dump(spec.to_dict()))
    params = {k: v for k, v in PARAMS.items() if not k.startswith("aperture")}
    meta = {"greybox": {"params": {**params, "aperture[r240,south]": 1.0}}}
    save_model(ThermalModel(ThermalNetwork(spec, [("r240", "r243")]), meta=meta),
               tmp_path / "out" / "model.json")
    monkeypatch.chdir(tmp_path)


@pytest.mark.parametrize("doc", ["README.md", "docs/quickstart.md"])
def test_python_snippets_run_on_the_demo_building(doc, tmp_path, monkeypatch):
    _demo_workdir(tmp_path, monkeypatch)
    blocks = _python_blocks(ROOT / doc)
    assert blocks, f"{doc} has no python block"
    for code in blocks:
        exec(compile(code, doc, "exec"), {})


def test_docs_say_how_to_call_what_they_show():
    text = (ROOT / "README.md").read_text() + (ROOT / "docs" / "quickstart.md").read_text()
    assert "p_value" in text                      # cm.p is a symbol; the number is p_value
    cli = (ROOT / "docs" / "cli.md").read_text()
    assert "f(x, u)" in cli and "p_value" in cli  # the CLI's f has p built in
    mpc = (ROOT / "docs" / "mpc.md").read_text() + (ROOT / "docs" / "operating-point.md").read_text()
    assert "step_response" in mpc and "input_labels.index" in mpc


# ------------------------------------------------------------------ item 8: documentation
def test_docs_config_math_api_and_pages():
    cfg = yaml.safe_load((ROOT / "mkdocs.yml").read_text().replace("!!python", "#"))
    assert any("mathjax" in str(js).lower() for js in cfg.get("extra_javascript", []))
    nav = json.dumps(cfg["nav"])
    assert "operating-point.md" in nav
    api = (ROOT / "docs" / "api.md").read_text()
    for obj in ("thermctl.reduce", "LikelihoodEstimator", "select_air_paths", "thermctl.export"):
        assert obj in api, f"docs/api.md lacks {obj}"
    cli = (ROOT / "docs" / "cli.md").read_text()
    out = cli[cli.index("## Output files"):]
    for f in ("model.json", "identification.json", "validation.json", "figures/", "report.html",
              "ss.npz"):
        assert f in out, f"docs/cli.md's output files lack {f}"
    op = (ROOT / "docs" / "operating-point.md").read_text()
    assert "identification.md#a-real-house" in op and "benchmarks/results/twinhouse.txt" in op
    assert "solar[" in op and "--op T=21" in op


MKDOCS = Path(__import__("sys").executable).with_name("mkdocs")


@pytest.mark.skipif(not MKDOCS.exists(), reason="mkdocs not installed (pip install -e '.[docs]')")
def test_rendered_docs_have_math_and_no_raw_sphinx_roles(tmp_path):
    import os
    import subprocess

    res = subprocess.run([str(MKDOCS), "build", "--strict", "--site-dir", str(tmp_path / "site")],
                         cwd=ROOT, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    site = tmp_path / "site"
    mpc = (site / "mpc" / "index.html").read_text()
    assert "mathjax" in mpc.lower() and 'class="arithmatex"' in mpc
    api = (site / "api" / "index.html").read_text()
    raw = re.findall(r":(?:func|meth|class|attr|mod|math|data|exc):<code>", api)
    assert not raw, f"raw Sphinx roles on the API page: {raw[:5]}"
    assert ".. math::" not in api and 'class="arithmatex"' in api
    assert "LikelihoodEstimator" in api and "select_air_paths" in api and "balanced_reduction" in api


def test_fast_gain_is_exported_with_its_stationary_variance():
    """``sigma_g``, ``tau_g`` of a fit with the fast gain: a first-order state per measured
    zone heating its zone, whose stationary variance (Lyapunov) is σ_g²."""
    from scipy.linalg import solve_continuous_lyapunov
    from thermctl.export.kalman import augment_noise
    A0 = np.array([[-1e-4, 5e-5], [5e-5, -1e-4]])
    cz = np.array([2e5, 3e5])
    p = {"sigma_q": 5.0, "sigma_phi": 0.3, "sigma_v": 0.05, "sigma_g": 40.0, "tau_g": 1800.0}
    A, C, Qc, R, extra = augment_noise(p, A0, cz, ["a", "b"], ["a", "b"])
    assert extra == ["d[a]", "d[b]", "g[a]", "g[b]"]
    g = [4, 5]
    assert A[0, 4] == pytest.approx(1 / 2e5) and A[1, 5] == pytest.approx(1 / 3e5)
    assert A[0, 5] == 0.0 and np.all(A[4:, :4] == 0.0)
    P = solve_continuous_lyapunov(A[np.ix_(g, g)], -Qc[np.ix_(g, g)])
    assert np.allclose(np.diag(P), 40.0 ** 2)
    A1, *_ , extra1 = augment_noise({k: v for k, v in p.items() if k not in ("sigma_g", "tau_g")},
                                     A0, cz, ["a", "b"], ["a", "b"])
    assert extra1 == ["d[a]", "d[b]"] and np.array_equal(A1, A[:4, :4])
