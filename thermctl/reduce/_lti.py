r"""Dense kernels of the reductions: symmetrisation, Gramians, balancing, residualization.

Private: the public functions in :mod:`thermctl.reduce.balanced` and
:mod:`thermctl.reduce.preserving` wrap these.

A linearized RC network has :math:`A = -\mathcal{C}^{-1}K` with :math:`\mathcal{C}`
diagonal positive and :math:`K` symmetric, so :math:`S A S^{-1}` is symmetric for
:math:`S = \mathcal{C}^{1/2}`. In the eigenbasis of that symmetric matrix the Lyapunov
equations are solved elementwise,

.. math::

    \hat P_{ij} = \frac{(\hat B \hat B^T)_{ij}}{-(\lambda_i + \lambda_j)}
    \quad\text{(continuous)}, \qquad
    \hat P_{ij} = \frac{(\hat B \hat B^T)_{ij}}{1 - \mu_i \mu_j}
    \quad\text{(discrete)},

which costs one symmetric eigendecomposition instead of a Bartels–Stewart solve and
keeps the balancing well conditioned (note §2, §7). Systems that are not symmetrisable
take the general scipy path.
"""

from __future__ import annotations

import hashlib
import logging
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse import csgraph
from scipy.linalg import lapack

from ..errors import ModelError

log = logging.getLogger(__name__)

_SYM_RTOL = 1e-9      # S A S^-1 must be symmetric to this relative accuracy
_HSV_RTOL = 1e-11       # usable HSVs: above this fraction of the largest (SVD path) ...
_HSV_RTOL_FAST = 1e-6   # ... or this one (eigenvalue path, which squares them)
_ACCURATE_LIMIT = 1000  # states up to which the SVD path is used


def symmetrizer(A, rtol: float = _SYM_RTOL):
    """Positive ``s`` with ``s_i² A_ij = s_j² A_ji`` for all ``i, j``, or None.

    For ``A = -C⁻¹K`` (RC network) ``s² ∝ C`` on every connected group of states. The
    ratios are read along a maximum spanning tree of the couplings ``sqrt(A_ij A_ji)``, so
    that tiny, inaccurate entries (e.g. of a matrix exponential) are not used.

    Parameters
    ----------
    A : ndarray, shape (n, n)
    rtol : float
        Relative tolerance of the symmetry check of ``S A S⁻¹``.
    """
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    prod = A * A.T
    np.fill_diagonal(prod, 0.0)
    pairs = prod > 0
    if not pairs.any():
        s = np.ones(n)
    else:
        w = np.where(pairs, np.sqrt(np.where(pairs, prod, 0.0)), 0.0)
        # minimum spanning tree of -w/max(w) is a maximum spanning tree of the couplings
        tree = csgraph.minimum_spanning_tree(sp.csr_matrix(-w / w.max()))
        tree = (tree + tree.T).tocsr()
        logs2 = np.full(n, np.nan)
        for root in range(n):
            if not np.isnan(logs2[root]):
                continue
            order, pred = csgraph.breadth_first_order(tree, root, directed=False)
            logs2[root] = 0.0
            for j in order[1:]:
                i = pred[j]
                logs2[j] = logs2[i] + np.log(A[i, j] / A[j, i])
        s = np.exp(0.5 * (logs2 - np.max(logs2)))
    As = (s[:, None] * A) / s[None, :]
    scale = max(np.max(np.abs(As)), np.finfo(float).tiny)
    if np.max(np.abs(As - As.T)) > rtol * scale:
        return None
    return s


@dataclass
class LTI:
    """A stable LTI system, possibly in the eigenbasis of its symmetrised state matrix.

    ``modal`` systems have ``A = diag(lam)``; ``to_x`` maps their coordinates back to the
    original state coordinates and ``from_x`` the other way (both identity otherwise).
    """

    A: np.ndarray | None      # None when modal
    lam: np.ndarray | None    # eigenvalues when modal
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float
    to_x: np.ndarray
    from_x: np.ndarray
    eig: tuple | None = None  # (eigenvalues, eigenvectors) of a general A, for fast responses

    @property
    def modal(self) -> bool:
        return self.lam is not None

    @property
    def n(self) -> int:
        return self.B.shape[0]

    def state_matrix(self) -> np.ndarray:
        return np.diag(self.lam) if self.modal else self.A


_EIG_CACHE: OrderedDict = OrderedDict()
_EIG_CACHE_SIZE = 2  # the full model's decomposition is reused by the reference and the reductions


