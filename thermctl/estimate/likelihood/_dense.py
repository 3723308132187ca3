"""Dense matrix products of a CasADi graph done by BLAS (numpy), with exact derivatives.

CasADi's virtual machine multiplies dense matrices with its own triple loop over the
sparsity pattern: 0.5–1.4 Gflop/s on this project's 2-core machine, against 20–40 with
OpenBLAS. The likelihood's hot products are dense (the chunked filter recursion, the
doubling of the discretisation), so :func:`dense_mtimes` hands them to numpy through a
:class:`casadi.Callback` with a raw-buffer ``eval``. Measured in a chain of 100 products
of 61×61 matrices: 42 µs a product against 182 µs for ``casadi.mtimes``.

The derivatives are exact to every order: the forward and reverse derivatives of
``C = A B`` are again products (``Ċ = Ȧ B + A Ḃ``; ``Ā = C̄ Bᵀ``, ``B̄ = Aᵀ C̄``),
built from the same callback, so CasADi can differentiate them again (the Hessians of
:meth:`LikelihoodProblem.hessian` stay exact).
"""

from __future__ import annotations

import threading

import casadi as ca
import numpy as np
import scipy.sparse as sp

__all__ = ["dense_mtimes", "linear_recursion", "BufferedFunction"]

# one callback per shape, kept alive here: a CasADi graph holds only a reference to it
_CACHE: dict = {}
_LOCK = threading.Lock()


def dense_mtimes(A, B):
    """``A @ B`` of two MX (or DM) matrices, evaluated by BLAS.

    Sparse operands are densified; use ``casadi.mtimes`` where one factor is a sparse
    selection or a network matrix (CasADi then skips the structural zeros).

    Parameters
    ----------
    A : casadi.MX, shape (n, k)
    B : casadi.MX, shape (k, m)

    Returns
    -------
    casadi.MX, shape (n, m)
    """
    n, k = A.shape
    k2, m = B.shape
    if k != k2:
        raise ValueError(f"dense_mtimes: inner dimensions differ ({A.shape} @ {B.shape})")
    if n == 0 or m == 0 or k == 0:
        return ca.MX(n, m)
    return _cached(("mm", n, k, m), _Matmul)(ca.densify(A), ca.densify(B))


def _blocks(X, rows: int, cols: int, count: int):
    """``X`` (rows, cols·count) as a list of ``count`` (rows, cols) blocks."""
    return [X[:, i * cols:(i + 1) * cols] for i in range(count)]


def _view(buf, shape):
    return np.frombuffer(buf, dtype=float).reshape(shape, order="F")


class _DenseCallback(ca.Callback):
    """A numpy function of dense matrices in a CasADi graph, with derivatives of every order.

    Subclasses set ``self.ins`` (the input shapes) and ``self.out`` (the output shape)
    before :meth:`_construct`, compute into the output in :meth:`compute`, and build their
    derivatives from such callbacks again in ``get_forward`` / ``get_reverse``.
    """

    ins: tuple = ()
    out: tuple = (0, 0)

    def _construct(self, name: str):
        self.construct(name, {"enable_fd": False})

    def get_n_in(self):
        return len(self.ins)

    def get_n_out(self):
        return 1

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(*self.ins[i])

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(*self.out)

    def has_eval_buffer(self):
        return True

    def eval_buffer(self, arg, res):
        # CasADi stores dense matrices column-major
        self.compute(*(_view(a, sh) for a, sh in zip(arg, self.ins)), _view(res[0], self.out))
        return 0

    def compute(self, *args):
        raise NotImplementedError

    def has_forward(self, nfwd):
        return True

    def has_reverse(self, nadj):
        return True


