"""Both estimation results share one base, FitResult (issue 18)."""

import numpy as np
import pytest

from thermctl.estimate import FitResult
from thermctl.estimate.likelihood.estimator import LikelihoodResult
from thermctl.estimate.simulation.result import EstimationResult


def test_both_results_are_fit_results_with_the_same_contract():
    lr = LikelihoodResult("nll", 1.0, {"rbar_v": 1e-3, "sigma_q": 3.0}, np.array([1e-3]),
                          np.array([5.0]), ["air:a-b"], 10, 2, 1.0, 2.0,
                          ["rbar_v at its upper bound 0.1 [K/(W m)]"], True, "ok", 5, 0.1)
    er = EstimationResult(rbar_v=1e-3, c_v=5.0, tau0=5e-3, J=1.0, J_nlp=1.0, method="m",
                          discretisation="d", status="s", success=False, iterations=3, n_sim=1,
                          wall_time=1.0, solve_time=0.5, active_bounds=[], x0=np.zeros(2),
                          theta0=np.zeros(2), initial_state="i", param_names=["rbar_v", "c_v"])
    for r in (lr, er):
        assert isinstance(r, FitResult)
        assert list(r.param_values) == r.param_names
        assert isinstance(r.summary(), str)
    assert lr.on_bound and not er.on_bound
    assert lr.param_values == {"rbar_v": 1e-3, "sigma_q": 3.0}
    assert er.param_values == pytest.approx({"rbar_v": 1e-3, "c_v": 5.0}) and er.message == ""
    with pytest.raises(TypeError):
        FitResult()          # abstract: only the criteria's results are made
