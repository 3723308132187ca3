"""Issue 22 ("a newcomer's first hour") on the command line: items 1, 2, 6 and 9.

A small building (the conftest spec) with no true air path, run through the testbed:
a model with strong false air paths must get a verdict for conduction-only; bad data
must stop with one line naming the column or time range (and read with the documented
override); progress must show as plain lines when stderr is not a terminal.
"""

from __future__ import annotations

import copy
import json
import re
import shutil

import pandas as pd
import pytest
from typer.testing import CliRunner

from conftest import SMALL_SPEC
from thermctl.cli import app
from thermctl.io import save_model
from thermctl.model import ThermalModel
from thermctl.network import ThermalNetwork
from thermctl.spec import spec_from_dict
from thermctl.testbed import generate

runner = CliRunner()


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def spec():
    return spec_from_dict(copy.deepcopy(SMALL_SPEC), source="small.yaml")


@pytest.fixture(scope="module")
def tb(spec, tmp_path_factory):
    """8 days of the small building, no true air path (6 calibration, 2 validation days)."""
    out = tmp_path_factory.mktemp("small")
    return generate(spec, days=8, seed=1).write(out)


@pytest.fixture(scope="module")
def wrong_model(spec, tb):
    """Three false air paths with 20× the paper's conductance per metre: worse at 1-6 h."""
    net = ThermalNetwork(spec, [("r1", "r2"), ("r2", "r3"), ("r1", "r3")])
    path = tb["data"].parent / "wrong" / "model.json"
    path.parent.mkdir()
    save_model(ThermalModel(net, rbar_v=1e-6, c_v=1.19e3), path)
    return path


# ---- item 1: the verdict ---------------------------------------------------------------
def test_validate_recommends_conduction_only_when_it_wins_at_mpc_horizons(tb, wrong_model):
    res = run("validate", wrong_model, tb["data"], "--hours", 24)
    assert res.exit_code == 0, res.output
    assert re.search(r"^validate: open loop.* 1/1, elapsed \d+:\d\d, done$", res.output, re.M)
    text = " ".join(res.output.split())
    doc = json.loads((wrong_model.parent / "validation.json").read_text())
    v = doc["verdict"]
    assert v["gains"]["1 h ahead"] < -0.05 and v["gains"]["6 h ahead"] < -0.05, v
    assert v["recommendation"] == "conduction-only"
    assert "Prefer the conduction-only model" in text
    assert "support the air paths" not in text
    # signs in words: "36 % worse", never "-36 % better" or "+..%"
    assert re.search(r"1 h ahead \d+ % worse", text), text
    assert not re.search(r"[-+−]\d+ % better", text)
    note = [b for b in doc["report"] if b["title"] == "What the data can support"][0]
    assert "Prefer the conduction-only model" in note["content"]


def test_foreign_truth_json_is_ignored_with_a_note(tb, wrong_model, tmp_path):
    d = tmp_path / "data"
    d.mkdir()
    shutil.copy(tb["data"], d / "data.csv")
    (d / "truth.json").write_text(json.dumps({"site": "N2", "doors": ["open"]}))
    res = run("validate", wrong_model, d / "data.csv", "--hours", 24, "--no-kstep",
              "--out", tmp_path / "v")
    assert res.exit_code == 0, res.output
    assert "ignored" in res.output and "not a testbed truth" in res.output
    doc = json.loads((tmp_path / "v" / "validation.json").read_text())
    assert doc["step_response_error"] == {}
    # an explicit --truth must be one
    res = run("validate", wrong_model, d / "data.csv", "--no-kstep", "--truth", d / "truth.json",
              "--out", tmp_path / "v2")
    assert res.exit_code == 2 and "not a testbed truth" in res.output


# ---- item 2: bad data ----------------------------------------------------------------
def _variant(tb, tmp_path, change):
    df = pd.read_csv(tb["data"])
    df = change(df)
    path = tmp_path / "data.csv"
    df.to_csv(path, index=False)
    return path


def test_one_column_in_fahrenheit(tb, wrong_model, tmp_path):
    def f(df):
        df["T:r2"] = df["T:r2"] * 1.8 + 32
        return df
    data = _variant(tb, tmp_path, f)
    res = run("simulate", wrong_model, data, "--hours", 2, "--out", tmp_path / "sim.csv")
    assert res.exit_code == 2, res.output
    err = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "T:r2" in err[0] and "--allow-odd-units" in res.output
    res = run("--allow-odd-units", "simulate", wrong_model, data, "--hours", 2,
              "--out", tmp_path / "sim.csv")
    assert res.exit_code == 0, res.output
    assert "warning (DataWarning)" in res.output and "T:r2" in res.output


def test_clock_jumping_back(tb, wrong_model, tmp_path):
    def f(df):
        i = 2 * 288 + 18 * 12                      # day 3, 18:00: the clock goes back 6 h
        again = df.iloc[i - 72:i].copy()
        again["T:r1"] += 1.0
        return pd.concat([df.iloc[:i], again, df.iloc[i:]], ignore_index=True)
    data = _variant(tb, tmp_path, f)
    res = run("simulate", wrong_model, data, "--hours", 2, "--out", tmp_path / "sim.csv")
    assert res.exit_code == 2, res.output
    out = " ".join(res.output.split())
    assert "72 time stamp(s) from 2011-01-23 12:00 to 2011-01-23 17:55" in out
    assert "--average-conflicts" in out
    res = run("--average-conflicts", "simulate", wrong_model, data, "--hours", 2,
              "--out", tmp_path / "sim.csv")
    assert res.exit_code == 0 and "averaged" in res.output, res.output


