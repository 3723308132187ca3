"""BLAS products inside CasADi graphs: same values and derivatives as ``casadi.mtimes``."""

import casadi as ca
import numpy as np
import pytest

from thermctl.estimate.likelihood._dense import dense_mtimes


def _graphs(n, k, m, seed):
    """f(x) built twice, with dense_mtimes and with casadi.mtimes, on the same x."""
    rng = np.random.default_rng(seed)
    x = ca.MX.sym("x", 4)
    Ma, Mb = rng.normal(size=(n * k, 4)), rng.normal(size=(k * m, 4))
    A = ca.reshape(ca.sin(ca.mtimes(ca.DM(Ma), x)), n, k)
    B = ca.reshape(ca.exp(0.3 * ca.mtimes(ca.DM(Mb), x)), k, m)
    out = []
    for mt in (dense_mtimes, ca.mtimes):
        C = mt(mt(A, B), B.T)           # a product of a product: second order through both
        out.append(C)
    return x, rng.normal(size=4), out


@pytest.mark.parametrize("n,k,m", [(3, 5, 2), (7, 7, 7), (1, 4, 6)])
def test_values_and_exact_derivatives(n, k, m):
    x, x0, (C1, C2) = _graphs(n, k, m, seed=n + k + m)
    vals = []
    for C in (C1, C2):
        f = ca.sum1(ca.sum2(ca.cos(C)))
        H, g = ca.hessian(f, x)
        J = ca.jacobian(ca.vec(C), x)          # 4 inputs, many outputs: forward mode
        Jr = ca.jacobian(ca.vertcat(f, 2 * f), x)      # 2 outputs: reverse mode
        vals.append([np.asarray(v) for v in ca.Function("f", [x], [C, g, H, J, Jr])(x0)])
    for a, b in zip(*vals):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    # and the derivative is that of the function: central differences of the gradient
    f = ca.Function("g", [x], [ca.gradient(ca.sum1(ca.sum2(ca.cos(C1))), x)])
    h = 1e-5
    Hfd = np.column_stack([(np.asarray(f(x0 + h * e)) - np.asarray(f(x0 - h * e))).ravel()
                           / (2 * h) for e in np.eye(4)])
    np.testing.assert_allclose(vals[0][2], Hfd, rtol=1e-6, atol=1e-7)


def test_shapes_checked():
    with pytest.raises(ValueError, match="inner dimensions"):
        dense_mtimes(ca.MX.sym("a", 2, 3), ca.MX.sym("b", 2, 3))
    assert dense_mtimes(ca.MX.sym("a", 0, 3), ca.MX.sym("b", 3, 2)).shape == (0, 2)


def _sequential(F, G, S, restart, L, regime=None):
    """x_{k+1} = F x_k + g_k step by step in time order (MX), from the chunk layout; with
    ``regime``, the step out of column k by ``F[:, r·n:(r+1)·n]``, r = regime[k]."""
    n, M = F.shape[0], len(restart)
    cols = [None] * (L * M)
    x = None
    for c in range(M):
        for j in range(L):
            k = j * M + c
            r = 0 if regime is None else regime[k]
            if j == 0 and restart[c] >= 0:
                x = S[:, restart[c]]
            cols[k] = x
            x = ca.mtimes(F[:, r * n:(r + 1) * n], x) + G[:, k]
    return ca.horzcat(*cols)


@pytest.mark.parametrize("L,restart", [(4, [0, -1, -1, 1, -1, 2]), (1, [0, -1, 1]),
                                       (8, [0])])
def test_recursion_matches_step_by_step(L, restart):
    from thermctl.estimate.likelihood._dense import linear_recursion
    rng = np.random.default_rng(L)
    n, M = 3, len(restart)
    nseg = max(restart) + 1
    x = ca.MX.sym("x", 3)
    F0 = rng.normal(size=(n, n)) * 0.3
    F = ca.DM(F0) + ca.diag(0.2 * ca.tanh(x))          # F, G and the starts depend on x
    G = ca.DM(rng.normal(size=(n, L * M))) * ca.exp(x[1])
    S = ca.DM(rng.normal(size=(n, nseg))) * (1 + x[2] ** 2)
    W = ca.DM(rng.normal(size=(n, L * M)))
    x0 = rng.normal(size=3)
    _assert_same_to_second_order(x, x0, W, linear_recursion(F, G, S, restart, L),
                                 _sequential(F, G, S, restart, L))


