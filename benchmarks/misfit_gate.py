"""The misfit check's gate on the twin house N2, with and without internal mass.

BIC's structure (no check, one shared R̄_v) is fitted; for R̄_v and the noise and capacity
parameters it prints the sandwich/Hessian variance ratio (the gate, from ``wald_intervals``)
and the information-matrix ratio J_rr/H_rr (the daily score scatter of one parameter over its
curvature, the others held). Usage: ``python benchmarks/misfit_gate.py nomass|mass [DATA_DIR]`` (the
twin house's directory as ``benchmarks/twinhouse.py`` finds it by default; about 3 min).

Measured (session 18): without mass R̄_v 181 / 163; with mass 1.00 (floored: the Hessian is
indefinite there, H of sigma_q and sigma_g negative) / 95.
"""
from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np

from thermctl.data import read_measurements
from thermctl.estimate.likelihood.uncertainty import hessian_fd, wald_intervals
from thermctl.identify import EstimationOptions, IdentifyOptions, SelectionOptions, identify
from thermctl.spec import load_spec

# the twin house's files beside the checkout, as benchmarks/twinhouse.py finds them
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "twinhouse-n2"


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else argv
    mass = bool(argv) and argv[0] == "mass"
    root = argv[1] if len(argv) > 1 else DATA
    spec = load_spec(f"{root}/building.yaml")
    opt = IdentifyOptions(selection=SelectionOptions(misfit_ratio=0),
                          estimation=EstimationOptions(intervals="none", per_edge=False,
                                                       internal_mass=mass))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meas = read_measurements(f"{root}/data.csv", spec)
        gb = identify(meas, opt).greybox
    prob, eta = gb.problem_, gb.eta_
    lay = prob.layout
    at_bound = lay.at_bound_names(eta)
    use = lay.free() & np.array([p.name not in at_bound for p in lay.params])
    idx = np.flatnonzero(use)
    H = hessian_fd(prob, eta, use, threads=2)
    wald, _ = wald_intervals(prob, eta, H=H, threads=2)
    G = prob.block_scores(eta, 86400.0, threads=2)[:, idx]     # one row per day
    Gc = G - G.mean(axis=0)
    J = Gc.T @ Gc * G.shape[0] / (G.shape[0] - 1)
    out = {}
    print("with internal mass" if mass else "without internal mass",
          [e.name for e in gb.network.convection_edges])
    for j, i in enumerate(idx):
        n = lay.params[i].name
        if n.startswith(("rbar_v", "tau0", "cap_factor", "sigma")):
            out[n] = (wald[n].inflation, J[j, j] / H[j, j])
            print(f"  {n:24s} sandwich/Hessian {out[n][0]:8.2f}   J/H diagonal {out[n][1]:8.2f}")
    return out


if __name__ == "__main__":
    main()
