"""Model reduction: from the full thermal network to a control-sized model.

Four families, all keeping the full model's input and output names
(``ms[z]``, ``Ts[z]``, ``T[b]``, ``Q[z]`` → ``T[z]``):

- :func:`balanced_reduction` — balanced truncation or singular perturbation (DC-matching,
  default) of the linearization, with Hankel singular values and the a-priori H∞ bound;
  order given or chosen from a tolerance.
- :func:`structured` — keeps every ``T[z]`` as a state and reduces only the edge (wall,
  air-path) states to a few modes; exactly bilinear in the supply flow, exact at steady
  state, valid at every flow.
- :func:`kron` — eliminates the fast (convection-edge) states; everything else physical.
- :func:`lumped` — the hand-written "one state per zone" baseline.

Every reduction returns a :class:`Reduction` (``.sys``, ``.save()``; :func:`load_reduction`);
:class:`Reference`, :func:`error_vs_order` and :func:`flow_sweep` measure their errors.

Examples
--------
>>> from thermctl.reduce import structured, linearize, Reference  # doctest: +SKIP
>>> op = model.operating_point(ms=0.1, Ts=14, T=5)  # doctest: +SKIP
>>> red = structured(model, op, order=2 * model.network.n_zones)  # doctest: +SKIP
>>> Reference(linearize(model, op)).step_error(red.sys).rel  # 1, 6, 24 h  # doctest: +SKIP
"""

from .balanced import INPUT_SCALES, BalancedContext, balanced_reduction, default_scales, hankel_singular_values
from .metrics import (DEFAULT_TIMES, Reference, StepError, default_omegas, error_vs_order, flow_sweep,
                      frequency_responses, step_matrices, step_responses)
from .network import ReducedNetwork, linearize
from .result import Reduction, load_reduction
from .preserving import StructuredContext, edge_basis, kron, lumped, structured

__all__ = [
    "INPUT_SCALES", "DEFAULT_TIMES", "default_scales", "default_omegas",
    "hankel_singular_values", "balanced_reduction", "BalancedContext",
    "structured", "StructuredContext", "edge_basis", "kron", "lumped",
    "ReducedNetwork", "linearize", "Reduction", "load_reduction",
    "Reference", "StepError", "step_matrices", "step_responses", "frequency_responses", "flow_sweep", "error_vs_order",
]