def _sym_eig(A, s):
    """Eigendecomposition of the symmetric ``S A S⁻¹``, cached on the bytes of ``A`` and ``s``."""
    key = hashlib.sha1(A.tobytes() + np.asarray(s, dtype=float).tobytes()).hexdigest()
    if key in _EIG_CACHE:
        _EIG_CACHE.move_to_end(key)
        return _EIG_CACHE[key]
    As = (s[:, None] * A) / s[None, :]
    lam, U = sla.eigh(0.5 * (As + As.T), driver="evr", check_finite=False)
    _EIG_CACHE[key] = (lam, U)
    while len(_EIG_CACHE) > _EIG_CACHE_SIZE:
        _EIG_CACHE.popitem(last=False)
    return lam, U


def prepare(A, B, C, D, dt: float = 0.0, s=None, state_names=None) -> LTI:
    """Check stability and move a symmetrisable system to its (orthonormal) eigenbasis.

    Parameters
    ----------
    A, B, C, D : ndarray
    dt : float
        0 for continuous time, else the sample time [s].
    s : ndarray, optional
        Symmetrizer (``sqrt`` of the capacitances [J/K]^0.5); detected when omitted.
    state_names : list of str, optional
        Used to name the states of an unstable mode in the error message.
    """
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    if s is None:
        s = symmetrizer(A)
    if s is not None:
        lam, U = _sym_eig(A, s)
        _check_stable(lam, U / s[:, None], dt, state_names)
        to_x = U / s[:, None]             # x = S⁻¹ U x̂
        from_x = U.T * s[None, :]          # x̂ = Uᵀ S x
        return LTI(None, lam, from_x @ B, C @ to_x, np.asarray(D, dtype=float), dt, to_x, from_x)
    lam, V = np.linalg.eig(A)
    _check_stable(lam, V, dt, state_names)
    eye = np.eye(n)
    return LTI(A, None, np.asarray(B, dtype=float), np.asarray(C, dtype=float),
               np.asarray(D, dtype=float), dt, eye, eye, eig=(lam, V))


def diagonalized(sys: LTI, max_cond: float = 1e8):
    """``(lam, C V, V⁻¹ B)`` of a general system if its eigenvectors are well conditioned, else None."""
    if sys.eig is None:
        return None
    lam, V = sys.eig
    if np.linalg.cond(V) > max_cond:
        return None
    return lam, sys.C @ V, np.linalg.solve(V, sys.B)


def _check_stable(lam, vecs, dt, names):
    mag = np.abs(lam) if dt else np.real(lam)
    worst = int(np.argmax(mag))
    limit = 1.0 if dt else 0.0
    if mag[worst] < limit - 1e-13 * max(1.0, np.max(np.abs(lam))):
        return
    v = np.abs(vecs[:, worst])
    idx = np.flatnonzero(v > 0.1 * v.max())
    who = [names[i] for i in idx] if names is not None else [f"x[{i}]" for i in idx]
    raise ModelError(
        f"the system is not asymptotically stable (eigenvalue {lam[worst]:.3g}"
        f"{'' if not dt else ' in discrete time'}); the mode lives on {who[:12]}"
        f"{' ...' if len(who) > 12 else ''}: a group of states with no conductance path to a "
        "boundary node or to supply air floats. Linearize at a supply flow > 0 or add a wall "
        "to a boundary node. Balanced reduction needs a stable system.")


def _denominator(sys: LTI):
    lam = sys.lam
    if sys.dt:
        return 1.0 - np.outer(lam, lam)
    return -(lam[:, None] + lam[None, :])


def gramians(sys: LTI):
    """Controllability and observability Gramians ``(P, Q)`` in the system's coordinates."""
    if sys.modal:
        den = _denominator(sys)
        P = (sys.B @ sys.B.T) / den
        Q = (sys.C.T @ sys.C) / den
    elif sys.dt:
        P = sla.solve_discrete_lyapunov(sys.A, sys.B @ sys.B.T)
        Q = sla.solve_discrete_lyapunov(sys.A.T, sys.C.T @ sys.C)
    else:
        P = sla.solve_continuous_lyapunov(sys.A, -sys.B @ sys.B.T)
        Q = sla.solve_continuous_lyapunov(sys.A.T, -sys.C.T @ sys.C)
    return 0.5 * (P + P.T), 0.5 * (Q + Q.T)


