"""The 3R2C element against closed forms and against a finely discretised slab."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from thermctl import rc
from thermctl.errors import SpecError


@pytest.mark.parametrize("R, C", [(1.0, 1.0), (0.05, 2.0e6), (3.0e-3, 1.19e3), (40.0, 0.5)],
                         ids=["unit", "wall", "convection", "small-C"])
def test_equal_rc_eigenvalues_closed_form(R, C):
    # Three equal R and two equal C: symmetric mode -1/RC, antisymmetric mode -3/RC.
    lam = rc.eigenvalues([R] * 3, [C] * 2)
    np.testing.assert_allclose(lam, [-1 / (R * C), -3 / (R * C)], rtol=1e-12)
    np.testing.assert_allclose(rc.time_constant([R] * 3, [C] * 2), R * C, rtol=1e-12)


@pytest.mark.parametrize("R, C", [
    ((0.01, 0.2, 0.05), (1.0e6, 3.0e5)),
    ((2.0, 0.1, 0.7), (10.0, 400.0)),
    ((1e-3, 1e-3, 5.0), (2e4, 2e4)),
], ids=["asymmetric-wall", "mixed-scales", "one-big-R"])
def test_general_eigenvalues_closed_form_quadratic(R, C):
    (R1, R2, R3), (C1, C2) = R, C
    # Characteristic polynomial lambda^2 - tr lambda + det, with trace and determinant
    # written out by hand: det = (R1 + R2 + R3) / (R1 R2 R3 C1 C2).
    tr = -(1 / R1 + 1 / R2) / C1 - (1 / R2 + 1 / R3) / C2
    det = (R1 + R2 + R3) / (R1 * R2 * R3 * C1 * C2)
    disc = np.sqrt(tr**2 - 4 * det)
    expected = [(tr + disc) / 2, (tr - disc) / 2]  # slowest (closest to 0) first
    np.testing.assert_allclose(rc.eigenvalues(R, C), expected, rtol=1e-10)
    np.testing.assert_allclose(rc.time_constant(R, C), -2 / (tr + disc), rtol=1e-10)


def test_state_matrices_are_the_nodal_equations():
    R, C = (0.5, 2.0, 4.0), (3.0, 7.0)
    A, B = rc.state_matrices(R, C)
    Ta, Tb, s = 10.0, -2.0, np.array([4.0, 1.0])
    # C1 ds1/dt = (Ta - s1)/R1 + (s2 - s1)/R2 ; C2 ds2/dt = (s1 - s2)/R2 + (Tb - s2)/R3
    by_hand = [((Ta - s[0]) / R[0] + (s[1] - s[0]) / R[1]) / C[0],
               ((s[0] - s[1]) / R[1] + (Tb - s[1]) / R[2]) / C[1]]
    np.testing.assert_allclose(A @ s + B @ [Ta, Tb], by_hand, rtol=1e-14)
    # steady state: linear profile, heat flow (Ta - Tb) / sum(R) through every resistor
    xs = np.linalg.solve(A, -B @ [Ta, Tb])
    q = (Ta - Tb) / sum(R)
    np.testing.assert_allclose(xs, [Ta - q * R[0], Ta - q * (R[0] + R[1])], rtol=1e-13)


def test_alpha_of_pi2_split_is_pi_squared():
    R, C = rc.homogeneous_split(0.37, 4.2e6)
    a = rc.alpha(R, C)
    assert abs(a - 9.87) <= 0.01
    # The split makes the symmetric mode exactly the slab's first mode: alpha = pi^2.
    np.testing.assert_allclose(a, np.pi**2, rtol=1e-12)


def test_alpha_of_equal_rc_is_six():
    assert rc.alpha([0.1] * 3, [5e5] * 2) == pytest.approx(6.0, rel=1e-12)


@pytest.mark.parametrize("kR, kC", [(1e-3, 1.0), (1.0, 1e4), (37.0, 0.02)])
def test_alpha_is_scale_invariant(kR, kC):
    R, C = (0.01, 0.2, 0.05), (1.0e6, 3.0e5)
    assert rc.alpha(np.multiply(R, kR), np.multiply(C, kC)) == pytest.approx(rc.alpha(R, C),
                                                                              rel=1e-12)


def test_homogeneous_split_keeps_totals():
    R, C = rc.homogeneous_split(0.25, 3.0e6)
    assert sum(R) == pytest.approx(0.25, rel=1e-15)
    assert sum(C) == pytest.approx(3.0e6, rel=1e-15)
    np.testing.assert_allclose(R, np.array([2 / np.pi**2, 1 - 4 / np.pi**2, 2 / np.pi**2]) * 0.25)


def test_from_u_value():
    R, C = rc.from_u_value(area=12.0, u_value=0.4, heat_capacity=2.5e5)
    assert sum(R) == pytest.approx(1 / (0.4 * 12.0), rel=1e-14)
    assert sum(C) == pytest.approx(2.5e5 * 12.0, rel=1e-14)
    assert rc.alpha(R, C) == pytest.approx(np.pi**2, rel=1e-12)


def _slab_slowest_time_constant(R_tot, C_tot, n):
    """Slowest time constant [s] of a homogeneous slab, both faces fixed, n interior nodes.

    Vertex-centred finite differences: n + 1 equal resistors R_tot/(n + 1); each interior node
    carries the capacity of one cell, C_tot/(n + 1) (the two half cells at the faces sit on
    the fixed boundary temperatures).
    """
    r, c = R_tot / (n + 1), C_tot / (n + 1)
    main = np.full(n, -2.0 / (r * c))
    off = np.full(n - 1, 1.0 / (r * c))
    lam = sla.eigvalsh_tridiagonal(main, off)
    return -1.0 / lam.max()


def test_fine_slab_slowest_time_constant_matches_3r2c_fit():
    # 20 cm of concrete on 10 m^2 plus films: R_tot = 0.2/(1.4*10) + 0.17/10, C = 2e6*0.2*10.
    R_tot, C_tot, n = 0.2 / 14.0 + 0.017, 4.0e6, 200
    tau_fd = _slab_slowest_time_constant(R_tot, C_tot, n)
    tau_3r2c = rc.time_constant(*rc.homogeneous_split(R_tot, C_tot))
    # The FD first mode is -(2(n+1))^2 sin^2(pi/(2(n+1))) / (R C): it is slower than the
    # continuum's -pi^2/(R C) by pi^2 / (12 (n+1)^2) = 2.0e-5 relative for n = 200, and the
    # 3R2C fit reproduces the continuum mode exactly. So they agree to ~2e-5.
    rel = tau_fd / tau_3r2c - 1.0
    np.testing.assert_allclose(rel, np.pi**2 / (12 * (n + 1) ** 2), rtol=0.01)
    assert abs(rel) < 3e-5
    # Sanity of the reference: the continuum value and convergence as the grid is refined.
    np.testing.assert_allclose(tau_3r2c, R_tot * C_tot / np.pi**2, rtol=1e-12)
    # n + 1 = 25, 50, 100: the grid step halves, the error must quarter (2nd order).
    err = [abs(_slab_slowest_time_constant(R_tot, C_tot, k) / tau_3r2c - 1) for k in (24, 49, 99)]
    np.testing.assert_allclose(np.log2(np.divide(err[:-1], err[1:])), 2.0, atol=0.01)
    # The naive split (equal R, equal C) is far off: alpha 6 instead of pi^2 (65 % slower).
    tau_equal = rc.time_constant([R_tot / 3] * 3, [C_tot / 2] * 2)
    assert tau_equal / tau_fd == pytest.approx(np.pi**2 / 6, rel=1e-4)


@pytest.mark.parametrize("R, C, match", [
    ([1.0, 1.0], [1.0, 1.0], r"R must have 3 values \[K/W\], found 2"),
    ([1.0, 1.0, 1.0], [1.0, 1.0, 1.0], r"C must have 2 values \[J/K\], found 3"),
    ([1.0, 0.0, 1.0], [1.0, 1.0], r"every R must be finite and > 0 \[K/W\]"),
    ([1.0, 1.0, np.inf], [1.0, 1.0], r"every R must be finite and > 0 \[K/W\]"),
    ([1.0, 1.0, 1.0], [-1.0, 1.0], r"every C must be finite and > 0 \[J/K\]"),
    ([1.0, 1.0, 1.0], [1.0, np.nan], r"every C must be finite and > 0 \[J/K\]"),
], ids=["R-length", "C-length", "R-zero", "R-inf", "C-negative", "C-nan"])
def test_element_errors(R, C, match):
    with pytest.raises(SpecError, match=match):
        rc.alpha(R, C)
    with pytest.raises(SpecError, match=match):
        rc.RC3R2C(tuple(R), tuple(C))


@pytest.mark.parametrize("call, match", [
    (lambda: rc.homogeneous_split(0.0, 1.0), r"R_tot must be finite and > 0 \[K/W\], found 0"),
    (lambda: rc.homogeneous_split(1.0, -5.0), r"C_tot must be finite and > 0 \[J/K\]"),
    (lambda: rc.from_u_value(0.0, 1.0, 1.0), r"area must be finite and > 0"),
    (lambda: rc.from_u_value(1.0, np.nan, 1.0), r"u_value must be finite and > 0"),
    (lambda: rc.from_u_value(1.0, 1.0, -1.0), r"heat_capacity must be finite and > 0"),
], ids=["R_tot-zero", "C_tot-negative", "area-zero", "u_value-nan", "heat_capacity-negative"])
def test_split_errors(call, match):
    with pytest.raises(SpecError, match=match):
        call()


def test_rc3r2c_totals():
    e = rc.RC3R2C((0.1, 0.2, 0.3), (4.0, 5.0))
    assert e.R_tot == pytest.approx(0.6)
    assert e.C_tot == pytest.approx(9.0)
