"""Issue 22, item 1: the validation verdict follows every horizon, not the best one.

The verdict is a pure function of the relative RMSE improvements (open loop 48 h, k-step
1/6/24 h); the identified model is recommended only when it wins at the horizons an MPC
uses (1 h and 6 h) by the margin.
"""

from __future__ import annotations

import pytest

from thermctl.validate import relative_words, verdict


def test_twin_house_numbers_recommend_conduction_only():
    # twin house N2 with 8 air paths: worse at 48 h, 1 h and 6 h, better only at 24 h
    v = verdict(-0.10, {1.0: -0.13, 6.0: -0.09, 24.0: 0.11})
    assert v.recommendation == "conduction-only"
    assert v.favours == {"48-h open loop": "conduction-only", "1 h ahead": "conduction-only",
                         "6 h ahead": "conduction-only", "24 h ahead": "identified"}
    assert "support the air paths" not in v.text
    assert "Prefer the conduction-only model" in v.text
    # signs in words: nothing like "-10 % better"
    assert "10 % worse" in v.text and "13 % worse" in v.text and "11 % better" in v.text
    assert "-" + "10 %" not in v.text and "+" not in v.text


def test_identified_recommended_only_when_it_wins_at_1_and_6_h():
    v = verdict(0.02, {1.0: 0.15, 6.0: 0.08, 24.0: -0.02})
    assert v.recommendation == "identified" and v.basis == "kstep"
    assert v.favours["48-h open loop"] == "neither"
    assert "Use the identified model" in v.text


@pytest.mark.parametrize("gains, rec", [
    ({1.0: 0.15, 6.0: 0.03, 24.0: 0.2}, "mixed"),            # 6 h within the margin
    ({1.0: 0.15, 6.0: -0.10, 24.0: 0.2}, "mixed"),           # wins 1 h, loses 6 h
    ({1.0: 0.04, 6.0: -0.04, 24.0: 0.30}, "conduction-only"),  # only 24 h
    ({1.0: 0.051, 6.0: 0.051}, "identified"),
])
def test_mixed_and_margin(gains, rec):
    v = verdict(0.0, gains)
    assert v.recommendation == rec, v.text
    if rec == "mixed":
        assert "Mixed evidence" in v.text


def test_open_loop_only_says_so():
    v = verdict(0.2, None)
    assert v.recommendation == "identified" and v.basis == "open-loop"
    assert "not checked" in v.text
    assert verdict(-0.2, {}).recommendation == "conduction-only"


def test_relative_words():
    assert relative_words(-0.08) == "8 % worse"
    assert relative_words(0.12) == "12 % better"
    assert relative_words(0.001) == "as good"


def test_a_testbed_truth_decides_the_verdict():
    """The demo's numbers: predictions within ±5 % at 6 h, step responses 2 % vs 64 % off the
    truth: the truth says the identified model, and the text says why."""
    from thermctl.validate import verdict
    v = verdict(0.0, {1.0: 0.11, 6.0: 0.04, 24.0: 0.05}, truth_gain=1 - 0.019 / 0.638)
    assert v.recommendation == "identified" and v.basis == "truth"
    assert "truth decides" in v.text
    # a truth that favours neither leaves the k-step rule in charge
    v = verdict(0.0, {1.0: 0.11, 6.0: 0.04}, truth_gain=0.01)
    assert v.recommendation == "mixed"
    # and a truth against the air paths recommends conduction-only even when k-step likes them
    v = verdict(0.2, {1.0: 0.2, 6.0: 0.2}, truth_gain=-0.5)
    assert v.recommendation == "conduction-only"
