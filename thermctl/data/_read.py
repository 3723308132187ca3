"""Reading measured data: the file, its columns, time stamps and units.

:func:`read_measurements` loads a CSV/parquet file or a DataFrame, matches its columns to
the building spec, parses the time stamps, converts to SI, clips negative flows, sorts
and merges duplicate stamps, then puts every column on the model grid
(:mod:`thermctl.data._grid`) and reports what it did in a
:class:`~thermctl.data.measurements.QualityReport`.
"""

from __future__ import annotations

import csv
import datetime as dt
import logging
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError, DataWarning
from ..spec import RHO_AIR, BuildingSpec
from ._grid import (_EXACT, _EXCLUDED, _FILLED, _RESAMPLED, _make_grid, _regrid, _runs,
                    _timedelta)
from .measurements import Gap, Measurements, QualityReport, _short_list

__all__ = ["read_measurements", "CFM"]

logger = logging.getLogger(__name__)

CFM = 0.3048 ** 3 / 60.0
"""One cubic foot per minute [m³/s]."""

_PREFIXES = ("T", "Ts", "ms", "vs", "Q", "solar")
_OFFSET_RE = re.compile(r"(Z|[+-]\d{2}:?\d{2})$")
_HAS_OFFSET_RE = re.compile(r"(?:Z|[+-]\d{2}:?\d{2})$")


