"""Twin house N2 (IEA EBC Annex 58): what thermctl finds on a real house.

The data (``../shared/data/twinhouse-n2/``, its README explains them) are 41 days of
10-minute measurements of an empty single-storey test house with 7 rooms. Living room,
corridor, bath and child's room are joined by OPEN doors (air paths parallel to walls,
not in the spec) and by the ventilation air (supply into the living room, extract from
bath and child); kitchen, entrance ("doorway") and bedroom are closed off. Nobody
simulated these data, so there is no true R̄_v: the checks are which couplings are
found (open doors in, closed rooms out) and whether the models predict held-back days
and reproduce the measured response to the living-room heat pulses.

The script answers, with numbers:

1. ``thermctl identify`` as a user runs it (default options, the paper's pipeline, with
   ``--allow-parallel``): does it run, what does it select, how long does it take.
2. Model-based selection (:func:`thermctl.selection.select_air_paths`, BIC on the
   Kalman likelihood, forward) over ALL 21 zone pairs, including the pairs that share a
   wall, with air path lengths from the spec's geometry (see :func:`door_hops`): the
   order, the BIC change of each step, R̄_v and the equivalent conductance per edge.
3. The same with and without per-zone solar apertures: likelihood/BIC, apertures, how
   the couplings change.
4. Validation on the held-back last quarter of the days (thermctl's default split):
   k-step-ahead RMSE at 1, 6, 24 h from Kalman-filtered states, 48-h prediction per zone
   (from the filtered state, and the paper's open loop from its mean-of-ends start), and
   the step-response matrix (heat into the living room → every zone) against the
   measured response to the 500 W pulses.
5. Run times.

Usage::

    OMP_NUM_THREADS=1 nice python benchmarks/twinhouse.py > benchmarks/results/twinhouse.txt
    python benchmarks/twinhouse.py --max-edges 2 --no-cli      # shorter (~5 min)

The full run took 23 min on a loaded 2-core machine, 11 of them in the default
``thermctl identify`` (section 2).

Progress goes to stderr, the report to stdout.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from thermctl.data import read_measurements
from thermctl.estimate.likelihood import LikelihoodEstimator, kstep_errors
from thermctl.estimate.likelihood.kstep import filtered_states
from thermctl.selection import select_air_paths
from thermctl.model import ThermalModel
from thermctl.network import ThermalNetwork
from thermctl.spec import load_spec
from thermctl.validate import minimum_flows, open_loop, step_response_matrix

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "twinhouse-n2"

ZONES = ["living", "corridor", "bath", "child", "kitchen", "doorway", "bedroom"]
# README, "Doors and ventilation air path": the internal doors (IDEAS elements W45-W50)
DOORS = {("corridor", "living"): "open", ("child", "corridor"): "open",
         ("bath", "corridor"): "open", ("kitchen", "living"): "closed",
         ("doorway", "living"): "closed", ("bedroom", "corridor"): "closed"}
OPEN = {frozenset(p) for p, s in DOORS.items() if s == "open"}
AIR_VOLUME = {"living", "corridor", "bath", "child"}      # one connected air volume
CLOSED = {"kitchen", "doorway", "bedroom"}
# README, "Experiment schedule" (stamps as in data.csv)
PHASES = [("constant 30 °C", "2013-08-21 00:00", "2013-08-30 00:00"),
          ("all off", "2013-08-30 00:10", "2013-08-30 01:00"),
          ("random 500 W pulses in living (ROLBS)", "2013-08-30 01:10", "2013-09-13 06:00"),
          ("all off", "2013-09-13 06:10", "2013-09-14 00:00"),
          ("constant 25 °C", "2013-09-14 00:10", "2013-09-20 00:00"),
          ("free float", "2013-09-20 00:10", "2013-10-01 00:00")]
HORIZONS_H = (1.0, 3.0, 6.0, 24.0)            # step-response horizons [h]
KSTEP_H = (1.0, 6.0, 24.0)                    # k-step horizons [h]


def say(msg: str) -> None:
    """Progress on stderr (the report is stdout)."""
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def table(headers, rows, fmt=None) -> str:
    """Plain-text table with right-aligned columns (first column left-aligned)."""
    cells = [[str(h) for h in headers]]
    for r in rows:
        cells.append([c if isinstance(c, str) else (fmt or "{:.3g}").format(c) for c in r])
    w = [max(len(row[i]) for row in cells) for i in range(len(headers))]
    out = []
    for k, row in enumerate(cells):
        out.append("  ".join(c.ljust(w[i]) if i == 0 else c.rjust(w[i]) for i, c in enumerate(row)))
        if k == 0:
            out.append("  ".join("-" * x for x in w))
    return "\n".join(out)


def section(title: str) -> None:
    print()
    print(title)
    print("=" * len(title))


def kind(a: str, b: str) -> str:
    """What the README says about the pair."""
    p = frozenset((a, b))
    if p in OPEN:
        return "OPEN DOOR"
    if DOORS.get(tuple(sorted((a, b)))) == "closed":
        return "closed door (spurious)"
    if p <= AIR_VOLUME:
        return "same air volume, indirect"
    return "closed-off room (spurious)"


# ------------------------------------------------------------------------------ geometry
def door_hops(spec):
    """Air path lengths for every zone pair, from the spec's own ``distances``.

    building.yaml lists lengths only for pairs without a common wall, each the sum of
    centre-to-centre hops through doors along the shortest door path (its comment). The
    door graph is a tree (README: living–corridor, living–kitchen, living–doorway,
    corridor–bath, corridor–child, corridor–bedroom), so every listed length is a sum of
    hop lengths; the hops follow by least squares. A pair that shares a wall gets the
    length of its door path: the hop for a door in the common wall, else the sum of the
    hops (the same convention as the listed lengths).

    Returns
    -------
    hops : dict (a, b) → float
        Door hop lengths [m].
    d : dict (a, b) → float
        Air path length of every zone pair [m] (sorted names).
    resid : list of (pair, listed, fitted)
    """
    import networkx as nx
    g = nx.Graph([tuple(sorted(p)) for p in DOORS])
    hop_list = sorted(tuple(sorted(e)) for e in g.edges)
    col = {h: i for i, h in enumerate(hop_list)}

    def path(a, b):
        nodes = nx.shortest_path(g, a, b)
        return [tuple(sorted(e)) for e in zip(nodes[:-1], nodes[1:])]

    A, y, pairs = [], [], []
    for dd in spec.distances:
        row = np.zeros(len(hop_list))
        for h in path(dd.a, dd.b):
            row[col[h]] = 1.0
        A.append(row)
        y.append(dd.d)
        pairs.append(tuple(sorted((dd.a, dd.b))))
    x, *_ = np.linalg.lstsq(np.array(A), np.array(y), rcond=None)
    hops = {h: float(v) for h, v in zip(hop_list, x)}
    resid = [(p, yy, float(r @ x)) for p, yy, r in zip(pairs, y, A)]
    d = {}
    for i, a in enumerate(ZONES):
        for b in ZONES[i + 1:]:
            p = tuple(sorted((a, b)))
            given = spec.distance(*p)
            d[p] = float(given) if given is not None else sum(hops[h] for h in path(*p))
    return hops, d, resid


# ------------------------------------------------------------------------------ data
def pulse_responses(frame: pd.DataFrame):
    """Measured temperature rise after the clean 500 W living-room pulses (ROLBS phase).

    A pulse is clean when the heater was off for the 3 h before and on for the 3 h after
    its start. Rise at 3 h = ``[T(t0+3h) − T(t0)] − [T(t0) − T(t0−3h)]`` (the drift of
    the 3 h before is extrapolated and removed), ``t0`` the last sample before the
    heater switched on.

    Returns
    -------
    DataFrame
        One row per clean pulse: start, mean power [W], rise per zone [K].
    """
    ro = frame.loc[PHASES[2][1]:PHASES[2][2]]
    on = (ro["Q:living"] > 250.0).astype(int)
    starts = ro.index[on.diff() == 1]
    h3, step = pd.Timedelta("3h"), frame.index[1] - frame.index[0]
    rows = []
    for t in starts:
        pre = frame.loc[t - h3:t - step, "Q:living"]
        post = frame.loc[t:t + h3 - step, "Q:living"]
        if pre.max() > 50.0 or post.min() < 250.0:
            continue
        t0 = t - step
        T = lambda s: frame.loc[s, [f"T:{z}" for z in ZONES]].to_numpy(float)  # noqa: E731
        rise = (T(t0 + h3) - T(t0)) - (T(t0) - T(t0 - h3))
        rows.append([t, float(post.mean()), *rise])
    return pd.DataFrame(rows, columns=["start", "P", *ZONES])


def phase_days(meas):
    out = []
    for name, a, b in PHASES:
        ta = pd.Timestamp(a).tz_localize(meas.tz)
        tb = pd.Timestamp(b).tz_localize(meas.tz)
        n = int(((meas.frame.index >= ta) & (meas.frame.index <= tb)).sum())
        if n:
            out.append(f"{name} ({n * meas.step.total_seconds() / 86400:.1f} d)")
    return ", ".join(out)


# ------------------------------------------------------------------------------ CLI
def run_cli(label, args, data, outdir, timeout):
    """Run ``thermctl identify`` as a user would; return a result dict."""
    exe = shutil.which("thermctl", path=str(Path(sys.executable).parent)) or shutil.which("thermctl")
    cmd = [exe, "identify", str(data / "data.csv"), "-b", str(data / "building.yaml"),
           "-o", str(outdir), *args]
    say(f"CLI: {' '.join(['thermctl', 'identify', 'data.csv', '-b', 'building.yaml', *args])}")
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                           env={**__import__("os").environ, "COLUMNS": "120"})
    except subprocess.TimeoutExpired:
        return {"label": label, "args": args, "rc": None, "time": time.perf_counter() - t0,
                "edges": [], "note": f"did not finish within {timeout:g} s"}
    res = {"label": label, "args": args, "rc": p.returncode, "time": time.perf_counter() - t0,
           "edges": [], "note": "", "stdout": p.stdout, "stderr": p.stderr}
    if p.returncode != 0:
        tail = (p.stderr.strip() or p.stdout.strip()).splitlines()[-3:]
        res["note"] = "FAILED: " + " | ".join(tail)
        return res
    from thermctl.io import load_model
    m = load_model(outdir / "model.json")
    rb = np.broadcast_to(np.atleast_1d(m.rbar_v), (len(m.network.convection_edges),))
    cv = np.broadcast_to(np.atleast_1d(m.c_v), (len(m.network.convection_edges),))
    res["edges"] = [(e.a, e.b, e.d, float(r), float(c))
                    for e, r, c in zip(m.network.convection_edges, rb, cv)]
    res["meta"] = m.meta
    warn = [ln.strip() for ln in (p.stdout + p.stderr).splitlines()
            if "bound" in ln.lower() or "warning" in ln.lower() or "NOT identifiable" in ln]
    res["warnings"] = warn
    try:
        doc = json.loads((outdir / "identification.json").read_text())
        res["doc"] = doc
    except (OSError, ValueError):
        res["doc"] = {}
    return res


def cli_options(data):
    exe = shutil.which("thermctl", path=str(Path(sys.executable).parent)) or shutil.which("thermctl")
    p = subprocess.run([exe, "identify", "--help"], capture_output=True, text=True,
                       env={**__import__("os").environ, "COLUMNS": "200"})
    return p.stdout


# ------------------------------------------------------------------------------ models
def fit(net, data, label, times, **kw):
    """Grey-box likelihood fit; returns the estimator (warnings recorded, not printed)."""
    say(f"fit: {label}")
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        est = LikelihoodEstimator(net, **kw).fit(data)
    times[label] = time.perf_counter() - t0
    est.warnings_ = [f"{w.category.__name__}: {w.message}" for w in caught]
    return est


def conductances(est, net):
    """Per convection edge: (name, d, R̄_v, c_v, conductance 1/(3 R̄_v d) [W/K])."""
    rb, cv = est.problem_.rbar_c(est.eta_)
    return [(e, e.d, float(r), float(c), 1.0 / (3.0 * r * e.d))
            for e, r, c in zip(net.convection_edges, rb, cv)]


def predict_from_filter(pb, eta, start_rows, H):
    """H-step prediction from the filtered state at each start row, no further updates.

    The same propagation as :func:`thermctl.estimate.likelihood.kstep_errors` (gains held at their
    filtered value, solar and measured inputs applied, supply heat from the predicted
    temperature), but returning every step so that the RMSE over a whole 48-h
    trajectory can be taken.

    Returns
    -------
    err : ndarray, shape (n_starts, H, ny)
        Prediction − measurement [K].
    """
    m = pb.matrices(eta)
    W = pb.inputs(eta)
    Phi, Gam, C = m["Phi"], m["Gamma"], pb.C
    segs = filtered_states(pb, eta)
    CT = np.zeros((pb.ny, pb.n))
    CT[np.arange(pb.ny), pb.meas] = 1.0
    out = np.full((len(start_rows), H, pb.ny), np.nan)
    for s, k0 in enumerate(start_rows):
        for a, b, Xp, Xf, E in segs:
            if a <= k0 < b and k0 + H < b:
                x = Xf[k0 - a].copy()
                for j in range(1, H + 1):
                    idx = k0 + j - 1
                    w = W[idx].copy()
                    w[pb.meas] -= pb.sup_gain[idx] * (CT @ x - pb.Tbar[idx])
                    x = Phi @ x + Gam @ w
                    out[s, j - 1] = C @ x - pb.Y[k0 + j]
    return out


# ------------------------------------------------------------------------------ main
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=DATA, help="twinhouse-n2 directory")
    ap.add_argument("--max-edges", type=int, default=5,
                    help="forward selection steps (with solar); the BIC rule alone does not stop early here")
    ap.add_argument("--nosolar-edges", type=int, default=0,
                    help="forward selection steps without solar (for the comparison of the order)")
    ap.add_argument("--screen", choices=("grid", "fit"), default="grid",
                    help="select_air_paths screening (grid: 3 R̄_v values per candidate; fit: a 1-D fit each, slower)")
    ap.add_argument("--no-cli", action="store_true", help="skip the thermctl identify runs")
    ap.add_argument("--cli-timeout", type=float, default=1500.0, help="per CLI run [s]")
    args = ap.parse_args(argv)
    T0 = time.perf_counter()
    times = {}
    rough = []

    print("Twin house N2 (IEA EBC Annex 58, Holzkirchen, experiment 1) — what thermctl finds")
    print(f"thermctl benchmark benchmarks/twinhouse.py, {time.strftime('%Y-%m-%d %H:%M')}; "
          f"options: --max-edges {args.max_edges} --nosolar-edges {args.nosolar_edges}")

    # ---------------------------------------------------------------- data
    section("1. Data and split")
    t0 = time.perf_counter()
    spec = load_spec(args.data / "building.yaml")
    meas = read_measurements(args.data / "data.csv", spec)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal, val = meas.split()
    times["read data"] = time.perf_counter() - t0
    print(meas.quality.summary())
    print(f"calibration {cal.start} .. {cal.end} ({len(cal)} samples): {phase_days(cal)}")
    print(f"validation  {val.start} .. {val.end} ({len(val)} samples): {phase_days(val)}")
    print("(thermctl's default split: the last quarter of the whole days validates. Here that is "
          "the free-float phase only: all heaters off, so the validation tests the passive "
          "dynamics; the heat-pulse response is checked against the calibration pulses below.)")

    hops, dist, resid = door_hops(spec)
    print("\nAir path lengths. building.yaml lists lengths only for the 9 pairs without a common wall, "
          "each a sum of door-to-door centre hops; the hop lengths follow by least squares "
          "(residuals ≤ {:.2f} m):".format(max(abs(a - b) for _, a, b in resid)))
    print(table(["door hop", "d [m]", "door"],
                [(f"{a}–{b}", f"{v:.2f}", DOORS.get((a, b), DOORS.get((b, a), "")))
                 for (a, b), v in hops.items()]))
    walls = spec.wall_pairs() if hasattr(spec, "wall_pairs") else \
        {frozenset((w.a, w.b)) for w in spec.walls}
    est_len = {}
    for p in dist:
        if hasattr(spec, "air_path_length"):
            v, estimated = spec.air_path_length(*p)
            if estimated:
                est_len[p] = v
    print("\nCandidates: all 21 zone pairs. Pairs sharing a wall get their door-path length "
          "(spec.distance gives none for them"
          + ("; spec.air_path_length's volume-cube estimate shown beside" if est_len else "")
          + "):")
    rows = []
    for p, v in dist.items():
        rows.append((f"{p[0]}–{p[1]}", f"{v:.1f}", "yes" if frozenset(p) in walls else "no",
                     f"{est_len[p]:.1f}" if p in est_len else "", kind(*p)))
    print(table(["pair", "d [m]", "wall", "spec estimate", "README"], rows))
    cands = [(a, b, d) for (a, b), d in dist.items()]

    pulses = pulse_responses(meas.frame)
    print(f"\nClean living-room heat pulses in the data (off ≥ 3 h before, on ≥ 3 h): {len(pulses)}, "
          "rise at 3 h after removing the preceding 3-h drift [K]:")
    print(table(["start", "P [W]", *ZONES],
                [(f"{r.start:%m-%d %H:%M}", f"{r.P:.0f}", *[f"{getattr(r, z):+.2f}" for z in ZONES])
                 for r in pulses.itertuples()]))
    med = pulses[ZONES].median()
    Pm = float(pulses["P"].mean())

    # ---------------------------------------------------------------- CLI
    section("2. thermctl identify, as a user runs it")
    cli_runs = []
    if args.no_cli:
        print("(skipped: --no-cli)")
    else:
        help_text = cli_options(args.data)
        variants = [("default options", [])]
        if "--criterion" in help_text:
            variants.append(("paper pipeline (--criterion simulation)", ["--criterion", "simulation"]))
            variants.append(("paper pipeline, --allow-parallel",
                             ["--criterion", "simulation", "--allow-parallel"]))
        else:
            variants.append(("--allow-parallel", ["--allow-parallel"]))
        tmp = Path(tempfile.mkdtemp(prefix="twinhouse-cli-"))
        for k, (label, extra) in enumerate(variants):
            r = run_cli(label, extra, args.data, tmp / f"run{k}", args.cli_timeout)
            times[f"CLI: {label}"] = r["time"]
            cli_runs.append(r)
        shutil.rmtree(tmp, ignore_errors=True)
        rows = []
        for r in cli_runs:
            edges = ", ".join(f"{a}–{b}" for a, b, *_ in r["edges"]) or ("none" if r["rc"] == 0 else "—")
            vals = sorted({round(x[3], 12) for x in r["edges"]})
            rb = (f"{vals[0]:.2g} (shared)" if len(vals) == 1 and len(r["edges"]) > 1
                  else ", ".join(f"{x[3]:.2g}" for x in r["edges"]))
            n_open = sum(frozenset((a, b)) in OPEN for a, b, *_ in r["edges"])
            n_spur = sum("spurious" in kind(a, b) for a, b, *_ in r["edges"])
            rows.append((r["label"], "ok" if r["rc"] == 0 else (r["note"] or f"rc {r['rc']}"),
                         f"{r['time']:.0f}", edges, rb, f"{n_open}/3", str(n_spur)))
        print(table(["run", "status", "time [s]", "selected air paths", "R̄_v [K/(W m)]",
                     "open doors", "spurious"], rows))
        for r in cli_runs:
            meta = r.get("meta") or {}
            reasons = (meta.get("selection") or {}).get("reasons") or {}
            for e, why in reasons.items():
                print(f"  [{r['label']}] {e[4:]} ({kind(*e[4:].split('-'))}): {why}")
            for v in ((meta.get("greybox") or {}).get("verdicts") or {}).values():
                print(f"  [{r['label']}] {v}")
            for w in r.get("warnings", [])[:6]:
                print(f"  [{r['label']}] {w}")
            if r["rc"] not in (0, None):
                print(f"  [{r['label']}] {r['note']}")
        if any(r["rc"] is None for r in cli_runs):
            rough.append("a thermctl identify run did not finish within the time limit")

    # ---------------------------------------------------------------- selection with solar
    section("3. Model-based selection over all 21 pairs (BIC on the Kalman likelihood, solar apertures on)")
    print("select_air_paths(spec, calibration, candidates=<21 (a, b, d)>, criterion='bic', "
          f"direction='forward', max_edges={args.max_edges}, final_per_edge=True, solar='auto', "
          f"screen='{args.screen}'); "
          "one R̄_v per edge, τ0 shared; margin 10.")
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sel = select_air_paths(spec, cal, candidates=cands, criterion="bic", direction="forward",
                           max_edges=args.max_edges, final_per_edge=True, solar="auto",
                           screen=args.screen, progress=lambda m: say(f"selection (solar): {m}"))
    times["selection with solar"] = time.perf_counter() - t0
    sel_warn = [f"{w.category.__name__}: {w.message}" for w in caught]
    _print_path(sel, dist)
    net_sel = ThermalNetwork(spec, sel.edges)
    est_s = sel.estimator
    est_s.warnings_ = []
    times["  of which final per-edge fit"] = est_s.wall_time_

    # ---------------------------------------------------------------- fits for comparison
    net0 = ThermalNetwork(spec, ())
    est0_s = fit(net0, cal, "conduction-only, solar", times, solar="auto")
    est0_n = fit(net0, cal, "conduction-only, no solar", times, solar=False)
    init = {k: v for k, v in est_s.params_.items() if not k.startswith("aperture")}
    say("fit: selected structure, no solar")
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        est_n = LikelihoodEstimator(net_sel, per_edge=True, solar=False).fit(cal, init=init)
    times["selected structure, no solar"] = time.perf_counter() - t0
    est_n.warnings_ = [f"{w.category.__name__}: {w.message}" for w in caught]

    print("\nThe selected structure, per edge (final fit with solar; equivalent conductance "
          "G = 1/(3·R̄_v·d), the DC conductance of the 3R2C chain R1 = R2 = R3 = R̄_v·d):")
    cs = {e.name: (e, d, r, c, g) for e, d, r, c, g in conductances(est_s, net_sel)}
    cn = {e.name: (e, d, r, c, g) for e, d, r, c, g in conductances(est_n, net_sel)}
    rows = []
    for name, (e, d, r, c, g) in cs.items():
        r2, g2 = cn[name][2], cn[name][4]
        wall_ua = sum(1.0 / sum(w.R) for w in spec.walls if frozenset((w.a, w.b)) == frozenset((e.a, e.b)))
        rows.append((f"{e.a}–{e.b}", kind(e.a, e.b), f"{d:.1f}", f"{r:.3g}", f"{g:.0f}",
                     f"{c:.3g}", f"{r2:.3g}", f"{g2:.0f}", f"{wall_ua:.1f}" if wall_ua else "—"))
    print(table(["edge", "README", "d [m]", "R̄_v solar", "G solar [W/K]", "c_v [J/K]",
                 "R̄_v no solar", "G no solar [W/K]", "spec walls UA [W/K]"], rows))
    tau = est_s.params_.get("tau0", float("nan"))
    print(f"τ0 = R̄_v·C_v = {tau:.3g} s/m (bounds {est_s.problem_.tau_bounds[0]:.3g}–"
          f"{est_s.problem_.tau_bounds[1]:.3g}); without solar {est_n.params_.get('tau0', float('nan')):.3g} s/m.")
    for lab, e_ in (("solar", est_s), ("no solar", est_n)):
        phys = [b for b in e_.result_.active_bounds if b.startswith(("rbar_v", "tau0"))]
        if phys:
            print(f"  at a bound ({lab}): " + "; ".join(phys))
    n_open = sum(frozenset((e.a, e.b)) in OPEN for e in net_sel.convection_edges)
    n_spur = sum("spurious" in kind(e.a, e.b) for e in net_sel.convection_edges)
    print(f"Open-door couplings recovered: {n_open}/3; spurious couplings to closed-off rooms: {n_spur}.")

    # ---------------------------------------------------------------- solar vs no solar
    section("4. With and without the solar term")
    sel_n = None
    if args.nosolar_edges > 0:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sel_n = select_air_paths(spec, cal, candidates=cands, criterion="bic", direction="forward",
                                 max_edges=args.nosolar_edges, final_per_edge=True, solar=False,
                                 screen=args.screen, progress=lambda m: say(f"selection (no solar): {m}"))
        times["selection without solar"] = time.perf_counter() - t0
        print(f"Forward selection without solar ({args.nosolar_edges} steps):")
        _print_path(sel_n, dist, short=True)
    else:
        print("(forward selection without solar skipped: --nosolar-edges 0; below, the structure "
              "selected with solar is refitted without it)")
    models = [("conduction-only, no solar", est0_n), ("conduction-only, solar", est0_s),
              ("selected, no solar", est_n), ("selected, solar", est_s)]
    base = est0_n.bic_
    print("\nLikelihood on the calibration data (all samples: the supply air never stops here, so "
          "fit_rows='auto' falls back to 'all'):")
    print(table(["model", "edges", "free par.", "−log L", "BIC", "ΔBIC vs cond.-only no solar",
                 "σ_v [K]", "σ_φ [W/√s]", "fit [s]"],
                [(n, str(len(e.problem_.edges)), str(e.n_free_), f"{e.nll_:.1f}", f"{e.bic_:.1f}",
                  f"{e.bic_ - base:+.1f}", f"{e.params_.get('sigma_v', float('nan')):.3f}",
                  f"{e.params_.get('sigma_phi', float('nan')):.3f}", f"{e.wall_time_:.0f}")
                 for n, e in models]))
    sol_names = est_s.problem_.data.solar_names
    print("\nSolar apertures [m²] (W per W/m² of the column; lower bound 0; blank = 0):")
    for n, e in (("conduction-only", est0_s), ("selected", est_s)):
        print(f"  {n}:")
        rows = []
        for z in ZONES:
            vals = [e.params_.get(f"aperture[{z},{s}]", 0.0) for s in sol_names]
            rows.append((z, *[f"{v:.3f}" if v > 5e-4 else "" for v in vals]))
        print(table(["zone", *sol_names], rows))
    mean_I = {s: float(np.mean(cal.frame[f"solar:{s}"])) for s in sol_names}
    gains = {z: sum(est_s.params_.get(f"aperture[{z},{s}]", 0.0) * mean_I[s] for s in sol_names)
             for z in ZONES}
    print("  mean solar gain over the calibration days (selected, solar) [W]: "
          + ", ".join(f"{z} {v:.0f}" for z, v in gains.items()))

    # ---------------------------------------------------------------- validation
    section("5. Validation on the held-back days")
    cond = ThermalModel(net0)
    vmodels = [("selected, solar", est_s), ("selected, no solar", est_n),
               ("conduction-only, solar", est0_s), ("conduction-only, no solar", est0_n)]
    t0 = time.perf_counter()
    ks = {}
    for n, e in vmodels:
        say(f"k-step: {n}")
        pb = e.problem_for(val)
        ks[n] = kstep_errors(pb, e.eta_, horizons=[3600.0 * h for h in KSTEP_H], stride=3600.0)
    print("k-step-ahead RMSE [K] from Kalman-filtered states (filter restarted on the validation "
          "days, 6-h burn-in; restarts hourly), RMS over the 7 zones:")
    print(table(["model", *[f"{h:g} h" for h in KSTEP_H], "n (1 h)"],
                [(n, *[f"{v:.3f}" for v in r.rmse_mean], str(r.n[0])) for n, r in ks.items()]))
    print("per zone at 6 h:")
    print(table(["model", *ZONES], [(n, *[f"{v:.3f}" for v in r.rmse[1]]) for n, r in ks.items()]))

    # 48-h predictions from the filtered state, the filter run through all data
    H = int(round(48 * 3600 / meas.step.total_seconds()))
    k_val = len(cal)
    starts = [k for k in range(k_val, len(meas) - H, H)]
    pred = {}
    for n, e in vmodels:
        say(f"48-h prediction: {n}")
        pb = e.problem_for(meas)
        err = predict_from_filter(pb, e.eta_, starts, H)
        pred[n] = np.sqrt(np.nanmean(err ** 2, axis=1))            # (n_starts, ny)
    zs = est_s.problem_.data.zones
    print(f"\n48-h prediction RMSE [K] from the filtered state (filter run through the calibration "
          f"days; no updates for 48 h; {len(starts)} consecutive windows from {val.start:%m-%d}), "
          "per zone, RMS over the windows:")
    print(table(["model", *zs, "all"],
                [(n, *[f"{v:.2f}" for v in np.sqrt(np.mean(r ** 2, axis=0))],
                  f"{np.sqrt(np.mean(r ** 2)):.2f}") for n, r in pred.items()]))
    print("\nThe paper's 48-h open loop (ThermalModel only: no gains, no solar; initial state: zones "
          "measured, walls and edges at the mean of their ends), same windows:")
    ol = {}
    for n, mdl in (("selected, solar", est_s.model_), ("selected, no solar", est_n.model_),
                   ("conduction-only", cond)):
        say(f"open loop: {n}")
        r_all = []
        for k in starts:
            win = meas.window(start=meas.frame.index[k], duration="48h")
            U = win.inputs(mdl.network)[:-1]
            Y = np.column_stack([win.frame[f"T:{z}"].to_numpy() for z in mdl.network.zones])
            Tb0 = win.frame[[f"T:{b}" for b in mdl.network.boundary]].iloc[0].to_numpy()
            res = open_loop(mdl, U, Y, win.step.total_seconds(), Tb0)
            r_all.append([res.rmse[z] for z in zs])
        ol[n] = np.array(r_all)
    print(table(["model", *zs, "all"],
                [(n, *[f"{v:.2f}" for v in np.sqrt(np.mean(r ** 2, axis=0))],
                  f"{np.sqrt(np.mean(r ** 2)):.2f}") for n, r in ol.items()]))
    times["validation (k-step, 48 h, open loop)"] = time.perf_counter() - t0

    # ---------------------------------------------------------------- step responses
    section("6. Step responses: heat into the living room → every zone")
    fr = cal.frame
    ms_min = minimum_flows(fr.reindex(columns=[f"ms:{z}" for z in net0.zones], fill_value=0.0).to_numpy())
    print(f"Supply flow held at {ms_min[0]:.4f} kg/s in the living room (5 % quantile; the house "
          "ventilates ~0.040 kg/s all the time). K per 100 W, and the 3-h value scaled to the "
          f"measured pulses' mean power {Pm:.0f} W beside the measured median rise:")
    G = {}
    for n, mdl in (("selected, solar", est_s.model_), ("selected, no solar", est_n.model_),
                   ("conduction-only", cond)):
        G[n] = step_response_matrix(mdl, ms_min, HORIZONS_H)
    i_liv = net0.zones.index("living")
    rows = []
    for z in ZONES:
        j = net0.zones.index(z)
        rows.append([z, *["/".join(f"{G[n][h, j, i_liv]:.3f}" for h in range(len(HORIZONS_H)))
                          for n in G],
                     *[f"{G[n][1, j, i_liv] * Pm / 100:.2f}" for n in G], f"{med[z]:+.2f}"])
    hz = "/".join(f"{h:g}" for h in HORIZONS_H)
    print(table(["zone", *[f"{n} {hz} h" for n in G], *[f"{n}, 3 h" for n in G],
                 "data, 3 h"], rows))
    print(f"(first three columns: K per 100 W at {hz} h; next: K at 3 h for {Pm:.0f} W; data: median "
          "measured rise of the clean pulses, section 1)")
    rel = {n: float(np.linalg.norm(G[n][1, :, i_liv] * Pm / 100 - med[net0.zones].to_numpy())
                    / np.linalg.norm(med[net0.zones].to_numpy())) for n in G}
    print("relative error of the 3-h living-room column against the measured median rise: "
          + ", ".join(f"{n} {100 * v:.0f} %" for n, v in rel.items()))
    spill = {n: float(G[n][1, [net0.zones.index(z) for z in ("corridor", "bath", "child")], i_liv].mean()
                      / G[n][1, i_liv, i_liv]) for n in G}
    dspill = float(med[["corridor", "bath", "child"]].mean() / med["living"])
    print("mean rise of corridor/bath/child relative to the living room's at 3 h: "
          + ", ".join(f"{n} {v:.2f}" for n, v in spill.items()) + f"; data {dspill:.2f}")

    # ---------------------------------------------------------------- along the path
    section("7. What each added edge does (refits of the selection path's prefixes, solar on)")
    t0 = time.perf_counter()
    prefix = []
    for k in range(len(sel.edges) + 1):
        if k == 0:
            e = est0_s
        elif k == len(sel.edges):
            e = est_s
        else:
            net_k = ThermalNetwork(spec, sel.edges[:k])
            init_k = {n: v for n, v in est_s.params_.items() if not n.startswith("rbar_v[")}
            init_k.update({f"rbar_v[air:{a}-{b}]": est_s.params_[f"rbar_v[air:{a}-{b}]"]
                           for a, b, _ in sel.edges[:k]})
            say(f"prefix fit: {k} edge(s)")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                e = LikelihoodEstimator(net_k, per_edge=True, solar="auto").fit(cal, init=init_k)
        r = kstep_errors(e.problem_for(val), e.eta_, horizons=[3600.0 * h for h in KSTEP_H],
                         stride=3600.0)
        Gk = step_response_matrix(e.model_, ms_min, HORIZONS_H)[1, :, i_liv] * Pm / 100
        err48 = predict_from_filter(e.problem_for(meas), e.eta_, starts, H)
        prefix.append((k, e, r, Gk, float(np.sqrt(np.nanmean(err48 ** 2)))))
    times["prefix refits and their validation"] = time.perf_counter() - t0
    rows = []
    for k, e, r, Gk, r48 in prefix:
        added = "conduction only" if k == 0 else "+ " + "–".join(sel.edges[k - 1][:2])
        rows.append((str(k), added, f"{e.bic_:.0f}", *[f"{v:.3f}" for v in r.rmse_mean],
                     f"{r48:.2f}", f"{Gk[i_liv]:.2f}",
                     f"{Gk[[net0.zones.index(z) for z in ('corridor', 'bath', 'child')]].mean():.2f}",
                     f"{Gk[[net0.zones.index(z) for z in ('kitchen', 'doorway', 'bedroom')]].mean():.2f}"))
    rows.append(("", "data (clean pulses)", "", "", "", "", "", f"{med['living']:.2f}",
                 f"{med[['corridor', 'bath', 'child']].mean():.2f}",
                 f"{med[['kitchen', 'doorway', 'bedroom']].mean():.2f}"))
    print(table(["edges", "added", "BIC (cal.)", *[f"k-step {h:g} h" for h in KSTEP_H], "48 h pred.",
                 f"living 3 h @{Pm:.0f} W", "corr/bath/child", "kitch/door/bed"], rows))
    print("(k-step and 48-h columns: RMSE [K] on the held-back days, all zones; last three: "
          f"temperature rise [K] 3 h after {Pm:.0f} W into the living room, mean over the zone group)")

    # ---------------------------------------------------------------- diagnostics
    section("8. Diagnostic: zone heat capacity")
    import yaml
    from thermctl.spec import spec_from_dict
    raw = yaml.safe_load((args.data / "building.yaml").read_text())
    cz = {z: spec.zone_capacitance(z) for z in ZONES}
    print("The spec gives no capacitance per zone, so thermctl uses capacity_multiplier · ρ·cp·V "
          "with the default multiplier 1 (air only): " + ", ".join(f"{z} {v / 1e3:.0f}" for z, v in cz.items())
          + " kJ/K. The convection edges' C_v (τ0 at its upper bound) adds capacity at the zones.")
    t0 = time.perf_counter()
    rows = []
    for mult in (1.0, 3.0, 10.0):
        sp = spec_from_dict({**raw, "capacity_multiplier": mult}) if mult != 1.0 else spec
        say(f"capacity ×{mult:g}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            e = est0_n if mult == 1.0 else LikelihoodEstimator(ThermalNetwork(sp, ()), solar=False).fit(cal)
        rows.append((f"×{mult:g}", f"{e.bic_:.0f}", f"{e.bic_ - est0_n.bic_:+.0f}"))
    times["capacity diagnostic"] = time.perf_counter() - t0
    print(table(["capacity_multiplier", "BIC conduction-only, no solar", "ΔBIC"], rows))

    # ---------------------------------------------------------------- summary
    section("9. Summary")
    order = [st.edge[4:] for st in sel.path if st.action == "add"]
    found_open = [n for n in order if frozenset(n.split("-")) in OPEN]
    spur = [n for n in order if "spurious" in kind(*n.split("-"))]
    print(f"- Forward selection (solar, {len(order)} steps) added, in order: {', '.join(order)}. "
          f"Open doors recovered: {len(found_open)}/3 ({', '.join(found_open) or 'none'}); "
          f"couplings to closed-off rooms: {len(spur)} ({', '.join(spur) or 'none'}).")
    stop = [st for st in sel.path if st.action == "stop"]
    print("- The BIC rule " + (f"stopped the search after {len(order)} edges." if stop else
                               f"did not stop the search: it was cut at --max-edges {args.max_edges} "
                               "with the best remaining candidate still improving BIC by "
                               f"{-min(sel.path[-1].screened.values() or [0.0]):.0f} (screen estimate)."))
    print(f"- Solar apertures: BIC {est0_s.bic_ - est0_n.bic_:+.0f} (conduction-only), "
          f"{est_s.bic_ - est_n.bic_:+.0f} (selected structure); k-step RMSE at 1/6/24 h with vs "
          "without solar (selected): " + ", ".join(
              f"{a:.3f}/{b:.3f}" for a, b in zip(ks['selected, solar'].rmse_mean,
                                                 ks['selected, no solar'].rmse_mean)) + " K.")
    gain = 1.0 - ks["selected, solar"].rmse_mean / ks["conduction-only, solar"].rmse_mean
    print("- Held-back k-step RMSE, selected vs conduction-only (both with solar): "
          + ", ".join(f"{h:g} h {100 * g:+.0f} %" for h, g in zip(KSTEP_H, gain))
          + " (positive = the selected model is better).")
    a48 = np.sqrt(np.mean(pred["selected, solar"] ** 2))
    b48 = np.sqrt(np.mean(pred["conduction-only, solar"] ** 2))
    print(f"- 48-h prediction from the filtered state: {a48:.2f} K (selected) vs {b48:.2f} K "
          f"(conduction-only); the paper's open loop from the mean-of-ends start: "
          f"{np.sqrt(np.mean(ol['selected, solar'] ** 2)):.2f} vs "
          f"{np.sqrt(np.mean(ol['conduction-only'] ** 2)):.2f} K.")
    best = {h: min(prefix, key=lambda t: t[2].rmse_mean[i])[0] for i, h in enumerate(KSTEP_H)}
    print("- Along the selection path, the held-back k-step RMSE is lowest with "
          + ", ".join(f"{k} edge(s) at {h:g} h" for h, k in best.items())
          + f" (BIC on the calibration days keeps falling to {len(sel.edges)} edges).")
    print(f"- Living-room heat reaching corridor/bath/child within 3 h (relative to the living "
          f"room's own rise): data {dspill:.2f}, selected {spill['selected, solar']:.2f}, "
          f"conduction-only {spill['conduction-only']:.2f}.")

    # ---------------------------------------------------------------- times, rough edges
    section("10. Run times (wall clock on the shared 2-core machine, OMP_NUM_THREADS=1)")
    print(table(["step", "time [s]"], [(k, f"{v:.0f}") for k, v in times.items()]
                + [("total", f"{time.perf_counter() - T0:.0f}")]))
    print(f"selection with solar: {sel.n_fits} likelihood fits/screens; "
          f"final model {est_s.problem_.describe()}")

    section("11. Warnings raised along the way")
    for w in sorted(set(sel_warn + est_s.warnings_ + est_n.warnings_ + est0_s.warnings_
                        + est0_n.warnings_))[:20]:
        print("  " + w[:300])
    for r in rough:
        print("  " + r)
    return 0


def _print_path(sel, dist, short=False):
    """The selection path: order, ΔBIC, R̄_v and conductance at entry."""
    rows = []
    for k, st in enumerate(sel.path):
        if st.action == "start":
            rows.append(("0", "start (conduction only)", "", f"{st.value:.1f}", "", "", "", ""))
            continue
        a, b = st.edge[len("air:"):].split("-")
        d = dist[tuple(sorted((a, b)))]
        rb = float("nan")
        if st.action == "add":
            txt = st.note.split("rbar_v ")[1].split(" ")[0] if "rbar_v " in st.note else "nan"
            rb = float(txt)
        best_other = sorted((v, n) for n, v in st.screened.items() if n != st.edge)[:1]
        rows.append((str(k), f"{st.action} {a}–{b}", kind(a, b), f"{st.value:.1f}",
                     f"{st.delta:+.1f}", f"{rb:.3g}" if np.isfinite(rb) else "",
                     f"{1 / (3 * rb * d):.0f}" if np.isfinite(rb) else "",
                     f"{best_other[0][1][4:]} {best_other[0][0]:+.0f}" if best_other else ""))
    print(table(["step", "action", "README", "BIC", "ΔBIC", "R̄_v [K/(W m)]", "G [W/K]",
                 "next-best screened (ΔBIC est.)"], rows))
    if short:
        return
    first = next((st for st in sel.path if st.screened), None)
    if first is not None:
        print("\nFirst screening round (ΔBIC of adding each pair to the conduction-only model, "
              "everything else held; negative = better):")
        items = sorted(first.screened.items(), key=lambda kv: kv[1])
        print(table(["pair", "README", "ΔBIC screen"],
                    [(n[4:], kind(*n[4:].split("-")), f"{v:+.0f}") for n, v in items]))
    last = [st for st in sel.path if st.screened][-1:]
    if last:
        st = last[0]
        items = sorted(st.screened.items(), key=lambda kv: kv[1])[:8]
        print(f"\nLast screening round (step {sel.path.index(st)}), best remaining candidates: "
              + ", ".join(f"{n[4:]} {v:+.0f}" for n, v in items))
        if st.action == "add" and len(sel.edges) >= 1:
            print("(the search stopped at --max-edges, not by the BIC margin: the best remaining "
                  "candidates still improve BIC by far more than 10)" if items and items[0][1] < -10
                  else "")


if __name__ == "__main__":
    sys.exit(main())
