r"""The 3R2C element: the building block of every edge of the thermal network.

A 3R2C chain between nodes ``a`` and ``b``::

    a --R1-- s1 --R2-- s2 --R3-- b
             |         |
             C1        C2

has two states (the temperatures of ``s1`` and ``s2``). With both ends held
fixed its dynamics are

.. math::

    C_1 \dot s_1 = (T_a - s_1)/R_1 + (s_2 - s_1)/R_2, \qquad
    C_2 \dot s_2 = (s_1 - s_2)/R_2 + (T_b - s_2)/R_3 .

``alpha`` is the dimensionless ratio between the product of the totals
:math:`R_{tot} C_{tot}` and the slowest time constant of that system,
:math:`\alpha = |\lambda_{slow}| R_{tot} C_{tot}`. For the 3R2C fit of a
homogeneous slab (``homogeneous_split``) it is :math:`\pi^2`, the paper's 9.86.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import SpecError

__all__ = [
    "RC3R2C",
    "state_matrices",
    "eigenvalues",
    "time_constant",
    "alpha",
    "homogeneous_split",
    "from_u_value",
]


@dataclass(frozen=True)
class RC3R2C:
    """Parameters of one 3R2C element.

    Attributes
    ----------
    R : tuple of 3 float
        Resistances ``(R1, R2, R3)`` [K/W].
    C : tuple of 2 float
        Capacitances ``(C1, C2)`` [J/K].
    """

    R: tuple[float, float, float]
    C: tuple[float, float]

    def __post_init__(self):
        _check_rc(self.R, self.C, "3R2C element")

    @property
    def R_tot(self) -> float:
        """Series resistance [K/W]."""
        return float(sum(self.R))

    @property
    def C_tot(self) -> float:
        """Total capacitance [J/K]."""
        return float(sum(self.C))


def _check_rc(R, C, where):
    R = np.asarray(R, dtype=float)
    C = np.asarray(C, dtype=float)
    if R.shape != (3,):
        raise SpecError(f"{where}: R must have 3 values [K/W], found {R.size}")
    if C.shape != (2,):
        raise SpecError(f"{where}: C must have 2 values [J/K], found {C.size}")
    if not np.all(np.isfinite(R)) or np.any(R <= 0):
        raise SpecError(f"{where}: every R must be finite and > 0 [K/W], found {R.tolist()}")
    if not np.all(np.isfinite(C)) or np.any(C <= 0):
        raise SpecError(f"{where}: every C must be finite and > 0 [J/K], found {C.tolist()}")
    return R, C


def state_matrices(R, C):
    r"""State matrices of a 3R2C element with both end temperatures as inputs.

    Parameters
    ----------
    R : array_like, shape (3,)
        Resistances [K/W].
    C : array_like, shape (2,)
        Capacitances [J/K].

    Returns
    -------
    A : ndarray, shape (2, 2)
        State matrix [1/s], states ``(s1, s2)``.
    B : ndarray, shape (2, 2)
        Input matrix [1/s], inputs ``(T_a, T_b)``.

    Examples
    --------
    >>> A, B = state_matrices([1.0, 1.0, 1.0], [1.0, 1.0])
    >>> A
    array([[-2.,  1.],
           [ 1., -2.]])
    """
    (R1, R2, R3), (C1, C2) = _check_rc(R, C, "3R2C element")
    A = np.array([[-(1 / R1 + 1 / R2) / C1, 1 / (R2 * C1)],
                  [1 / (R2 * C2), -(1 / R2 + 1 / R3) / C2]])
    B = np.array([[1 / (R1 * C1), 0.0],
                  [0.0, 1 / (R3 * C2)]])
    return A, B


def eigenvalues(R, C):
    """Eigenvalues [1/s] of the 3R2C element with both ends fixed, slowest first.

    Parameters
    ----------
    R : array_like, shape (3,)
        Resistances [K/W].
    C : array_like, shape (2,)
        Capacitances [J/K].

    Returns
    -------
    ndarray, shape (2,)
        Real, negative eigenvalues [1/s], sorted from slowest (closest to 0).
    """
    A, _ = state_matrices(R, C)
    # A is similar to a symmetric matrix (diagonal scaling by sqrt(C)): real spectrum.
    lam = np.linalg.eigvals(A).real
    return np.sort(lam)[::-1]


def time_constant(R, C) -> float:
    """Slowest time constant [s] of the 3R2C element with both ends fixed."""
    return float(-1.0 / eigenvalues(R, C)[0])


def alpha(R, C) -> float:
    r"""Ratio :math:`R_{tot} C_{tot} / \tau_{slow}` of a 3R2C element [-].

    For the homogeneous-slab split (:func:`homogeneous_split`) this is
    :math:`\pi^2 \approx 9.87`; for three equal R and two equal C it is 6.

    Parameters
    ----------
    R : array_like, shape (3,)
        Resistances [K/W].
    C : array_like, shape (2,)
        Capacitances [J/K].

    Returns
    -------
    float
        alpha [-].

    Examples
    --------
    >>> R, C = homogeneous_split(0.5, 2e6)
    >>> round(alpha(R, C), 4)
    9.8696
    """
    R, C = _check_rc(R, C, "3R2C element")
    return float(R.sum() * C.sum() / time_constant(R, C))


def homogeneous_split(R_tot: float, C_tot: float):
    r"""3R2C parameters of a homogeneous slab.

    R is split :math:`(2/\pi^2,\ 1 - 4/\pi^2,\ 2/\pi^2) R_{tot}` and C in halves, so
    that the slowest eigenvalue equals the slab's first mode,
    :math:`-\pi^2 / (R_{tot} C_{tot})`, and the series resistance (steady heat
    flow) is exact.

    Parameters
    ----------
    R_tot : float
        Series resistance of the slab including films [K/W].
    C_tot : float
        Heat capacity of the slab [J/K].

    Returns
    -------
    R : tuple of 3 float
        [K/W]
    C : tuple of 2 float
        [J/K]
    """
    if not (np.isfinite(R_tot) and R_tot > 0):
        raise SpecError(f"R_tot must be finite and > 0 [K/W], found {R_tot}")
    if not (np.isfinite(C_tot) and C_tot > 0):
        raise SpecError(f"C_tot must be finite and > 0 [J/K], found {C_tot}")
    f = 2.0 / np.pi**2
    R = (f * R_tot, (1.0 - 2.0 * f) * R_tot, f * R_tot)
    C = (0.5 * C_tot, 0.5 * C_tot)
    return tuple(float(r) for r in R), tuple(float(c) for c in C)


def from_u_value(area: float, u_value: float, heat_capacity: float):
    """3R2C parameters of a wall from its area, U-value and areal heat capacity.

    Parameters
    ----------
    area : float
        Wall area [m²].
    u_value : float
        Thermal transmittance including surface films [W/(m² K)].
    heat_capacity : float
        Areal heat capacity [J/(m² K)].

    Returns
    -------
    R : tuple of 3 float
        [K/W]
    C : tuple of 2 float
        [J/K]
    """
    for name, v in (("area", area), ("u_value", u_value), ("heat_capacity", heat_capacity)):
        if not (np.isfinite(v) and v > 0):
            raise SpecError(f"{name} must be finite and > 0, found {v}")
    return homogeneous_split(1.0 / (u_value * area), heat_capacity * area)