def read_measurements(source, spec: BuildingSpec | str | Path, units: str = "si", step=None,
                      gap_limit="30min", tz=None, name: str | None = None, *,
                      sep: str = ",", time_format: str | None = None,
                      allow_odd_units: bool = False,
                      average_conflicts: bool = False, snap="auto") -> Measurements:
    """Read measured data (CSV, parquet or a DataFrame) onto a regular SI grid.

    Parameters
    ----------
    source : str, Path or pandas.DataFrame
        ``.csv`` (any other suffix is read as CSV) or ``.parquet``/``.pq`` file, or a
        DataFrame with a ``time`` column (or a ``DatetimeIndex``).
    spec : BuildingSpec, str or Path
        The building (a path is read with :func:`thermctl.spec.load_spec`). Gives the zones (``T:`` needed for every measured zone) and boundary nodes
        (``T:`` needed for each).
    units : {"si", "imperial"}, default "si"
        ``si``: °C, kg/s, m³/s, W, W/m². ``imperial``: °F for ``T:``/``Ts:``, CFM for
        ``ms:`` and ``vs:`` (ρ = 1.2 kg/m³); W and W/m² unchanged.
    step : str or Timedelta, optional
        Model grid step (must divide a day). Default: the data's median spacing, snapped
        to a whole number of minutes (seconds below one minute) dividing a day.
    gap_limit : str or Timedelta, default "30min"
        Longest gap (time between the valid samples around it) that is linearly
        interpolated; longer gaps stay NaN and are reported. ``0`` fills nothing.
    tz : str, optional
        Time zone of the result (IANA name, ``"UTC"`` or ``"+01:00"``); also the zone of
        stamps without a UTC offset. Default: the data's own offset (UTC for naive stamps).
    name : str, optional
        Name used in messages for a DataFrame source.
    sep : str, default ","
        CSV field separator (``";"`` for many European spreadsheet exports; with ``";"`` a
        decimal comma is read too).
    time_format : str, optional
        How the ``time`` column is written. Default ISO 8601. ``"excel"``: spreadsheet
        serial days (``40564.25`` is 2011-01-21 06:00, local time); ``"unix"``: seconds since
        1970-01-01 UTC; anything with a ``%`` is a :func:`~datetime.datetime.strptime`
        format such as ``"%d.%m.%Y %H:%M"``.
    allow_odd_units : bool, default False
        A zone temperature column whose level does not fit ``units`` (e.g. a median of
        72 read as °C) is an error naming the column; with this flag it is read as given,
        with a :class:`~thermctl.errors.DataWarning`.
    average_conflicts : bool, default False
        Repeated time stamps whose rows disagree (a clock set back, a daylight-saving
        hour exported without offsets) are an error naming the time range; with this
        flag they are averaged, with a :class:`~thermctl.errors.DataWarning`.
    snap : "auto", str, Timedelta or None
        A stamp this close to a grid point is that point's sample, taken as is (a BAS
        that polls every 5 min and stamps each row up to 20 s late or early); less than
        half the step. ``"auto"`` (default): a tenth of the step (30 s at 5 min). None:
        1 s, so that a stamp further off the grid is used only through linear
        interpolation in time — which blends neighbouring rows, and so makes up supply
        flows between two box positions that never happened: on a messy export of a
        16-day testbed log (stamps jittered by up to 20 s), interpolation changed 1–2 air
        paths of the identified structure, snapping none (benchmarks/results/messy.txt).

    Returns
    -------
    Measurements

    Raises
    ------
    DataError
        One line naming the file and the column, zone or line at fault, and the option
        that overrides the check where there is one.

    Examples
    --------
    >>> spec = load_spec("building.yaml")                      # doctest: +SKIP
    >>> meas = read_measurements("data.csv", spec, units="imperial")  # doctest: +SKIP
    >>> cal, val = meas.split()                                 # doctest: +SKIP
    >>> print(meas.quality.summary())                           # doctest: +SKIP
    """
    if units not in ("si", "imperial"):
        raise DataError(f"units must be 'si' or 'imperial', found {units!r}")
    if isinstance(spec, (str, Path)):
        from ..spec import load_spec
        spec = load_spec(spec)
    elif not isinstance(spec, BuildingSpec):
        raise DataError(f"read_measurements: spec must be a BuildingSpec or the path of a "
                        f"building YAML, found {type(spec).__name__}")
    df, src, row_label = _load_table(source, name, sep)
    cols = _classify(df.columns, spec, src)
    t_ns, tzinfo, notes = _parse_time(df["time"], src, tz, row_label, time_format)
    gap_ns = _timedelta(gap_limit, "gap_limit").value
    if gap_ns < 0:
        raise DataError(f"gap_limit must be >= 0, found {gap_limit!r}")

    # numbers, unit conversion, flow clipping (per file column, before any regridding)
    values, missing, conversions, clipped = {}, {}, [], {}
    for fcol, scol in cols["used"].items():
        v = _numeric(df[scol], src, scol, row_label)
        missing[scol] = int(np.isnan(v).sum())
        v, conv = _to_si(v, scol, units)
        if conv:
            conversions.append(conv)
        if fcol.startswith("ms:"):
            neg = v < 0
            if neg.any():
                clipped[scol] = int(neg.sum())
                v = np.where(neg, 0.0, v)
        values[fcol] = v
    if clipped:
        warnings.warn(f"{src}: negative flows set to 0: {clipped}", DataWarning, stacklevel=2)

    # order, duplicates
    raw = pd.DataFrame(values, index=pd.Index(t_ns, name="time"))
    out_of_order = int((np.diff(t_ns) < 0).sum())
    raw = raw.sort_index(kind="stable")
    dup = raw.index.duplicated(keep=False)
    n_dups, conflicts = 0, 0
    if dup.any():
        grp = raw[dup].groupby(level=0)
        n_dups = int(dup.sum() - grp.ngroups)
        bad = (grp.nunique(dropna=False) > 1).any(axis=1)
        conflicts = int(bad.sum())
        if conflicts:
            _conflicting_stamps(bad[bad].index.to_numpy(), t_ns, tzinfo, src, row_label,
                                average_conflicts)
        raw = raw.groupby(level=0, sort=True).mean()
        logger.info("%s: %d duplicate rows removed (%d conflicting)", src, n_dups, conflicts)
    t = raw.index.to_numpy(dtype=np.int64)
    if len(t) < 2:
        raise DataError(f"{src}: need at least 2 distinct time stamps, found {len(t)}")

    # grid
    grid = _make_grid(t, step, tzinfo, src, notes, snap)
    index = grid.index
    frame, counts, gaps = {}, {c: {} for c in range(4)}, []
    for fcol, v in raw.items():
        scol = cols["used"][fcol]
        vals, code = _regrid(t, v.to_numpy(), grid.times, grid.bridge, gap_ns, grid.snap)
        frame[fcol] = vals
        for c in range(4):
            counts[c][scol] = int((code == c).sum())
        gaps += [Gap(scol, index[a], index[b - 1], b - a) for a, b in _runs(code == _EXCLUDED)]
    frame = pd.DataFrame(frame, index=index)

    notes += _sanity(frame, spec, units, src, allow_odd_units)
    quality = QualityReport(
        source=src, units=units, rows_read=len(df), columns_used=dict(cols["used"]),
        ignored_columns=cols["ignored"], unmeasured_zone_columns=cols["unmeasured"],
        zones_without_supply=cols["no_supply"], conversions=conversions,
        time_zone=str(tzinfo), step=grid.step_ns / 1e9, step_inferred=step is None,
        data_step=grid.data_step / 1e9, start=index[0], end=index[-1], n_samples=len(index),
        rows_out_of_order=out_of_order, duplicates_removed=n_dups,
        duplicate_conflicts=conflicts, off_grid_stamps=grid.off_grid,
        snapped_stamps=grid.snapped, snap=grid.snap / 1e9, missing_cells=missing,
        exact=counts[_EXACT], resampled=counts[_RESAMPLED], interpolated=counts[_FILLED],
        excluded=counts[_EXCLUDED], long_gaps=gaps, clipped_flows=clipped, notes=notes)
    if gaps:
        warnings.warn(f"{src}: {sum(g.n for g in gaps)} samples excluded in {len(gaps)} long "
                      f"gap(s) over {len({g.column for g in gaps})} column(s), e.g. "
                      f"{gaps[0].column} {gaps[0].start} to {gaps[0].end}", DataWarning,
                      stacklevel=2)
    for note in notes:
        logger.info("%s: %s", src, note)
    return Measurements(frame, pd.Timedelta(grid.step_ns), spec, units, src, quality)


