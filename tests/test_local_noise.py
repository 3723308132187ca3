"""A large building's apertures and noise from its local problems (no whole-building fit):
the names they get, how the problems' values combine, and how close the filter they make
comes to a whole-building maximum-likelihood fit of the same parameters."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from thermctl.data import read_measurements
from thermctl.local import LocalResult, combine_zone_params, local_problems, zone_params
from thermctl.testbed import generate


def test_zone_params_name_a_local_fits_shared_noise_by_zone(small_spec):
    p = next(p for p in local_problems(small_spec) if p.latent)
    z, lat = p.zone, p.latent
    fitted = {"rbar_v[air:r1-r3]": 3e-4, "tau0": 1.0, "ua_factor[partition]": 1.1,
              "sigma_v": 0.02, "sigma_q": 500.0, "sigma_phi": 2.0,
              f"aperture[{z},solar:s]": 0.3, "tau_g": 1800.0}
    out = zone_params(p, fitted)
    want = {f"sigma_v[{z}]": 0.02, f"sigma_phi[{z}]": 2.0, f"aperture[{z},solar:s]": 0.3,
            "tau_g": 1800.0, f"sigma_q[{z}]": 500.0, **{f"sigma_q[{u}]": 500.0 for u in lat}}
    assert out == want          # R̄_v, τ0 and UA factors have LocalResult fields of their own


def _res(zone, params, error=None, bounds=()):
    return LocalResult(zone, [], {}, {}, float("nan"), 10, error=error, params=params,
                       at_bounds=list(bounds))


def test_combine_takes_a_zones_own_problem_the_median_for_the_rest_and_fills_gaps(small_spec):
    res = [_res("r1", {"sigma_v[r1]": 0.02, "sigma_q[r1]": 400.0, "sigma_q[hallway]": 400.0,
                       "aperture[r1,solar:s]": 0.3, "aperture[hallway,solar:s]": 2.0,
                       "tau_g": 1000.0},
                bounds=["sigma_v[r1] at its lower bound 0.0001 [K]",
                        "aperture[hallway,solar:s] at its lower bound 0 [m²]"]),
           # r3's problem sees r1 as an input and fits nothing of it; were it to name r1,
           # r1's own problem still wins
           _res("r3", {"sigma_v[r3]": 0.04, "sigma_q[r3]": 800.0, "sigma_q[hallway]": 800.0,
                       "sigma_q[r1]": 9e9, "aperture[hallway,solar:s]": 4.0, "tau_g": 3000.0}),
           _res("r2", {}, error="RuntimeError: boom")]
    out, bounds, notes = combine_zone_params(small_spec, res)
    assert out["sigma_q[r1]"] == 400.0 and out["sigma_v[r3]"] == 0.04
    assert out["sigma_q[hallway]"] == 600.0            # median of the two that reach it
    assert out["aperture[hallway,solar:s]"] == 3.0
    assert out["tau_g"] == 2000.0
    # r2 failed: its noise is the others' median, and said; it gets no aperture
    assert out["sigma_v[r2]"] == pytest.approx(0.03) and out["sigma_q[r2]"] == 600.0
    assert "aperture[r2,solar:s]" not in out
    assert any(n.startswith("sigma_v of 1 zone(s)") and "r2" in n for n in notes)
    # a zone's own parameters report their bounds; the hallway's aperture is on its bound
    # in one of the two problems that fit it, and their median (3.0) is not
    assert bounds == ["sigma_v[r1] at its lower bound 0.0001 [K]"]


def test_a_median_on_the_bound_most_problems_reached_is_reported_there(small_spec):
    low = "lower bound 0.1 [W s^0.5]"
    res = [_res("r1", {"sigma_q[r1]": 400.0, "sigma_q[hallway]": 0.1, "tau_g": 600.0},
                bounds=[f"sigma_q[hallway] at its {low}", "tau_g at its lower bound 600 [s]"]),
           _res("r2", {"sigma_q[r2]": 300.0, "sigma_q[hallway]": 0.1, "tau_g": 2000.0},
                bounds=[f"sigma_q[hallway] at its {low}"]),
           _res("r3", {"sigma_q[r3]": 200.0, "sigma_q[hallway]": 900.0, "tau_g": 3000.0})]
    out, bounds, _ = combine_zone_params(small_spec, res)
    assert out["sigma_q[hallway]"] == 0.1 and out["tau_g"] == 2000.0
    # the hallway's heat noise: on its bound in 2 of 3 problems, and so is the median; the
    # building-level tau_g: in 1 of 3, its median 2000 s is not
    assert bounds == [f"sigma_q[hallway] at its {low} (in 2 of 3 local problems)"]


@pytest.fixture(scope="module")
def corridor_local(tmp_path_factory):
    """A 9-zone corridor (8 offices, unmeasured hallway), 6 days, identified by local
    problems with the whole-building refit switched off (as above refit_max_states): three
    air paths kept."""
    from thermctl.identify import EstimationOptions, IdentifyOptions, SplitOptions, identify
    from thermctl.spec import load_spec
    out = tmp_path_factory.mktemp("corr9")
    generate("corridor", zones=9, days=6, seed=1).write(out)
    spec = load_spec(out / "building.yaml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meas = read_measurements(out / "data.csv", spec)
        ida = identify(meas, IdentifyOptions(estimation=EstimationOptions(intervals="none"),
                                             split=SplitOptions(scale="local", workers=2,
                                                                refit_max_states=0)))
    return spec, ida, out


def test_a_local_model_exports_its_disturbances_and_a_stable_filter(corridor_local):
    from thermctl.export import disturbances, export_point, kalman_filter
    spec, ida, _ = corridor_local
    model = ida.model
    assert ida.greybox is None and model.meta["greybox"]["source"] == "local"
    assert len(model.network.convection_edges) >= 2       # the path with air paths
    from thermctl.outputs import identification_document
    doc = identification_document(ida)
    assert "one local problem per measured zone" in doc["method"] and "SIN" not in doc["method"]
    # the report lists the parameters the summary may point to
    table = next(b for b in doc["report"] if b["section"] == "Parameters")
    assert {r["parameter"] for r in table["content"]} == set(model.meta["greybox"]["params"])
    assert any(n.startswith("solar apertures and noise") for n in ida.notes)
    p = model.meta["greybox"]["params"]
    assert all(f"sigma_q[{z}]" in p for z in model.network.zones)
    assert all(f"sigma_v[{z}]" in p for z in spec.measured_zones)
    # the solar input of the export heats every zone by its aperture
    dist = disturbances(model)
    assert dist.names == ["solar[south]"]
    ap = {z: p[f"aperture[{z},south]"] for z in model.network.zones}
    cz = 1.0 / np.asarray(model.sym.inv_cz, float)
    np.testing.assert_allclose(dist.E[:model.network.n_zones, 0],
                               [ap[z] / c for z, c in zip(model.network.zones, cz)], rtol=1e-12)
    point = export_point(model, {"ms": 0.05, "Ts": 14.0, "T": 10.0})
    kf = kalman_filter(model, point.op, dt=600.0)
    assert kf is not None and np.isfinite(kf.K).all()
    # the stationary filter's error dynamics (I - K C) Φ are stable
    rho = max(abs(np.linalg.eigvals((np.eye(len(kf.states)) - kf.K @ kf.C) @ kf.Phi)))
    assert rho < 1.0
    # above the state limit the dense discrete filter is left out, and said
    big = kalman_filter(model, point.op, dt=600.0, max_states=len(kf.states) - 1)
    assert big.K is None and big.dt is None and "no stationary gain" in big.note
    assert np.array_equal(big.Qc, kf.Qc) and not kf.note


def test_the_local_filter_is_close_to_a_whole_building_fit_of_the_same_parameters(
        corridor_local):
    """Two estimates of the same noise and apertures (the structure and R̄_v held): each
    zone's from its own local problem, and all at once by the whole building's likelihood.
    Measured here: 0.0031 nats per observation apart, k-step RMSE 0.201 / 0.610 K against
    0.203 / 0.654 K at 1 / 6 h, sensor noises 0.97-1.03× (13 zones, 14 days: 0.010 nats,
    +3 % at 1 h, -2 % at 6 h)."""
    from thermctl.estimate.likelihood import LikelihoodEstimator, kstep_errors
    from thermctl._blas import single_thread_blas
    from thermctl.validate import _physical_fix
    spec, ida, _ = corridor_local
    model = ida.model
    p = model.meta["greybox"]["params"]
    fix, per_edge = _physical_fix(model)
    assert per_edge and len(fix) == len(model.network.convection_edges) + 1   # R̄_v's, τ0
    est = LikelihoodEstimator(model.network, fix=fix, per_edge=per_edge, solar=True,
                              noise="zone", fit_rows="all",
                              rbar_v=np.asarray(model.rbar_v, float))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.fit(ida.calibration, init=p)
    pb = est.problem_
    assert set(pb.layout.names) - set(fix) <= set(p)      # the local set names every one
    with single_thread_blas():
        eta_local = pb.layout.eta_from(p, est.eta_)
        gap = (pb.nll(eta_local) - est.nll_) / pb.n_obs
        pv = est.problem_for(ida.validation)
        k_local = kstep_errors(pv, eta_local, horizons=[3600.0, 6 * 3600.0]).rmse_mean
        k_whole = kstep_errors(pv, est.eta_, horizons=[3600.0, 6 * 3600.0]).rmse_mean
    assert 0.0 <= gap < 0.02
    assert np.all(k_local < 1.1 * k_whole), (k_local, k_whole)
    ratio = [p[f"sigma_v[{z}]"] / est.params_[f"sigma_v[{z}]"] for z in spec.measured_zones]
    assert 0.8 < min(ratio) and max(ratio) < 1.25, ratio


def test_a_problem_without_candidates_still_fits_its_zones_parameters(corridor_local):
    """Nothing to select, but its zone's noise and aperture come from this one fit; a
    problem whose structure rule proposed nothing keeps its reasons too."""
    from dataclasses import replace

    from thermctl.local import fit_local
    spec, ida, _ = corridor_local
    p = ida.local.problems[0]
    frame = ida.calibration.frame
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = fit_local(replace(p, candidates=()), frame)
        q = fit_local(replace(p, proposed=()), frame)
    for res in (r, q):
        assert res.edges == [] and res.n_fits == 1 and res.error is None
        assert {f"sigma_v[{p.zone}]", f"sigma_q[{p.zone}]", f"aperture[{p.zone},south]"} \
            <= set(res.params)
    assert r.reasons == {} and set(q.reasons.values()) == {"out: not proposed"}


def test_a_zones_own_capacity_factor_scales_its_capacitance(small_spec):
    from thermctl.local import LocalIdentification
    res = [_res("r1", {"cap_factor[r1]": 3.0, "sigma_v[r1]": 0.02}),
           _res("r3", {"cap_factor[r3]": 2.0, "cap_factor[r1]": 9.0})]
    li = LocalIdentification([], res, [], [], {}, float("nan"), "both", 0.0, 0.0)
    fs = li.fitted_spec(small_spec)
    assert fs.zone_capacitance("r1") == pytest.approx(3.0 * small_spec.zone_capacitance("r1"))
    assert fs.zone_capacitance("r3") == pytest.approx(2.0 * small_spec.zone_capacitance("r3"))
    assert fs.zone_capacitance("r2") == small_spec.zone_capacitance("r2")


def test_validate_filters_a_large_local_model_with_local_noise(corridor_local, tmp_path,
                                                              monkeypatch):
    """Above the whole-building limit a local model's k-step errors come from local noise
    fits (the conduction-only model's fitted per zone), not from whole-building fits."""
    import json

    from typer.testing import CliRunner

    import thermctl.validate as V
    from thermctl.cli import app
    from thermctl.outputs import write_outputs
    spec, ida, out = corridor_local
    write_outputs(ida, tmp_path / "run")
    monkeypatch.setattr(V, "KSTEP_MAX_STATES", 10)      # this model has more states
    res = CliRunner().invoke(app, ["validate", str(tmp_path / "run" / "model.json"),
                                   str(out / "data.csv"), "--hours", "24"])
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "run" / "validation.json").read_text())
    assert any("from local fits" in n and "the truth's not computed" in n for n in doc["notes"])
    ks = doc["kstep_rmse"]
    assert set(ks) == {"identified", "conduction-only"}
    for r in ks.values():
        m = np.array(r["rmse_mean"], float)
        assert np.all(np.isfinite(m[:2])) and m[0] < m[1]      # 1 h better than 6 h


