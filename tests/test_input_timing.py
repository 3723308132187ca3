"""Input timing: inputs held as logged, or centred on the step (interval means stamped at
the interval's end), and the ``auto`` decision between them by BIC."""

import json

import numpy as np
import pandas as pd
import pytest

from thermctl.data import read_measurements
from thermctl.identify import IdentifyOptions, _resolve_input_timing
from thermctl.model import ThermalModel
from thermctl.network import ThermalNetwork
from thermctl.testbed import generate


@pytest.fixture(scope="module")
def minute_testbed():
    """Pugh Hall, 2 days."""
    return generate(days=2, seed=1)


def test_centred_inputs_arithmetic(minute_testbed):
    tb = minute_testbed
    meas = read_measurements(tb.data.iloc[:50], tb.spec, name="x")
    q = meas.frame["T:outside"].to_numpy(float).copy()
    frame = meas.frame.copy()
    frame.iloc[10, frame.columns.get_loc("T:outside")] = np.nan
    meas = type(meas)(frame, meas.step, meas.spec, meas.units, meas.source, meas.quality)
    c = meas.centred_inputs()
    assert c.input_timing == "centred" and meas.input_timing == "held"
    assert c.centred_inputs() is c
    out = c.frame["T:outside"].to_numpy(float)
    # the mean of each row and the next; the row before a gap and the last row keep theirs
    np.testing.assert_allclose(out[:9], 0.5 * (q[:9] + q[1:10]), rtol=0, atol=1e-12)
    assert out[9] == q[9] and np.isnan(out[10]) and out[-1] == q[-1]
    np.testing.assert_allclose(out[11:-1], 0.5 * (q[11:-1] + q[12:]), rtol=0, atol=1e-12)
    # zone temperatures are states, never moved; supply air is an input
    for z in tb.spec.measured_zones:
        np.testing.assert_array_equal(c.frame[f"T:{z}"].to_numpy(), meas.frame[f"T:{z}"].to_numpy())
    ms = next(col for col in meas.frame.columns if col.startswith("ms:"))
    m = meas.frame[ms].to_numpy(float)
    np.testing.assert_allclose(c.frame[ms].to_numpy(float)[:-1], 0.5 * (m[:-1] + m[1:]))
    # windows and splits keep the timing
    assert c.window(c.start, c.start + pd.Timedelta("2h")).input_timing == "centred"