# ---------------------------------------------------------------------------- internals
def _load_table(source, name, sep=","):
    """Read the table; returns (DataFrame with a 'time' column, source name, row labeller)."""
    if isinstance(source, pd.DataFrame):
        src = name or "<DataFrame>"
        df = source.copy()
        df.columns = [str(c).strip() for c in df.columns]
        if "time" not in df.columns and isinstance(df.index, pd.DatetimeIndex):
            df = df.rename_axis("time").reset_index()
        dupes = sorted({c for c in df.columns if list(df.columns).count(c) > 1})
        _check_table(df, src, dupes)
        df = df.reset_index(drop=True)
        return df, src, (lambda i: f"row {i}")
    path = Path(source)
    src = str(path)
    if not path.exists():
        raise DataError(f"{src}: data file not found")
    if not path.is_file():
        raise DataError(f"{src}: not a file")
    if path.stat().st_size == 0:
        raise DataError(f"{src}: data file is empty")
    if path.suffix.lower() not in (".parquet", ".pq"):
        _not_a_spec(path)
    if not isinstance(sep, str) or len(sep) != 1:
        raise DataError(f"sep must be one character such as ',' or ';', found {sep!r}")
    parquet = path.suffix.lower() in (".parquet", ".pq")
    try:
        if parquet:
            df = pd.read_parquet(path)
            if "time" not in df.columns and df.index.name == "time":
                df = df.reset_index()
            df.columns = [str(c).strip() for c in df.columns]
            dupes = sorted({c for c in df.columns if list(df.columns).count(c) > 1})
        else:
            with open(path, newline="", encoding="utf-8-sig") as fh:
                header = next(csv.reader(fh, delimiter=sep), [])
            header = [h.strip() for h in header]
            dupes = sorted({h for h in header if header.count(h) > 1})
            if not any(h for h in header):
                raise DataError(f"{src}: data file is empty (no header line)")
            # a ';'-separated export (European spreadsheets) usually has decimal commas;
            # cells with a decimal point stay strings and _numeric still reads them
            df = pd.read_csv(path, encoding="utf-8-sig", skipinitialspace=True, sep=sep,
                             decimal="," if sep == ";" else ".")
            df.columns = [str(c).strip() for c in df.columns]
    except DataError:
        raise
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, OSError,
            ValueError) as exc:
        kind = "parquet" if parquet else "CSV"
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise DataError(f"{src}: not a readable {kind} file: {msg}") from None
    _check_table(df, src, dupes)
    # CSV line of data row i: line 1 is the header
    return df, src, ((lambda i: f"row {i}") if parquet else (lambda i: f"line {i + 2}"))


