"""A messy export of a testbed building against its clean export: does the structure hold?

Run:  OMP_NUM_THREADS=1 .venv/bin/python benchmarks/messy.py [--days 16] [--seed 0]
          [--building pugh-hall ring] [--single [MESS ...]] [--out FILE]

Issue 20 ("robust to what real logs look like"). For each building the testbed's data are
written as the user's CSV exactly as ``thermctl testbed`` writes them
(:func:`thermctl.testbed.output.write_data_csv`, SI units, ISO 8601 stamps with offset);
a copy is then made messy by a seeded RNG doing exactly six things to the CSV lines
(:func:`make_messy`), the header and the cell formatting kept as exported:

* ``outage``:    every row of one 6-hour window removed (a BAS server down);
* ``missing``:   1 % of the remaining rows removed at random;
* ``empty``:     8 single cells emptied (a sensor not answering one poll);
* ``jitter``:    every time stamp moved by a whole number of seconds in [-20, 20];
* ``duplicate``: 20 rows written twice, verbatim, right after themselves;
* ``disorder``:  60 pairs of rows less than an hour apart swapped.

Both files are read with :func:`thermctl.data.read_measurements` (the messy one also with
``snap="30s"``: a stamp within 30 s of a grid point is its sample) and identified with
:func:`thermctl.identify.identify` and the default options. The table gives what reading
did (rows read, dropped, repaired; the data-quality summary), the air paths found on each
export and their symmetric difference, the geometric mean of R̄_v, and CPU seconds.
``--single`` adds one row per manipulation alone (which mess moves what; all six, or
those named).
"""

from __future__ import annotations

import argparse
import io
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import gmean

from thermctl.data import read_measurements
from thermctl.identify import identify
from thermctl.testbed import generate
from thermctl.testbed.output import write_data_csv

MESSES = ("outage", "missing", "empty", "jitter", "duplicate", "disorder")
OUTAGE_H = 6.0          # [h]
MISSING_FRACTION = 0.01  # [-] of the rows left after the outage
N_EMPTY = 8             # cells
JITTER_S = 20           # [s], uniform whole seconds in [-JITTER_S, JITTER_S]
N_DUPLICATE = 20        # rows
N_SWAP = 60             # pairs of rows, each less than an hour apart


