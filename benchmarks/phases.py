"""Where the wall time of one ``thermctl identify`` goes: phase by phase, and how many cores
each phase keeps busy.

Runs the command line as a user would (default options unless given after ``--``), stamps
every progress line it prints with the time, samples the process's CPU time from
``/proc/<pid>/stat`` every 0.25 s (Linux), and prints one row per phase: wall time, CPU
time, cores busy (CPU / wall), and the core-seconds the phase left idle on this machine's
cores. A phase runs from the first progress line of its stage to the first line of the
next; the selection's first fit, which runs while the gain model is decided and then alone,
is the row between "gain model ... done" and the selection's first count.

Issue 19 asks for the twin house N2 within 2 minutes on the 2-core machine: the last line
says what the same CPU would take with every core busy throughout.

Usage::

    OMP_NUM_THREADS=1 python benchmarks/phases.py                   # the twin house N2
    OMP_NUM_THREADS=1 python benchmarks/phases.py --data DIR -- --workers 1
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "twinhouse-n2"
_PROGRESS = re.compile(r"^identify: (?P<stage>.*?) (?P<n>\d+)(/\d+)?, elapsed [\d:]+(?P<done>, done)?")


def _cpu_seconds(pid: int) -> float | None:
    """User + system CPU of ``pid`` and its reaped children so far [s] (None once gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except OSError:
        return None
    tck = os.sysconf("SC_CLK_TCK")
    # after the ")": state is field 3 of stat(5), utime 14, stime 15, cutime 16, cstime 17
    return sum(int(fields[k]) for k in (11, 12, 13, 14)) / tck


def run(cmd: list[str], period: float = 0.25):
    """``(lines, samples, wall)``: progress lines as ``(t, text)``, CPU samples as
    ``(t, cpu)``, both from the start of the process [s]."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "200"})
    samples, lines = [(0.0, 0.0)], []

    def sample():
        while proc.poll() is None:
            c = _cpu_seconds(proc.pid)
            if c is not None:
                samples.append((time.perf_counter() - t0, c))
            time.sleep(period)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    for text in proc.stdout:
        lines.append((time.perf_counter() - t0, text.rstrip("\n")))
    proc.wait()
    th.join()
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        tail = "\n".join(t for _, t in lines[-15:])
        raise SystemExit(f"thermctl identify exited with {proc.returncode}:\n{tail}")
    return lines, samples, wall


def phases(lines, wall):
    """``[(start, end, name)]`` from the progress lines."""
    marks = [(0.0, "reading the data")]
    for t, text in lines:
        m = _PROGRESS.match(text)
        if m:
            stage = m["stage"]
            if marks[-1][1] != stage:
                marks.append((t, stage))
            if m["done"] and stage.startswith("gain model"):
                marks.append((t, "the selection's first fit (alone)"))
        elif text.startswith("wrote "):
            marks.append((t, "tables, figures, exit"))
    out = []
    for (a, name), (b, _) in zip(marks, marks[1:] + [(wall, "")]):
        if b - a >= 0.05:                   # a stage done at once (the structure) is no row
            out.append((a, b, name))
    return out


def interp(samples, t):
    """CPU at time ``t`` by linear interpolation of the samples (the last one after them) [s]."""
    ts, cs = zip(*samples)
    return float(np.interp(t, ts, cs))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA,
                    help="a directory with data.csv and building.yaml (default: the twin "
                         "house N2)")
    ap.add_argument("extra", nargs="*", help="more identify options, after --")
    args = ap.parse_args(argv)
    if not (args.data / "data.csv").exists():
        raise SystemExit(f"{args.data}: no data.csv there (--data DIR)")
    cores = os.cpu_count() or 1
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as out:
        exe = Path(sys.executable).with_name("thermctl")
        cmd = [str(exe), "identify", str(args.data / "data.csv"), "-b",
               str(args.data / "building.yaml"), "-o", out, *args.extra]
        lines, samples, wall = run(cmd)
    cpu = samples[-1][1]
    rows = phases(lines, wall)
    print(f"# {' '.join(['thermctl identify', str(args.data), *args.extra])}")
    print(f"machine: {cores} cores; load average at start {load0[0]:.2f} {load0[1]:.2f} "
          f"{load0[2]:.2f}, at end {' '.join(f'{x:.2f}' for x in os.getloadavg())}; "
          f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}")
    print()
    print("| phase | from s | wall s | CPU s | cores busy | idle core-s |")
    print("|---|---:|---:|---:|---:|---:|")
    idle = 0.0
    for a, b, name in rows:
        c = interp(samples, b) - interp(samples, a)
        w = b - a
        gap = max(cores * w - c, 0.0)
        idle += gap
        print(f"| {name} | {a:.1f} | {w:.1f} | {c:.1f} | {c / w if w > 0 else 0:.2f} | "
              f"{gap:.0f} |")
    print(f"| **total** | | **{wall:.1f}** | **{cpu:.1f}** | {cpu / wall:.2f} | {idle:.0f} |")
    print()
    print(f"With every one of the {cores} cores busy throughout, the same {cpu:.0f} s of CPU "
          f"would take {cpu / cores:.0f} s.")


if __name__ == "__main__":
    main()