class _Matmul(_DenseCallback):
    """``C = A B`` for dense ``A`` (n×k) and ``B`` (k×m) by ``numpy.matmul``."""

    def __init__(self, n: int, k: int, m: int):
        ca.Callback.__init__(self)
        self.n, self.k, self.m = n, k, m
        self.ins, self.out = ((n, k), (k, m)), (n, m)
        self._construct(f"matmul_{n}x{k}x{m}")

    def compute(self, a, b, out):
        np.matmul(a, b, out=out)

    def get_forward(self, nfwd, name, inames, onames, opts):
        n, k, m = self.n, self.k, self.m
        A, B = ca.MX.sym("A", n, k), ca.MX.sym("B", k, m)
        C = ca.MX.sym("C", n, m)
        dA, dB = ca.MX.sym("dA", n, k * nfwd), ca.MX.sym("dB", k, m * nfwd)
        # Ȧ_i B for every direction in one product: stack the Ȧ_i vertically
        dAB = dense_mtimes(ca.vertcat(*_blocks(dA, n, k, nfwd)), B)
        dC = ca.horzcat(*[dAB[i * n:(i + 1) * n, :] for i in range(nfwd)]) + dense_mtimes(A, dB)
        return ca.Function(name, [A, B, C, dA, dB], [dC], inames, onames, opts)

    def get_reverse(self, nadj, name, inames, onames, opts):
        n, k, m = self.n, self.k, self.m
        A, B = ca.MX.sym("A", n, k), ca.MX.sym("B", k, m)
        C = ca.MX.sym("C", n, m)
        Cb = ca.MX.sym("Cb", n, m * nadj)
        # Ā_i = C̄_i Bᵀ for every direction in one product: stack the C̄_i vertically
        CbBt = dense_mtimes(ca.vertcat(*_blocks(Cb, n, m, nadj)), B.T)
        Ab = ca.horzcat(*[CbBt[i * n:(i + 1) * n, :] for i in range(nadj)])
        Bb = dense_mtimes(A.T, Cb)
        return ca.Function(name, [A, B, C, Cb], [Ab, Bb], inames, onames, opts)


# ---------------------------------------------------------------------- the recursion
def linear_recursion(F, GZ, starts, restart, L: int, regime=None):
    r"""All states of ``x_{k+1} = F x_k + g_k``, segment by segment, evaluated by numpy.

    The contract of :func:`thermctl.estimate.likelihood.kalman.chunked_recursion` (chunk
    layout: column ``j·M + c`` is step ``j`` of chunk ``c``; chunk ``c`` starts segment
    ``restart[c]`` or continues chunk ``c − 1``). One graph node instead of ``2L + M``
    products. Its derivatives are again recursions (the adjoint runs backward in time with
    ``Fᵀ``; see :class:`_Recursion`), so they are exact to every order.

    Parameters
    ----------
    F : casadi.MX, shape (n, n) or (n, n·R)
        With ``regime``: the R matrices side by side, ``F_r = F[:, r·n:(r+1)·n]``.
    GZ : casadi.MX, shape (n, L·M)
    starts : casadi.MX, shape (n, n_segments)
    restart : sequence of int, length M
    L : int
    regime : sequence of int, length L·M, optional
        ``regime[k]``: the matrix of the step out of column ``k`` (chunk layout; a regime
        may change within a chunk). Default: one matrix.

    Returns
    -------
    casadi.MX, shape (n, L·M)
    """
    reg = _regime_key(regime, L * len(restart))
    cb = _cached(("rec", F.shape[0], L, tuple(restart), starts.shape[1], reg), _Recursion)
    return cb(ca.densify(F), ca.densify(GZ), ca.densify(starts))


def _regime_key(regime, LM: int):
    """``regime`` as a tuple of L·M ints, or None for a single matrix."""
    if regime is None:
        return None
    reg = tuple(int(r) for r in regime)
    if len(reg) != LM:
        raise ValueError(f"regime: {len(reg)} entries for {LM} columns")
    if min(reg) < 0:
        raise ValueError("regime: indices must be >= 0")
    return None if max(reg) == 0 else reg


def _n_regimes(reg) -> int:
    return 1 if reg is None else max(reg) + 1


