"""The report opens with the verdict and the next step, and reads like the console (issue 22, item 5).

The fixture directory holds what ``thermctl identify`` and ``thermctl validate`` write
(trimmed): a grey-box fit with τ0 on its upper bound and 42 solar apertures, 40 of them 0,
a one-step selection path, an identifiability verdict, six measured zones of which four
have open-loop traces, and step-response errors as fractions.
"""

from __future__ import annotations

import json
import re
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from thermctl.report import build_report, save_figure  # noqa: E402

ZONES = ["r240", "r241", "r242", "r243", "r244", "r247"]
SOLAR = ["solar_s", "solar_w", "solar_e", "solar_n", "solar_h", "solar_d", "solar_x"]
VERDICTS = {
    "rbar_v": "R̄_v = 0.000296 K/(W m), 90 % interval [0.000262, 0.000338] K/(W m) (profile): "
              "identified (within ±14 %).",
    "tau0": "τ0 = R̄_v·C_v = 2.03 s/m, 90 % interval [0.405, 2.03] s/m (profile): NOT identifiable "
            "from these data — the criterion changes by less than the 90 % threshold over the whole "
            "allowed range; the value is where the optimiser stopped, not a measurement.",
}


def _identification(run_id="run-a"):
    params = {"rbar_v": 0.000296, "tau0": 2.026, "sigma_v": 0.0527, "sigma_q": 246.3,
              "sigma_phi": 0.48}
    at_bounds = ["tau0 at its upper bound 2.02642 [s/m]"]
    for z in ZONES:
        for s in SOLAR:
            name = f"aperture[{z},{s}]"
            params[name] = {("r240", "solar_s"): 1.25, ("r243", "solar_w"): 0.4}.get((z, s), 0.0)
            if params[name] == 0.0:
                at_bounds.append(f"{name} at its lower bound 0 [m²]")
    blocks = [
        {"section": "Data quality", "kind": "text", "title": "Summary",
         "content": "data.csv: 7488 rows, 2011-01-21 00:00 to 2011-02-15 23:55 (UTC-05:00), step 5 min\n"
                    "grid: 7488 samples × 24 columns; 0 duplicate rows removed (0 conflicting, averaged); "
                    "0 rows out of order; 0 off-grid stamps; " + "a long line that must wrap " * 12},
        {"section": "Structure", "kind": "table", "title": "Model-based selection (BIC, margin 10)",
         "content": [{"step": "keep", "edge": "", "BIC": -49816.3, "change": 108.7,
                      "note": "removing any edge costs more than the margin 10"}]},
        {"section": "Parameters", "kind": "table",
         "title": "Grey-box estimate (likelihood, 18000 observations, rows: supply_off)",
         "content": [{"parameter": k, "value": v} for k, v in params.items()]},
        {"section": "Parameters", "kind": "text", "title": "Identifiability",
         "content": "\n".join(VERDICTS.values())},
    ]
    return {"format": "thermctl-identification", "version": 2, "run_id": run_id,
            "model": {"rbar_v": 0.000296, "c_v": 6837.0},
            "structure": {"selection": {
                "criterion": "bic", "margin": 10.0,
                "candidates": ["air:r240-r243", "air:r241-r247", "air:r242-r244"],
                "path": [{"action": "keep", "edge": None, "value": -49816.3, "delta": 108.7,
                          "note": "removing any edge costs more than the margin 10"}]}},
            "greybox": {"criterion": "likelihood", "params": params, "n_obs": 18000,
                        "rows": "supply_off", "active_bounds": at_bounds,
                        "intervals": {"rbar_v": {"value": 0.000296, "lower": 0.000262,
                                                 "upper": 0.000338, "level": 0.9, "unit": "K/(W m)",
                                                 "identifiable": True},
                                      "tau0": {"value": 2.026, "lower": 0.405, "upper": 2.026,
                                               "level": 0.9, "unit": "s/m", "identifiable": False}},
                        "verdicts": VERDICTS},
            "report": blocks}


def _validation(verdict=None, run_id="run-a"):
    rows = [{"zone": z, "RMSE identified": 0.4, "RMSE conduction-only": 0.5} for z in ZONES]
    doc = {"format": "thermctl-validation", "version": 1, "identification_run_id": run_id,
           "window": ["2011-02-10 00:00:00-05:00", "2011-02-11 23:55:00-05:00"], "units": "°C",
           "open_loop": rows, "rmse_mean": {"identified": 0.40, "conduction-only": 0.50},
           "kstep_rmse": {"identified": {"horizons_s": [3600.0, 21600.0, 86400.0],
                                         "rmse_mean": [0.30, 1.0, 2.0]},
                          "conduction-only": {"horizons_s": [3600.0, 21600.0, 86400.0],
                                              "rmse_mean": [0.36, 1.2, 2.1]}},
           "report": [
               {"section": "Validation", "kind": "table", "title": "Per-zone error", "content": rows},
               {"section": "Validation", "kind": "table",
                "title": "Step-response error vs the truth (relative Frobenius norm)",
                "content": [{"model": "identified", "1 h": 0.02758, "6 h": 0.0191},
                            {"model": "conduction-only", "1 h": 0.4591, "6 h": 0.6378}]},
           ]}
    if verdict is not None:
        doc["verdict"] = verdict
    return doc