@pytest.mark.slow
def test_local_kstep_filters_agree_with_whole_building_fits(corridor_local):
    """The same comparison two ways: each model's noise from local fits (one level per zone),
    and from a whole-building maximum-likelihood fit (one level for the building, what
    validate does up to 150 states). Measured: identified 0.201 / 0.610 K against
    conduction-only 0.233 / 0.843 K at 1 / 6 h locally (14 %, 28 % better), 0.220 / 0.870
    against 0.264 / 1.069 K by whole-building fits (17 %, 19 %)."""
    from thermctl.cli.pipeline import _local_kstep_params
    from thermctl.model import ThermalModel
    from thermctl.validate import kstep_validation
    spec, ida, _ = corridor_local
    model = ida.model
    models = {"identified": model,
              "conduction-only": ThermalModel(model.network.conduction_only(), meta={})}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        local = kstep_validation(models, ida.calibration, ida.validation, (1.0, 6.0),
                                 params=_local_kstep_params(model, ida.calibration))
        whole = kstep_validation(models, ida.calibration, ida.validation, (1.0, 6.0))
    gain = {}
    for way, ks in (("local", local), ("whole", whole)):
        gain[way] = 1.0 - ks["identified"].rmse_mean / ks["conduction-only"].rmse_mean
        assert np.all(gain[way] > 0.05), (way, gain[way])      # both see the air paths help
    assert np.all(np.abs(gain["local"] - gain["whole"]) < 0.12), gain
    for name in models:         # per-zone local noise filters no worse than one shared level
        assert np.all(local[name].rmse_mean < 1.05 * whole[name].rmse_mean), name
