"""The synthetic testbed: determinism, physics, round trips, the plant against the model core."""

from __future__ import annotations

import inspect
import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from thermctl.cli import app
from thermctl.errors import ModelError, SpecError
from thermctl.model import C_V_PAPER, RBAR_V_PAPER, ThermalModel, make_stepper
from thermctl.network import ThermalNetwork
from thermctl.spec import RHO_AIR, load_spec
from thermctl.testbed import (Disturbances, PadeZoneStepper, Plant, corridor_floor_spec, generate,
                              load_truth, pugh_hall_spec, run_closed_loop, single_thread_blas)
from thermctl.testbed.output import CFM, punch_holes


@pytest.fixture(scope="module")
def paper():
    """The paper's situation with every default: 26 days of 5-min data from 2011-01-21."""
    return generate()


@pytest.fixture(scope="module")
def clean():
    """Perfect sensors, controller at the data step: the data are the plant's ZOH inputs."""
    return generate(days=2, noise=None, control_minutes=5, burn_in_days=1, seed=4)


def _walled(spec):
    return {frozenset((w.a, w.b)) for w in spec.walls}


# ---- the paper's case ---------------------------------------------------------------

def test_defaults_are_the_papers_case(paper):
    sig = inspect.signature(generate).parameters
    assert sig["days"].default == 26 and sig["step_minutes"].default == 5
    assert sig["start"].default == "2011-01-21"
    assert sig["rbar_v"].default == RBAR_V_PAPER == 3.36e-4
    assert sig["c_v"].default == C_V_PAPER == 1.19e3
    idx = paper.data.index
    assert len(idx) == 26 * 288 == paper.states.shape[0] == len(paper.gains)
    assert idx[0] == pd.Timestamp("2011-01-21 00:00", tz="America/New_York")
    assert idx[-1] == pd.Timestamp("2011-02-15 23:55", tz="America/New_York")
    assert (np.diff(idx.asi8) == np.diff(idx.asi8)[0]).all()
    assert paper.gains.index.equals(idx)
    # 6 measured offices and 6 boundary nodes are logged; the hallway is not
    assert [c for c in paper.data.columns if c.startswith("T:")] == [
        "T:r240", "T:r241", "T:r242", "T:r243", "T:r244", "T:r247", "T:outside", "T:r200",
        "T:r210", "T:r230", "T:r248", "T:corridor"]
    assert "T:hallway" not in paper.data and "ms:hallway" not in paper.data
    assert paper.states.shape[1] == paper.network.n_states == 7 + 2 * (21 + 3)


def test_truth_edges_join_zones_without_walls():
    spec, edges = pugh_hall_spec()
    walled = _walled(spec)
    assert len(edges) == 3
    for a, b, d in edges:
        assert frozenset((a, b)) not in walled
        assert spec.distance(a, b) == d > 0
        assert a in spec.measured_zones and b in spec.measured_zones
    # every office in at most one air path (the open-door pairs)
    ends = [z for a, b, _ in edges for z in (a, b)]
    assert len(ends) == len(set(ends))
    # distances exist for every office pair without a wall, and only for those
    offices = spec.measured_zones
    pairs = {frozenset((a, b)) for i, a in enumerate(offices) for b in offices[i + 1:]}
    assert {frozenset((d.a, d.b)) for d in spec.distances} == pairs - walled


def test_wall_alpha_is_pi_squared_and_truth_carries_it(paper):
    # every wall uses the homogeneous-slab split, so alpha = pi^2 exactly (rc module)
    np.testing.assert_allclose(list(paper.truth.alphas.values()), np.pi**2, rtol=1e-12)
    np.testing.assert_allclose(paper.truth.alpha, np.pi**2, rtol=1e-12)
    # tau per unit distance of an equal-R, equal-C edge is rbar_v·c_v (alpha = 6 for it)
    rc = paper.truth.details["rbar_v_c_v"]
    np.testing.assert_allclose(rc, 3.36e-4 * 1.19e3, rtol=1e-12)
    taus = paper.truth.details["convection_time_constants_s"]
    for a, b, d in paper.truth.edges:
        np.testing.assert_allclose(taus[f"{a}-{b}"], rc * d, rtol=1e-10)


# ---- physics of the generated data --------------------------------------------------

def _occupied(tb):
    return tb.disturbances.occupied[:: int(tb.settings["step_minutes"] / tb.settings["control_minutes"])]