def make_messy(csv_text: str, seed: int, messes=MESSES) -> tuple[str, dict]:
    """A messy copy of an exported CSV (header and cell formatting kept).

    Parameters
    ----------
    csv_text : str
        The clean export: header line, then one line per time stamp, ``time`` first.
    seed : int
        Seeds the one RNG; every mess draws from it in the fixed order of :data:`MESSES`,
        whether or not it is applied, so a single mess does the same thing alone as in
        the full mix.
    messes : iterable of str
        Which of :data:`MESSES` to apply.

    Returns
    -------
    text : str
        The messy CSV.
    log : dict
        What was done: ``outage`` (first and last stamp removed), ``missing`` (rows),
        ``empty`` (cells), ``jitter`` (rows moved), ``duplicate`` (rows), ``swapped``
        (pairs).
    """
    messes = set(messes)
    unknown = messes - set(MESSES)
    if unknown:
        raise ValueError(f"unknown mess(es) {sorted(unknown)}; choose from {MESSES}")
    rng = np.random.default_rng(seed)
    header, *lines = csv_text.rstrip("\n").split("\n")
    times = pd.DatetimeIndex([pd.Timestamp(s.split(",", 1)[0]) for s in lines])
    n = len(lines)
    log = {}
    keep = np.ones(n, dtype=bool)

    # outage: a 6-hour window starting on a random row, not in the first or last day
    step = times[1] - times[0]
    per_day = int(pd.Timedelta(days=1) / step)
    i0 = int(rng.integers(per_day, n - per_day))
    out = (times >= times[i0]) & (times < times[i0] + pd.Timedelta(hours=OUTAGE_H))
    if "outage" in messes:
        keep &= ~out
        log["outage"] = (str(times[i0]), str(times[np.flatnonzero(out)[-1]]), int(out.sum()))

    # 1 % of the remaining rows
    cand = np.flatnonzero(~out)
    drop = rng.choice(cand, size=int(round(MISSING_FRACTION * len(cand))), replace=False)
    if "missing" in messes:
        keep[drop] = False
        log["missing"] = len(drop)

    cells = [line.split(",") for line in lines]
    ncol = len(cells[0])
    # single empty cells (not the time column)
    rows_e = rng.integers(0, n, N_EMPTY)
    cols_e = rng.integers(1, ncol, N_EMPTY)
    if "empty" in messes:
        done = 0
        for r, c in zip(rows_e, cols_e):
            if keep[r] and cells[r][c] != "":
                cells[r][c] = ""
                done += 1
        log["empty"] = done

    # jitter every stamp by whole seconds; written in the export's own format and offset
    shift = rng.integers(-JITTER_S, JITTER_S + 1, n)
    if "jitter" in messes:
        for r in range(n):
            if shift[r]:
                cells[r][0] = (times[r] + pd.Timedelta(seconds=int(shift[r]))).isoformat()
        log["jitter"] = int((shift != 0).sum())

    rows = [",".join(c) for c, k in zip(cells, keep) if k]
    # verbatim duplicates right after their originals
    dup = np.sort(rng.choice(len(rows), size=N_DUPLICATE, replace=False))
    if "duplicate" in messes:
        for r in dup[::-1]:
            rows.insert(int(r) + 1, rows[int(r)])
        log["duplicate"] = N_DUPLICATE

    # swap pairs of rows less than an hour apart (a log merged from buffers)
    m = len(rows)
    a = rng.integers(0, m - 12, N_SWAP)
    b = a + rng.integers(1, 12, N_SWAP)
    if "disorder" in messes:
        for i, j in zip(a, b):
            rows[i], rows[j] = rows[j], rows[i]
        log["swapped"] = N_SWAP
    return header + "\n" + "\n".join(rows) + "\n", log


def _run(path, spec, name, **read_kw):
    """Read and identify one file; returns a result row."""
    c0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meas = read_measurements(path, spec, name=name, **read_kw)
        c1 = time.process_time()
        ident = identify(meas)
    c2 = time.process_time()
    q = meas.quality
    model = ident.model
    edges = {tuple(sorted((e.a, e.b))) for e in model.network.convection_edges}
    rb = np.atleast_1d(np.asarray(model.rbar_v, float)) if edges else np.array([])
    return {
        "name": name, "quality": q, "edges": edges,
        "rbar_v": float(gmean(rb)) if rb.size else float("nan"),
        "read_s": c1 - c0, "identify_s": c2 - c1, "notes": list(ident.notes),
        "cal": (ident.calibration.start, ident.calibration.end),
    }


def _fmt_row(r, clean_edges, true_edges):
    q = r["quality"]
    tot = lambda d: sum(d.values())  # noqa: E731
    diff = r["edges"] ^ clean_edges
    wrong = r["edges"] ^ true_edges
    return (f"{r['name']:<18s} {q.rows_read:>5d} {q.duplicates_removed:>4d} "
            f"{q.rows_out_of_order:>4d} {q.off_grid_stamps:>5d} {tot(q.exact):>6d} "
            f"{tot(q.resampled):>6d} {tot(q.interpolated):>5d} {tot(q.excluded):>5d} "
            f"{len(r['edges']):>3d} {len(diff):>4d} {len(wrong):>4d} {r['rbar_v']:>9.3g} "
            f"{r['read_s']:>6.1f} {r['identify_s']:>7.1f}")


HEAD = (f"{'export':<18s} {'rows':>5s} {'dup':>4s} {'ooo':>4s} {'offg':>5s} {'exact':>6s} "
        f"{'resamp':>6s} {'fill':>5s} {'excl':>5s} {'n':>3s} {'Δcln':>4s} {'Δtru':>4s} "
        f"{'R̄_v':>9s} {'read s':>6s} {'ident s':>7s}")