def _column_masks(reg):
    """Per regime with columns, ``(r, Sel_r)``: the sparse (len(reg), n_r) selection of its
    columns (a gather; ``Sel_rᵀ`` scatters back). Products then run on each regime's columns
    only: one full product's flops in all, where diagonal masks cost one per regime."""
    cols = np.asarray(reg)
    out = []
    for r in range(_n_regimes(reg)):
        idx = np.flatnonzero(cols == r)
        if len(idx):
            sel = sp.csc_matrix((np.ones(len(idx)), (idx, np.arange(len(idx)))),
                                shape=(len(cols), len(idx)))
            out.append((r, ca.DM(sel)))
    return out


def _step_groups(F, reg, M: int, L: int, transpose: bool = False):
    """Per step j of a chunk: ``[(F_r, chunks whose column (c, j) is in regime r), ...]``,
    and per chunk its single regime or -1 where it changes within the chunk."""
    n = F.shape[0]
    Fs = _split(F, n, _n_regimes(reg))
    if transpose:
        Fs = [Fr.T for Fr in Fs]
    if reg is None:
        return Fs, None, [Fs[0]] * L, np.zeros(M, dtype=int)
    R3 = np.asarray(reg).reshape((M, L), order="F")          # [c, j] = reg[j·M + c]
    groups = []
    for j in range(L):
        g = [(Fs[r], np.flatnonzero(R3[:, j] == r)) for r in range(len(Fs))]
        g = [(Fr, idx) for Fr, idx in g if len(idx)]
        groups.append(g[0][0] if len(g) == 1 else g)          # one regime: no indexing
        # (a bare matrix where every chunk is in one regime at step j)
    pure = np.where((R3 == R3[:, :1]).all(axis=1), R3[:, 0], -1)
    return Fs, R3, groups, pure


def _apply(group, A, out=None):
    """``F_r A`` column by column in their regimes (``group`` from :func:`_step_groups`)."""
    if isinstance(group, np.ndarray):
        return np.matmul(group, A, out=out)
    B = np.empty_like(A) if out is None else out
    for Fr, idx in group:
        B[:, idx] = Fr @ A[:, idx]
    return B


def _split(F, n: int, R: int):
    """The R (n, n) blocks of ``F`` (n, n·R)."""
    return [F[:, r * n:(r + 1) * n] for r in range(R)]


def _per_regime(dF, Y, masks, n):
    """``Σ_r dF_r (Y D_r)``: each column of ``Y`` times its own regime's block of ``dF``."""
    if masks is None:
        return dense_mtimes(dF, Y)
    return sum(ca.mtimes(dense_mtimes(dF[:, r * n:(r + 1) * n], ca.mtimes(Y, S)), S.T)
               for r, S in masks)


def _per_regime_outer(Gb, X, masks, R: int):
    """``[(Ḡ D_0) Xᵀ, (Ḡ D_1) Xᵀ, ...]``: the derivative of each of the R regime blocks."""
    if masks is None:
        return dense_mtimes(Gb, X.T)
    n = Gb.shape[0]
    blocks = {r: dense_mtimes(ca.mtimes(Gb, S), ca.mtimes(X, S).T) for r, S in masks}
    return ca.densify(ca.horzcat(*[blocks.get(r, ca.MX(n, n)) for r in range(R)]))


def _adjoint(F, Xb, restart, L: int, regime=None):
    """``Ḡ`` of :func:`linear_recursion` for the output seed ``Xb`` (see :class:`_Adjoint`)."""
    n = F.shape[0]
    cb = _cached(("adj", n, L, tuple(restart), _regime_key(regime, L * len(restart))), _Adjoint)
    return cb(ca.densify(F), ca.densify(Xb))


def _cached(key, cls):
    """The callback ``cls(*key[1:])``, made once per key."""
    with _LOCK:
        cb = _CACHE.get(key)
        if cb is None:
            cb = _CACHE[key] = cls(*key[1:])
    return cb


