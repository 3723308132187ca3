"""Runnable MPC examples that control the testbed plant with an identified thermctl model.

Split like do-mpc's examples (model / controller / simulator / main):

* :mod:`mpc_examples.common` — HVAC energy model, comfort band, KPIs, table and figure output;
* :mod:`mpc_examples.model` — the controller's internal model (identified, true or
  conduction-only) and the Kalman filter that estimates its state and the unmeasured gains;
* :mod:`mpc_examples.simulator` — the closed loop on the testbed plant and the baseline;
* :mod:`mpc_examples.economic_mpc` — nonlinear economic MPC (CasADi, multiple shooting, IPOPT);
* :mod:`mpc_examples.linear_mpc` — linear MPC on the exported ``StateSpace`` (a QP);
* :mod:`mpc_examples.scaling` — solve time against building size.

Run from the repository root, e.g. ``python -m mpc_examples.economic_mpc --hours 6``.
"""
