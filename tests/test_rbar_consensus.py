"""One R̄_v for the building: combined local air paths far from the building's median go."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from thermctl.errors import DataError, EstimationError
from thermctl.identify import EstimationOptions, IdentifyOptions, SplitOptions, identify
from thermctl.local import (ONE_SIDED, RBAR_WINDOW, EdgeVerdict, LocalResult, assemble,
                            local_problems, rbar_consensus)
from thermctl.network import air_path_name
from thermctl.testbed import corridor_for_zones, generate


def _verdict(a, b, rb, d=5.0, kept=True):
    return EdgeVerdict(a, b, d, kept, {a: -30.0, b: -20.0}, rb, "in by rule 'both': ...")


def _building(seed=0):
    """14 paths whose R̄_v scatter ×0.7–1.4 around 3.3e-4 (as the true paths kept on the
    196-zone corridor do) and 4 at ×0.2–0.4 of it (as the false ones between offices on one
    side of a corridor), a path kept without a local R̄_v and one left out."""
    rng = np.random.default_rng(seed)
    good = 3.3e-4 * np.exp(rng.uniform(np.log(0.7), np.log(1.4), 14))
    bad = 3.3e-4 * np.array([0.2, 0.25, 0.3, 0.4])
    vs = [_verdict(f"n{i:02d}", f"s{i:02d}", float(r)) for i, r in enumerate(good)]
    vs += [_verdict(f"n{i:02d}", f"n{i + 2:02d}", float(r), d=9.0) for i, r in enumerate(bad)]
    vs += [_verdict("x0", "x1", float("nan")), _verdict("y0", "y1", float("nan"), kept=False)]
    return vs, good, bad


def test_paths_far_below_the_building_value_go_and_the_median_settles_on_the_rest():
    vs, good, bad = _building()
    out, med = rbar_consensus(vs)
    kept = {v.name for v in out if v.kept}
    assert kept == {v.name for v in vs[:14]} | {"air:x0-x1"}
    # the settled value is the median of the paths that share it, not of all 18: the false
    # ones pull the first median down (to about ×0.9 here)
    assert med == pytest.approx(math.exp(np.median(np.log(good))), rel=1e-12)
    first = math.exp(np.median(np.log(np.r_[good, bad])))
    assert first < 0.95 * med
    for v, r in zip(out[14:18], bad):
        assert not v.kept and math.isnan(v.rbar_v)
        assert f"×{r / med:.2f} the building's" in v.reason and "in by rule 'both'" in v.reason
        # the conductance it carries against a door of its length at the building's R̄_v
        assert f"{med / r:.1f}× the conductance" in v.reason and "9.0 m long" in v.reason
    # the paths that were not judged are as they were
    assert out[18] == vs[18] and out[19] == vs[19]


def test_the_window_is_symmetric_in_log_and_its_edge_is_kept():
    base = [_verdict(f"a{i}", f"b{i}", 3e-4) for i in range(9)]
    edge = [_verdict("c0", "d0", 3e-4 / RBAR_WINDOW), _verdict("c1", "d1", 3e-4 * RBAR_WINDOW)]
    past = [_verdict("e0", "f0", 3e-4 / 2.2), _verdict("e1", "f1", 3e-4 * 2.2)]
    out, med = rbar_consensus(base + edge + past)
    assert med == pytest.approx(3e-4)
    assert [v.kept for v in out[9:]] == [True, True, False, False]


def test_too_few_paths_or_no_window_judge_nothing():
    vs, _, _ = _building()
    few = vs[:5] + vs[14:16]            # 7 paths with an R̄_v, two of them far below
    out, med = rbar_consensus(few)
    assert out == few and math.isnan(med)
    out, med = rbar_consensus(vs, window=None)
    assert out == vs and math.isnan(med)
    for w in (1.0, 0.5):
        with pytest.raises(EstimationError, match="factor above 1"):
            rbar_consensus(vs, window=w)
    with pytest.raises(DataError, match="split.rbar_window"):
        SplitOptions(rbar_window=1.0).check()
    with pytest.raises(DataError, match="split.search_again must be true or false"):
        SplitOptions(search_again="no").check()


def _made_up(probs, true_edges, spread=0.15):
    """Local results on real local problems, made up: every true path kept at both ends with
    R̄_v near 3.4e-4 (log-normal, ``spread``), and one pair of north offices on floor 1 at a
    quarter of it; every other candidate out. Returns (results, that pair's name)."""
    true = {air_path_name(a, b) for a, b, *_ in true_edges}
    rng = np.random.default_rng(1)
    rb = {nm: float(3.4e-4 * np.exp(rng.normal(0.0, spread))) for nm in sorted(true)}
    cand = {air_path_name(a, b) for p in probs for a, b, _ in p.candidates}
    false = next(nm for nm in sorted(cand - true) if nm[4:6] == nm[10:12] == "f1"
                 and nm[6] == nm[12] == "n")          # two offices on the north side
    rb[false] = 0.85e-4
    res = []
    for p in probs:
        mine = [air_path_name(a, b) for a, b, _ in p.candidates]
        kept = [nm for nm in mine if nm in rb]
        res.append(LocalResult(p.zone, kept, {nm: (-40.0 if nm in rb else 5.0) for nm in mine},
                               {nm: rb[nm] for nm in kept}, 2.0, 10, cpu=1.0))
    return res, false


def test_assemble_leaves_a_path_out_of_the_model_and_says_why():
    """On the 49-zone corridor's local problems, with made-up local verdicts (_made_up)."""
    lay = corridor_for_zones(49, seed=0)
    probs = local_problems(lay.spec)
    true = {air_path_name(a, b) for a, b, _ in lay.edges}
    res, false = _made_up(probs, lay.edges)
    li = assemble(probs, res)
    assert {air_path_name(a, b) for a, b, _ in li.edges} == true
    assert false not in li.rbar_v and set(li.rbar_v) == true
    why = li.reasons[false]
    assert why.startswith("out by R̄_v: in by rule 'both'") and "×0.2" in why
    # switched off, the pair is in, as the rule of both ends says
    off = assemble(probs, res, rbar_window=None)
    assert {air_path_name(a, b) for a, b, _ in off.edges} == true | {false}


@pytest.mark.slow
def test_on_the_196_zone_corridor_the_test_takes_false_paths_only():
    """Seed 0, 14 days (benchmarks/scale.py's building): the window takes false paths only
    (19 in session 45), and the model holds 44 of the 51 true paths and 13 false ones (32
    and 10 by the AND rule alone, session 38; 20 false without the window)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate(building="corridor", zones=196, days=14, seed=0)
        from thermctl.data import read_measurements
        meas = read_measurements(tb.data, tb.spec, name="corridor 196")
        ident = identify(meas, IdentifyOptions(estimation=EstimationOptions(intervals="none"),
                                               split=SplitOptions(scale="local", workers=2)))
    true = {air_path_name(a, b) for a, b, _ in tb.truth.edges}
    dropped = {v.name for v in ident.local.verdicts if v.reason.startswith("out by R̄_v")}
    kept = {e.name for e in ident.model.network.convection_edges}
    assert len(dropped) >= 8 and not dropped & true
    assert len(kept & true) >= 40 and len(kept - true) <= 15


def test_settle_searches_the_ends_of_a_path_out_by_rbar_again_without_it():
    """A 49-zone corridor, 6 days: first-round verdicts made up as in the test above (one
    same-side pair at a quarter of the building's R̄_v); the two problems at its ends are
    searched again, for real, without it, and the others keep their results."""
    from thermctl.data import read_measurements
    from thermctl.local import OUT_BY_RBAR, settle
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate(building="corridor", zones=49, days=6, seed=0)
        meas = read_measurements(tb.data, tb.spec, name="corridor 49")
    probs = local_problems(meas.spec, meas.frame.columns)
    res, false = _made_up(probs, tb.truth.edges)
    ends = {false[4:9], false[10:15]}
    # again=False: assemble alone, nothing searched
    li0, probs0, res0 = settle(probs, res, meas.frame, again=False, margin=10.0)
    assert all(a is b for a, b in zip(res0, res)) and all(a is b for a, b in zip(probs0, probs))
    assert false not in li0.rbar_v and next(v for v in li0.verdicts if v.name == false).out_by_rbar
    li, probs2, res2 = settle(probs, res, meas.frame, workers=1, margin=10.0, min_t=2.0)
    again = [i for i, p in enumerate(probs) if p.zone in ends]
    assert len(again) == 2
    for i, (p, r) in enumerate(zip(probs2, res2)):
        if i in again:
            # searched again, for real, and the path is no longer a candidate there
            assert false not in {air_path_name(a, b) for a, b, _ in p.candidates}
            assert r.n_fits > 0 and r.error is None and r is not res[i]
            assert len(p.candidates) == len(probs[i].candidates) - 1
        else:
            assert p is probs[i] and r is res[i]
    v = next(v for v in li.verdicts if v.name == false)
    assert not v.kept and v.reason.startswith(OUT_BY_RBAR)
    assert false not in {air_path_name(a, b) for a, b, _ in li.edges}
    assert li.cpu > sum(r.cpu for r in res)         # the second searches are counted


def test_identify_says_which_paths_are_out_by_rbar():
    """The note of a local identification names the paths put out and their ratio."""
    from thermctl.identify import _rbar_window_note
    lay = corridor_for_zones(49, seed=0)
    probs = local_problems(lay.spec)
    res, false = _made_up(probs, lay.edges, spread=0.0)
    li = assemble(probs, res)
    assert li.rbar_v_building == pytest.approx(3.4e-4) and li.rbar_window == RBAR_WINDOW
    notes = []
    _rbar_window_note(li, notes)
    assert len(notes) == 1
    assert "1 air path(s) both ends kept are out" in notes[0]
    assert f"{false} (×0.25)" in notes[0] and "0.00034 K/(W m)" in notes[0]
    notes = []
    _rbar_window_note(assemble(probs, res, rbar_window=None), notes)
    assert notes == []


def test_a_path_put_out_carries_its_ratio():
    vs, good, bad = _building()
    out, med = rbar_consensus(vs)
    assert [v.rbar_ratio for v in out[14:18]] == pytest.approx(list(bad / med), rel=1e-12)
    assert all(math.isnan(v.rbar_ratio) for v in out[:14] + out[18:])
    assert [v.out_by_rbar for v in out] == [False] * 14 + [True] * 4 + [False] * 2


@pytest.mark.parametrize("args, window, again, one_sided", [
    ([], RBAR_WINDOW, False, ONE_SIDED),
    (["--local-rbar-window", "0"], None, False, ONE_SIDED),
    (["--local-rbar-window", "3", "--local-search-again"], 3.0, True, ONE_SIDED),
    (["--local-one-sided", "inf"], RBAR_WINDOW, False, math.inf),
    (["--local-one-sided", "45.5"], RBAR_WINDOW, False, 45.5),
])
def test_cli_options_reach_the_split_options(identify_split, args, window, again, one_sided):
    """``thermctl identify`` hands --local-rbar-window (0: off), --local-search-again and
    --local-one-sided (inf: never) to ``split``."""
    split = identify_split(*args)
    assert split.rbar_window == window and split.search_again is again
    assert split.one_sided == one_sided