_SPEC_SUFFIXES = (".yaml", ".yml", ".json")
_YAML_KEY_RE = re.compile(r"^(---|\{|\[|[A-Za-z_][\w-]*:(\s|$))")


def _not_a_spec(path: Path) -> None:
    """A building spec (or any YAML/JSON) passed as data: say so, rather than fail on 'time'."""
    first = ""
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as fh:
            for line in fh:
                if line.strip() and not line.lstrip().startswith("#"):
                    first = line.strip()
                    break
    except OSError:
        return
    if path.suffix.lower() in _SPEC_SUFFIXES or _YAML_KEY_RE.match(first):
        raise DataError(f"{path}: looks like a building spec or other YAML/JSON, not "
                        "measurements (CSV or parquet); did you swap DATA and --building?")


def _check_table(df, src, dupes):
    if dupes:
        raise DataError(f"{src}: column(s) {dupes} appear more than once")
    if "time" not in df.columns:
        hint = ""
        if len(df.columns) == 1 and any(s in str(df.columns[0]) for s in ";\t"):
            which = ";" if ";" in str(df.columns[0]) else "\\t"
            hint = (f" (the file looks {which!r}-separated; pass sep={which!r}, "
                    f"on the command line thermctl --sep '{which}' ...)")
        raise DataError(f"{src}: no 'time' column{hint}; found columns "
                        f"{_short_list([str(c) for c in df.columns])}")
    if len(df) == 0:
        raise DataError(f"{src}: data file has a header but no data rows")


def _classify(columns, spec: BuildingSpec, src):
    """Map file columns to frame columns; check them against the spec."""
    zones, bnd = spec.zone_names, list(spec.boundary)
    measured = set(spec.measured_zones)
    t_cols, zone_cols, solar, ignored, unmeasured = {}, {}, [], [], []
    unknown_t, unknown_z = [], []
    for col in columns:
        if col == "time":
            continue
        prefix, sep, node = col.partition(":")
        if not sep or prefix not in _PREFIXES or not node:
            ignored.append(col)
        elif prefix == "T":
            if node in measured or node in bnd:
                t_cols[node] = col
            elif node in zones:
                unmeasured.append(col)
            else:
                unknown_t.append(node)
        elif prefix == "solar":
            solar.append(col)
        elif node in zones:
            zone_cols[(prefix, node)] = col
        else:
            unknown_z.append(col)
    need = [n for n in list(spec.measured_zones) + bnd if n not in t_cols]
    if unknown_t or need:
        parts = []
        if unknown_t:
            parts.append(f"T: column(s) for node(s) not in the spec: {unknown_t}")
        if need:
            parts.append(f"measured zone(s)/boundary node(s) with no T: column: {need}")
        raise DataError(f"{src}: columns do not match {spec.source}: " + "; ".join(parts)
                        + f" (spec zones {zones}, boundary {bnd})")
    if unknown_z:
        raise DataError(f"{src}: column(s) {unknown_z} name no zone of {spec.source} "
                        f"(zones {zones}; boundary nodes take only T: columns)")
    used, no_supply = {}, []
    for node in list(spec.measured_zones) + bnd:
        used[f"T:{node}"] = t_cols[node]
    for z in zones:
        ms, vs, ts = (zone_cols.get((p, z)) for p in ("ms", "vs", "Ts"))
        if ms and vs:
            raise DataError(f"{src}: zone {z!r} has both {ms} and {vs}; give one supply flow")
        flow = ms or vs
        if flow and not ts:
            raise DataError(f"{src}: zone {z!r} has supply flow {flow} but no Ts:{z} column")
        if ts and not flow:
            raise DataError(f"{src}: zone {z!r} has {ts} but no supply flow (ms:{z} or vs:{z})")
        if flow:
            used[f"Ts:{z}"] = ts
            used[f"ms:{z}"] = flow
        else:
            no_supply.append(z)
    for z in zones:
        if ("Q", z) in zone_cols:
            used[f"Q:{z}"] = zone_cols[("Q", z)]
    for col in solar:
        used[col] = col
    for f in spec.flows:
        if f.column is None:
            continue
        if f.column not in columns:
            raise DataError(f"{src}: column {f.column!r} missing: the spec's directed flow "
                            f"{f.src} → {f.dst} takes its rate [kg/s] from it")
        used[f.column] = f.column
        if f.column in ignored:
            ignored.remove(f.column)
    if unmeasured:
        warnings.warn(f"{src}: {unmeasured} belong to zone(s) the spec marks 'measured: false'; "
                      "ignored (set measured: true to use them)", DataWarning, stacklevel=3)
    return {"used": used, "ignored": ignored, "unmeasured": unmeasured, "no_supply": no_supply}


