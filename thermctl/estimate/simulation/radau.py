r"""Sparse Radau IIA simulation of the cost window, with sensitivities: for large networks.

The exact step of :mod:`.sim` costs one dense eigendecomposition per distinct supply
flow: fine for tens of states, too much for hundreds when the VAV flows change every
step. This simulator takes the model's own L-stable Radau IIA step (Padé (1,2) of the
exponential, written once in :mod:`thermctl._step`) with ``s`` sub-steps of ``h = dt/s``,

.. math::

    D x^+ = N x + c, \quad D = I - \tfrac{2h}{3}A_u + \tfrac{h^2}{6}A_u^2,\;
    N = I + \tfrac{h}{3}A_u,\; c = h\big(b - \tfrac{h}{6}A_u b\big),

with one sparse LU of ``D`` per distinct flow (shared by the sub-steps of a sample), and
forward sensitivities from the same LU. For a parameter direction ``E = ∂A_u/∂η``
(:func:`thermctl._step.radau_tangent`):

.. math::

    D\,\partial x^+ = N\,\partial x + \tfrac{h}{3}E x + \tfrac{2h}{3}E x^+
    - \tfrac{h^2}{6}\big(E A_u x^+ + A_u E x^+ + E b\big).

Its error against the exact step is third order in ``h`` (about 2e-3 K at 60-s sub-steps
for a building with window elements of a few minutes' time constant); J and its
minimiser move accordingly little. Everything else (J, gradient, Gauss–Newton Hessian,
variable projection) is the shared code of :class:`~.sim.Simulator`.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..._step import radau_d_matrix, radau_forcing, radau_n, radau_tangent
from ...errors import EstimationError
from .sim import Simulator

__all__ = ["RadauSimulator", "default_substeps"]

_LU_CACHE = 64     # LU factorisations kept per parameter point (repeated flows: nights)


def default_substeps(dt: float) -> int:
    """Sub-steps per data step: one per minute (``ceil(dt / 60 s)``)."""
    return max(1, math.ceil(dt / 60.0))


class RadauFactors:
    """Sparse ``A(θ)``, its parameter derivatives and an LU per flow pattern."""

    def __init__(self, sim: "RadauSimulator", eta, derivs: bool):
        self.sim = sim
        pb = sim.problem
        p = pb.p(eta)
        self.A = sp.csr_matrix(pb.model.matrices(p)[0])
        self.c = np.sqrt(pb.model.capacitances(p))     # C^½: C^½ A_u C^-½ is symmetric
        E = sim._dA_sparse(eta) if derivs else []
        self.ne = len(E)
        # stacked (ne·n × n): one sparse product gives every E_i v (Python overhead per
        # scipy call is comparable to the product itself at these sizes)
        self.E = sp.csr_matrix(sp.vstack(E)) if E else None
        self.cache = {}

    def get(self, j):
        """``(A_u, solve)`` of flow pattern ``j`` (``solve`` applies ``D⁻¹``)."""
        item = self.cache.get(j)
        if item is not None:
            return item
        sim, h, c = self.sim, self.sim.h, self.c
        A_u = sp.csr_matrix(self.A - sp.diags(sim.supply[j]))
        # D = C^-½ D_s C^½ with D_s = I − (2h/3) S + (h²/6) S², S = C^½ A_u C^-½ symmetric
        # and ≤ 0, so D_s is symmetric positive definite: factor it with a symmetric
        # ordering and no pivoting (stable, and a third less fill than COLAMD on D)
        S = sp.diags(c) @ A_u @ sp.diags(1.0 / c)
        S = 0.5 * (S + S.T)
        Ds = radau_d_matrix(S, h)
        try:
            lu = spla.splu(Ds, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options={"SymmetricMode": True})
        except RuntimeError as exc:   # cannot happen for a stable network; say so if it does
            raise EstimationError(f"Radau step matrix is singular at flow pattern {j}: {exc}") \
                from None

        def solve(r, _s=lu.solve, _c=c):
            if r.ndim == 1:
                return _s(_c * r) / _c
            return _s(_c[:, None] * r) / _c[:, None]

        item = (A_u, solve)
        if len(self.cache) < _LU_CACHE:
            self.cache[j] = item
        return item


class RadauSimulator(Simulator):
    """Sparse Radau IIA simulator (see the module docstring).

    Parameters
    ----------
    problem : CostProblem
    substeps : int, optional
        Sub-steps per data step (default one per minute).
    """

    def __init__(self, problem, substeps: int | None = None):
        super().__init__(problem)
        if self.b_varies:
            raise EstimationError("the Radau simulator needs air paths between states only; "
                                  "an air path to a boundary node (a local problem's "
                                  "neighbour) needs simulator='exact'")
        self.substeps = default_substeps(problem.dt) if substeps is None else int(substeps)
        if self.substeps < 1:
            raise EstimationError(f"substeps must be >= 1, found {substeps}")
        self.h = problem.dt / self.substeps

    @property
    def description(self):
        return (f"Radau IIA, {self.substeps} sub-steps of {self.h:g} s, sparse LU "
                f"({self.n_patterns} flow patterns)")

    def _make_factors(self, eta, derivs):
        return RadauFactors(self, eta, derivs)

    def propagate(self, fac, X, k0: int, k1: int, record=None, out=None):
        """Advance the columns of ``X`` (state, parameter and initial-state sensitivities)
        from sample ``k0`` to ``k1``; see :meth:`.sim.ExactSimulator.propagate`."""
        h, ne, n = self.h, fac.ne, self.n
        for k in range(k0, k1):
            A_u, solve = fac.get(self.inverse[k])
            b = self.b[k]
            Av = A_u.__matmul__
            c = radau_forcing(Av, b, h)
            if ne:
                Eb = (fac.E @ b).reshape(ne, n).T                    # (n, ne)
            for _ in range(self.substeps):
                R = radau_n(Av, X, h)
                R[:, 0] += c
                x = X[:, 0]
                Xn = solve(R)
                if ne:
                    xn = Xn[:, 0]
                    Axn = A_u @ xn
                    EV = (fac.E @ np.column_stack([x, xn, Axn])).reshape(ne, n, 3)
                    Exn = EV[:, :, 1].T                              # (n, ne)
                    extra = radau_tangent(EV[:, :, 0].T, Exn, EV[:, :, 2].T, A_u @ Exn, Eb, h)
                    Xn[:, 1:1 + ne] += solve(extra)
                X = Xn
            if record is not None and k + 1 in record:
                out[record[k + 1]] = X[self.zone_index]
        return X