def _heated_house(small_spec, days=8, seed=0):
    """The small building (3 measured rooms, a hallway) simulated at 1 min, open loop:
    heaters switched on a random 1-h grid (0/800 W in r1, 0/500 W in r2, as the twin
    house's pulses), a daily outdoor swing, white heat noise; sensors ±0.02 K. Every column
    at the 1-min step, for :func:`_log_every_ten`."""
    rng = np.random.default_rng(seed)
    net = ThermalNetwork(small_spec, [("r1", "r3")])
    model = ThermalModel(net)
    n = int(days * 1440)
    t = np.arange(n) * 60.0
    hour = (t // 3600).astype(int)
    q1 = 800.0 * (rng.random(hour.max() + 1) < 0.4)[hour]
    q2 = 500.0 * (rng.random(hour.max() + 1) < 0.4)[hour]
    t_out = 5.0 + 5.0 * np.sin(2 * np.pi * t / 86400.0)
    cols = {"ms": np.zeros((n, net.n_zones)), "Ts": np.full((n, net.n_zones), 20.0)}
    Q = np.column_stack([q1, q2, np.zeros(n), np.zeros(n)])
    Q += rng.normal(0.0, 20.0, Q.shape)
    U = np.column_stack([cols["ms"], cols["Ts"], t_out, np.full(n, 10.0), Q])
    X = model.simulate(U, 60.0, np.full(net.n_states, 18.0))[:-1]   # row k: state at t_k
    idx = pd.date_range("2024-01-08", periods=n, freq="1min", tz="UTC", name="time")
    frame = pd.DataFrame({"T:outside": t_out, "T:ground": 10.0,
                          "Q:r1": Q[:, 0], "Q:r2": Q[:, 1]}, index=idx)
    for i, z in enumerate(net.zones):
        if z in small_spec.measured_zones:
            frame[f"T:{z}"] = X[:, i] + rng.normal(0.0, 0.02, n)
    return frame


def _log_every_ten(frame, how):
    """Logged every 10 min: instantaneous samples at the stamp, or means over the 10 min
    that end at the stamp (temperatures too, as meters and many BAS exports)."""
    if how == "sample":
        return frame[frame.index.minute % 10 == 0]
    # rows [s − 10 min, s) are the minutes that end by s
    return frame.resample("10min", label="right", closed="left").mean().iloc[:-1]


@pytest.fixture(scope="module")
def heated_house(small_spec):
    return _heated_house(small_spec)


@pytest.mark.parametrize("scale", ["global", "local"])
@pytest.mark.parametrize("how, expect", [("mean", "centred"), ("sample", "held")])
def test_auto_follows_how_the_log_was_made(small_spec, heated_house, how, expect, scale):
    meas = read_measurements(_log_every_ten(heated_house, how), small_spec, name=how)
    opt = IdentifyOptions()
    opt.split.scale = scale
    cal, val = meas.split(calibration=opt.calibration, validation=opt.validation)
    m2, cal2, val2, opt2, note, off = _resolve_input_timing(meas, cal, val, opt)
    assert cal2.input_timing == val2.input_timing == expect
    assert opt2.estimation.input_timing == expect and m2.input_timing == expect, note
    assert note.startswith("input timing:") and ("used" in note) == (expect == "centred")
    if scale == "global":
        # the conduction-only fit on the chosen data is handed on to the gain-model decision
        assert off is not None and off.n_obs_ > 0
    else:
        # decided on the local problems' own conduction-only models (3 measured rooms)
        assert off is None and "3 local problems" in note
    # an explicit choice is taken as given, without fits or a note
    for given in ("held", "centred"):
        o = IdentifyOptions()
        o.estimation.input_timing = given
        m3, _, _, o3, note3, off3 = _resolve_input_timing(meas, cal, val, o)
        assert m3.input_timing == given and note3 == "" and off3 is None


def test_option_is_checked():
    opt = IdentifyOptions()
    opt.estimation.input_timing = "late"
    with pytest.raises(Exception, match="input_timing"):
        opt.check()


def test_validate_centres_the_data_of_a_centred_model(tmp_path, monkeypatch):
    """``validate`` reads the model's input timing and gives the held-back days the same."""
    from typer.testing import CliRunner

    from thermctl.cli import app
    from thermctl.data import Measurements

    tb = generate(days=8, seed=2)
    tb.write(tmp_path / "tb")
    runner = CliRunner()
    res = runner.invoke(app, ["identify", str(tmp_path / "tb" / "data.csv"), "--building",
                              str(tmp_path / "tb" / "building.yaml"), "--out",
                              str(tmp_path / "out"), "--intervals", "none",
                              "--input-timing", "centred", "--candidates", "all"])
    assert res.exit_code == 0, res.output
    model = json.loads((tmp_path / "out" / "model.json").read_text())
    assert model["meta"]["options"]["estimation"]["input_timing"] == "centred"
    calls = []
    orig = Measurements.centred_inputs
    monkeypatch.setattr(Measurements, "centred_inputs",
                        lambda self: calls.append(1) or orig(self))
    res = runner.invoke(app, ["validate", str(tmp_path / "out" / "model.json"),
                              str(tmp_path / "tb" / "data.csv"), "--hours", "24", "--no-kstep"])
    assert res.exit_code == 0, res.output
    assert calls == [1]


def test_benchmark_quick_run_prints_the_decision(capsys):
    """``benchmarks/input_timing.py --quick``: the testbed's samples are held."""
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "input_timing.py"
    spec = importlib.util.spec_from_file_location("bench_input_timing", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    try:
        spec.loader.exec_module(mod)
        mod.main(["--quick", "--days", "6"])
    finally:
        sys.modules.pop(spec.name, None)
    row = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("pugh-hall")]
    assert len(row) == 1 and row[0].split()[2] == "held" and float(row[0].split()[3]) > 10