def _assert_same_to_second_order(x, x0, W, *Xs):
    """The recursions ``Xs`` (MX in ``x``): equal values, gradients, Hessians and forward
    Jacobians of a scalar of them at ``x0``, to 1e-11; returns the first one's value."""
    out = []
    for X in Xs:
        f = ca.sum1(ca.sum2(W * X)) + ca.sumsqr(X) / 7
        H, g = ca.hessian(f, x)
        J = ca.jacobian(ca.vec(X), x)
        out.append([np.asarray(v) for v in ca.Function("f", [x], [X, f, g, H, J])(x0)])
    for a, b in zip(*out):
        np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-11)
    return out[0][0]


@pytest.mark.parametrize("L,restart,chunks", [
    (4, [0, -1, -1, 1, -1, 2], [0, 1, 1, 0, 1, 0]),     # one regime per chunk
    (4, [0, -1, -1, 1, -1, 2], None),                   # regimes changing within chunks
    (1, [0, -1, 1], [1, 0, 1]),
    (3, [0, -1, -1, -1], None)])
def test_switched_recursion_matches_step_by_step(L, restart, chunks):
    """One matrix per step (the occupied-hours filter): values, gradients, Hessians and
    forward Jacobians equal those of the step-by-step recursion, to 1e-11."""
    from thermctl.estimate.likelihood._dense import linear_recursion
    rng = np.random.default_rng(10 + L)
    n, M = 3, len(restart)
    if chunks is not None:
        regime = list(np.tile(chunks, L))          # column j·M + c is in chunk c
    else:
        regime = list(rng.integers(0, 3, L * M))
    R = max(regime) + 1
    nseg = max(restart) + 1
    x = ca.MX.sym("x", 3)
    blocks = [ca.DM(rng.normal(size=(n, n)) * 0.3) + ca.diag((0.1 + 0.1 * r) * ca.tanh(x))
              for r in range(R)]
    blocks[-1] = blocks[-1] * ca.exp(0.2 * x[0])
    F = ca.horzcat(*blocks)
    G = ca.DM(rng.normal(size=(n, L * M))) * ca.exp(x[1])
    S = ca.DM(rng.normal(size=(n, nseg))) * (1 + x[2] ** 2)
    W = ca.DM(rng.normal(size=(n, L * M)))
    x0 = rng.normal(size=3)
    X1 = _assert_same_to_second_order(x, x0, W, linear_recursion(F, G, S, restart, L, regime),
                                      _sequential(F, G, S, restart, L, regime))
    # and the regimes matter: with every step on matrix 0 the states differ
    X0 = ca.Function("x", [x], [linear_recursion(F[:, :n], G, S, restart, L)])(x0)
    assert np.abs(np.asarray(X0) - X1).max() > 1e-3


@pytest.mark.skipif(not __import__("sys").platform.startswith("linux"), reason="glibc only")
def test_keep_heap_reuses_freed_memory():
    """After keep_heap, 100 MB of arrays freed and allocated again are not page-faulted in
    again (glibc's default trims the freed heap: measured 123 000 minor faults for the ten
    rounds below in a fresh process, 0 with keep_heap)."""
    import os
    import resource

    from thermctl._blas import keep_heap
    if os.environ.get("MALLOC_MMAP_THRESHOLD_"):
        pytest.skip("the user's own malloc settings")
    assert keep_heap() and keep_heap()

    def touch():
        a = [np.ones(1 << 19) for _ in range(25)]        # 25 blocks of 4 MB
        return sum(float(x[-1]) for x in a)

    touch(), touch()
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(10):
        touch()
    assert resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0 < 1000


def test_buffered_function_equals_call_and_is_reused():
    from thermctl.estimate.likelihood._dense import BufferedFunction
    x = ca.MX.sym("x", 3)
    f = ca.Function("f", [x], [ca.sumsqr(ca.sin(x)), ca.densify(ca.gradient(ca.sumsqr(x), x))])
    b = BufferedFunction(f)
    for v in ([0.1, 0.2, 0.3], [1.0, -2.0, 0.5]):
        got = b(np.array(v))
        want = [np.asarray(o).ravel() for o in f(v)]
        for g, w in zip(got, want):
            np.testing.assert_array_equal(g, w)
    first = b(np.zeros(3))
    b(np.ones(3))
    np.testing.assert_array_equal(first[1], np.zeros(3))    # copies, not views of the buffer
    b.release()
    np.testing.assert_allclose(b(np.ones(3))[1], 2 * np.ones(3))
    # several inputs, a matrix among them (column-major like CasADi)
    M = ca.MX.sym("M", 2, 3)
    g = BufferedFunction(ca.Function("g", [x, M], [ca.densify(ca.mtimes(M, x))]))
    Mv = np.arange(6.0).reshape(2, 3)
    np.testing.assert_allclose(g(np.array([1.0, 2.0, 3.0]), Mv)[0], Mv @ [1.0, 2.0, 3.0])
