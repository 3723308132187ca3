"""k-step-ahead prediction from Kalman-filtered states (validation measure).

Restart every ``stride`` from the filtered state :math:`\\hat x_{t|t}` of the stationary
filter, predict ``h`` steps ahead with the measured inputs and without further updates,
and compare with the measured zone temperatures. The unmeasured gains are held at their
filtered values over the horizon (the random walk's best prediction), and the supply
heat uses the *predicted* zone temperature, so a prediction learns nothing from the
measurements it is scored on. This is the measure thermctl validates with at 1, 6 and 24 h,
for the identified and the conduction-only model alike.

The CasADi version of the same criterion (for estimation) is
:meth:`LikelihoodProblem.kstep <thermctl.estimate.likelihood.problem.LikelihoodProblem.kstep>`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._blas import single_thread_blas
from ...errors import DataError

__all__ = ["KStepResult", "filtered_states", "kstep_errors", "kstep_block_mse"]


@dataclass
class KStepResult:
    """k-step-ahead prediction errors.

    Attributes
    ----------
    horizons : ndarray, shape (n_h,)
        [s]
    zones : list of str
        Measured zones (columns of ``rmse``).
    rmse : ndarray, shape (n_h, n_zones)
        Root-mean-square error per horizon and zone [K].
    bias : ndarray, shape (n_h, n_zones)
        Mean error (prediction − measurement) [K].
    n : ndarray of int, shape (n_h,)
        Predictions scored per horizon.
    """

    horizons: np.ndarray
    zones: list
    rmse: np.ndarray
    bias: np.ndarray
    n: np.ndarray

    @property
    def rmse_mean(self) -> np.ndarray:
        """RMSE over all zones per horizon [K]."""
        return np.sqrt(np.mean(self.rmse ** 2, axis=1))

    def table(self) -> str:
        head = "horizon  " + " ".join(f"{z:>9s}" for z in self.zones) + "       all"
        rows = [head]
        for h, r, m in zip(self.horizons, self.rmse, self.rmse_mean):
            rows.append(f"{h / 3600:5.1f} h  " + " ".join(f"{v:9.3f}" for v in r) + f" {m:9.3f}")
        return "\n".join(rows)


def _regime_matrices(m):
    """Per filter regime (0, 1): ``(Phi, Gamma, Gamma_y or None, Kf)`` from
    :meth:`LikelihoodProblem.matrices`: one regime, the gain schedule's (its own gain), or the
    loop gain's (its own dynamics, gain and held-reading input ``Gamma_y``)."""
    r0 = (m["Phi"], m["Gamma"], None, m["Kf"])
    if "Kf_on" in m:
        return r0, (m["Phi_on"], m["Gamma_on"], m["Gamma_y"], m["Kf_on"])
    if "Kf_occ" in m:
        return r0, (m["Phi"], m["Gamma"], None, m["Kf_occ"])
    return r0, r0


def filtered_states(problem, eta):
    """Run the stationary filter of ``problem`` at ``eta`` in numpy.

    Returns
    -------
    list of (a, b, X_pred, X_filt, E)
        Per data segment ``[a, b)``: predicted and filtered states, shape (b − a, n), and
        innovations, shape (b − a, ny).
    """
    m = problem.matrices(eta)
    W = problem.inputs(eta)
    C = problem.C
    # each row steps on its regime's matrices and gain (one regime unless gain_schedule or
    # loop_gain is set)
    mats = _regime_matrices(m)
    reg = problem.row_regime
    out = []
    with single_thread_blas():
        for s, (a, b) in enumerate(problem.segments):
            x = m["X0"][:, s].copy()
            Xp = np.empty((b - a, problem.n))
            Xf = np.empty((b - a, problem.n))
            E = np.empty((b - a, problem.ny))
            for k in range(a, b):
                Phi, Gam, Gy, K = mats[reg[k]]
                e = problem.Y[k] - C @ x
                Xp[k - a] = x
                x = x + K @ e
                Xf[k - a] = x
                E[k - a] = e
                x = Phi @ x + Gam @ W[k]
                if Gy is not None:          # the loops' held readings
                    x += Gy @ problem.Y[k]
            out.append((a, b, Xp, Xf, E))
    return out


