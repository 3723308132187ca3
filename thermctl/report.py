"""The HTML report: one self-contained page (figures embedded as PNG data URIs).

`thermctl identify` and `thermctl validate` write into an output directory:
``identification.json``, ``validation.json``, ``model.json`` and PNG figures under
``figures/`` listed in ``figures.json`` (name, section, caption). This module only
assembles what is there, so a report can be rebuilt at any time.

The page opens with what a reader needs first: problems with the directory (files from
different runs), the verdict of the validation and the next step, what the data pin down
and which parameters sit on a bound. The sections follow in the order of
:data:`SECTIONS`.
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .errors import DataError  # noqa: E402
from .io import atomic_write_text  # noqa: E402

__all__ = ["save_figure", "build_report"]

SECTIONS = ["Data quality", "Structure", "Parameters", "Validation", "Reduction", "Model"]

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1100px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}
h1{border-bottom:2px solid #345;padding-bottom:.2em}h2{color:#345;margin-top:1.6em}
table{border-collapse:collapse;margin:.6em 0;font-size:.92em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right;white-space:nowrap}
.wrap{white-space:normal}th{background:#eef2f6}
td:first-child,th:first-child,.text{text-align:left}
tr.bound td{background:#fff3f0}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}
figcaption{font-size:.9em;color:#555}
pre{background:#f6f8fa;padding:.6em;font-size:.85em;white-space:pre-wrap;overflow-wrap:anywhere}
.lines{overflow-wrap:anywhere}
.note{background:#fff8e1;border-left:4px solid #f0b400;padding:.4em .8em}
.problems{background:#fdecea;border-left:4px solid #c62828;padding:.4em .8em;margin:1em 0}
.summary{background:#f4f7fa;border:1px solid #cfd8e3;padding:.2em 1em .6em;margin:1em 0}
.summary h2{margin-top:.4em}.summary li{margin:.2em 0}
.verdict{font-size:1.05em}.verdict strong{color:#1b5e20}.verdict.against strong{color:#b71c1c}
.muted{color:#777;font-size:.85em}
"""

# what each grey-box parameter group is (units come from thermctl.estimate.likelihood.params.GROUP_UNITS)
_MEANING = {
    "rbar_v": "air-path resistance per metre of path",
    "tau0": "τ0 = R̄_v·C_v",
    "c_v": "air-path capacitance C_v = τ0/R̄_v (derived)",
    "sigma_v": "measurement noise (std)",
    "sigma_q": "process noise on each zone's heat balance",
    "sigma_phi": "random walk of the unmeasured gains",
    "sigma_e": "coloured measurement noise (std)",
    "tau_e": "time constant of the coloured measurement noise",
    "sigma_b": "slow shared disturbance (std)",
    "tau_b": "time constant of the slow shared disturbance",
    "sigma_g": "fast (first-order) gain per zone (std)",
    "tau_g": "time constant of the fast gains",
    "loading": "heat of a common gain in a zone (zone, gain)",
    "tau_c": "time constant of the common gains",
    "aperture": "solar aperture (zone, solar column)",
    "gain": "time-of-day gain level (zone, basis)",
}
_SUMMARISED = ("aperture", "gain")  # many per zone, mostly zero: only the nonzero ones are listed
_ZERO = 1e-3  # [m²] or [W]: an aperture or gain level below this counts as zero


def save_figure(fig, outdir, name: str, section: str, caption: str) -> Path:
    """Save a matplotlib figure as ``outdir/figures/name.png`` and list it in ``figures.json``."""
    outdir = Path(outdir)
    figdir = outdir / "figures"
    figdir.mkdir(parents=True, exist_ok=True)
    path = figdir / f"{name}.png"
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    manifest_path = outdir / "figures.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else []
    manifest = [m for m in manifest if m["name"] != name]
    manifest.append({"name": name, "section": section, "caption": caption})
    atomic_write_text(manifest_path, json.dumps(manifest, indent=2))
    return path