def psd_factor(P) -> np.ndarray:
    """Low-rank ``F`` with ``P ≈ F Fᵀ`` by pivoted Cholesky (LAPACK ``dpstrf``).

    Rank-revealing: stops when the remaining diagonal drops below ``n·eps·max(diag)``;
    falls back to an eigendecomposition if LAPACK reports a failure.
    """
    n = P.shape[0]
    dmax = float(np.max(np.diag(P))) if n else 0.0
    if dmax <= 0.0:
        return np.zeros((n, 0))
    c, piv, rank, info = lapack.dpstrf(P, tol=n * np.finfo(float).eps * dmax, lower=1)
    if info < 0:
        w, V = np.linalg.eigh(P)
        keep = w > n * np.finfo(float).eps * w.max()
        return V[:, keep] * np.sqrt(w[keep])
    L = np.tril(c)[:, :rank]
    F = np.empty((n, rank))
    F[piv - 1] = L
    return F


@dataclass
class Balanced:
    """Hankel singular values and balancing projections of a stable system.

    Only the leading ``n_min`` directions (numerically minimal part) are used; the
    projections ``T_l`` (rows) and ``T_r`` (columns) of the leading ``r`` balanced states
    are formed on demand and cached for the largest ``r`` asked for.

    Attributes
    ----------
    hsv : ndarray
        Hankel singular values, descending (unresolved ones are tiny or 0).
    n_min : int
        Number of balanced states that can be used.
    sys : LTI
    """

    hsv: np.ndarray
    n_min: int
    sys: LTI
    _Y: np.ndarray          # right singular vectors of Loᵀ Lc (columns)
    _Lc: np.ndarray
    _left: object           # callable r -> T_l (r × n)
    _cache: dict

    @property
    def n_full(self) -> int:
        return self.sys.n

    def bound(self, r: int) -> float:
        """A-priori H∞ error bound ``2 Σ_{i>r} σ_i`` of an order-``r`` reduction."""
        return float(2.0 * np.sum(self.hsv[r:]))

    def order_for(self, tol: float) -> int:
        """Smallest order (≥ 1) whose a-priori bound is ≤ ``tol``."""
        tails = 2.0 * np.cumsum(self.hsv[::-1])[::-1]   # tails[r] = 2 Σ_{i≥r} σ_i
        ok = np.flatnonzero(np.append(tails, 0.0) <= tol)
        return int(max(1, min(ok[0], self.n_min)))

    def projections(self, r: int):
        """``(T_l, T_r)`` of the leading ``r`` balanced states, ``T_l T_r = I``."""
        if self._cache.get("r", -1) < r:
            si = 1.0 / np.sqrt(self.hsv[:r])
            Tr = self._Lc @ (self._Y[:, :r] * si)
            self._cache.update(r=r, Tl=self._left(r), Tr=Tr)
        return self._cache["Tl"][:r], self._cache["Tr"][:, :r]

    def reduce(self, r: int, method: str = "matchdc"):
        """Truncate or residualize (``matchdc``) to order ``r``.

        Residualization is computed as the reciprocal of the truncation of the
        reciprocal system (same Gramians): with :math:`M = T_l A^{-1} T_r`,
        :math:`A_r = M^{-1}`, :math:`B_r = M^{-1} T_l A^{-1} B`,
        :math:`C_r = C A^{-1} T_r M^{-1}`,
        :math:`D_r = D - C A^{-1} B + C A^{-1} T_r M^{-1} T_l A^{-1} B`
        (discrete time: :math:`A - I` in place of :math:`A` and :math:`A_r = I + M^{-1}`).
        Only the leading ``r`` balanced directions are needed.

        Returns
        -------
        A, B, C, D : ndarray
        to_x : ndarray, shape (n_full, r)
        from_x : ndarray, shape (r, n_full)
        """
        if method not in ("matchdc", "truncate"):
            raise ModelError(f"method must be 'matchdc' or 'truncate', found {method!r}")
        sys = self.sys
        Tl, Tr = self.projections(r)
        to_x, from_x = sys.to_x @ Tr, Tl @ sys.from_x
        if method == "truncate":
            if sys.modal:
                Ar = Tl @ (sys.lam[:, None] * Tr)
            else:
                Ar = Tl @ sys.A @ Tr
            return Ar, Tl @ sys.B, sys.C @ Tr, sys.D.copy(), to_x, from_x
        if sys.modal:
            shifted = sys.lam - 1.0 if sys.dt else sys.lam
            AiTr = Tr / shifted[:, None]
            AiB = sys.B / shifted[:, None]
        else:
            shifted = sys.A - np.eye(sys.n) if sys.dt else sys.A
            lu = sla.lu_factor(shifted)
            AiTr = sla.lu_solve(lu, Tr)
            AiB = sla.lu_solve(lu, sys.B)
        M = Tl @ AiTr
        TAB = Tl @ AiB
        CAT = sys.C @ AiTr
        lu = sla.lu_factor(M)
        Minv = sla.lu_solve(lu, np.eye(r))
        Br = Minv @ TAB
        Cr = CAT @ Minv
        Dr = sys.D - sys.C @ AiB + CAT @ Br
        Ar = np.eye(r) + Minv if sys.dt else Minv
        return Ar, Br, Cr, Dr, to_x, from_x