def test_supply_is_off_outside_occupied_hours_and_within_box_limits(paper):
    occ = _occupied(paper)
    ms = paper.data.filter(like="ms:")
    Ts = paper.data.filter(like="Ts:")
    assert (ms[~occ] == 0).all().all()
    boxes = paper.truth.details["vav_boxes"]
    gain = paper.truth.details["flow_gain"]
    for z, box in boxes.items():
        on = ms[f"ms:{z}"][occ].to_numpy() / gain[z]
        # 2 % flow noise and 1 CFM rounding: 5 sigma plus one rounding step
        slack = 0.1 * box["ms_min"] + CFM * RHO_AIR
        assert on.min() >= box["ms_min"] - slack
        assert on.max() <= box["ms_max"] + 0.1 * box["ms_max"] + slack
        t = Ts[f"Ts:{z}"][occ].to_numpy()
        # cold deck 12.8 ± 0.3 K (AR), reheat up to 32 °C, 0.1 K sensor noise
        assert t.min() > 11.0 and t.max() < 32.8


def test_zone_temperatures_are_controlled_in_occupied_hours(paper):
    occ = _occupied(paper)
    hour = paper.data.index.hour
    settled = occ & (hour >= 9)  # after the morning warm-up
    for z, box in paper.truth.details["vav_boxes"].items():
        T = paper.data[f"T:{z}"][settled].to_numpy() - paper.truth.details["sensor_bias"][z]
        assert 20.0 < T.min() and T.max() < 25.0
        med = np.median(T)
        assert box["heat_setpoint"] - 0.3 < med < box["cool_setpoint"] + 0.3


def test_zones_float_down_on_cold_nights(paper):
    zones = [f"T:{z}" for z in paper.spec.measured_zones]
    d = paper.data
    drops = []
    for day in pd.date_range("2011-01-24", "2011-02-11", freq="D", tz="America/New_York"):
        if day.day_of_week >= 4:  # the night after Friday..Sunday is part of a weekend
            continue
        night = d.loc[day + pd.Timedelta(hours=19): day + pd.Timedelta(hours=29, minutes=55)]
        out = night["T:outside"].mean()
        zone_start = night[zones].iloc[0].mean()
        if out < zone_start - 8.0:
            assert (night.filter(like="ms:") == 0).all().all()
            drops.append(zone_start - night[zones].iloc[-1].mean())
            # floating, they stay between the outdoor minimum and where they started
            assert night[zones].min().min() > night["T:outside"].min()
    assert len(drops) >= 5
    assert min(drops) > 0.2 and np.mean(drops) > 0.5


def test_weather_is_gainesville_in_january(paper):
    out = paper.data["T:outside"]
    daily = out.groupby(out.index.date).agg(["min", "max"])
    assert 2.0 < daily["min"].mean() < 10.0
    assert 15.0 < daily["max"].mean() < 24.0
    assert 5.0 < (daily["max"] - daily["min"]).mean() < 16.0


def test_gains_follow_occupancy(paper):
    g = paper.gains
    hour = g.index.hour
    weekday = g.index.day_of_week < 5
    day = weekday & (hour >= 10) & (hour < 16)
    night = (hour < 5)
    for z in paper.spec.measured_zones:
        assert g[z][day].mean() > g[z][night].mean() + 100.0
        assert g[z][night].max() < 120.0  # standby equipment only
    assert (g["hallway"] > 0).all()
    # different zones get different days: pairwise correlation well below 1
    c = np.corrcoef(g[paper.spec.measured_zones].to_numpy().T)
    assert c[np.triu_indices_from(c, 1)].max() < 0.95


# ---- determinism --------------------------------------------------------------------

def test_same_seed_same_files_different_seed_different_data(tmp_path):
    a = generate(days=1, seed=7, burn_in_days=0.5, missing=0.05)
    b = generate(days=1, seed=7, burn_in_days=0.5, missing=0.05)
    c = generate(days=1, seed=8, burn_in_days=0.5, missing=0.05)
    pa, pb = a.write(tmp_path / "a"), b.write(tmp_path / "b")
    for role in pa:
        assert pa[role].read_bytes() == pb[role].read_bytes(), role
    assert not a.data.equals(c.data)
    diff = (a.data["T:r240"] - c.data["T:r240"]).abs()
    assert diff.mean() > 0.05
    assert json.loads(pa["truth"].read_text())["seed"] == 7


# ---- round trips --------------------------------------------------------------------

