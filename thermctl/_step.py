r"""The model's one discrete step: two-stage Radau IIA, the (1,2) Padé approximant of exp.

For :math:`\dot x = A x + b` with ``b`` held over a sub-step of length ``h`` (zero-order
hold), two-stage Radau IIA collocation (order 3) gives

.. math::

    D x^+ = N x + c, \quad D = I - \tfrac{2h}{3}A + \tfrac{h^2}{6}A^2,\;
    N = I + \tfrac{h}{3}A,\; c = h\big(b - \tfrac{h}{6}A b\big),

i.e. :math:`x^+ = R(hA)\,x + \dots` with :math:`R(z) = (1 + z/3)/(1 - 2z/3 + z^2/6)`,
the (1,2) Padé approximant of :math:`e^z`. It is L-stable (:math:`R(-\infty) = 0`): the
convection edges have time constants of seconds and ``h`` is a minute, so a step that
is merely A-stable would ring on them. For any ``h`` the steady state
:math:`x = -A^{-1}b` is a fixed point.

This module is the only place the formula is written; every simulator and NLP of the
package uses it:

* numpy: :func:`radau_stepper` (``make_stepper(..., "radau")`` of :mod:`thermctl.model`,
  ``ThermalModel.simulate``, ``ReducedNetwork.simulate``); :func:`radau_d_matrix`,
  :func:`radau_n`, :func:`radau_forcing` and :func:`radau_tangent` for the sparse
  simulator with sensitivities of :mod:`thermctl.estimate.simulation.radau`;
* CasADi, explicit: :func:`radau_casadi_step` (``ThermalModel.to_casadi().F``,
  ``ReducedNetwork.to_casadi``), a symbolic linear solve with ``D`` per sub-step;
* CasADi, implicit: :func:`radau_residual`, ``D x⁺ − N x − c`` as equality constraints
  (the ``casadi_radau`` estimation NLP, the economic MPC): only products with ``A``, so
  the constraint Jacobian is as sparse as the network.

The operator forms take ``Av``, a function ``v -> A v``: a sparse product in numpy, a
CasADi expression (the supply term subtracted on the zone rows, or ``f(v) − f(0)``) in
the NLPs, so the same lines serve both. The testbed plant
(:class:`thermctl.testbed.PadeZoneStepper`) takes the same step but factors ``D``
through the zones, for speed; it is tested against :func:`radau_stepper`.
"""

from __future__ import annotations

import casadi as ca
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["radau_forcing", "radau_n", "radau_residual", "radau_tangent",
           "radau_d_matrix", "radau_n_matrix", "radau_stepper", "radau_casadi_step"]

_DENSE_LIMIT = 400  # above this many states, sparse LU beats dense linear algebra


# ---- operator forms (numpy arrays or CasADi expressions) -------------------------------
def radau_forcing(Av, b, h):
    """``c = h (b − (h/6) A b)``: the held input's contribution to one sub-step [K].

    Parameters
    ----------
    Av : callable
        ``v -> A v`` [1/s].
    b : array_like or casadi expression
        Constant term of the dynamics over the sub-step [K/s].
    h : float or casadi expression
        Sub-step [s].
    """
    return h * (b - (h / 6) * Av(b))


def radau_n(Av, x, h):
    """``N x = x + (h/3) A x`` (``x`` may have several columns: sensitivities)."""
    return x + (h / 3) * Av(x)


def radau_residual(Av, x, x_next, b, h):
    """``D x_next − N x − c`` [K]: zero when ``x_next`` is the Radau step from ``x``.

    The implicit form for equality constraints: no linear solve, three products with
    ``A`` per sub-step.
    """
    # one expression, in this order and with ``A x_next`` formed twice: CasADi's derivatives
    # of a shared node accumulate in another order, and IPOPT's iterates (the economic
    # MPC's optimum) would move in the last digits
    return (x_next - (2 * h / 3) * Av(x_next) + (h * h / 6) * Av(Av(x_next))
            - x - (h / 3) * Av(x) - radau_forcing(Av, b, h))