def balance(sys: LTI, accurate: bool | None = None) -> Balanced:
    """Square-root balancing (Laub; Tombs & Postlethwaite) from Gramian factors.

    With ``P = Lc Lcᵀ`` and ``Q = Lo Loᵀ``, ``Loᵀ Lc = Z Σ Yᵀ``; the leading balanced
    directions are ``T_r = Lc Y Σ^{-1/2}`` and ``T_l = Σ^{-1/2} Zᵀ Loᵀ``.

    Parameters
    ----------
    sys : LTI
    accurate : bool, optional
        True: SVD of ``Loᵀ Lc`` (resolves Hankel singular values down to ~1e-11 of the
        largest). False: eigendecomposition of ``Lcᵀ Q Lc = Y Σ² Yᵀ`` and
        ``T_l = Σ^{-3/2} Yᵀ Lcᵀ Q`` — about 3× faster for large systems, resolves values
        down to ~1e-6 of the largest, which caps the usable order there. Default: True
        up to 1000 states.
    """
    P, Q = gramians(sys)
    if accurate is None:
        accurate = sys.n <= _ACCURATE_LIMIT
    Lc = psd_factor(P)
    if Lc.shape[1] == 0 or not np.any(np.diag(Q) > 0):
        raise ModelError("the system has no controllable and observable part (all Hankel "
                         "singular values are zero): check the inputs and outputs")
    if accurate:
        Lo = psd_factor(Q)
        Z, sig, Yt = np.linalg.svd(Lo.T @ Lc, full_matrices=False)
        Y = Yt.T
        floor = _HSV_RTOL

        def left(r):
            return (Z[:, :r] / np.sqrt(sig[:r])).T @ Lo.T
    else:
        QLc = Q @ Lc
        H = Lc.T @ QLc
        w, Y = sla.eigh(0.5 * (H + H.T), driver="evr", check_finite=False)
        w, Y = w[::-1], Y[:, ::-1]
        sig = np.sqrt(np.clip(w, 0.0, None))
        floor = _HSV_RTOL_FAST

        def left(r):
            return (Y[:, :r] * sig[:r] ** -1.5).T @ QLc.T
    k = int(np.count_nonzero(sig > floor * sig[0]))
    if k < sys.n:
        log.info("balanced: %d of %d states usable (Hankel singular values > %.0e of the largest)",
                 k, sys.n, floor)
    return Balanced(hsv=sig, n_min=k, sys=sys, _Y=Y, _Lc=Lc, _left=left, _cache={})


