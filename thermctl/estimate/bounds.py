"""The paper's parameter ranges: one definition for both criteria."""

__all__ = ["T_MIN", "T_MAX", "RBAR_BOUNDS"]

T_MIN = 4.0
"""Lower bound of the convective time constant per unit distance [s/m] (paper, from CFD)."""
T_MAX = 20.0
"""Upper bound of the convective time constant per unit distance [s/m] (paper, from CFD)."""
RBAR_BOUNDS = (1e-6, 1e-2)
"""Search range of rbar_v [K/(W m)] (paper IV-B)."""