LEGEND = ("rows: data rows in the file; dup: duplicate rows removed; ooo: rows out of order "
          "(sorted); offg: distinct stamps more than 1 s off the grid; exact/resamp/fill/excl: "
          "grid cells (all columns) taken as is / interpolated between neighbouring stamps / "
          "filled across a short gap / left NaN in a long gap; n: air paths found; Δcln, Δtru: "
          "size of the symmetric difference to the clean export's paths and to the true "
          "paths; R̄_v: geometric mean [K/(W m)]; CPU seconds to read and to identify.")


def study(building: str, days: float, seed: int, mess_seed: int, single=(), out=sys.stdout):
    """Generate, export clean and messy, read and identify both; print to ``out``."""
    c0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = generate(building, days=days, seed=seed)
    gen_s = time.process_time() - c0
    true_edges = {tuple(sorted(e[:2])) for e in tb.truth.edges}
    print(f"# {building}, {days:g} days, seed {seed}, mess seed {mess_seed}: "
          f"{tb.network.n_zones} zones ({len(tb.spec.measured_zones)} measured), true paths "
          f"{sorted(true_edges)}; generated in {gen_s:.1f} CPU s", file=out, flush=True)
    variants = [("clean", (), {}), ("messy", MESSES, {}),
                ("messy snap 30 s", MESSES, {"snap": "30s"})]
    variants += [(f"only {m}", (m,), {}) for m in single]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        buf = io.StringIO()
        write_data_csv(tb.data, buf)
        clean = buf.getvalue()
        for name, messes, read_kw in variants:
            text, log = (clean, {}) if not messes else make_messy(clean, mess_seed, messes)
            path = Path(tmp) / f"{name.replace(' ', '_')}.csv"
            path.write_text(text)
            r = _run(path, tb.spec, name, **read_kw)
            r["log"], r["dir"] = log, str(tmp) + os.sep
            rows.append(r)
            if name == "clean":
                print(HEAD, file=out)
            print(_fmt_row(r, rows[0]["edges"], true_edges), file=out, flush=True)
    clean_edges = rows[0]["edges"]
    for r in rows:
        print(f"## {r['name']}: paths {sorted(r['edges'])}", file=out)
        if r["name"] != "clean":
            d = r["edges"] ^ clean_edges
            print(f"   vs clean: +{sorted(r['edges'] - clean_edges)} "
                  f"-{sorted(clean_edges - r['edges'])} ({len(d)} differ)", file=out)
        if r["log"]:
            print(f"   mess: {r['log']}", file=out)
        print(f"   calibration {r['cal'][0]} to {r['cal'][1]}", file=out)
        for line in r["quality"].summary().splitlines():
            print("   | " + line.replace(r["dir"], ""), file=out)
        for note in r["notes"]:
            print(f"   note: {str(note)[:300]}", file=out)
    out.flush()
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=float, default=16.0)
    ap.add_argument("--seed", type=int, default=0, help="testbed seed")
    ap.add_argument("--mess-seed", type=int, default=20, help="seed of the messy copy")
    ap.add_argument("--building", nargs="+", default=["pugh-hall"])
    ap.add_argument("--single", nargs="*", metavar="MESS",
                    help=f"also each mess alone (all of {', '.join(MESSES)}, or those named)")
    ap.add_argument("--out", type=Path, help="also write the output here")
    args = ap.parse_args(argv)

    class Tee(io.TextIOBase):
        def __init__(self, *fs):
            self.fs = fs

        def write(self, s):
            for f in self.fs:
                f.write(s)
            return len(s)

        def flush(self):
            for f in self.fs:
                f.flush()

    fh = open(args.out, "w") if args.out else None
    out = Tee(sys.stdout, fh) if fh else sys.stdout
    c0 = time.process_time()
    print(f"messy export vs clean export (issue 20); load average {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} CPUs, OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}",
          file=out)
    print(LEGEND, file=out)
    for b in args.building:
        single = () if args.single is None else (args.single or MESSES)
        study(b, args.days, args.seed, args.mess_seed, single, out)
    print(f"total {time.process_time() - c0:.1f} CPU s", file=out)
    if fh:
        fh.close()


if __name__ == "__main__":
    main()