def _rec_np(F, G, S, restart, L, out, regime=None):
    """numpy kernel of :func:`linear_recursion` into ``out``; ``G`` and ``out`` are (n, L·M)
    column-major chunk layouts, viewed as (n, M, L) so that every step is one contiguous block.
    With ``regime`` the step out of column ``k`` is by ``F[:, r·n:(r+1)·n]``,
    ``r = regime[k]``: each step's columns grouped by regime, and the chain through a chunk
    whose regime changes goes step by step."""
    n, M = F.shape[0], len(restart)
    Fs, R3, groups, pure = _step_groups(F, regime, M, L)
    G3 = G.reshape((n, M, L), order="F")           # [i, c, j] = G[i, j·M + c]
    X = out.reshape((n, M, L), order="F")
    # pass 1: every chunk from zero (X[:, :, j] holds that partial state for now)
    X[:, :, 0] = 0.0
    last = np.zeros((n, M))
    for j in range(L):
        nxt = X[:, :, j + 1] if j + 1 < L else last
        _apply(groups[j], X[:, :, j], out=nxt)
        nxt += G3[:, :, j]
    # chain the chunk starts
    FL = [np.linalg.matrix_power(Fr, L) for Fr in Fs]
    H = np.empty((n, M), order="F")
    x = None
    for c in range(M):
        if restart[c] >= 0:
            x = S[:, restart[c]]
        H[:, c] = x
        if pure[c] >= 0:
            x = FL[pure[c]] @ x
        else:
            for j in range(L):
                x = Fs[R3[c, j]] @ x
        x = x + last[:, c]
    # pass 2: add F^j x_{c,0}
    for j in range(L):
        X[:, :, j] += H
        if j + 1 < L:
            H = _apply(groups[j], H)


def _adj_np(F, Xb, restart, L, out, regime=None):
    """numpy kernel of the adjoint into ``out``: ``Ḡ_k = λ_{k+1}`` where the step k → k+1
    exists, else 0, with ``λ_k = X̄_k + Fᵀ λ_{k+1}`` backward in each segment (with regimes,
    ``F`` of column k's regime)."""
    n, M = F.shape[0], len(restart)
    FTs, R3, groups, pure = _step_groups(F, regime, M, L, transpose=True)
    Xb3 = Xb.reshape((n, M, L), order="F")
    Gb = out.reshape((n, M, L), order="F")
    # λ within each chunk with nothing coming in: λ_{c,j} is stored at Gb[:, c, j − 1]
    acc = np.array(Xb3[:, :, L - 1], order="F")
    first = np.empty((n, M))
    for j in range(L - 1, 0, -1):
        Gb[:, :, j - 1] = acc
        acc = _apply(groups[j - 1], acc)
        acc += Xb3[:, :, j - 1]
    first[:] = acc                                   # λ_{c,0} of the chunk alone
    FLT = [np.linalg.matrix_power(FT, L) for FT in FTs]
    mu = np.zeros((n, M), order="F")                 # λ at the start of the next chunk
    nxt = np.zeros(n)
    for c in range(M - 1, -1, -1):
        if c + 1 < M and restart[c + 1] < 0:
            mu[:, c] = nxt
        if pure[c] >= 0:
            v = FLT[pure[c]] @ mu[:, c]
        else:
            v = mu[:, c]
            for j in range(L - 1, -1, -1):
                v = FTs[R3[c, j]] @ v
        nxt = first[:, c] + v
    # add what comes in from the next chunk: λ_{c,j} += (Fᵀ)^{L−j} μ_c
    Gb[:, :, L - 1] = mu
    Hb = mu
    for j in range(L - 1, 0, -1):
        Hb = _apply(groups[j], Hb)
        Gb[:, :, j - 1] += Hb


