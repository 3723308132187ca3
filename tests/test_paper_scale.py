"""The paper's pipeline at building scale: neighbourhood SIN and the simulation criterion
summed over local problems (air paths to measured neighbours as boundary inputs)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from thermctl.data import read_measurements
from thermctl.errors import BoundWarning, ConvergenceWarning
from thermctl.estimate.simulation import CompositeCostProblem, grid_search
from thermctl.identify import IdentifyOptions, identify
from thermctl.local import local_cost_problem, local_problems
from thermctl.model import ThermalModel
from thermctl.network import ThermalNetwork
from thermctl.structure import NeighbourhoodStructureIdentifier, StructureIdentifier
from thermctl.testbed import generate


@pytest.fixture(scope="module")
def pugh(tmp_path_factory):
    out = tmp_path_factory.mktemp("pugh")
    tb = generate("pugh-hall", days=14, seed=3)
    tb.write(out)
    meas = read_measurements(out / "data.csv", out / "building.yaml")
    cal, _ = meas.split()
    return meas, cal, tb


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    """9 zones (8 measured offices, unmeasured hallway), 6 days: too few for SIN over the
    building (10 days), enough for the neighbourhoods."""
    out = tmp_path_factory.mktemp("corr")
    tb = generate("corridor", zones=9, days=6, seed=2)
    tb.write(out)
    meas = read_measurements(out / "data.csv", out / "building.yaml")
    meas.dir = out
    return meas, tb


def _truth(tb):
    return [(e.a, e.b, e.d) for e in tb.network.convection_edges]


def test_neighbourhood_sin_equals_building_sin_when_the_neighbourhood_is_the_building(pugh):
    meas, cal, _ = pugh
    net = ThermalNetwork(meas.spec)
    whole = StructureIdentifier().fit(cal.frame, net)
    local = NeighbourhoodStructureIdentifier().fit(cal.frame, net)
    assert [(e.a, e.b) for e in local.edges_] == [(e.a, e.b) for e in whole.edges_]
    full = [z for z, nb in local.neighbourhoods_.items() if set(nb) == set(whole.zones_)]
    assert full, "no zone's neighbourhood is the whole floor: the comparison below is empty"
    for pair, by_zone in local.zone_scores_.items():
        for z, s in by_zone.items():
            if z in full:       # same zones conditioned on: the same partial correlations
                assert s == pytest.approx(whole.scores_[pair], abs=1e-12)


def test_neighbourhood_sin_runs_where_building_sin_cannot(corridor):
    meas, tb = corridor
    cal, _ = meas.split()
    net = ThermalNetwork(meas.spec)
    with pytest.raises(Exception, match="complete days"):
        StructureIdentifier().fit(cal.frame, net)
    sid = NeighbourhoodStructureIdentifier().fit(cal.frame, net)
    assert sid.edges_ and not sid.skipped_
    n_days = len(__import__("thermctl").data.day_array(cal.frame, net.measured_zones).days)
    assert n_days < len(net.measured_zones) + 2
    # trimmed to N - 2 zones, the zone itself first
    assert all(len(nb) <= n_days - 2 for nb in sid.neighbourhoods_.values())
    assert all(z == nb[0] for z, nb in sid.neighbourhoods_.items())
    # every measured zone gets its best partner under the paper's rule
    ends = {z for e in sid.edges_ for z in (e.a, e.b)}
    assert ends == set(sid.neighbourhoods_)


def test_local_forcing_matches_an_independent_integrator(pugh):
    """An air path to a boundary node puts R̄_v into the input matrix; the exact
    simulator's eta-dependent forcing must reproduce CasADi's CVODES on the same model."""
    meas, cal, tb = pugh
    cp = local_cost_problem(meas.spec, _truth(tb), cal.frame, initial_state="paper")
    pb = cp.parts[0]
    assert pb.simulator.b_varies
    eta = pb.eta_from_theta(4e-4, 5e3)
    X = pb.simulator.trajectory(eta)
    model = ThermalModel(pb.network, rbar_v=4e-4, c_v=5e3)
    Xc = model.simulate(pb.U_sim, pb.dt, pb.x0_ref, method="cvodes")
    zi = pb.zone_index
    assert np.abs(X[:len(Xc)][:, zi] - Xc[:len(X)][:, zi]).max() < 1e-4


def test_composite_gradient_and_batch_agree_with_finite_differences(pugh):
    meas, cal, tb = pugh
    cp = local_cost_problem(meas.spec, _truth(tb), cal.frame)
    assert isinstance(cp, CompositeCostProblem) and len(cp.parts) >= 4
    sim = cp.simulator
    eta = cp.eta_from_theta(3e-4, 7e3)
    ev = sim.cost(eta, grad=True)
    h = 1e-6
    for i in range(2):
        e1, e2 = eta.copy(), eta.copy()
        e1[i] += h
        e2[i] -= h
        fd = (sim.cost(e1).objective - sim.cost(e2).objective) / (2 * h)
        assert ev.grad[i] == pytest.approx(fd, rel=1e-4, abs=1e-6 * abs(ev.objective))
    J, O = sim.cost_batch(np.array([eta, eta + 0.2]), objective=True)
    assert J[0] == pytest.approx(ev.J, rel=1e-10)
    assert O[1] == pytest.approx(sim.cost(eta + 0.2).objective, rel=1e-10)
    assert ev.J == pytest.approx(sum(pb.simulator.cost(eta).J for pb in cp.parts), rel=1e-12)


def test_paper_pipeline_on_neighbourhoods_and_local_problems(corridor):
    meas, tb = corridor
    opt = IdentifyOptions()
    opt.estimation.criterion = "simulation"
    opt.split.local_above = 4
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", BoundWarning)
        warnings.simplefilter("ignore", ConvergenceWarning)
        ident = identify(meas, opt)
    notes = " ".join(ident.notes)
    assert "neighbourhood" in notes and "summed over" in notes
    assert isinstance(ident.structure, NeighbourhoodStructureIdentifier)
    assert ident.estimate is not None and ident.grid is not None
    # the NLP, started at the grid's best, never ends above it (same composite objective)
    assert ident.estimate.J <= ident.grid.best_J * (1 + 1e-6) + 1e-9 or \
        "start is returned" in ident.estimate.message
    assert ident.model.network.convection_edges
    # picks scoring below the SIN level are what a pair without an air path scores: said
    weak = [e for e in ident.structure.edges_ if e.score < opt.structure.level]
    assert bool(weak) == any("score below the SIN level" in n for n in ident.notes)


def test_composite_parts_must_share_their_bounds(pugh):
    meas, cal, tb = pugh
    cp = local_cost_problem(meas.spec, _truth(tb), cal.frame)
    from thermctl.estimate.simulation import CostProblem
    other = CostProblem(cp.parts[0].network, cp.parts[0].data, alpha=1.0)
    with pytest.raises(Exception, match="alpha|tau"):
        CompositeCostProblem([cp.parts[1], other])


def test_cli_scope_and_snap(corridor, tmp_path):
    from typer.testing import CliRunner

    from thermctl.cli import app
    meas, _ = corridor
    d = meas.dir
    args = ["identify", str(d / "data.csv"), "--building", str(d / "building.yaml"),
            "--criterion", "simulation", "--scope", "neighbourhood", "--estimator", "grid",
            "--scale", "global", "--out"]
    res = CliRunner().invoke(app, ["--snap", "none"] + args + [str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "a" / "model.json").is_file()
    bad = CliRunner().invoke(app, ["--snap", "banana"] + args + [str(tmp_path / "b")])
    assert bad.exit_code != 0 and "snap" in bad.output
    assert not (tmp_path / "b" / "model.json").exists()
    bad = CliRunner().invoke(app, args[:-1] + ["--scope", "floor", "--out", str(tmp_path / "c")])
    assert bad.exit_code != 0 and "scope" in bad.output


def test_ipopt_progress_shows_its_limit_not_an_eta(capsys):
    from thermctl.cli._common import progress
    with progress("identify", terminal=False, min_interval=0.0, heartbeat=0.0) as p:
        for k in range(1, 4):
            p.callback()("ipopt", k, 500)
    err = capsys.readouterr().err.splitlines()
    assert err[-1].startswith("identify: ipopt iteration 3 (limit 500), elapsed")
    assert not any("ETA" in ln for ln in err)