def _esc(v) -> str:
    return html.escape(str(v))


def _table(rows: list[dict], floatfmt: str = "{:.4g}", percent: bool = False,
           classes: list[str] | None = None) -> str:
    """An HTML table; ``percent`` shows float cells (fractions) as percentages.

    Columns of numbers are right-aligned, columns of words left-aligned.
    """
    if not rows:
        return ""
    cols = list(rows[0])

    def cell(v):
        if isinstance(v, float):
            return f"{100 * v:.1f} %" if percent else floatfmt.format(v)
        return str(v)

    text = {c for c in cols if any(not _numeric(cell(r.get(c, ""))) for r in rows if r.get(c, "") != "")}
    # short cells never break ("[0.000262, 0.000338]"); columns of sentences wrap
    wrap = {c for c in cols if any(len(cell(r.get(c, ""))) > 32 for r in rows)}
    align = {c: " class='" + " ".join(k for k, on in (("text", c in text), ("wrap", c in wrap)) if on)
             + "'" if c in text or c in wrap else "" for c in cols}
    head = "".join(f"<th{align[c]}>{_esc(c)}</th>" for c in cols)
    body = []
    for i, r in enumerate(rows):
        cells = "".join(f"<td{align[c]}>{_esc(cell(r.get(c, '')))}</td>" for c in cols)
        cls = f" class='{classes[i]}'" if classes and classes[i] else ""
        body.append(f"<tr{cls}>{cells}</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def _numeric(v: str) -> bool:
    try:
        float(v.replace("%", "").replace(" ", "").replace("−", "-"))
    except ValueError:
        return False
    return True


def _text(content: str) -> str:
    """Text that wraps: one line per input line, never a clipped block."""
    lines = [_esc(s) for s in str(content).splitlines()]
    return f"<p class='lines'>{'<br>'.join(lines)}</p>"


def _figure(path: Path, caption: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (f'<figure><img alt="{_esc(caption)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{_esc(caption)}</figcaption></figure>")


def _fmt(v) -> str:
    """A number, or per-path values (a model with one R̄_v, C_v per air path) in order."""
    if isinstance(v, (list, tuple)):
        return ", ".join(f"{x:.3g}" for x in v)
    return f"{v:.3g}"


# ---------------------------------------------------------------------------- consistency
def _consistency(outdir: Path, ident: dict | None, valid: dict | None) -> tuple[list[str], bool]:
    """Problems with the directory, and whether validation.json belongs to identification.json.

    Uses :func:`thermctl.outputs.check_consistent` when it exists; compares the run ids
    itself either way (``identification.json["run_id"]`` against
    ``validation.json["identification_run_id"]``).
    """
    problems = []
    try:
        from .outputs import check_consistent
    except ImportError:
        check_consistent = None
    if check_consistent is not None:
        try:
            problems += [str(p) for p in check_consistent(outdir)]
        except Exception as exc:  # the report still shows what is there
            problems.append(f"could not check that the files belong together: {exc}")
    rid = (ident or {}).get("run_id")
    vid = (valid or {}).get("identification_run_id")
    matches = not (rid and vid and rid != vid)
    if not matches and check_consistent is None:
        problems.append(f"validation.json validates identification run {vid}, but identification.json "
                        f"is run {rid}: re-run `thermctl validate` on this model.json.")
    if not matches:
        problems.append("The validation section and verdict are left out: they describe another model.")
    return problems, matches


# ---------------------------------------------------------------------------- verdict
def _verdict(valid: dict) -> dict | None:
    """``{"recommendation", "text", "gains"}`` from validation.json, read defensively.

    A structured ``verdict`` (dict with ``text`` and ``recommendation``) is used as is; a
    string verdict is shown as text; without one the verdict is recomputed from the RMSEs
    by :func:`thermctl.validate.verdict`.
    """
    v = valid.get("verdict")
    if isinstance(v, dict) and (v.get("text") or v.get("recommendation")):
        return {"recommendation": v.get("recommendation"), "text": str(v.get("text") or ""),
                "gains": v.get("gains") or {}}
    if isinstance(v, str) and v.strip():
        return {"recommendation": None, "text": v, "gains": {}}
    ol = valid.get("rmse_mean") or {}
    ks = valid.get("kstep_rmse") or {}
    try:
        from .validate import verdict
        ol_gain = (1.0 - ol["identified"] / ol["conduction-only"]
                   if ol.get("identified") is not None and ol.get("conduction-only") else None)
        kg = {}
        if "identified" in ks and "conduction-only" in ks:
            for h, a, b in zip(ks["identified"]["horizons_s"], ks["identified"]["rmse_mean"],
                               ks["conduction-only"]["rmse_mean"]):
                if b:
                    kg[h / 3600.0] = 1.0 - a / b
        if ol_gain is None and not kg:
            return None
        vd = verdict(ol_gain, kg, open_loop_hours=_window_hours(valid.get("window")))
    except (KeyError, TypeError, ValueError, ZeroDivisionError, ImportError):
        return None
    return {"recommendation": vd.recommendation, "text": vd.text, "gains": vd.gains}


def _window_hours(window) -> float:
    try:
        import pandas as pd
        h = (pd.Timestamp(window[1]) - pd.Timestamp(window[0])).total_seconds() / 3600.0
        return float(round(h)) if h > 1 else h
    except (TypeError, ValueError, IndexError):
        return 48.0


_HEADLINE = {"identified": "Use the identified model.",
             "conduction-only": "Prefer the conduction-only model.",
             "mixed": "Mixed evidence: prefer the conduction-only model."}


def _next_step(rec: str | None, outdir: Path, validated: bool, weak: list[str]) -> str:
    d = _esc(outdir)
    if not validated:
        return (f"Validate on held-back data: <code>thermctl validate {d}/model.json DATA</code>, "
                f"then <code>thermctl report {d}</code>.")
    if rec == "identified":
        step = (f"Export it for the controller: <code>thermctl export {d}/model.json --statespace "
                "ss.npz --op ms=… --op Ts=… --op T=…</code>.")
        if weak:
            step += (" Parameters the data do not pin down (" + ", ".join(_esc(w) for w in weak)
                     + ") are set by their bounds: check that the controller is robust to them.")
        return step
    if rec in ("conduction-only", "mixed"):
        return ("Control with the conduction-only model (the building spec's walls, e.g. "
                "<code>thermctl reduce building.yaml …</code>), or identify again with more "
                "held-back days or a larger <code>--margin</code> before trusting the air paths.")
    return "Read the validation section below and decide which model to control with."


# ---------------------------------------------------------------------------- parameters
def _bounds(at_bounds) -> dict:
    """``"tau0 at its upper bound 2.02642 [s/m]"`` → ``{"tau0": "upper bound 2.03 s/m"}``."""
    out = {}
    for s in at_bounds or []:
        name, _, rest = str(s).partition(" at its ")
        words = rest.replace("[", "").replace("]", "").split()
        if len(words) >= 3 and words[1] == "bound":
            try:
                words[2] = _fmt(float(words[2]))
            except ValueError:
                pass
        out[name] = " ".join(words) if words else "on a bound"
    return out


def _parameter_rows(ident: dict) -> tuple[list[dict], list[str], list[str]]:
    """Rows of the parameter table (units, intervals, bound flags), row classes, flagged names."""
    from .estimate.likelihood.params import GROUP_UNITS

    g = ident.get("greybox") or {}
    params = g.get("params") or {}
    bounds = _bounds(g.get("active_bounds"))
    ivs = g.get("intervals") or {}
    level = next((iv.get("level") for iv in ivs.values() if iv.get("level")), None)
    icol = f"{100 * level:.0f} % interval" if level else "interval"
    rows, classes, flagged = [], [], []

    def add(name, group, value, unit, bound="", interval=""):
        rows.append({"parameter": name, "meaning": _MEANING.get(group, ""), "value": _fmt(value),
                     "unit": unit, icol: interval, "on a bound": bound or "no"})
        classes.append("bound" if bound else "")
        if bound:
            flagged.append(name)

    summarised = {grp: [] for grp in _SUMMARISED}
    for name, v in params.items():
        group = name.split("[")[0]
        if group in summarised:
            summarised[group].append((name, v))
            continue
        iv = ivs.get(name)
        interval = f"[{_fmt(iv['lower'])}, {_fmt(iv['upper'])}]" if iv else ""
        add(name, group, v, GROUP_UNITS.get(group, ""), bounds.get(name, ""), interval)
        if group == "tau0" and (ident.get("model") or {}).get("c_v") is not None:
            add("c_v", "c_v", ident["model"]["c_v"], "J/K",
                f"set by τ0's {bounds['tau0']}" if "tau0" in bounds else "")
    for group, items in summarised.items():
        nonzero = [(n, v) for n, v in items if abs(v) >= _ZERO]
        for n, v in nonzero:
            add(n, group, v, GROUP_UNITS.get(group, ""), bounds.get(n, ""))
        zero = len(items) - len(nonzero)
        if zero:
            rows.append({"parameter": f"{group}[…]: {zero} {'others' if nonzero else 'all'}",
                         "meaning": _MEANING[group], "value": "0",
                         "unit": GROUP_UNITS.get(group, ""), icol: "", "on a bound": ""})
            classes.append("")
    return rows, classes, flagged


def _parameter_table(ident: dict) -> str:
    g = ident.get("greybox") or {}
    rows, classes, _ = _parameter_rows(ident)
    head = (f"<h3>Grey-box estimate ({_esc(g.get('criterion', ''))}, {_esc(g.get('n_obs', '?'))} "
            f"observations, rows: {_esc(g.get('rows', ''))})</h3>")
    foot = ("<p class='muted'>On a bound: the criterion, not the building, chose that value. "
            "Apertures and gain levels are listed only where nonzero.</p>")
    return head + _table(rows, classes=classes) + foot


_FLAGS_PER_GROUP = 5
"""Parameters of one group on the same bound listed by name in the summary; above, counted
(a 490-zone building's local fits left 180 zones' heat noise on its lower bound)."""


def _bound_flags(rows) -> list[str]:
    """The summary's lines for parameters on a bound: by name, or per group and bound when
    more than :data:`_FLAGS_PER_GROUP` share them (the parameter table lists every one)."""
    def line(r):
        return (f"{r['parameter']} = {r['value']} {r['unit']}: "
                + ("" if r["on a bound"].startswith("set by") else "at its ") + r["on a bound"])
    by = {}
    for r in rows:
        by.setdefault((r["parameter"].split("[")[0], r["on a bound"]), []).append(r)
    out = []
    for (group, bound), rs in by.items():
        if len(rs) > _FLAGS_PER_GROUP:
            names = ", ".join(r["parameter"] for r in rs[:3])
            out.append(f"{group}: {len(rs)} parameters at its {bound} ({names}, …; every one "
                       f"in the parameter table)")
        else:
            out += [line(r) for r in rs]
    return out


# ---------------------------------------------------------------------------- the top
def _summary(outdir: Path, ident: dict | None, valid: dict | None, problems: list[str],
             left_out: bool = False) -> str:
    out = []
    if problems:
        out.append("<div class='problems'><strong>This directory is not consistent.</strong><ul>"
                   + "".join(f"<li>{_esc(p)}</li>" for p in problems) + "</ul></div>")
    out.append("<section class='summary' id='summary'><h2>Verdict</h2>")
    g = (ident or {}).get("greybox") or {}
    verdicts = g.get("verdicts") or {}
    weak = [k for k, v in verdicts.items() if "not identifiable" in str(v).lower()]
    vd = _verdict(valid) if valid is not None else None
    rec = vd and vd.get("recommendation")
    if vd is not None:
        cls = "verdict" + (" against" if rec in ("conduction-only", "mixed") else "")
        head = _HEADLINE.get(rec, "")
        out.append(f"<p class='{cls}'>" + (f"<strong>{_esc(head)}</strong> " if head else "")
                   + f"{_esc(vd['text'])}</p>")
    elif valid is not None:
        out.append("<p class='verdict'>validation.json holds no verdict and no errors to weigh; "
                   "see the validation section.</p>")
    elif left_out:
        out.append("<p class='verdict against'><strong>No verdict.</strong> The validation here "
                   "describes another identification run (see above).</p>")
    else:
        out.append("<p class='verdict against'><strong>Not validated yet.</strong> The identified "
                   "model has not been compared with the conduction-only model on held-back data.</p>")
    out.append(f"<p><strong>Next step:</strong> {_next_step(rec, outdir, vd is not None, weak)}</p>")
    if verdicts:
        out.append("<h3>What the data pin down</h3><ul>"
                   + "".join(f"<li>{_esc(v)}</li>" for v in verdicts.values()) + "</ul>")
    flags = []
    if g.get("params"):
        rows, _, flagged = _parameter_rows(ident)
        flags = _bound_flags([r for r in rows if r["parameter"] in flagged])
    for key in ("grid", "estimate"):
        for b in ((ident or {}).get(key) or {}).get("active_bounds") or []:
            flags.append(f"{key}: {b}")
    if flags:
        out.append("<h3>On a bound</h3><p>The criterion, not the building, chose these values:</p><ul>"
                   + "".join(f"<li>{_esc(f)}</li>" for f in flags) + "</ul>")
    out.append("</section>")
    return "\n".join(out)


# ---------------------------------------------------------------------------- blocks
def _selection_text(b: dict, ident: dict | None) -> str | None:
    """A selection path in which nothing was added or removed, as one sentence."""
    rows = b["content"]
    if any(r.get("step") not in ("start", "keep") for r in rows):
        return None
    sel = ((ident or {}).get("structure") or {}).get("selection") or {}
    crit = str(sel.get("criterion", "")).upper() or "criterion"
    start = next((r for r in rows if r.get("step") == "start"), rows[0])
    keep = next((r for r in rows if r.get("step") == "keep"), None)
    cands = sel.get("candidates") or []
    val = start.get(crit)
    s = (f"{b['title']}: started from {len(cands) or start.get('note', '')} candidate edge(s)"
         + (f" ({', '.join(cands)})" if cands else "")
         + (f", {crit} {val:.1f}" if isinstance(val, (int, float)) else "") + "; none removed")
    if keep is not None and keep.get("note"):
        s += f" — {keep['note']}"
    return f"<p>{_esc(s)}.</p>"


def _is_greybox_table(b: dict) -> bool:
    """identify's bare table of grey-box values (no units), replaced by :func:`_parameter_table`."""
    rows = b.get("content") or []
    return b["kind"] == "table" and (str(b.get("title", "")).startswith("Grey-box estimate")
                                     or bool(rows) and all(set(r) == {"parameter", "value"} for r in rows))


def _block(b: dict, ident: dict | None) -> str:
    title = b.get("title") or ""
    if b["kind"] == "table":
        if _is_greybox_table(b) and ((ident or {}).get("greybox") or {}).get("params"):
            return _parameter_table(ident)
        if title.startswith("Model-based selection") and b["content"]:
            sentence = _selection_text(b, ident)
            if sentence is not None:
                return sentence
        head = f"<h3>{_esc(title)}</h3>" if title else ""
        # relative errors are fractions in the JSON; the console and the text show %
        return head + _table(b["content"], percent=title.startswith("Step-response error"))
    head = f"<h3>{_esc(title)}</h3>" if title else ""
    if b["kind"] == "note":
        return head + f"<p class='note'>{_esc(b['content'])}</p>"
    if "\n" in str(b["content"]):
        return head + _text(b["content"])
    return head + f"<p>{_esc(b['content'])}</p>"


def _truncation_note(figs: list[dict], valid: dict | None) -> str:
    """Say so when the open-loop traces show only some of the zones."""
    shown = [f["name"][len("openloop-"):] for f in figs if f["name"].startswith("openloop-")]
    zones = [r.get("zone") for r in (valid or {}).get("open_loop") or [] if r.get("zone")]
    if not shown or len(shown) >= len(zones):
        return ""
    return (f"<p class='note'>Open-loop traces: first {len(shown)} of {len(zones)} measured zones "
            f"shown ({', '.join(shown)}); the per-zone error table covers all {len(zones)}.</p>")


def _load(p: Path) -> dict:
    try:
        return json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise DataError(f"{p}: not valid JSON ({exc})") from None


def build_report(outdir, title: str | None = None) -> Path:
    """Assemble ``outdir/report.html`` from what identify/validate wrote there.

    Each JSON file may carry a ``report`` entry: a list of blocks
    ``{"section": ..., "kind": "text"|"table"|"note", "title": ..., "content": ...}``.
    The page opens with the verdict and the next step (see the module docstring); the
    grey-box parameters are shown with units and bound flags, apertures and gain levels
    summarised.

    Returns
    -------
    Path of the report.
    """
    outdir = Path(outdir)
    if not outdir.is_dir():
        raise DataError(f"{outdir}: not a directory (run `thermctl identify ... --out {outdir}` first)")
    docs = {name: _load(outdir / name)
            for name in ("identification.json", "validation.json", "reduction.json")
            if (outdir / name).exists()}
    if not docs:
        raise DataError(f"{outdir}: no identification.json, validation.json or reduction.json to report on")
    ident, valid = docs.get("identification.json"), docs.get("validation.json")
    problems, valid_ok = _consistency(outdir, ident, valid)
    sources = list(docs)
    if not valid_ok:
        docs.pop("validation.json")
        valid = None
        sources = [s if s != "validation.json" else "validation.json (left out: another run)"
                   for s in sources]
    blocks = [b for d in docs.values() for b in d.get("report", [])]
    manifest_path = outdir / "figures.json"
    figures = json.loads(manifest_path.read_text()) if manifest_path.exists() else []
    if not valid_ok:
        figures = [f for f in figures if f["section"] != "Validation"]
    name = title or "thermctl report"
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{_esc(name)}"
             f"</title><style>{_CSS}</style></head><body><h1>{_esc(name)}</h1>",
             f"<p class='muted'>Built from {', '.join(sources)} in {_esc(outdir)}.</p>",
             _summary(outdir, ident, valid, problems, left_out=not valid_ok)]
    sections = SECTIONS + sorted({b["section"] for b in blocks} - set(SECTIONS))
    for sec in sections:
        sec_blocks = [b for b in blocks if b["section"] == sec]
        sec_figs = [f for f in figures if f["section"] == sec and (outdir / "figures" / f"{f['name']}.png").exists()]
        if not sec_blocks and not sec_figs:
            continue
        parts.append(f"<h2>{_esc(sec)}</h2>")
        if (sec == "Parameters" and ((ident or {}).get("greybox") or {}).get("params")
                and not any(_is_greybox_table(b) for b in sec_blocks)):
            parts.append(_parameter_table(ident))  # identify's blocks changed: still show it
        parts += [_block(b, ident) for b in sec_blocks]
        if sec == "Validation":
            parts.append(_truncation_note(sec_figs, valid))
        for f in sec_figs:
            parts.append(_figure(outdir / "figures" / f"{f['name']}.png", f["caption"]))
    parts.append("</body></html>")
    path = outdir / "report.html"
    atomic_write_text(path, "\n".join(p for p in parts if p))
    return path