def _parse_time(col: pd.Series, src, tz, row_label, time_format=None):
    """Time stamps → (int64 ns UTC array, tzinfo of the result, notes)."""
    notes = []
    target = _tzinfo(tz) if tz is not None else None
    empty = col.isna()
    if empty.any():
        raise DataError(f"{src}: column 'time' is empty at {row_label(int(np.argmax(empty)))}")
    fmt = None if time_format is None else str(time_format).strip()
    if fmt and fmt.lower() not in ("iso", "iso8601"):
        col = _parse_time_format(col, fmt, src, row_label)
    if pd.api.types.is_datetime64_any_dtype(col):
        idx = pd.DatetimeIndex(col)
        native = idx.tz
        if native is None:
            idx, native = _localize(idx, target, src, notes)
        utc = idx.tz_convert("UTC")
        out_tz = target or native
    else:
        s = col.astype(str).str.strip()
        # naive stamps parse as UTC wall clock here; they are localized below
        parsed = pd.to_datetime(s, format="ISO8601", utc=True, errors="coerce")
        bad = parsed.isna().to_numpy()
        if bad.any():
            i = int(np.argmax(bad))
            raise DataError(f"{src}: column 'time': cannot parse {s.iloc[i]!r} at {row_label(i)} "
                            f"({int(bad.sum())} unparsable); expected ISO 8601 such as "
                            f"2011-01-21T00:05:00-05:00{_format_hint(s.iloc[i])}")
        has_off = s.str.contains(_HAS_OFFSET_RE)
        if has_off.any() and not has_off.all():
            i = int(np.argmax(~has_off.to_numpy() if has_off.iloc[0] else has_off.to_numpy()))
            raise DataError(f"{src}: column 'time' mixes stamps with and without a UTC offset "
                            f"(first different: {s.iloc[i]!r} at {row_label(i)})")
        idx = pd.DatetimeIndex(parsed)
        if has_off.all():
            offsets = sorted({_offset_minutes(m) for m in s.str.extract(_OFFSET_RE)[0].unique()})
            native = _fixed(offsets[0])
            if len(offsets) > 1 and target is None:
                notes.append(f"time stamps carry UTC offsets {offsets} min; days are taken in "
                             f"standard time {native}")
            utc = idx
            out_tz = target or native
        else:
            idx, out_tz = _localize(idx.tz_localize(None), target, src, notes)
            utc = idx.tz_convert("UTC")
    t_ns = utc.as_unit("ns").asi8.copy()
    return t_ns, out_tz, notes


_EXCEL_EPOCH = pd.Timestamp("1899-12-30")   # serial day 0 of spreadsheets (1900 date system)


