"""Wall time to generate the paper's 26 days of 5-min data for 7, 50 and 200 zones.

Run:  .venv/bin/python benchmarks/testbed.py [--days 26] [--zones 7 50 200] [--repeat 1]
                                            [--plant rc|rc-exact|fd]

Each row is one ``thermctl.testbed.generate`` call (3 burn-in days, 1-min control and
integration step, default sensors) split into model build (the model core's CasADi
matrices plus the plant's factorisations) and closed-loop simulation. CPU time is given
beside wall time because the machine may be shared.
"""

from __future__ import annotations

import argparse
import os
import time

from thermctl.testbed import generate


def _one(zones: int, days: float, seed: int, plant: str = "rc"):
    building = "pugh-hall" if zones == 7 else "corridor"
    marks = {}

    def progress(done, total):
        if "first" not in marks:
            marks["first"] = (time.perf_counter(), time.process_time())

    w0, c0 = time.perf_counter(), time.process_time()
    tb = generate(building, zones=None if zones == 7 else zones, days=days, seed=seed,
                  plant=plant, progress=progress)
    w1, c1 = time.perf_counter(), time.process_time()
    wf, cf = marks["first"]
    steps = round((days + 3) * 1440)
    return {
        "building": tb.spec.name, "zones": tb.network.n_zones,
        "measured": len(tb.spec.measured_zones), "states": tb.states.shape[1],
        "air paths": len(tb.truth.edges), "steps": steps,
        "build s": wf - w0, "sim s": w1 - wf, "wall s": w1 - w0, "cpu s": c1 - c0,
        "us/step": 1e6 * (c1 - cf) / steps,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=float, default=26.0)
    ap.add_argument("--zones", type=int, nargs="+", default=[7, 50, 200])
    ap.add_argument("--repeat", type=int, default=1, help="best of this many runs")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--plant", default="rc", choices=["rc", "rc-exact", "fd"],
                    help="the plant (fd: finite-volume walls; states counts its cells)")
    args = ap.parse_args()
    print(f"testbed generation, {args.days:g} days of 5-min data (+3 burn-in days), "
          f"1-min control, plant {args.plant}; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    cols = ["building", "zones", "measured", "states", "air paths", "steps", "build s", "sim s",
            "wall s", "cpu s", "us/step"]
    print(" | ".join(f"{c:>16s}" if i == 0 else f"{c:>9s}" for i, c in enumerate(cols)))
    for z in args.zones:
        best = min((_one(z, args.days, args.seed, args.plant) for _ in range(args.repeat)),
                   key=lambda r: r["wall s"])
        cells = []
        for i, c in enumerate(cols):
            v = best[c]
            cells.append(f"{v:>16s}" if i == 0 else f"{v:>9.2f}" if isinstance(v, float)
                         else f"{v:>9d}")
        print(" | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
