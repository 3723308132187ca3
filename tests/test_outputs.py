"""Output directories: one run's outputs are never mixed with another's (issue 22, item 3)."""

import json
from types import SimpleNamespace

import numpy as np
import pytest

from thermctl.validate import verdict
from thermctl.errors import DataError
from thermctl.identify import Identification, IdentifyOptions
from thermctl.outputs import (check_consistent, check_outdir, staged_output, validation_document,
                              write_outputs)


def _ident(model):
    """An Identification without running one: no structure, no estimate (no figures drawn)."""
    quality = SimpleNamespace(to_dict=lambda: {}, summary=lambda: "no gaps")
    meas = SimpleNamespace(quality=quality)
    return Identification(model=model, structure=None, estimate=None, grid=None, calibration=meas,
                          validation=meas, options=IdentifyOptions())


def _vr(zones=("z1",)):
    """The fields of a ValidationReport that validation_document reads."""
    ol = SimpleNamespace(zones=list(zones), rmse={z: 0.5 for z in zones},
                         max_abs={z: 1.0 for z in zones}, rmse_mean=0.5)
    return SimpleNamespace(open_loop={"identified": ol, "conduction-only": ol}, step_errors={},
                           step_responses={}, horizons_h=(1.0, 6.0, 24.0), kstep={}, units="K",
                           window=("2011-02-01", "2011-02-03"), zones=list(zones),
                           to_data_units=lambda v: v, verdict=verdict(0.0, {}), notes=[])


def _copy(model):
    """A second identification of the same building (a re-run)."""
    m = model.__class__(model.network, model.rbar_v, model.c_v, meta={})
    return m


def _write_validation(outdir, run_id):
    (outdir / "validation.json").write_text(json.dumps({"identification_run_id": run_id}))


def test_run_id_in_identification_and_model(small_model, tmp_path):
    write_outputs(_ident(small_model), tmp_path)
    ident = json.loads((tmp_path / "identification.json").read_text())
    model = json.loads((tmp_path / "model.json").read_text())
    assert len(ident["run_id"]) == 16 and int(ident["run_id"], 16) >= 0
    assert model["meta"]["run_id"] == ident["run_id"] == small_model.meta["run_id"]
    assert check_consistent(tmp_path) == []


def test_rerun_removes_stale_validation_and_figures(small_model, tmp_path):
    write_outputs(_ident(small_model), tmp_path)
    first = small_model.meta["run_id"]
    # what validate of the first run leaves: its document and figures
    _write_validation(tmp_path, first)
    (tmp_path / "figures").mkdir()
    (tmp_path / "figures" / "openloop-z1.png").write_bytes(b"png")
    (tmp_path / "figures" / "mine.png").write_bytes(b"a user's file")
    (tmp_path / "figures.json").write_text(json.dumps(
        [{"name": "openloop-z1", "section": "Validation", "caption": ""}]))
    (tmp_path / "report.html").write_text("<html>old</html>")
    (tmp_path / "notes.txt").write_text("a user's file")
    assert check_consistent(tmp_path) == []

    second = _copy(small_model)
    write_outputs(_ident(second), tmp_path)
    assert second.meta["run_id"] != first
    for stale in ("validation.json", "figures.json", "report.html", "figures/openloop-z1.png"):
        assert not (tmp_path / stale).exists(), stale
    # files thermctl did not write are kept
    assert (tmp_path / "notes.txt").read_text() == "a user's file"
    assert (tmp_path / "figures" / "mine.png").exists()
    assert json.loads((tmp_path / "identification.json").read_text())["run_id"] == second.meta["run_id"]
    assert check_consistent(tmp_path) == []
    assert not [p for p in tmp_path.parent.iterdir() if p.name.startswith(f".{tmp_path.name}.")], \
        "staging or backup directory left behind"


def test_foreign_directory_is_refused(small_model, tmp_path):
    (tmp_path / "data.csv").write_text("time,T\n")
    with pytest.raises(DataError, match="no thermctl outputs.*data.csv"):
        write_outputs(_ident(small_model), tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data.csv"]
    assert "\n" not in str(pytest.raises(DataError, check_outdir, tmp_path).value)


def test_hidden_files_and_demo_testbed_are_not_foreign(small_model, tmp_path):
    (tmp_path / ".gitignore").write_text("*\n")
    (tmp_path / "testbed").mkdir()
    (tmp_path / "testbed" / "data.csv").write_text("time,T\n")
    write_outputs(_ident(small_model), tmp_path)
    assert (tmp_path / "testbed" / "data.csv").exists() and (tmp_path / ".gitignore").exists()


def test_output_path_that_is_a_file_is_refused(small_model, tmp_path):
    (tmp_path / "out").write_text("")
    with pytest.raises(DataError, match="not a directory"):
        write_outputs(_ident(small_model), tmp_path / "out")


def test_check_consistent_flags_validation_of_another_run(small_model, tmp_path):
    write_outputs(_ident(small_model), tmp_path)
    _write_validation(tmp_path, "0123456789abcdef")
    problems = check_consistent(tmp_path)
    assert len(problems) == 1 and problems[0].startswith("validation.json")
    assert "0123456789abcdef" in problems[0] and small_model.meta["run_id"] in problems[0]
    # a validation written before run ids cannot be matched either
    (tmp_path / "validation.json").write_text(json.dumps({"format": "thermctl-validation"}))
    assert ["validation.json" in p for p in check_consistent(tmp_path)] == [True]


def test_check_consistent_flags_model_of_another_run(small_model, tmp_path):
    write_outputs(_ident(small_model), tmp_path)
    doc = json.loads((tmp_path / "model.json").read_text())
    doc["meta"]["run_id"] = "fedcba9876543210"
    (tmp_path / "model.json").write_text(json.dumps(doc))
    assert [p.split(" ")[0] for p in check_consistent(tmp_path)] == ["model.json"]


def test_check_consistent_without_run_ids_or_outputs(tmp_path):
    assert check_consistent(tmp_path) == []
    (tmp_path / "identification.json").write_text("{}")   # from before run ids: cannot tell
    _write_validation(tmp_path, None)
    assert check_consistent(tmp_path) == []
    (tmp_path / "validation.json").write_text("{not json")
    assert check_consistent(tmp_path)[0].startswith("validation.json: unreadable")


def test_validation_document_names_its_identification(small_model):
    small_model.meta["run_id"] = "00112233aabbccdd"
    doc = validation_document(_vr(), small_model)
    assert doc["identification_run_id"] == "00112233aabbccdd"
    assert validation_document(_vr())["identification_run_id"] is None


def test_validate_into_another_runs_directory_is_refused(small_model, tmp_path):
    write_outputs(_ident(small_model), tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(DataError, match="validation.json belongs to identification run"):
        with staged_output(tmp_path) as tmp:
            _write_validation(tmp, "0123456789abcdef")
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    # the model's own run adds its validation
    with staged_output(tmp_path) as tmp:
        _write_validation(tmp, small_model.meta["run_id"])
    assert check_consistent(tmp_path) == []


def test_failed_write_leaves_the_earlier_run(small_model, tmp_path):
    write_outputs(_ident(small_model), tmp_path)
    _write_validation(tmp_path, small_model.meta["run_id"])
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    with pytest.raises(RuntimeError):
        with staged_output(tmp_path, replace=True) as tmp:
            (tmp / "model.json").write_text("{}")
            raise RuntimeError("identification failed half way")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    assert np.isfinite(json.loads(before["model.json"])["parameters"]["c_v"]).all()