def test_written_spec_loads_and_rebuilds_the_true_network(paper, tmp_path):
    paths = paper.write(tmp_path)
    spec = load_spec(paths["building"])
    assert spec == paper.spec
    truth = load_truth(paths["truth"])
    assert truth.edges == paper.truth.edges
    net = ThermalNetwork(spec, truth.edges)
    assert net.state_names == paper.network.state_names
    assert net.input_names == paper.network.input_names
    model = ThermalModel(net, truth.rbar_v, truth.c_v)
    A1, B1 = model.matrices()
    A0, B0 = paper.model.matrices()
    assert abs(A1 - A0).max() <= 1e-12 * abs(A0).max()
    assert abs(B1 - B0).max() <= 1e-12 * abs(B0).max()
    # the testbed's network is the loaded one plus exactly the true convection edges
    assert net.conduction_only().state_names == ThermalNetwork(spec).state_names
    assert sorted(net.convection_pairs) == sorted(paper.network.convection_pairs)
    # the data file reads back to the data
    csv = pd.read_csv(paths["data"])
    assert list(csv.columns) == ["time"] + list(paper.data.columns)
    t = pd.to_datetime(csv["time"]).dt.tz_convert("America/New_York")
    assert (t.to_numpy() == paper.data.index.to_numpy()).all()
    np.testing.assert_allclose(csv.iloc[:, 1:].to_numpy(), paper.data.to_numpy(), atol=5e-6)


def test_imperial_output_converts_back_to_si(tmp_path):
    tb = generate(days=1, seed=2, burn_in_days=0.5)
    si = pd.read_csv(tb.write(tmp_path / "si")["data"])
    imp = pd.read_csv(tb.write(tmp_path / "imp", units="imperial")["data"])
    assert [c for c in imp.columns if c.startswith("vs:")] == \
        [c.replace("ms:", "vs:") for c in si.columns if c.startswith("ms:")]
    for col in si.columns[1:]:
        kind, _, name = col.partition(":")
        if kind in ("T", "Ts"):
            f = imp[col].to_numpy()
            # exported temperatures sit on the 0.1 °F grid
            np.testing.assert_allclose(f * 10, np.round(f * 10), atol=1e-6)
            # 3 decimals of °F (≤ 2.8e-4 K) plus 5 decimals of °C
            np.testing.assert_allclose((f - 32) / 1.8, si[col], atol=3e-4)
        else:
            cfm = imp[f"vs:{name}"].to_numpy()
            # exported flows sit on the 1 CFM grid; 0.005 CFM of 2-decimal rounding
            np.testing.assert_allclose(cfm, np.round(cfm), atol=1e-6)
            np.testing.assert_allclose(cfm * CFM * RHO_AIR, si[col], atol=3e-6)
    assert (imp["time"] == si["time"]).all()


# ---- the plant against the model core -----------------------------------------------

def test_clean_data_are_the_plants_true_values(clean):
    d, x = clean.data, clean.states
    for i, z in enumerate(clean.network.zones):
        if z in clean.spec.measured_zones:
            np.testing.assert_array_equal(d[f"T:{z}"].to_numpy(), x[:, i])
            np.testing.assert_array_equal(d[f"ms:{z}"].to_numpy(), clean.inputs[:, i])
    sl = clean.network.input_slices()
    Tb = clean.inputs[:, sl["T"]]
    for j, b in enumerate(clean.network.boundary):
        np.testing.assert_array_equal(d[f"T:{b}"].to_numpy(), Tb[:, j])


def test_plant_equals_model_core_simulation(clean):
    # midnight to 12:30: the floating night, the morning warm-up and the controlled morning
    n = 150
    U = clean.inputs[:n]
    # same scheme (Radau IIA, 5 sub-steps of 60 s): round-off apart
    X = clean.model.simulate(U, 300.0, clean.states[0], method="radau", substeps=5)
    np.testing.assert_allclose(X, clean.states[:n + 1], atol=1e-9)
    # exact matrix exponential: the plant's discretisation error is O(h^3)
    with single_thread_blas():  # expm of 110x110 on threaded BLAS is 70x slower on a busy box
        X = clean.model.simulate(U, 300.0, clean.states[0], method="exact")
    np.testing.assert_allclose(X, clean.states[:n + 1], atol=1e-4)


def test_plant_replays_the_baseline_closed_loop(clean):
    plant = clean.plant()
    ctrl = clean.controller
    ctrl.reset()  # the data start at midnight: supply off, integrators at zero
    seen = []
    run_closed_loop(plant, ctrl, n_steps=len(clean.states) - 1,
                    callback=lambda m, ms, Ts, p: seen.append(p.x.copy()))
    seen.append(plant.x.copy())
    np.testing.assert_allclose(np.array(seen), clean.states, atol=1e-10)
    assert plant.time == clean.data.index[-1]