def radau_tangent(Ex, Exn, EAxn, AExn, Eb, h):
    r"""Extra right side of the sensitivity step for a parameter direction ``E = ∂A/∂η``.

    Differentiating ``D x⁺ = N x + c`` gives
    :math:`D\,\partial x^+ = N\,\partial x + \tfrac{h}{3}E x + \tfrac{2h}{3}E x^+
    - \tfrac{h^2}{6}(E A x^+ + A E x^+ + E b)`; this returns everything after
    :math:`N\,\partial x`.

    Parameters
    ----------
    Ex, Exn, EAxn, AExn, Eb : ndarray
        ``E x``, ``E x⁺``, ``E A x⁺``, ``A E x⁺``, ``E b`` (one column per direction).
    h : float
        Sub-step [s].
    """
    return (h / 3) * Ex + (2 * h / 3) * Exn - (h * h / 6) * (EAxn + AExn + Eb)


# ---- numpy ---------------------------------------------------------------------------
def radau_d_matrix(A, h: float):
    """``D = I − (2h/3) A + (h²/6) A²`` as a sparse CSC matrix, to factor.

    Parameters
    ----------
    A : sparse matrix, shape (n, n)
        [1/s]. ``A @ A`` keeps the caller's format (its rounding depends on it).
    h : float
        Sub-step [s].
    """
    I = sp.identity(A.shape[0], format="csc")
    return sp.csc_matrix(I - (2 * h / 3) * A + (h * h / 6) * (A @ A))


def radau_n_matrix(A, h: float):
    """``N = I + (h/3) A`` as a sparse CSR matrix (one product per sub-step)."""
    I = sp.identity(A.shape[0], format="csc")
    return sp.csr_matrix(I + (h / 3) * A)


def radau_stepper(A_u, dt: float, substeps: int = 1):
    """A function ``step(x, b) -> x_next`` over ``dt`` in ``substeps`` Radau sub-steps.

    One LU of ``D`` (dense up to 400 states, sparse above, so it scales to large
    buildings), shared by the sub-steps and by every call.

    Parameters
    ----------
    A_u : sparse or dense matrix, shape (n, n)
        State matrix at the current supply flow [1/s].
    dt : float
        Step [s].
    substeps : int
        Sub-steps of ``dt / substeps``.
    """
    h = dt / substeps
    A_csc = sp.csc_matrix(A_u)
    n = A_csc.shape[0]
    D = radau_d_matrix(A_csc, h)
    N = radau_n_matrix(A_csc, h)
    Av = sp.csr_matrix(A_csc).__matmul__
    if n > _DENSE_LIMIT:
        solve = spla.splu(D).solve
    else:
        lu = sla.lu_factor(D.toarray())
        solve = lambda r: sla.lu_solve(lu, r)  # noqa: E731

    def step(x, b):
        c = radau_forcing(Av, b, h)
        for _ in range(substeps):
            x = solve(N @ x + c)
        return x

    return step


# ---- CasADi --------------------------------------------------------------------------
def radau_casadi_step(A, b, x, h, substeps: int):
    """``x`` after ``substeps`` Radau sub-steps of ``h`` (CasADi, explicit).

    Parameters
    ----------
    A : casadi.MX or DM, shape (n, n)
        State matrix at the step's supply flow [1/s].
    b : casadi.MX, shape (n, 1)
        Constant term [K/s].
    x : casadi.MX, shape (n, 1)
        Start state [°C].
    h : float or casadi.MX
        Sub-step [s].
    substeps : int

    Returns
    -------
    casadi.MX
        A symbolic linear solve with ``D`` per sub-step (dense derivatives; for sparse
        NLP constraints use :func:`radau_residual`).
    """
    # D and N as matrices, with the coefficients multiplied in the order this step has
    # always used (h is symbolic here: (2/3)·h and 2h/3 differ in the last bit)
    I = ca.DM.eye(A.size1())
    D = I - (2.0 / 3.0) * h * A + (h * h / 6.0) * ca.mtimes(A, A)
    N = I + (h / 3.0) * A
    c = radau_forcing(lambda v: ca.mtimes(A, v), b, h)
    for _ in range(substeps):
        x = ca.solve(D, ca.mtimes(N, x) + c)
    return x