def _fig():
    fig = Figure(figsize=(3, 2))
    fig.add_subplot().plot([0, 1], [0, 1])
    return fig


@pytest.fixture
def outdir(tmp_path):
    (tmp_path / "identification.json").write_text(json.dumps(_identification()))
    (tmp_path / "validation.json").write_text(json.dumps(_validation()))
    save_figure(_fig(), tmp_path, "network", "Structure", "The network.")
    for z in ZONES[:4]:
        save_figure(_fig(), tmp_path, f"openloop-{z}", "Validation", f"Open loop of {z}.")
    return tmp_path


def _html(outdir):
    return build_report(outdir).read_text()


def _body(page):
    return page.split("<body>", 1)[1]


def test_verdict_and_next_step_come_first(outdir):
    page = _html(outdir)
    first = page.index("<h2>Data quality</h2>")
    # identified wins at 1 h (17 %) and 6 h (17 %): recommended, computed from the RMSEs
    assert page.index("Use the identified model") < first
    assert page.index("Next step") < first
    assert "thermctl export" in page[:first]
    # the interval verdicts are at the top too, with what the data cannot pin down
    assert page.index("NOT identifiable") < first


def test_structured_verdict_from_validation_is_used(outdir):
    v = {"recommendation": "conduction-only", "basis": "kstep", "gains": {"1 h": -0.1},
         "text": "Prefer the conduction-only model: the air paths do not help at 1-6 h."}
    (outdir / "validation.json").write_text(json.dumps(_validation(verdict=v)))
    page = _html(outdir)
    first = page.index("<h2>Data quality</h2>")
    assert page.index("the air paths do not help at 1-6 h") < first
    assert "Use the identified model" not in page
    assert "conduction-only model" in page[page.index("Next step"):first]
    # an older, plain-text verdict is shown as it is
    (outdir / "validation.json").write_text(json.dumps(_validation(verdict="Keep it simple.")))
    page = _html(outdir)
    assert page.index("Keep it simple.") < page.index("<h2>Data quality</h2>")


def test_without_validation_the_next_step_is_to_validate(outdir):
    (outdir / "validation.json").unlink()
    page = _html(outdir)
    first = page.index("<h2>Data quality</h2>")
    assert page.index("Not validated yet") < first
    assert "thermctl validate" in page[:first]


def test_no_clipped_blocks(outdir):
    body = _body(_html(outdir))
    # multi-line text wraps instead of scrolling sideways in a <pre>
    assert "<pre" not in body
    assert "a long line that must wrap" in body
    assert "white-space:pre-wrap" in _html(outdir)  # and any <pre> would wrap too


def _param_rows(page):
    table = page[page.index("<h3>Grey-box estimate"):]
    table = table[:table.index("</table>")]
    rows = re.findall(r"<tr( class='bound')?>(.*?)</tr>", table)
    return [(bool(b), re.findall(r"<td[^>]*>(.*?)</td>", r)) for b, r in rows[1:]]


def test_parameters_have_units(outdir):
    rows = {cells[0]: cells for _, cells in _param_rows(_html(outdir))}
    assert "K/(W m)" in rows["rbar_v"]
    assert "s/m" in rows["tau0"]
    assert "J/K" in rows["c_v"]  # C_v = τ0/R̄_v, derived
    assert "K" in rows["sigma_v"]
    assert "W s^0.5" in rows["sigma_q"]
    assert "W/s^0.5" in rows["sigma_phi"]
    assert "m²" in rows["aperture[r240,solar_s]"]
    # and the interval of the identified ones
    assert "[0.000262, 0.000338]" in rows["rbar_v"]


def test_parameters_at_bounds_are_flagged(outdir):
    page = _html(outdir)
    flagged = {cells[0] for bound, cells in _param_rows(page) if bound}
    assert flagged == {"tau0", "c_v"}  # c_v is τ0/R̄_v: set by τ0's bound
    top = page[:page.index("<h2>Data quality</h2>")]
    assert "tau0 = 2.03 s/m: at its upper bound 2.03 s/m" in top
    assert "c_v" in top


def test_apertures_summarised(outdir):
    rows = _param_rows(_html(outdir))
    names = [cells[0] for _, cells in rows]
    assert [n for n in names if n.startswith("aperture[r")] == ["aperture[r240,solar_s]",
                                                                "aperture[r243,solar_w]"]
    summary = [cells for _, cells in rows if cells[0].startswith("aperture[…]")]
    assert summary and "40 others" in summary[0][0] and summary[0][2] == "0"
    assert len(rows) < 12  # not 42 aperture rows


