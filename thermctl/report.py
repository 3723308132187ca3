"""The HTML report: one self-contained page (figures embedded as PNG data URIs).

`thermctl identify` and `thermctl validate` write into an output directory:
``identification.json``, ``validation.json``, ``model.json`` and PNG figures under
``figures/`` listed in ``figures.json`` (name, section, caption). This module only
assembles what is there, so a report can be rebuilt at any time.
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
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right}th{background:#eef2f6}
td:first-child,th:first-child{text-align:left}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}
figcaption{font-size:.9em;color:#555}pre{background:#f6f8fa;padding:.6em;overflow-x:auto;font-size:.85em}.note{background:#fff8e1;border-left:4px solid #f0b400;
padding:.4em .8em}.muted{color:#777;font-size:.85em}
"""


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


def _table(rows: list[dict], floatfmt: str = "{:.4g}") -> str:
    if not rows:
        return ""
    cols = list(rows[0])
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in cols)
    body = []
    for r in rows:
        cells = []
        for c in cols:
            v = r.get(c, "")
            if isinstance(v, float):
                v = floatfmt.format(v)
            cells.append(f"<td>{html.escape(str(v))}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def _figure(path: Path, caption: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def build_report(outdir, title: str | None = None) -> Path:
    """Assemble ``outdir/report.html`` from what identify/validate wrote there.

    Each JSON file may carry a ``report`` entry: a list of blocks
    ``{"section": ..., "kind": "text"|"table"|"note", "title": ..., "content": ...}``.

    Returns
    -------
    Path of the report.
    """
    outdir = Path(outdir)
    if not outdir.is_dir():
        raise DataError(f"{outdir}: not a directory (run `thermctl identify ... --out {outdir}` first)")
    blocks = []
    sources = []
    for name in ("identification.json", "validation.json", "reduction.json"):
        p = outdir / name
        if p.exists():
            sources.append(name)
            blocks += json.loads(p.read_text()).get("report", [])
    if not sources:
        raise DataError(f"{outdir}: no identification.json, validation.json or reduction.json to report on")
    manifest_path = outdir / "figures.json"
    figures = json.loads(manifest_path.read_text()) if manifest_path.exists() else []
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title or 'thermctl report')}"
             f"</title><style>{_CSS}</style></head><body><h1>{html.escape(title or 'thermctl report')}</h1>",
             f"<p class='muted'>Built from {', '.join(sources)} in {html.escape(str(outdir))}.</p>"]
    sections = SECTIONS + sorted({b["section"] for b in blocks} - set(SECTIONS))
    for sec in sections:
        sec_blocks = [b for b in blocks if b["section"] == sec]
        sec_figs = [f for f in figures if f["section"] == sec and (outdir / "figures" / f"{f['name']}.png").exists()]
        if not sec_blocks and not sec_figs:
            continue
        parts.append(f"<h2>{html.escape(sec)}</h2>")
        for b in sec_blocks:
            if b.get("title"):
                parts.append(f"<h3>{html.escape(b['title'])}</h3>")
            if b["kind"] == "table":
                parts.append(_table(b["content"]))
            elif b["kind"] == "note":
                parts.append(f"<p class='note'>{html.escape(b['content'])}</p>")
            elif "\n" in b["content"]:
                parts.append(f"<pre>{html.escape(b['content'])}</pre>")
            else:
                parts.append(f"<p>{html.escape(b['content'])}</p>")
        for f in sec_figs:
            parts.append(_figure(outdir / "figures" / f"{f['name']}.png", f["caption"]))
    parts.append("</body></html>")
    path = outdir / "report.html"
    atomic_write_text(path, "\n".join(parts))
    return path