def kstep_errors(problem, eta, horizons=(3600.0, 6 * 3600.0, 24 * 3600.0), stride: float | None = 3600.0,
                 rows: str = "all") -> KStepResult:
    """Prediction errors at several horizons from filtered states.

    Parameters
    ----------
    problem : LikelihoodProblem
        Built on the data to score (validation data: build it with
        :meth:`LikelihoodEstimator.problem_for`).
    eta : array_like
        Parameters (e.g. ``estimator.eta_``).
    horizons : sequence of float
        Prediction horizons [s], multiples of the data step.
    stride : float
        Spacing of the restarts [s].
    rows : {"all", "fit"}
        Score every prediction, or only those whose target row is one the likelihood
        used (e.g. supply off).

    Returns
    -------
    KStepResult
    """
    sse, se, cnt = _kstep_sums(problem, eta, horizons, stride, rows, block=None)
    sse, se, cnt = sse[:, 0], se[:, 0], cnt[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        rmse = np.sqrt(sse / cnt[:, None])
        bias = se / cnt[:, None]
    return KStepResult(np.asarray(horizons, float), list(problem.data.zones), rmse, bias, cnt)


def kstep_block_mse(problem, eta, horizon: float = 6 * 3600.0, stride: float | None = 3600.0,
                    block: float = 86400.0) -> tuple[np.ndarray, np.ndarray]:
    """Mean squared ``horizon``-ahead prediction error per time block (day), over all zones.

    The same predictions as :func:`kstep_errors`, grouped by the block of the row they
    predict: what a day-by-day comparison of two models' predictions needs.

    Returns
    -------
    ids : ndarray of int
        Block numbers (row // rows per block) with at least one scored prediction.
    mse : ndarray
        Mean squared error of those blocks' predictions [K²].
    """
    sse, _, cnt = _kstep_sums(problem, eta, (horizon,), stride, "all", block=block)
    tot, n = sse[0].sum(axis=1), cnt[0] * problem.ny       # squared errors, zone values
    ids = np.flatnonzero(n > 0)
    return ids, tot[ids] / n[ids]


def _kstep_sums(problem, eta, horizons, stride, rows, block):
    """Sums of squared and plain errors per horizon, block and zone, and counts per
    horizon and block (``block=None``: one block)."""
    dt = problem.data.dt
    hs = np.array([int(round(h / dt)) for h in horizons])
    if np.any(hs < 1):
        raise DataError(f"horizons must be at least one step ({dt:g} s), found {list(horizons)}")
    st = max(1, int(round((stride or dt) / dt)))
    N = len(problem.Y)
    per = N + 1 if block is None else max(1, int(round(block / dt)))
    nb = N // per + 1
    W = problem.inputs(eta)
    (Phi, Gam, _, _), (Phi1, Gam1, Gy1, _) = _regime_matrices(problem.matrices(eta))
    C = problem.C
    ny = problem.ny
    meas = problem.meas
    CT = problem.zone_pick
    sse = np.zeros((len(hs), nb, ny))
    se = np.zeros((len(hs), nb, ny))
    cnt = np.zeros((len(hs), nb), dtype=int)
    use = problem.fit_rows if rows == "fit" else np.ones(N, dtype=bool)
    with single_thread_blas():
        for a, b, Xp, Xf, E in filtered_states(problem, eta):
            starts = np.arange(a + problem.burn, b - 1, st)
            if not len(starts):
                continue
            X = Xf[starts - a].T.copy()                     # (n, R)
            hmax = hs.max()
            for j in range(1, hmax + 1):
                idx = starts + j - 1
                live = idx + 1 < b
                idc = np.minimum(idx, b - 1)
                Wj = W[idc].T.copy()
                fb = problem.sup_gain[idc].T * (CT @ X - problem.Tbar[idc].T)
                Wj[meas] -= fb
                Xn = Phi @ X + Gam @ Wj
                if Gy1 is not None:
                    # supply on: the loops answer the predicted temperature held over the step
                    on = problem.row_regime[idc] == 1
                    Xn[:, on] = Phi1 @ X[:, on] + Gam1 @ Wj[:, on] + Gy1 @ (CT @ X[:, on])
                X = Xn
                for q in np.flatnonzero(hs == j):
                    tgt = starts + j
                    ok = live & (tgt < b)
                    ok[ok] &= use[tgt[ok]]
                    if not ok.any():
                        continue
                    err = (C @ X[:, ok]).T - problem.Y[tgt[ok]]
                    blk = tgt[ok] // per
                    np.add.at(sse[q], blk, err ** 2)
                    np.add.at(se[q], blk, err)
                    np.add.at(cnt[q], blk, 1)
    return sse, se, cnt