class _Recursion(_DenseCallback):
    """``X = rec(F, GZ, starts)`` (:func:`linear_recursion`).

    Derivatives: forward ``Ẋ = rec(F, ĠZ + Ḟ X, ṡtarts)``; reverse ``ḠZ = adj(F, X̄)``,
    ``F̄ = ḠZ Xᵀ``, ``s̄tarts`` from ``λ`` at each segment's first step. With regimes each
    column takes its own chunk's block of ``Ḟ`` and gives to its own block of ``F̄``.
    """

    def __init__(self, n, L, restart, nseg, regime=None):
        ca.Callback.__init__(self)
        self.n, self.L, self.restart, self.nseg = n, L, list(restart), nseg
        self.M = len(restart)
        self.regime = regime
        self.R = _n_regimes(regime)
        self.masks = None if regime is None else _column_masks(regime)
        sel = np.zeros((self.M, nseg))
        for c, s in enumerate(self.restart):
            if s >= 0:
                sel[c, s] = 1.0
        self.sel = ca.DM(sel)
        self.ins, self.out = ((n, n * self.R), (n, L * self.M), (n, nseg)), (n, L * self.M)
        self._construct(f"recursion_{n}x{L}x{self.M}_{id(self):x}")

    def compute(self, F, GZ, S, out):
        _rec_np(F, GZ, S, self.restart, self.L, out, self.regime)

    def _syms(self):
        n, LM = self.n, self.L * self.M
        return (ca.MX.sym("F", n, n * self.R), ca.MX.sym("GZ", n, LM),
                ca.MX.sym("S", n, self.nseg), ca.MX.sym("X", n, LM))

    def get_forward(self, nfwd, name, inames, onames, opts):
        n, LM, ns, nR = self.n, self.L * self.M, self.nseg, self.n * self.R
        F, GZ, S, X = self._syms()
        dF = ca.MX.sym("dF", n, nR * nfwd)
        dG = ca.MX.sym("dG", n, LM * nfwd)
        dS = ca.MX.sym("dS", n, ns * nfwd)
        out = [linear_recursion(F, dG[:, i * LM:(i + 1) * LM]
                                + _per_regime(dF[:, i * nR:(i + 1) * nR], X, self.masks, n),
                                dS[:, i * ns:(i + 1) * ns], self.restart, self.L, self.regime)
               for i in range(nfwd)]
        return ca.Function(name, [F, GZ, S, X, dF, dG, dS], [ca.horzcat(*out)], inames, onames,
                           opts)

    def get_reverse(self, nadj, name, inames, onames, opts):
        n, LM, M = self.n, self.L * self.M, self.M
        F, GZ, S, X = self._syms()
        Xb = ca.MX.sym("Xb", n, LM * nadj)
        Fb, Gb, Sb = [], [], []
        # the regime of each chunk's first column (columns 0..M−1)
        head = None if self.masks is None else _column_masks(self.regime[:M])
        for i in range(nadj):
            xb = Xb[:, i * LM:(i + 1) * LM]
            gb = _adjoint(F, xb, self.restart, self.L, self.regime)
            Fb.append(_per_regime_outer(gb, X, self.masks, self.R))
            Gb.append(gb)
            # λ at a chunk's first step (columns 0..M−1): X̄ there plus Fᵀ λ one step on
            FTg = _per_regime(_transposed_blocks(F, n, self.R), gb[:, :M], head, n)
            Sb.append(ca.mtimes(xb[:, :M] + FTg, self.sel))
        return ca.Function(name, [F, GZ, S, X, Xb],
                           [ca.horzcat(*Fb), ca.horzcat(*Gb), ca.horzcat(*Sb)],
                           inames, onames, opts)


def _transposed_blocks(F, n: int, R: int):
    """``[F_0ᵀ, F_1ᵀ, ...]`` side by side."""
    return ca.horzcat(*[F[:, r * n:(r + 1) * n].T for r in range(R)])