def test_truncated_traces_say_so(outdir):
    page = _html(outdir)
    assert "first 4 of 6 measured zones shown" in page
    # all zones traced: nothing to say
    save_figure(_fig(), outdir, "openloop-r244", "Validation", "r244")
    save_figure(_fig(), outdir, "openloop-r247", "Validation", "r247")
    assert "measured zones shown" not in _html(outdir)


def test_relative_errors_in_percent(outdir):
    page = _html(outdir)
    table = page[page.index("Step-response error"):]
    table = table[:table.index("</table>")]
    assert "45.9 %" in table and "2.8 %" in table
    assert "0.4591" not in table


def test_one_step_selection_is_a_sentence(outdir):
    page = _html(outdir)
    assert "<th>step</th>" not in page
    i = page.index("Model-based selection (BIC, margin 10)")
    assert "none removed" in page[i:i + 600]
    assert "removing any edge costs more than the margin 10" in page[i:i + 600]


def test_validation_of_another_run_is_left_out(outdir):
    (outdir / "validation.json").write_text(json.dumps(_validation(run_id="run-b")))
    page = _html(outdir)
    top = page[:page.index("<h2>Data quality</h2>")]
    assert "class='problems'" in top and "run-b" in top
    assert "<h2>Validation</h2>" not in page
    assert "Use the identified model" not in page and "No verdict" in top
    assert "thermctl validate" in top  # the next step: validate this model
    assert "Open loop of r240" not in page


def test_consistency_problems_shown_at_the_top(outdir, monkeypatch):
    outputs = pytest.importorskip("thermctl.outputs")
    monkeypatch.setattr(outputs, "check_consistent",
                        lambda d: ["model.json is older than identification.json"], raising=False)
    page = _html(outdir)
    i = page.index("model.json is older than identification.json")
    assert page.rfind("class='problems'", 0, i) != -1
    assert i < page.index("<h2>Data quality</h2>")
    assert "<h2>Validation</h2>" in page  # run ids match: the validation stays


# ---------------------------------------------------------------------------- network figure
def test_network_labels_fit_inside_their_nodes(small_network):
    from thermctl.plots.structure import plot_network

    sid = SimpleNamespace(graphs_=None, network_=small_network, scores_={("r1", "r3"): 0.5},
                          method="sin", rule="majority")
    fig = plot_network(sid)
    FigureCanvasAgg(fig)
    renderer = fig.canvas.get_renderer()
    ax = fig.axes[0]
    names = set(small_network.zones) | set(small_network.boundary)
    labels = [t for t in ax.texts if t.get_text() in names]
    assert {t.get_text() for t in labels} == names
    for t in labels:
        box = t.get_window_extent(renderer)
        xy = ax.transData.transform(t.get_position())
        node = next(c for c in ax.collections
                    if np.allclose(ax.transData.transform(c.get_offsets()[0]), xy))
        size = np.sqrt(node.get_sizes()[0]) * fig.dpi / 72.0  # diameter or side [px]
        square = t.get_text() in small_network.boundary
        need = max(box.width, box.height) if square else np.hypot(box.width, box.height)
        assert need <= size, f"label {t.get_text()!r} ({need:.0f} px) overflows its node ({size:.0f} px)"


def test_parameter_table_does_not_depend_on_identifys_blocks(outdir):
    doc = _identification()
    doc["report"] = [b for b in doc["report"] if not b["title"].startswith("Grey-box estimate")]
    (outdir / "identification.json").write_text(json.dumps(doc))
    rows = {cells[0]: cells for _, cells in _param_rows(_html(outdir))}
    assert "s/m" in rows["tau0"]


def test_many_parameters_on_one_bound_are_counted_in_the_summary():
    """A large building's local fits leave many zones' noise on a bound: the summary counts
    them per group and bound (the parameter table lists every one); a few stay by name."""
    from thermctl.report import _FLAGS_PER_GROUP, _bound_flags
    n = _FLAGS_PER_GROUP + 2
    rows = [{"parameter": f"sigma_q[z{i}]", "value": "0.1", "unit": "W s^0.5",
             "on a bound": "lower bound 0.1 W s^0.5"} for i in range(n)]
    rows += [{"parameter": "tau0", "value": "2.03", "unit": "s/m",
              "on a bound": "upper bound 2.03 s/m"}]
    out = _bound_flags(rows)
    assert out == [f"sigma_q: {n} parameters at its lower bound 0.1 W s^0.5 (sigma_q[z0], "
                   f"sigma_q[z1], sigma_q[z2], …; every one in the parameter table)",
                   "tau0 = 2.03 s/m: at its upper bound 2.03 s/m"]
    few = _bound_flags(rows[:2])
    assert few == [f"sigma_q[z{i}] = 0.1 W s^0.5: at its lower bound 0.1 W s^0.5" for i in (0, 1)]