def _parse_time_format(col: pd.Series, fmt: str, src, row_label) -> pd.Series:
    """Stamps written as ``fmt`` ("excel", "unix" or a strptime format) → datetime Series.

    Excel serial days and strptime stamps without ``%z`` are local wall-clock time (naive);
    unix seconds are UTC instants.
    """
    key = fmt.lower()
    if key in ("excel", "unix"):
        num = pd.to_numeric(col, errors="coerce")
        bad = num.isna().to_numpy()
        if not bad.any():
            if key == "excel":
                # serial days carry float round-off of ~1e-6 s; stamps are whole seconds
                out = (_EXCEL_EPOCH + pd.to_timedelta(num.to_numpy(), unit="D")).round("s")
            else:
                out = pd.to_datetime(num.to_numpy(), unit="s", utc=True).round("ms")
            return pd.Series(out, index=col.index)
        what = ("spreadsheet serial days such as 40564.25" if key == "excel"
                else "seconds since 1970-01-01 UTC such as 1295568300")
    elif "%" in fmt:
        parsed = pd.to_datetime(col.astype(str).str.strip(), format=fmt, errors="coerce")
        bad = parsed.isna().to_numpy()
        if not bad.any():
            return parsed
        what = f"time_format {fmt!r}"
    else:
        raise DataError(f"time_format must be iso, excel, unix or a strptime format with %, "
                        f"such as '%d.%m.%Y %H:%M'; found {fmt!r}")
    i = int(np.argmax(bad))
    raise DataError(f"{src}: column 'time': cannot parse {col.iloc[i]!r} at {row_label(i)} "
                    f"({int(bad.sum())} unparsable); expected {what}")


def _format_hint(text: str) -> str:
    """Which --time-format an unparsable ISO stamp probably needs ("" if no guess)."""
    text = str(text).strip()
    try:
        x = float(text)
    except ValueError:
        x = None
    if x is not None:
        if 20_000 < x < 80_000:         # 1954..2119 as spreadsheet serial days
            return "; it looks like a spreadsheet serial date: pass time_format='excel' " \
                   "(thermctl --time-format excel ...)"
        if 1e8 < x < 4e9:
            return "; it looks like unix seconds: pass time_format='unix' " \
                   "(thermctl --time-format unix ...)"
        return ""
    if re.fullmatch(r"\d{1,2}[./]\d{1,2}[./]\d{4}.*", text):
        return ("; for day-first or month-first dates pass a strptime format, e.g. "
                "thermctl --time-format '%d.%m.%Y %H:%M' ...")
    return ""


def _localize(idx, target, src, notes):
    if target is None:
        notes.append("time stamps have no UTC offset; taken as UTC")
        return idx.tz_localize("UTC"), dt.timezone.utc
    try:
        return idx.tz_localize(target, ambiguous="infer", nonexistent="raise"), target
    except Exception as exc:        # pytz/zoneinfo raise several types for DST problems
        why = str(exc).splitlines()[0].split(". Try")[0] if str(exc) else type(exc).__name__
        raise DataError(f"{src}: column 'time': local stamps do not fit time zone {target} "
                        f"({why}); export stamps with a UTC offset") from None


def _offset_minutes(text) -> int:
    if text == "Z":
        return 0
    sign = -1 if text[0] == "-" else 1
    digits = text[1:].replace(":", "")
    return sign * (int(digits[:2]) * 60 + int(digits[2:]))


def _fixed(minutes: int):
    """Fixed-offset tzinfo (``UTC`` for 0, else ``UTC±hh:mm``)."""
    return dt.timezone(dt.timedelta(minutes=minutes)) if minutes else dt.timezone.utc


def _tzinfo(tz):
    if isinstance(tz, dt.tzinfo):
        return tz
    text = str(tz).strip()
    m = re.fullmatch(r"(?:UTC)?([+-]\d{2}:?\d{2})", text)
    if m:
        return _fixed(_offset_minutes(m.group(1)))
    try:
        return pd.Timestamp("2000-01-01", tz=text).tzinfo
    except Exception:               # the tz libraries raise several exception types
        raise DataError(f"tz: unknown time zone {tz!r} (use an IANA name such as "
                        "'America/New_York', 'UTC' or an offset '+01:00')") from None


def _numeric(col: pd.Series, src, name, row_label) -> np.ndarray:
    num = pd.to_numeric(col, errors="coerce")
    bad = (col.notna() & num.isna()).to_numpy()
    inf = np.isinf(num.to_numpy(dtype=float))
    if bad.any() or inf.any():
        i = int(np.argmax(bad | inf))
        raise DataError(f"{src}: column {name}: non-numeric value {col.iloc[i]!r} at "
                        f"{row_label(i)} ({int((bad | inf).sum())} such cells)")
    v = num.to_numpy(dtype=float)
    if np.isnan(v).all():
        raise DataError(f"{src}: column {name} has no values (all empty/NaN)")
    return v