@pytest.mark.parametrize("building, dense_limit", [("pugh-hall", 400), ("pugh-hall", 0),
                                                    ("corridor", 0)],
                         ids=["pugh-dense", "pugh-sparse", "corridor-sparse"])
@pytest.mark.parametrize("substeps", [1, 3])
def test_zone_stepper_equals_make_stepper(building, dense_limit, substeps):
    if building == "pugh-hall":
        spec, edges = pugh_hall_spec()
    else:
        spec, edges = corridor_floor_spec(6, floors=2)
    model = ThermalModel(ThermalNetwork(spec, edges))
    net = model.network
    rng = np.random.default_rng(0)
    nz = net.n_zones
    A, _ = model.matrices()
    st = PadeZoneStepper(A, nz, 120.0, substeps, dense_limit=dense_limit)
    assert st.dense == (dense_limit > net.n_states)
    x = rng.uniform(10, 30, net.n_states)
    base = rng.uniform(0.0, 0.15, nz) * (rng.random(nz) > 0.3)
    # zero flow; near zero (sparse: iterate on the zero-flow factor); 6x (refactor);
    # near that (iterate on the new factor)
    with single_thread_blas():  # make_stepper's dense LU: threads only cost at this size
        for scale in (0.0, 1.0, 1.01, 6.0, 6.05):  # flows up to 0.9 kg/s
            ms = scale * base
            u = np.concatenate([ms, rng.uniform(12, 32, nz),
                                rng.uniform(0, 25, len(net.boundary)), rng.uniform(0, 500, nz)])
            A_u, b = model.affine(u)
            ref = make_stepper(A_u, 120.0, "radau", substeps)(x, b)
            got = st.step(x, ms * model.sym.kz, b)
            np.testing.assert_allclose(got, ref, atol=1e-11)
    if not st.dense:  # refactored once, for 6x, iff the contraction bound exceeds 0.05
        bound = abs(st.beta) * np.max(6.0 * base * model.sym.kz)
        assert st.refactorizations == int(bound > 0.05)


def test_plant_relaxes_to_the_boundary_temperature():
    # closed form: no supply, no gains, every boundary at 10 °C → every state tends to 10 °C
    spec, edges = pugh_hall_spec()
    model = ThermalModel(ThermalNetwork(spec, edges))
    n = 4 * 24 * 40  # 40 days of 15 min
    time = pd.date_range("2011-01-21", periods=n, freq="15min", tz="UTC")
    nb, nz = len(spec.boundary), len(spec.zones)
    d = Disturbances(time, 900.0, list(spec.boundary), spec.zone_names, np.full((n, nb), 10.0),
                     np.full((n, nb), 10.0), np.zeros((n, nz)), np.zeros(n, bool),
                     np.full(n, 12.8), np.zeros(n))
    # one Radau sub-step per 15 min: L-stable and exact in steady state, all this test needs
    plant = Plant(model, d, x0=np.full(model.network.n_states, 25.0), substeps=1)
    meas = run_closed_loop(plant, lambda m: (0.0, 20.0))
    np.testing.assert_allclose(plant.x, 10.0, atol=1e-6)
    np.testing.assert_allclose(meas.T, 10.0, atol=1e-6)
    # a constant supply: the zone balance ms·cp·(Ts − T) + Σ q = 0 has the model's steady state
    plant.reset()
    ms = np.full(nz, 0.05)
    for _ in range(2000):
        plant.step(ms, 30.0)
    u = plant.inputs(ms, np.full(nz, 30.0), 0)
    np.testing.assert_allclose(plant.x, model.steady_state(u), atol=1e-6)


def test_plant_rejects_bad_commands(clean):
    plant = clean.plant()
    with pytest.raises(ModelError, match=r"supply flow must be finite and >= 0.*r241"):
        plant.step([0.1, -0.01, 0, 0, 0, 0, 0], 20.0)
    with pytest.raises(ModelError, match=r"supply temperature must be finite.*hallway"):
        plant.step(0.0, [20, 20, 20, 20, 20, 20, np.nan])
    with pytest.raises(ModelError, match=r"ms needs a scalar or 7 values"):
        plant.step([0.1, 0.1], 20.0)
    assert plant.k == 0  # nothing was applied
    short = Plant(clean.model, clean.disturbances.window(0, 2), x0=clean.states[0])
    short.step(0.0, 20.0)
    short.step(0.0, 20.0)
    with pytest.raises(ModelError, match="disturbances end after 2 steps"):
        short.step(0.0, 20.0)


