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

With ``--against REV`` the same command runs alternately with the thermctl of another
commit (a temporary ``git worktree``, put first on ``PYTHONPATH``) and with this checkout's,
``--runs`` times each, and a last table compares each pair: this machine's speed drifts by
10-20 % over minutes, so a refactor's before and after are compared within a pair.

Usage::

    OMP_NUM_THREADS=1 python benchmarks/phases.py                   # the twin house N2
    OMP_NUM_THREADS=1 python benchmarks/phases.py --data DIR -- --workers 1
    OMP_NUM_THREADS=1 python benchmarks/phases.py --against 6d2d509 --runs 2
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


def run(cmd: list[str], period: float = 0.25, env=None):
    """``(lines, samples, wall)``: progress lines as ``(t, text)``, CPU samples as
    ``(t, cpu)``, both from the start of the process [s]. ``env``: more environment."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "200",
                                 **(env or {})})
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


def table(lines, samples, wall, cores) -> float:
    """Print the phase table of one run; returns its idle core-seconds."""
    cpu = samples[-1][1]
    print("| phase | from s | wall s | CPU s | cores busy | idle core-s |")
    print("|---|---:|---:|---:|---:|---:|")
    idle = 0.0
    for a, b, name in phases(lines, wall):
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
    return idle


def pairs(results) -> list[str]:
    """Lines of the table comparing alternate runs: ``results`` is ``[(label, wall, cpu,
    idle), ...]`` in the order run, the other commit's first in each pair."""
    out = ["| pair | wall before → after | ratio | CPU before → after | ratio | "
           "idle core-s |", "|---|---|---:|---|---:|---|"]
    for k in range(0, len(results) - 1, 2):
        (_, w0, c0, i0), (_, w1, c1, i1) = results[k], results[k + 1]
        out.append(f"| {k // 2 + 1} | {w0:.1f} → {w1:.1f} s | {w1 / w0:.3f} | "
                   f"{c0:.1f} → {c1:.1f} s | {c1 / c0:.3f} | {i0:.0f} → {i1:.0f} |")
    return out


def _worktree(rev: str, where: str) -> Path:
    repo = Path(__file__).resolve().parents[1]
    path = Path(where) / "base"
    subprocess.run(["git", "-C", str(repo), "worktree", "add", "--detach", "-q", str(path),
                    rev], check=True)
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--data", type=Path, default=DATA,
                    help="a directory with data.csv and building.yaml (default: the twin "
                         "house N2)")
    ap.add_argument("--against", metavar="REV",
                    help="also run the thermctl of this commit, alternately with this one's")
    ap.add_argument("--runs", type=int, default=2, help="with --against: pairs of runs")
    ap.add_argument("extra", nargs="*", help="more identify options, after --")
    args = ap.parse_args(argv)
    if not (args.data / "data.csv").exists():
        raise SystemExit(f"{args.data}: no data.csv there (--data DIR)")
    cores = os.cpu_count() or 1
    exe = Path(sys.executable).with_name("thermctl")
    print(f"# {' '.join(['thermctl identify', str(args.data), *args.extra])}")
    with tempfile.TemporaryDirectory() as tmp:
        base = _worktree(args.against, tmp) if args.against else None
        plan = ([("HEAD", None)] if base is None else
                [(args.against, {"PYTHONPATH": str(base)}), ("HEAD", None)] * args.runs)
        results = []
        try:
            for k, (label, env) in enumerate(plan):
                load0 = os.getloadavg()
                out = Path(tmp) / f"out{k}"
                cmd = [str(exe), "identify", str(args.data / "data.csv"), "-b",
                       str(args.data / "building.yaml"), "-o", str(out), *args.extra]
                lines, samples, wall = run(cmd, env=env)
                print()
                if base is not None:
                    print(f"## run {k + 1}: thermctl at {label}")
                print(f"machine: {cores} cores; load average at start {load0[0]:.2f} "
                      f"{load0[1]:.2f} {load0[2]:.2f}, at end "
                      f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}; "
                      f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}")
                print()
                idle = table(lines, samples, wall, cores)
                results.append((label, wall, samples[-1][1], idle))
        finally:
            if base is not None:
                subprocess.run(["git", "-C", str(Path(__file__).resolve().parents[1]),
                                "worktree", "remove", "--force", str(base)], check=False)
    if base is not None:
        print()
        print(f"## {args.against} (before) against this checkout (after), run alternately")
        print()
        print("\n".join(pairs(results)))


if __name__ == "__main__":
    main()
