"""Structure identification: SIN p-values, graphical lasso, scores, selection, figures.

Reference values are computed here independently of ``thermctl.structure``: partial
correlations from regression residuals, normal tails from ``math.erfc`` or
``scipy.stats``, Holm's adjustment by an explicit loop, the graphical lasso by
scikit-learn. Recovery tests use Gaussian graphical models with a known precision.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from thermctl.errors import DataError, DataWarning
from thermctl.network import ThermalNetwork
from thermctl.spec import spec_from_dict
from thermctl.structure import (ScoredEdge, StructureIdentifier, day_array,
                                graphical_lasso_batch, level_penalty, partial_correlations,
                                select_edges, sin_pvalues)

# ---------------------------------------------------------------- Gaussian graphical model
# Ten zones; the true concentration graph has components of size <= 3 (pairs and short
# paths). Such graphs satisfy the graphical lasso's irrepresentability condition
# (Ravikumar et al. 2011), so both methods can recover them; on a chain with chords
# (z0-...-z7 plus z0-z3, z2-z6) the lasso's best precision at full recall was 0.89 at
# N = 300 (measured), whatever the penalty.
ZONES = [f"z{i}" for i in range(10)]
GGM_EDGES = [(0, 1), (2, 3), (3, 4), (5, 6), (6, 7), (8, 9)]
WALLS = [(0, 1), (3, 4)]             # conduction pairs that are also in the graph
CONVECTION = [(2, 3), (5, 6), (8, 9)]  # true air paths with a known distance
NO_DISTANCE = (6, 7)                 # in the graph, but the spec gives no air path length
NULL_WITH_DISTANCE = [(0, 2), (1, 5), (4, 9), (7, 8), (2, 9)]


def ggm_precision(w=0.3):
    P = np.eye(len(ZONES))
    for i, j in GGM_EDGES:
        P[i, j] = P[j, i] = -w
    return P


def ggm_network():
    z = ZONES
    walls = [{"between": [x, "outside"], "R": [0.02, 0.06, 0.02], "C": [1e6, 1e6]} for x in z]
    walls += [{"between": [z[i], z[j]], "R": [0.02, 0.06, 0.02], "C": [3e5, 3e5]}
              for i, j in WALLS]
    pairs = CONVECTION + NULL_WITH_DISTANCE + [(0, 1)]
    spec = spec_from_dict({
        "name": "ggm", "zones": {x: {"volume": 50.0} for x in z}, "boundary": ["outside"],
        "walls": walls,
        "distances": [{"between": [z[i], z[j]], "d": 3.0 + i + j} for i, j in pairs]})
    return ThermalNetwork(spec)


def ggm_frame(P, n_days, step_h=1, seed=0, mean=21.0, tz="UTC", prefix="T:"):
    """Independent draws N(mean, P⁻¹) at every time of every day."""
    rng = np.random.default_rng(seed)
    K = 24 // step_h
    X = rng.multivariate_normal(np.zeros(len(P)), np.linalg.inv(P), size=n_days * K) + mean
    idx = pd.date_range("2024-01-01", periods=n_days * K, freq=f"{step_h}h", tz=tz)
    return pd.DataFrame(X, index=idx, columns=[prefix + z for z in ZONES])


def precision_recall(graphs, truth):
    tp = (graphs & truth).sum()
    fp = (graphs & ~truth).sum()
    fn = (~graphs & truth).sum()
    return tp / max(1, tp + fp), tp / max(1, tp + fn)


@pytest.fixture(scope="module")
def ggm_data():
    return ggm_frame(ggm_precision(), n_days=300)


@pytest.fixture(scope="module")
def ggm_net():
    return ggm_network()


@pytest.fixture(scope="module")
def fitted_sin(ggm_data, ggm_net):
    return StructureIdentifier(method="sin", rule="threshold").fit(ggm_data, ggm_net)


# ---------------------------------------------------------------- sin_pvalues
def test_sin_hand_case():
    # equicorrelation 0.5, n = 3: partial correlation rho/(1 + rho) = 1/3,
    # z = atanh(1/3)·sqrt(20 - 3 - 1) = 0.5·ln 2·4 = 2 ln 2, raw p = erfc(z/√2) = 0.165657
    S = np.full((3, 3), 0.5) + 0.5 * np.eye(3)
    p_raw = math.erfc(2 * math.log(2) / math.sqrt(2))
    assert p_raw == pytest.approx(0.165657, abs=1e-6)  # table: 2(1 - Φ(1.3863))
    np.testing.assert_allclose(partial_correlations(S)[0, 1], 1 / 3, rtol=1e-12)
    np.testing.assert_allclose(sin_pvalues(S, 20, adjust="none")[0, 1], p_raw, rtol=1e-10)
    np.testing.assert_allclose(sin_pvalues(S, 20)[0, 1], 1 - (1 - p_raw) ** 3, rtol=1e-10)
    assert sin_pvalues(S, 20)[0, 1] == pytest.approx(0.4192, abs=1e-4)
    # Holm with three equal p-values: all become 3p
    np.testing.assert_allclose(sin_pvalues(S, 20, adjust="holm")[0, 1], 3 * p_raw, rtol=1e-10)
    assert np.isnan(sin_pvalues(S, 20)).sum() == 3  # diagonal only


def _residual_partial_corr(X, i, j):
    """Correlation of the residuals of x_i and x_j regressed on the rest (with intercept)."""
    rest = [k for k in range(X.shape[1]) if k not in (i, j)]
    A = np.column_stack([np.ones(len(X)), X[:, rest]])
    ri = X[:, i] - A @ np.linalg.lstsq(A, X[:, i], rcond=None)[0]
    rj = X[:, j] - A @ np.linalg.lstsq(A, X[:, j], rcond=None)[0]
    return ri @ rj / np.sqrt((ri @ ri) * (rj @ rj))


def _holm_loop(p):
    order = sorted(range(len(p)), key=lambda k: p[k])
    out, running = [0.0] * len(p), 0.0
    for rank, k in enumerate(order):
        running = max(running, min(1.0, (len(p) - rank) * p[k]))
        out[k] = running
    return out


def test_sin_matches_definition():
    rng = np.random.default_rng(3)
    N, n = 40, 5
    X = rng.standard_normal((N, n)) @ rng.standard_normal((n, n))
    S = np.cov(X.T, bias=True)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    E = len(pairs)
    r = np.array([_residual_partial_corr(X, i, j) for i, j in pairs])
    z = np.arctanh(r) * np.sqrt(N - n - 1)
    raw = 2 * stats.norm.sf(np.abs(z))
    sidak = 1 - (1 - raw) ** E
    holm = _holm_loop(list(raw))
    got = {adj: sin_pvalues(S, N, adjust=adj) for adj in ("none", "sidak", "holm")}
    pc = partial_correlations(S)
    for k, (i, j) in enumerate(pairs):
        assert pc[i, j] == pytest.approx(r[k], rel=1e-9)
        assert got["none"][i, j] == pytest.approx(raw[k], rel=1e-9)
        assert got["sidak"][i, j] == pytest.approx(sidak[k], rel=1e-9)
        assert got["holm"][i, j] == pytest.approx(holm[k], rel=1e-9)
        assert got["sidak"][j, i] == got["sidak"][i, j]


@pytest.mark.parametrize("adjust", ["sidak", "holm"])
def test_sin_scale_invariance(adjust):
    rng = np.random.default_rng(4)
    X = rng.standard_normal((30, 6)) @ rng.standard_normal((6, 6))
    S = np.cov(X.T)
    D = np.diag([1e-3, 1.0, 5.0, 1e3, 0.2, 7.0])  # °C vs mK vs anything
    Rm = np.corrcoef(X.T)
    ref = sin_pvalues(S, 30, adjust)
    np.testing.assert_allclose(sin_pvalues(D @ S @ D, 30, adjust), ref, rtol=1e-9)
    np.testing.assert_allclose(sin_pvalues(Rm, 30, adjust), ref, rtol=1e-9)


def test_adjustment_properties():
    rng = np.random.default_rng(5)
    n, N = 8, 60
    P = ggm_precision()[:n, :n]
    X = rng.multivariate_normal(np.zeros(n), np.linalg.inv(P), size=N)
    S = np.cov(X.T)
    iu = np.triu_indices(n, 1)
    raw, sid, holm = (sin_pvalues(S, N, a)[iu] for a in ("none", "sidak", "holm"))
    E = len(raw)
    assert raw.min() < 1e-3 and raw.max() > 0.3  # a spread of p-values to compare
    assert np.all(holm >= raw - 1e-15)
    assert np.all(sid >= raw - 1e-15)
    assert np.all(sid <= np.minimum(1, E * raw) + 1e-15)  # Šidák is below Bonferroni
    order = np.argsort(raw)
    assert np.all(np.diff(sid[order]) >= 0)  # Šidák is monotone in the raw p-values
    assert np.all(np.diff(holm[order]) >= 0)


def test_stack_equals_single():
    rng = np.random.default_rng(6)
    stack = [np.cov(rng.standard_normal((25, 4)).T) for _ in range(7)]
    got = sin_pvalues(np.array(stack), 25, "holm")
    for k, S in enumerate(stack):
        np.testing.assert_allclose(got[k], sin_pvalues(S, 25, "holm"), rtol=1e-12)


_rank2 = np.cov(np.random.default_rng(7).standard_normal((3, 4)).T)  # 3 samples, 4 variables


@pytest.mark.parametrize("S, N, match", [
    (np.eye(5), 6, r"n_samples >= n \+ 2 = 7.*glasso"),
    (np.eye(5), 5, r"N = 5 samples for n = 5"),
    (_rank2, 10, "singular"),
    (np.diag([1.0, 0.0, 2.0]), 10, "zero variance"),
    (np.array([[1, 0.2], [0.3, 1]]), 10, "not symmetric"),
    (np.ones((3, 2)), 10, "square"),
    (np.array([np.eye(3), np.diag([1.0, 0.0, 1.0])]), 10, r"zero variance at index \(1,\)"),
], ids=["N=n+1", "N=n", "singular", "zero-variance", "asymmetric", "not-square", "stack-index"])
def test_sin_errors(S, N, match):
    with pytest.raises(DataError, match=match):
        sin_pvalues(S, N)


# ---------------------------------------------------------------- graphical lasso
@pytest.mark.parametrize("alpha", [0.05, 0.2, 0.4])
def test_glasso_batch_matches_sklearn(alpha):
    from sklearn.covariance import graphical_lasso
    rng = np.random.default_rng(8)
    Rs = []
    for _ in range(4):
        X = rng.multivariate_normal(np.zeros(6), np.linalg.inv(ggm_precision()[:6, :6]), size=40)
        Rs.append(np.corrcoef(X.T))
    P, _, n_iter = graphical_lasso_batch(np.array(Rs), alpha, tol=1e-7)
    assert np.all(n_iter < 2000)
    for k, R in enumerate(Rs):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # sklearn may warn at this tight tolerance
            _, ref = graphical_lasso(R, alpha, tol=1e-10, enet_tol=1e-10, max_iter=2000)
        np.testing.assert_allclose(P[k], ref, atol=1e-4)
        clear = np.abs(ref) > 1e-3  # entries away from the soft-threshold boundary
        np.testing.assert_array_equal((P[k] != 0)[clear], clear[clear])
        tiny = np.abs(ref) < 1e-8
        assert np.all(P[k][tiny] == 0)


@pytest.mark.parametrize("method, N, n", [("sin", 40, 6), ("glasso", 40, 6), ("glasso", 8, 10)],
                         ids=["sin", "glasso", "glasso-N<n"])
def test_null_false_edge_rate(method, N, n):
    # independent zones: the probability that a graph has any edge is <= level (0.05)
    K = 400
    rng = np.random.default_rng(9)
    X = rng.standard_normal((N, K, n))
    Z = (X - X.mean(0)) / X.std(0)
    R = np.einsum("dki,dkj->kij", Z, Z) / N
    if method == "sin":
        g = sin_pvalues(R, N) <= 0.05
    else:
        P, _, _ = graphical_lasso_batch(R, level_penalty(N, n, 0.05))
        g = P != 0
        g[:, np.arange(n), np.arange(n)] = False
    rate = np.any(g, axis=(1, 2)).mean()
    # binomial sd at 0.05 over 400 graphs is 0.011: 0.085 is 3 sd above the level
    assert rate <= 0.085


def test_level_penalty_decreases_with_days():
    lam = [level_penalty(N, 10, 0.05) for N in (10, 30, 100, 1000)]
    assert all(0 < a < 1 for a in lam) and np.all(np.diff(lam) < 0)
    # large N: t → z quantile, penalty ≈ z/sqrt(N)
    z = stats.norm.isf(0.05 / 200)
    assert level_penalty(10**6, 10, 0.05) == pytest.approx(z / 1e3, rel=1e-3)


# ---------------------------------------------------------------- estimator on a GGM
@pytest.mark.parametrize("kwargs", [{"method": "sin"}, {"method": "glasso", "alpha": "level"}],
                         ids=["sin", "glasso-level"])
def test_ggm_recovery(kwargs, ggm_data, ggm_net):
    sid = StructureIdentifier(rule="threshold", **kwargs).fit(ggm_data, ggm_net)
    truth = ggm_precision() != 0
    np.fill_diagonal(truth, False)
    prec, rec = precision_recall(sid.graphs_, truth[None])
    assert prec >= 0.9 and rec >= 0.9, (prec, rec)
    assert sid.graphs_.shape == (24, 10, 10) and len(sid.days_used_) == 300
    for i, j in GGM_EDGES:
        assert sid.scores_[(ZONES[i], ZONES[j])] >= 0.9
    # walls and the pair without a distance are not candidates: the threshold rule
    # returns exactly the true air paths with known distances
    got = {(e.a, e.b) for e in sid.edges_}
    assert got == {(ZONES[i], ZONES[j]) for i, j in CONVECTION}
    for e in sid.edges_:
        assert e.d == ggm_net.spec.distance(e.a, e.b) and e.score >= 0.9
    assert {(e.a, e.b) for e in sid.network_.convection_edges} == got
    assert len(sid.network_.conduction_edges) == len(ggm_net.conduction_edges)


def test_ggm_paper_rule(ggm_data, ggm_net):
    sid = StructureIdentifier(method="sin", rule="paper").fit(ggm_data, ggm_net)
    got = {(e.a, e.b) for e in sid.edges_}
    assert {(ZONES[i], ZONES[j]) for i, j in CONVECTION} <= got
    # every selected pair is some zone's best candidate
    for e in sid.edges_:
        best = max(sid.scores_[p] for p in sid.candidates_ if e.a in p)
        best_b = max(sid.scores_[p] for p in sid.candidates_ if e.b in p)
        assert e.score in (best, best_b)
    assert ("z0", "z1") not in sid.candidates_ and ("z6", "z7") not in sid.candidates_


def test_allow_parallel_keeps_wall_pairs(ggm_data, ggm_net):
    sid = StructureIdentifier(rule="threshold", allow_parallel=True).fit(ggm_data, ggm_net)
    got = {(e.a, e.b) for e in sid.edges_}
    # z0-z1 share a wall and the graph edge; with a distance it now becomes an air path
    assert ("z0", "z1") in got
    # z3-z4 share a wall but the spec gives no length: the estimated one (a door in the
    # common wall, BuildingSpec.air_path_length) makes it a candidate too
    spec = ggm_net.spec
    assert spec.distance("z3", "z4") is None and ("z3", "z4") in got
    e = next(e for e in sid.edges_ if (e.a, e.b) == ("z3", "z4"))
    assert e.d == spec.air_path_length("z3", "z4")[0]
    # without allow_parallel, neither wall pair is a candidate
    plain = StructureIdentifier(rule="threshold").fit(ggm_data, ggm_net)
    assert {("z0", "z1"), ("z3", "z4")}.isdisjoint(plain.candidates_)


def test_glasso_cv(ggm_data, ggm_net):
    sid = StructureIdentifier(method="glasso").fit(ggm_data, ggm_net)  # alpha="cv"
    assert sid.alpha_ == sid.cv_alphas_[np.argmax(sid.cv_scores_)]
    truth = ggm_precision() != 0
    np.fill_diagonal(truth, False)
    prec, rec = precision_recall(sid.graphs_, truth[None])
    assert rec >= 0.95
    # CV chooses the penalty that predicts best, which keeps more (false) edges than the
    # level penalty: the paper rule still finds the true air paths
    lvl = StructureIdentifier(method="glasso", alpha="level").fit(ggm_data, ggm_net)
    assert sid.alpha_ < lvl.alpha_
    assert sid.graphs_.sum() > lvl.graphs_.sum()
    assert prec < precision_recall(lvl.graphs_, truth[None])[0]
    paper = StructureIdentifier(method="glasso", rule="paper").fit(ggm_data, ggm_net)
    assert {(ZONES[i], ZONES[j]) for i, j in CONVECTION} <= {(e.a, e.b) for e in paper.edges_}


def test_few_days(ggm_net):
    df = ggm_frame(ggm_precision(), n_days=11)  # N = n + 1
    with pytest.raises(DataError, match=r"needs >= 12 complete days for 10 measured zones.*"
                                        r"found N = 11.*glasso"):
        StructureIdentifier(method="sin").fit(df, ggm_net)
    df = ggm_frame(ggm_precision(), n_days=8)  # N < n: S is singular, glasso still works
    sid = StructureIdentifier(method="glasso", alpha="level").fit(df, ggm_net)
    assert sid.graphs_.shape == (24, 10, 10) and np.isfinite(sid.precisions_).all()
    assert sid.alpha_ == pytest.approx(level_penalty(8, 10, 0.05))
    with pytest.raises(DataError, match="needs >= 5 complete days"):
        StructureIdentifier(method="glasso", alpha="cv").fit(df.iloc[:24 * 4], ggm_net)


def test_zero_variance_times_are_skipped(ggm_net):
    df = ggm_frame(ggm_precision(), n_days=200)
    df.loc[df.index.hour == 3, "T:z4"] = 20.0  # a stuck reading at 03:00 every day
    with pytest.warns(DataWarning, match=r"1 of 24 times of day.*z4"):
        sid = StructureIdentifier().fit(df, ggm_net)
    assert sid.times_skipped_ == [3]
    assert not sid.graphs_[3].any()
    assert sid.graphs_.any(axis=(1, 2)).sum() == 23  # every other time has edges


# ---------------------------------------------------------------- selection rules
def test_select_edges_paper_ties():
    zones = ["a", "b", "c", "d"]
    scores = {("a", "b"): 0.5, ("a", "c"): 0.5, ("a", "d"): 0.5, ("b", "c"): 0.2,
              ("c", "d"): 0.0}
    dist = {("a", "b"): 9.0, ("a", "c"): 4.0, ("a", "d"): 4.0, ("b", "c"): 1.0,
            ("c", "d"): 1.0}
    got = select_edges(scores, dist, zones, "paper")
    # a: ties at 0.5 -> shorter path (c, d at 4 m) -> name (c); b: a-b (0.5 > 0.2);
    # c: a-c; d: a-d (c-d has score 0, never chosen)
    assert [(e.a, e.b) for e in got] == [("a", "c"), ("a", "d"), ("a", "b")]
    assert got[0] == ScoredEdge("a", "c", 0.5, 4.0)


def test_select_edges_threshold():
    zones = ["a", "b", "c", "d"]
    scores = {("a", "b"): 0.9, ("a", "c"): 0.8, ("b", "c"): 0.7, ("c", "d"): 0.3,
              ("b", "d"): 0.1}
    dist = dict.fromkeys(scores, 5.0)
    pairs = lambda edges: [(e.a, e.b) for e in edges]  # noqa: E731
    assert pairs(select_edges(scores, dist, zones, "threshold", 0.3)) == \
        [("a", "b"), ("a", "c"), ("b", "c"), ("c", "d")]
    assert pairs(select_edges(scores, dist, zones, "threshold", 0.3, max_per_zone=1)) == \
        [("a", "b"), ("c", "d")]
    assert select_edges(scores, dist, zones, "threshold", 0.95) == []


@pytest.mark.parametrize("kwargs, match", [
    ({"method": "pc"}, "method"), ({"level": 0}, "level"), ({"level": 1.5}, "level"),
    ({"adjust": "bonferroni"}, "adjust"), ({"alpha": -0.1}, "alpha"), ({"alpha": "bic"}, "alpha"),
    ({"rule": "best"}, "rule"), ({"s_min": 2.0}, "s_min"), ({"max_per_zone": 2}, "threshold"),
    ({"rule": "threshold", "max_per_zone": 0}, "max_per_zone"), ({"n_folds": 1}, "n_folds"),
], ids=lambda v: str(v) if isinstance(v, dict) else "")
def test_bad_parameters(kwargs, match, ggm_data, ggm_net):
    with pytest.raises(ValueError, match=match):
        StructureIdentifier(**kwargs).fit(ggm_data, ggm_net)


# ---------------------------------------------------------------- data shaping
def test_day_array_drops_and_counts():
    df = ggm_frame(ggm_precision(), n_days=6, step_h=1, tz="America/New_York", prefix="")
    df.iloc[30, 2] = np.nan                          # day 2: a gap in z2
    df = df.drop(df.index[100])                      # day 5: a missing row
    df = df.iloc[5:]                                 # day 1 starts at 05:00
    da = day_array(df, ZONES[:4])
    assert da.values.shape == (3, 24, 4) and da.step == 3600.0
    assert da.zones == ZONES[:4] and da.n_times == 24
    reasons = dict(da.dropped)
    assert list(reasons) == [pd.Timestamp(d).date() for d in
                             ("2024-01-01", "2024-01-02", "2024-01-05")]
    assert reasons[pd.Timestamp("2024-01-01").date()] == "incomplete (19 of 24 samples)"
    assert reasons[pd.Timestamp("2024-01-02").date()] == "gap in z2"
    np.testing.assert_array_equal(da.values[0], df.loc["2024-01-03", ZONES[:4]].to_numpy())


def test_day_array_clock_change():
    # a tz-aware hourly grid across the spring and autumn clock changes (US, 2024)
    idx = pd.date_range("2024-03-09", "2024-03-12", freq="1h", tz="America/New_York",
                        inclusive="left")
    df = pd.DataFrame({"T:a": np.arange(len(idx), dtype=float), "T:b": 1.0}, index=idx)
    da = day_array(df, ["a", "b"])
    assert [d.isoformat() for d in da.days] == ["2024-03-09", "2024-03-11"]
    assert dict(da.dropped)[pd.Timestamp("2024-03-10").date()] == "incomplete (23 of 24 samples)"
    idx = pd.date_range("2024-11-02", "2024-11-04", freq="1h", tz="America/New_York",
                        inclusive="left")
    df = pd.DataFrame({"a": 0.0, "b": 1.0}, index=idx)
    da = day_array(df, ["a", "b"])
    assert dict(da.dropped)[pd.Timestamp("2024-11-03").date()].startswith("repeated time")
    assert dict(da.dropped)[pd.Timestamp("2024-11-03").date()] == \
        "repeated time of day (clock change, 25 of 24 samples)"


@pytest.mark.parametrize("make, match", [
    (lambda df: df.rename(columns={"T:z1": "x"}), r"no temperature column for measured zone 'z1'"),
    (lambda df: df.assign(z1=1.0), "two temperature columns"),
    (lambda df: df.drop(df.index[3]).set_axis(
        df.index.drop(df.index[3]) + pd.to_timedelta(np.r_[0, 0, 0, [17] * (len(df) - 4)], "min"),
        axis=0), "not on a regular grid"),
    (lambda df: df.reset_index(drop=True), "DatetimeIndex"),
    (lambda df: df.iloc[::-1], "sorted"),
    (lambda df: df.set_axis(pd.date_range("2024-01-01", periods=len(df), freq="7min", tz="UTC"),
                            axis=0), "does not divide 24 h"),
    (lambda df: df.assign(**{"T:z2": "warm"}), r"\['T:z2'\] are not numeric"),
], ids=["missing", "ambiguous", "irregular", "no-datetime", "unsorted", "step", "text"])
def test_data_errors(make, match, ggm_net):
    df = make(ggm_frame(ggm_precision(), n_days=13))
    with pytest.raises(DataError, match=match):
        StructureIdentifier().fit(df, ggm_net)


def test_plain_and_prefixed_columns_agree(ggm_net):
    a = ggm_frame(ggm_precision(), n_days=40)
    b = a.rename(columns=lambda c: c[2:]).tz_localize(None)  # plain names, naive index
    sa = StructureIdentifier().fit(a, ggm_net)
    sb = StructureIdentifier().fit(b, ggm_net)
    np.testing.assert_array_equal(sa.graphs_, sb.graphs_)
    assert sa.edges_ == sb.edges_


# ---------------------------------------------------------------- figures
def test_figures(fitted_sin):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from thermctl.plots.structure import plot_correlations, plot_network, plot_scores

    sid = fitted_sin
    fig = plot_network(sid)
    lines = fig.axes[0].lines
    assert sum(ln.get_gid() == "convection" for ln in lines) == len(sid.edges_) == 3
    assert all(ln.get_linestyle() == "--" for ln in lines if ln.get_gid() == "convection")
    assert sum(ln.get_gid() == "conduction" for ln in lines) == len(ZONES) + len(WALLS)
    fig = plot_scores(sid)
    patches = fig.axes[0].patches
    assert sum(p.get_gid() == "selected" for p in patches) == 2 * len(sid.edges_)
    assert sum(p.get_gid() == "wall" for p in patches) == 2 * len(WALLS)
    fig = plot_correlations(sid, pairs=[("z2", "z3"), ("z2", "z9")])
    top, bottom = fig.axes[:2]
    np.testing.assert_allclose(top.lines[0].get_ydata(), sid.correlations_[:, 2, 3])
    np.testing.assert_allclose(bottom.lines[0].get_ydata(), sid.partial_correlations_[:, 2, 3])
    assert len(plot_correlations(sid).axes[0].get_legend().get_texts()) == 4
    FigureCanvasAgg(fig).draw()  # renders without a display


# ---------------------------------------------------------------- testbed (known air paths)
@pytest.fixture(scope="module")
def testbed():
    generate = pytest.importorskip("thermctl.testbed").generate
    return generate(seed=0)  # Pugh-Hall-like section, 26 days at 5 min, as in the paper


def _true_pairs(tb):
    return {tuple(sorted(e[:2])) for e in tb.truth.edges}


def test_testbed_sin(testbed):
    tb = testbed
    truth = _true_pairs(tb)
    paper = StructureIdentifier(method="sin", rule="paper").fit(tb.data, tb.network)
    assert len(paper.days_used_) == 26 and paper.graphs_.shape == (288, 6, 6)
    assert truth <= {(e.a, e.b) for e in paper.edges_}
    thr = StructureIdentifier(method="sin", rule="threshold").fit(tb.data, tb.network)
    got = {(e.a, e.b) for e in thr.edges_}
    assert truth <= got and len(got - truth) <= 1
    # the identified network carries the spec's air path lengths
    d_true = {tuple(sorted((a, b))): d for a, b, d in tb.truth.edges}
    for e in thr.network_.convection_edges:
        if (e.a, e.b) in d_true:
            assert e.d == pytest.approx(d_true[(e.a, e.b)])


def test_testbed_glasso_paper(testbed):
    tb = testbed
    sid = StructureIdentifier(method="glasso", rule="paper").fit(tb.data, tb.network)
    assert _true_pairs(tb) <= {(e.a, e.b) for e in sid.edges_}


@pytest.mark.xfail(strict=True, reason=(
    "measured (seed 0, 26 days): zone temperatures are marginally correlated 0.8-1.0 at every "
    "time of day (common drift), so the lasso keeps nearly every pair: CV chooses the "
    "smallest penalty tried (0.01) and all 11 candidates score >= 0.99, the level penalty "
    "(0.59) gives all 15 pairs a score of 1.00; the threshold rule then selects 8 false "
    "edges. SIN on the same data: true scores 0.88, 0.50, 0.46 vs 0.12 for the best false "
    "candidate."))
def test_testbed_glasso_threshold(testbed):
    tb = testbed
    truth = _true_pairs(tb)
    thr = StructureIdentifier(method="glasso", rule="threshold").fit(tb.data, tb.network)
    got = {(e.a, e.b) for e in thr.edges_}
    assert truth <= got and len(got - truth) <= 1


def test_every_parameter_documented():
    import inspect

    import thermctl.structure as mod
    for obj in (StructureIdentifier, StructureIdentifier.fit, sin_pvalues, partial_correlations,
                day_array, graphical_lasso_batch, level_penalty, select_edges):
        doc = inspect.getdoc(obj)
        for name in inspect.signature(obj).parameters:
            if name != "self":
                assert f"\n{name} :" in doc or f"\n{name}, " in doc or f", {name} :" in doc, \
                    f"{obj.__qualname__}: parameter {name!r} not documented"
    assert set(mod.__all__) >= {"StructureIdentifier", "sin_pvalues", "ScoredEdge"}


# ---------------------------------------------------------------------------- local SIN
def _chain_frame(n_days, seed=0):
    """Hourly zone temperatures: z follows n1 (a door), n2 is independent of z given n1."""
    import pandas as pd
    rng = np.random.default_rng(seed)
    K = 24
    n1 = rng.normal(size=(n_days, K))
    n2 = 0.7 * n1 + rng.normal(size=(n_days, K))       # correlated with z only through n1
    z = 0.8 * n1 + 0.6 * rng.normal(size=(n_days, K))
    idx = pd.date_range("2024-01-01", periods=n_days * K, freq="1h")
    return pd.DataFrame({"T:z": 20 + z.ravel(), "T:n1": 20 + n1.ravel(),
                         "T:n2": 20 + n2.ravel()}, index=idx)


def test_neighbourhood_scores_find_the_direct_neighbour_only():
    from thermctl.structure.neighbourhood import neighbourhood_scores
    sc = neighbourhood_scores(_chain_frame(40), "z", ["n1", "n2"])
    assert set(sc) == {"n1", "n2"}
    # partial correlation of z and n1 given n2 is 0.8/sqrt(0.8²+0.6²)·… ≫ 0: every hour
    assert sc["n1"] == 1.0
    # z ⟂ n2 | n1: SIN (Šidák over 3 pairs, level 0.05) joins them at ≤ ~5 % of the hours
    assert sc["n2"] <= 3 / 24
    # plain correlation of z and n2 is 0.8·0.7/…≈0.45: without conditioning it would score 1
    f = _chain_frame(40)
    assert np.corrcoef(f["T:z"], f["T:n2"])[0, 1] > 0.3


def test_neighbourhood_scores_need_neighbourhood_plus_two_days():
    from thermctl.structure.neighbourhood import neighbourhood_scores
    with pytest.raises(DataError, match="needs >= 5 complete days"):
        neighbourhood_scores(_chain_frame(4), "z", ["n1", "n2"])
    assert set(neighbourhood_scores(_chain_frame(5), "z", ["n1", "n2"])) == {"n1", "n2"}


def test_neighbourhood_scores_trim_to_the_days_available():
    from thermctl.structure.neighbourhood import neighbourhood_scores
    # 4 days: a neighbourhood of 2 zones (z + n1); n2 gets no score instead of an error
    sc = neighbourhood_scores(_chain_frame(4), "z", ["n1", "n2"], trim=True)
    assert set(sc) == {"n1"}