# ---- larger layouts -----------------------------------------------------------------

@pytest.mark.parametrize("n, floors", [(3, 1), (10, 2), (25, 4)], ids=["3x1", "10x2", "25x4"])
def test_corridor_floor_spec(n, floors):
    spec, edges = corridor_floor_spec(n, floors=floors, seed=1)
    assert len(spec.zones) == floors * (2 * n + 1)
    assert len(spec.measured_zones) == floors * 2 * n
    walled = _walled(spec)
    ends = [z for a, b, _ in edges for z in (a, b)]
    assert len(ends) == len(set(ends))
    for a, b, d in edges:
        assert frozenset((a, b)) not in walled
        assert spec.distance(a, b) == d <= 8.0
        assert a[:2] == b[:2]  # same floor
    assert all(d.d <= 15.0 for d in spec.distances)
    if n * floors >= 10:  # 35 % of offices pair up: some edges, not all offices
        assert 0.1 * n * floors < len(edges) < n * floors
    assert corridor_floor_spec(n, floors=floors, seed=1) == (spec, edges)
    if n >= 10:
        assert corridor_floor_spec(n, floors=floors, seed=2)[1] != edges
    ThermalNetwork(spec, edges)  # valid network


def test_corridor_building_has_sun_and_about_the_requested_zones():
    tb = generate("corridor", zones=20, days=1, burn_in_days=0.5, seed=3)
    assert 17 <= tb.network.n_zones <= 23
    assert "solar:south" in tb.data
    south = [z for z in tb.spec.measured_zones if "s" in z[2:]]
    north = [z for z in tb.spec.measured_zones if "n" in z[2:]]
    noon = tb.gains.index.hour == 12
    assert tb.gains[south][noon].mean().mean() > tb.gains[north][noon].mean().mean()


# ---- missing data, errors, CLI ------------------------------------------------------

@pytest.mark.parametrize("fraction", [0.0, 0.02, 0.2])
def test_missing_fraction(fraction):
    rng = np.random.default_rng(0)
    v = punch_holes(np.ones((5000, 8)), fraction, rng)
    got = np.isnan(v).mean()
    if fraction == 0:
        assert got == 0
    else:
        # gaps are runs, so the fraction overshoots by at most about one run per column
        assert fraction <= got < 1.3 * fraction
        assert np.isnan(v).all(axis=1).any()  # some export outages


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(building="nowhere"), SpecError, "unknown testbed building 'nowhere'"),
    (dict(zones=50), SpecError, "'pugh-hall' has 7 zones"),
    (dict(step_minutes=5, control_minutes=2), SpecError, "whole multiple of control_minutes"),
    (dict(missing=1.0), SpecError, r"missing must be in \[0.0, 1.0\)"),
    (dict(days=0), SpecError, r"days must be finite and > 0 \[days\], found 0"),
    (dict(days=0.001), SpecError, "whole number of 5"),
    (dict(start="yesterday-ish"), SpecError, "start: not a date"),
    (dict(rbar_v=[1e-4, 2e-4]), ModelError, "rbar_v: expected a scalar or 3 values"),
    (dict(building="corridor", zones=3), SpecError, "zones must be an integer >= 5"),
], ids=["building", "zones", "step", "missing", "days", "partial-step", "start", "rbar_v",
        "corridor-size"])
def test_generate_errors(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        generate(**{"days": 1, "burn_in_days": 0, **kwargs})


def test_cli_writes_files_and_reports_errors(tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["testbed", "--out", str(tmp_path), "--days", "0.5", "--seed", "3",
                              "--units", "imperial", "--missing", "0.02"])
    assert res.exit_code == 0, res.output
    for f in ("building.yaml", "data.csv", "truth.json", "gains.csv"):
        assert (tmp_path / f).is_file()
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["seed"] == 3 and truth["settings"]["units"] == "imperial"
    assert truth["settings"]["missing"] == 0.02
    assert "vs:r240" in (tmp_path / "data.csv").read_text().splitlines()[0]
    res = runner.invoke(app, ["testbed", "--out", str(tmp_path), "--days", "1", "--step", "5",
                              "--control", "2"])
    assert res.exit_code == 2
    assert "whole multiple of control_minutes" in res.output
    res = runner.invoke(app, ["testbed", "--help"])
    assert res.exit_code == 0 and "Example:" in res.output