def residualize_edges(K, G, cap, nz: int, Phi_a):
    r"""Keep the zone states and the edge coordinates ``Phi_a``; hold the rest quasi-static.

    The edge states are written :math:`x_e = \Phi_a a + \Phi_b b` with
    :math:`\Phi_b` the :math:`\mathcal{C}_e`-orthogonal complement of :math:`\Phi_a`,
    and :math:`b` is residualized (:math:`\Phi_b^T \mathcal{C}_e \dot x_e = 0`). That
    condition says that the edge heat balance lies in the range of
    :math:`\mathcal{C}_e\Phi_a`, which gives the result with sparse solves of
    :math:`K_{ee}` only — :math:`\Phi_b` is never formed. With
    :math:`X = K_{ee}^{-1}[\mathcal{C}_e\Phi_a,\ K_{ez},\ G_e]`,
    :math:`W = \Phi_a^T\mathcal{C}_e`, :math:`D_a = W\Phi_a` (diagonal),
    :math:`N = W X_a`, :math:`P_T = W X_z`, :math:`P_u = W X_u`:

    .. math::

        K_{TT} = K_{zz} - K_{ze}X_z + P_T^T N^{-1} P_T,\quad
        K_{aT} = D_a N^{-1} P_T,\quad K_{aa} = D_a N^{-1} D_a,

        G_T = G_z - K_{ze}X_u + P_T^T N^{-1} P_u,\quad G_a = D_a N^{-1} P_u .

    This is the Schur complement of the eliminated block (for a selection
    :math:`\Phi_a`, exactly Kron reduction): symmetric, exact at DC for every input and
    for any positive term later added to the zone block (the supply flow).

    Parameters
    ----------
    K : sparse matrix, shape (n, n)
        Conductance matrix without supply [W/K], zone states first.
    G : ndarray, shape (n, n_boundary)
        Conductances to the boundary nodes [W/K].
    cap : ndarray, shape (n,)
        Capacitances [J/K].
    nz : int
        Number of zone states (kept as they are).
    Phi_a : ndarray, shape (n - nz, r_e)
        Kept edge coordinates, columns :math:`\mathcal{C}_e`-orthogonal.

    Returns
    -------
    K_r : ndarray, shape (nz + r_e, nz + r_e)
    G_r : ndarray, shape (nz + r_e, n_boundary)
    cap_a : ndarray, shape (r_e,)
        :math:`\mathrm{diag}(D_a)` [J/K].
    lift_x : ndarray, shape (n, nz + r_e)
    lift_b : ndarray, shape (n, n_boundary)
        Full state ``x = lift_x @ [T; a] + lift_b @ T_b`` with ``b`` quasi-static.
    restrict : ndarray, shape (nz + r_e, n)
        ``[T; a]`` from a full state (``a`` by the capacitance-weighted projection).
    """
    K = sp.csr_matrix(K)
    n = K.shape[0]
    ne, re = n - nz, Phi_a.shape[1]
    nb = G.shape[1]
    Kzz = K[:nz, :nz].toarray()
    Kez = K[nz:, :nz].toarray()
    Kee = sp.csc_matrix(K[nz:, nz:])
    Ce = cap[nz:]
    try:
        lu = spla.splu(Kee)
        X = lu.solve(np.hstack([Ce[:, None] * Phi_a, Kez, G[nz:]]))
    except RuntimeError:
        X = np.full((ne, re + nz + nb), np.nan)
    if not np.all(np.isfinite(X)):
        raise ModelError("the edge states have no conductance path to a zone or a boundary node "
                         "(their conductance block is singular)")
    Xa, Xz, Xu = X[:, :re], X[:, re:re + nz], X[:, re + nz:]
    W = Phi_a.T * Ce[None, :]
    Da = np.einsum("ij,ji->i", W, Phi_a)
    PT, Pu = W @ Xz, W @ Xu
    KTT = Kzz - Kez.T @ Xz
    GT = G[:nz] - Kez.T @ Xu
    lift_x = np.zeros((n, nz + re))
    lift_x[:nz, :nz] = np.eye(nz)
    lift_x[nz:, :nz] = -Xz
    lift_b = np.zeros((n, nb))
    lift_b[nz:] = Xu
    if re:
        N = W @ Xa  # Φaᵀ C_e K_ee⁻¹ C_e Φa: symmetric positive definite
        cf = sla.cho_factor(0.5 * (N + N.T))
        NiPT, NiPu = sla.cho_solve(cf, PT), sla.cho_solve(cf, Pu)
        NiDa = sla.cho_solve(cf, np.diag(Da))
        KTT = KTT + PT.T @ NiPT
        GT = GT + PT.T @ NiPu
        KaT = Da[:, None] * NiPT
        Kaa = Da[:, None] * NiDa
        Kr = np.block([[KTT, KaT.T], [KaT, Kaa]])
        Gr = np.vstack([GT, Da[:, None] * NiPu])
        lift_x[nz:, :nz] += Xa @ NiPT
        lift_x[nz:, nz:] = Xa @ NiDa
        lift_b[nz:] -= Xa @ NiPu
    else:
        Kr, Gr = KTT, GT
    restrict = np.zeros((nz + re, n))
    restrict[:nz, :nz] = np.eye(nz)
    restrict[nz:, nz:] = W / Da[:, None]
    return 0.5 * (Kr + Kr.T), Gr, Da, lift_x, lift_b, restrict