class _Adjoint(_DenseCallback):
    """``Ḡ = adj(F, X̄)``: the reverse sweep of :class:`_Recursion`, linear in ``X̄``.

    Derivatives: forward ``Ḡ̇ = adj(F, Ẋ̄ + Ḟᵀ Ḡ)``; reverse ``ν = rec(F, Ḡ̄, 0)``,
    ``X̄̄ = ν``, ``F̄ = Ḡ νᵀ`` (per regime block, as in :class:`_Recursion`).
    """

    def __init__(self, n, L, restart, regime=None):
        ca.Callback.__init__(self)
        self.n, self.L, self.restart = n, L, list(restart)
        self.M = len(restart)
        self.regime = regime
        self.R = _n_regimes(regime)
        self.masks = None if regime is None else _column_masks(regime)
        self.nseg = max(max(self.restart) + 1, 1)
        self.ins, self.out = ((n, n * self.R), (n, L * self.M)), (n, L * self.M)
        self._construct(f"recursion_adj_{n}x{L}x{self.M}_{id(self):x}")

    def compute(self, F, Xb, out):
        _adj_np(F, Xb, self.restart, self.L, out, self.regime)

    def _syms(self):
        n, LM = self.n, self.L * self.M
        return ca.MX.sym("F", n, n * self.R), ca.MX.sym("Xb", n, LM), ca.MX.sym("Gb", n, LM)

    def get_forward(self, nfwd, name, inames, onames, opts):
        n, LM, nR = self.n, self.L * self.M, self.n * self.R
        F, Xb, Gb = self._syms()
        dF = ca.MX.sym("dF", n, nR * nfwd)
        dX = ca.MX.sym("dX", n, LM * nfwd)
        out = [_adjoint(F, dX[:, i * LM:(i + 1) * LM]
                        + _per_regime(_transposed_blocks(dF[:, i * nR:(i + 1) * nR], n, self.R),
                                      Gb, self.masks, n),
                        self.restart, self.L, self.regime)
               for i in range(nfwd)]
        return ca.Function(name, [F, Xb, Gb, dF, dX], [ca.horzcat(*out)], inames, onames, opts)

    def get_reverse(self, nadj, name, inames, onames, opts):
        n, LM = self.n, self.L * self.M
        F, Xb, Gb = self._syms()
        Gbb = ca.MX.sym("Gbb", n, LM * nadj)
        zero = ca.MX(n, self.nseg)
        Fb, Xbb = [], []
        for i in range(nadj):
            nu = linear_recursion(F, Gbb[:, i * LM:(i + 1) * LM], zero, self.restart, self.L,
                                  self.regime)
            Fb.append(_per_regime_outer(Gb, nu, self.masks, self.R))
            Xbb.append(nu)
        return ca.Function(name, [F, Xb, Gb, Gbb], [ca.horzcat(*Fb), ca.horzcat(*Xbb)],
                           inames, onames, opts)


# ---------------------------------------------------------------------- evaluation
class BufferedFunction:
    """A CasADi Function of dense inputs, called on buffers that live with it.

    ``casadi.Function.__call__`` allocates the work vector on every call. For the
    likelihood's gradient that is 67 MB on the twin house (119 states, 49 parameters), above
    glibc's largest threshold for keeping freed memory, so each call page-faulted it in again:
    16 000 faults and 244 → 199 ms a call with a :meth:`casadi.Function.buffer`.

    Each thread gets its own buffers, so that threads may evaluate the same problem at once
    (the profile intervals do).

    Parameters
    ----------
    fn : casadi.Function
        Dense inputs and outputs (``casadi.densify`` them).
    """

    def __init__(self, fn: ca.Function):
        self.fn = fn
        self._lock = threading.Lock()
        self._bufs = {}

    def _make(self):
        fb, run = self.fn.buffer()
        args = [np.zeros(self.fn.nnz_in(i)) for i in range(self.fn.n_in())]
        res = [np.zeros(self.fn.nnz_out(i)) for i in range(self.fn.n_out())]
        for i, a in enumerate(args):
            fb.set_arg(i, memoryview(a))
        for i, r in enumerate(res):
            fb.set_res(i, memoryview(r))
        return fb, run, args, res

    def __call__(self, *xs) -> list[np.ndarray]:
        """Outputs at the inputs ``xs`` as flat numpy arrays (column-major), copies."""
        tid = threading.get_ident()
        with self._lock:
            buf = self._bufs.get(tid)
            if buf is None:
                buf = self._bufs[tid] = self._make()
        fb, run, args, res = buf
        for a, x in zip(args, xs, strict=True):
            a[:] = np.asarray(x, dtype=float).ravel(order="F")
        run()
        if fb.ret() != 0:
            raise RuntimeError(f"CasADi function {self.fn.name()} failed (return code "
                               f"{fb.ret()})")
        return [r.copy() for r in res]

    def release(self) -> None:
        """Free the buffers (a fitted problem kept for later use need not hold them)."""
        with self._lock:
            self._bufs = {}
