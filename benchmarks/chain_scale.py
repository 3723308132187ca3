"""The command-line chain after identify at building scale: validate, export, reduce.

For each corridor building (``thermctl testbed --building corridor --zones Z --days 14``)
this script runs, as a user would, each command in its own process under
``/usr/bin/time -v`` and prints one markdown row per command:

* ``testbed``: generate the building and its data;
* ``identify``: the defaults (local problems above 12 measured zones, all cores);
* ``validate``: the defaults (k-step errors only up to 150 states, see
  ``thermctl.validate.KSTEP_MAX_STATES``; step responses by sparse Radau steps above
  ``EXACT_LIMIT`` states plus zones);
* ``export``: the continuous state-space model (``--statespace``);
* ``export --dt``: the same, discretised at 10 min (dense, exact; ``--skip-dt`` leaves it out);
* ``reduce``: the structured reduction (2 states per zone) with its error table.

Columns: wall and CPU (user + system) time [s], peak resident memory [MB] of the command's
process, exit status, and for identify the true air paths found and the false ones. The
machine's load average is printed under the table (compare CPU, not wall, on a shared
machine).

Usage::

    python benchmarks/chain_scale.py --zones 49                  # ~5 min
    OMP_NUM_THREADS=1 python benchmarks/chain_scale.py --zones 49 490 --skip-dt   # ~40 min
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

THERMCTL = str(Path(sys.executable).with_name("thermctl"))


def timed(args, log: Path, timeout: float) -> dict:
    """Run ``thermctl ARGS`` under ``/usr/bin/time -v``; wall, CPU, peak MB, exit status."""
    t0 = time.perf_counter()
    with log.open("w") as f:
        try:
            rc = subprocess.run(["/usr/bin/time", "-v", THERMCTL, *map(str, args)], stdout=f,
                                stderr=subprocess.STDOUT, timeout=timeout).returncode
        except subprocess.TimeoutExpired:
            rc = "timeout"
    wall = time.perf_counter() - t0
    text = log.read_text(errors="replace")

    def num(label):
        m = re.search(rf"{label}: ([0-9.]+)", text)
        return float(m.group(1)) if m else float("nan")
    return {"wall": wall, "cpu": num(r"User time \(seconds\)") + num(r"System time \(seconds\)"),
            "mb": num(r"Maximum resident set size \(kbytes\)") / 1024.0, "rc": rc}


def score(d: Path) -> str:
    truth = json.loads((d / "truth.json").read_text())
    model = json.loads((d / "out" / "model.json").read_text())
    true = {tuple(sorted((e["a"], e["b"]))) for e in truth["edges"]}
    found = {tuple(sorted((e["a"], e["b"]))) for e in model["convection"]}
    return f"{len(true & found)}/{len(true)} true, {len(found - true)} false"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zones", type=int, nargs="+", default=[49])
    ap.add_argument("--days", type=float, default=14.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip-dt", action="store_true", help="leave out export --dt 600")
    ap.add_argument("--timeout", type=float, default=3600.0, help="per command [s]")
    ap.add_argument("--keep", type=Path, default=None, help="work directory to keep")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()
    print("| zones | command | wall s | CPU s | peak MB | exit | note |")
    print("|---:|---|---:|---:|---:|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        for z in args.zones:
            d = root / f"corridor{z}"
            d.mkdir(parents=True, exist_ok=True)
            m, data = d / "out" / "model.json", d / "data.csv"
            steps = [
                ("testbed", ["testbed", "--building", "corridor", "--zones", z, "--days",
                             args.days, "--seed", args.seed, "-o", d]),
                ("identify", ["identify", data, "-b", d / "building.yaml", "-o", d / "out"]),
                ("validate", ["validate", m, data]),
                ("export", ["export", m, "--statespace", d / "ss.npz", "--data", data]),
                ("export --dt 600", ["export", m, "--statespace", d / "ssd.npz", "--data", data,
                                     "--dt", 600]),
                ("reduce", ["reduce", m, "--out", d / "red.npz"]),
            ]
            for name, cmd in steps:
                if name == "export --dt 600" and args.skip_dt:
                    continue
                r = timed(cmd, d / f"{name.split()[0]}.log", args.timeout)
                note = score(d) if name == "identify" and r["rc"] == 0 else ""
                print(f"| {z} | {name} | {r['wall']:.1f} | {r['cpu']:.1f} | {r['mb']:.0f} | "
                      f"{r['rc']} | {note} |", flush=True)
                if r["rc"] != 0 and name in ("testbed", "identify"):
                    break
    load1 = os.getloadavg()
    print(f"\nmachine: {os.cpu_count()} cores; load average (1, 5, 15 min) at start "
          f"{' '.join(f'{v:.2f}' for v in load0)}, at end {' '.join(f'{v:.2f}' for v in load1)}; "
          f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}")


if __name__ == "__main__":
    main()
