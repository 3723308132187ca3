"""The misfit check's gate on the twin house N2, with and without internal mass.

BIC's structure (no check, one shared R̄_v) is fitted; for R̄_v and the noise and capacity
parameters it prints the sandwich/Hessian variance ratio (the gate, from ``wald_intervals``)
and the information-matrix ratio J_rr/H_rr (the daily score scatter of one parameter over its
curvature, the others held). Usage: ``python benchmarks/misfit_gate.py nomass|mass`` (needs
the twin house data in /work/shared/data/twinhouse-n2; about 3 min).

Measured (session 18): without mass R̄_v 181 / 163; with mass 1.00 (floored: the Hessian is
indefinite there, H of sigma_q and sigma_g negative) / 95.
"""
import sys, warnings
import numpy as np
from thermctl.spec import load_spec
from thermctl.data import read_measurements
from thermctl.identify import identify, IdentifyOptions, EstimationOptions, SelectionOptions
from thermctl.estimate.likelihood.uncertainty import hessian_fd, wald_intervals
D = sys.argv[2] if len(sys.argv) > 2 else "/work/shared/data/twinhouse-n2"
mass = sys.argv[1] == "mass"
spec = load_spec(f"{D}/building.yaml")
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    meas = read_measurements(f"{D}/data.csv", spec)
    ident = identify(meas, IdentifyOptions(selection=SelectionOptions(misfit_ratio=0),
                                           estimation=EstimationOptions(intervals="none", per_edge=False,
                                                                        internal_mass=mass)))
gb = ident.greybox
prob, eta = gb.problem_, gb.eta_
lay = prob.layout
free = lay.free()
at_bound = {b.split(" ")[0] for b in lay.at_bounds(eta)}
use = free & np.array([p.name not in at_bound for p in lay.params])
idx = np.flatnonzero(use)
H = hessian_fd(prob, eta, use, threads=2)
wald, _ = wald_intervals(prob, eta, H=H, threads=2)
G = prob.block_scores(eta, 86400.0, threads=2)[:, idx]
nb = G.shape[0]
Gc = G - G.mean(axis=0)
J = Gc.T @ Gc * nb / (nb - 1)
names = [lay.params[i].name for i in idx]
print("mass" if mass else "no mass", [e.name for e in ident.model.network.convection_edges])
for j, n in enumerate(names):
    if n.startswith("rbar_v") or n == "tau0" or n.startswith("cap_factor") or n.startswith("sigma"):
        print(f"  {n:24s} sandwich/Hessian {wald[n].inflation:8.2f}   J/H diag {J[j, j] / H[j, j]:8.2f}")