def _to_si(v, col, units):
    prefix = col.partition(":")[0]
    if units == "imperial":
        if prefix in ("T", "Ts"):
            return (v - 32.0) / 1.8, f"{col} °F → °C"
        if prefix in ("ms", "vs"):
            return v * CFM * RHO_AIR, f"{col} CFM → kg/s (ρ = {RHO_AIR} kg/m³)"
    elif prefix == "vs":
        return v * RHO_AIR, f"{col} m³/s → kg/s (ρ = {RHO_AIR} kg/m³)"
    return v, None
def _conflicting_stamps(stamps, t_file, tzinfo, src, row_label, average: bool) -> None:
    """Repeated stamps whose rows disagree: an error, or a warning with ``average``.

    A clock set back (or a daylight-saving hour exported without UTC offsets) writes the
    same stamps twice with different readings; averaging them blends two different hours
    into one, so the default refuses and says where.

    Parameters
    ----------
    stamps : ndarray of int64
        The conflicting stamps [ns UTC], sorted.
    t_file : ndarray of int64
        All stamps in file order [ns UTC] (to find the backward jump).
    """
    def local(ns):
        return pd.Timestamp(int(ns), tz="UTC").tz_convert(tzinfo).strftime("%Y-%m-%d %H:%M")

    n = len(stamps)
    where = f"{n} time stamp(s) from {local(stamps[0])} to {local(stamps[-1])} appear more " \
            "than once with different values"
    back = np.diff(t_file)
    if (back < 0).any():
        i = int(np.argmin(back))          # the largest backward jump in file order
        where += (f" (the clock jumps back from {local(t_file[i])} to {local(t_file[i + 1])} "
                  f"at {row_label(i + 1)})")
    if not average:
        raise DataError(f"{src}: {where}; fix the export's clock, or pass "
                        "average_conflicts=True (thermctl --average-conflicts ...) to "
                        "average the conflicting rows")
    warnings.warn(f"{src}: {where}; averaged (average_conflicts)", DataWarning, stacklevel=3)


# Plausible medians of zone temperatures: an indoor zone is not at 40 °C for weeks (72
# read as °C is a room in °F), nor below 41 °F (5 °C; 20 read as °F is a room in °C).
# Supply, outdoor and ground columns are left alone: either unit can be plausible there.
_MAX_MEDIAN_C = 40.0
_MIN_MEDIAN_F = 41.0


def _sanity(frame, spec, units, src="<data>", allow: bool = False) -> list[str]:
    """Zone temperature columns whose level looks like the other unit system.

    Checked per column, so one °F column among °C columns is caught (a median over all
    zones would hide it). An error naming the columns, or with ``allow`` a warning.
    """
    odd, checked = [], 0
    for z in spec.measured_zones:
        col = f"T:{z}"
        v = frame[col].to_numpy() if col in frame else np.array([])
        if not np.isfinite(v).any():
            continue
        checked += 1
        med = float(np.nanmedian(v))
        if units == "si" and med > _MAX_MEDIAN_C:
            odd.append((col, f"{med:.1f} °C"))
        elif units == "imperial" and med * 1.8 + 32.0 < _MIN_MEDIAN_F:
            odd.append((col, f"{med * 1.8 + 32.0:.1f} °F"))
    if not odd:
        return []
    cols = ", ".join(f"{c} (median {m})" for c, m in odd)
    other, opt = ("°F", "units='imperial' (--units imperial)") if units == "si" else \
        ("°C", "units='si' (--units si)")
    if len(odd) == checked:     # the whole file is in the other unit
        msg = f"{cols} look(s) like {other}; read the file with {opt}"
    else:                       # a column exported in another unit than the rest
        msg = (f"{cols} look(s) like {other} while the other temperature columns fit "
               f"{'°C' if units == 'si' else '°F'}; convert that column")
    if not allow:
        raise DataError(f"{src}: {msg}; or pass allow_odd_units=True "
                        "(thermctl --allow-odd-units ...) to read it as given")
    warnings.warn(f"{src}: {msg} (read as given: allow_odd_units)", DataWarning, stacklevel=3)
    return [msg]