def test_two_days_warn_where_the_data_are_split(spec, tmp_path, wrong_model):
    paths = generate(spec, days=2, seed=2).write(tmp_path / "short")
    res = run("validate", wrong_model, paths["data"], "--hours", 12, "--no-kstep",
              "--out", tmp_path / "v")
    assert res.exit_code == 0, res.output
    out = " ".join(res.output.split())
    assert "warning (DataWarning)" in out and "only 1.0 day(s) of calibration data" in out


# ---- item 6: progress without a terminal ----------------------------------------------
def test_identify_progress_lines_without_a_terminal(tb, tmp_path):
    res = run("identify", tb["data"], "-b", tb["building"], "-o", tmp_path / "o",
              "--intervals", "none")
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.output.splitlines() if ln.startswith("identify: ")]
    assert any(re.fullmatch(r"identify: structure 0/1, elapsed \d+:\d\d", ln) for ln in lines), lines
    assert any(re.fullmatch(r"identify: structure 1/1, elapsed \d+:\d\d, done", ln) for ln in lines)
    # one line per fit of the selection (their number depends on what the data keep)
    assert any(re.match(r"identify: selection fits \(\d+ candidates\) \d+, elapsed \d+:\d\d", ln)
               for ln in lines), lines


def test_identify_shows_the_intervals_as_a_stage_and_the_final_fit_as_a_fit():
    """After the search, the final fit ticks the fit count and the intervals are their own
    stage (they took 12-17 s of the twin house's run, shown as selection before)."""
    import warnings

    from thermctl.data import read_measurements
    from thermctl.identify import IdentifyOptions, SelectionOptions, identify
    from thermctl.testbed import generate as generate_testbed
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pugh = generate_testbed(days=8, seed=3)         # Pugh Hall: 3 true air paths
        meas = read_measurements(pugh.data, pugh.spec)
    seen = []
    # the selection's own count (the gain-schedule check after it counts its fits apart)
    opt = IdentifyOptions(selection=SelectionOptions(swaps=False, schedule_check=False))
    ident = identify(meas, opt, progress=lambda stage, n, total: seen.append((stage, n, total)))
    assert ident.model.network.convection_edges, "the test needs a model with air paths"
    stages = [s for s, _, _ in seen]
    assert ("intervals", 0, 1) in seen and ("intervals", 1, 1) in seen
    fits = [n for s, n, _ in seen if s.startswith("selection fits")]
    # the last count shown is the selection's own, the final fit included (fits in two threads
    # may report out of order; the final fit comes after them); then the intervals
    assert fits[-1] == max(fits) == ident.selection.n_fits
    assert stages.index("intervals") > max(i for i, s in enumerate(stages)
                                           if s.startswith("selection fits"))


def test_progress_reporter_eta_heartbeat_and_log(caplog, capsys):
    import time

    from thermctl.cli._common import progress
    caplog.set_level("INFO", logger="thermctl")
    with progress("identify", terminal=False, min_interval=0.0, heartbeat=0.3) as p:
        cb = p.callback()
        cb("structure", 0, 1)
        time.sleep(0.8)                              # one long step: not frozen
        cb("structure", 1, 1)
        for k in range(4):
            cb("selection", k, 4)
    err = capsys.readouterr().err.splitlines()
    assert any(ln.startswith("identify: structure 0/1") and ln.endswith("(working)") for ln in err), err
    assert any(re.fullmatch(r"identify: selection 2/4, elapsed \d+:\d\d, ETA ~\d+:\d\d", ln)
               for ln in err), err
    assert [r.getMessage() for r in caplog.records if r.name == "thermctl"] == err


# ---- item 9: small things --------------------------------------------------------------
def test_version():
    from thermctl import __version__
    res = run("--version")
    assert res.exit_code == 0 and res.output.strip() == f"thermctl {__version__}"


def test_swapped_data_and_building(tb, tmp_path):
    res = run("identify", tb["building"], "--building", tb["data"], "-o", tmp_path / "o")
    assert res.exit_code == 2
    assert "did you swap DATA and --building" in res.output and "Traceback" not in res.output


def test_sep_and_time_format_options(tb, wrong_model, tmp_path):
    df = pd.read_csv(tb["data"])
    t = pd.to_datetime(df["time"], utc=True).dt.tz_convert("-05:00").dt.tz_localize(None)
    df["time"] = (t - pd.Timestamp("1899-12-30")) / pd.Timedelta(days=1)
    data = tmp_path / "excel.csv"
    df.to_csv(data, index=False, sep=";", decimal=",")
    res = run("simulate", wrong_model, data, "--hours", 2, "--out", tmp_path / "sim.csv")
    assert res.exit_code == 2 and "--sep" in res.output
    res = run("--sep", ";", "simulate", wrong_model, data, "--hours", 2, "--out", tmp_path / "sim.csv")
    assert res.exit_code == 2 and "--time-format excel" in " ".join(res.output.split())
    res = run("--sep", ";", "--time-format", "excel", "simulate", wrong_model, data, "--hours", 2,
              "--out", tmp_path / "sim.csv")
    assert res.exit_code == 0, res.output
    assert len(pd.read_csv(tmp_path / "sim.csv")) == 24      # 2 h of 5-min steps


def test_mpc_output_is_git_ignored():
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    assert "mpc-output/" in (root / ".gitignore").read_text().split()
