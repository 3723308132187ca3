"""The HTML report renders in a real browser (headless Chromium, when installed)."""

from __future__ import annotations

import json
import shutil
import subprocess

import matplotlib

matplotlib.use("Agg")
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from thermctl.report import build_report, save_figure  # noqa: E402

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def _report(tmp_path):
    fig = Figure(figsize=(4, 3))
    ax = fig.add_subplot()
    ax.plot([0, 1, 2], [0, 1, 4])
    save_figure(fig, tmp_path, "curve", "Validation", "A test curve.")
    blocks = [{"section": "Validation", "kind": "table", "title": "Per-zone error",
               "content": [{"zone": "r1", "RMSE": 0.5}, {"zone": "r2", "RMSE": 0.7}]},
              {"section": "Structure", "kind": "note", "title": "", "content": "a note"}]
    (tmp_path / "validation.json").write_text(json.dumps({"report": blocks}))
    return build_report(tmp_path, title="render test")


def test_report_is_self_contained(tmp_path):
    html = _report(tmp_path).read_text()
    assert html.count("data:image/png;base64,") == 1
    assert "<table>" in html and "Per-zone error" in html
    assert "src=\"figures/" not in html  # nothing refers to files beside the page
    # sections in the documented order
    assert html.index("<h2>Structure</h2>") < html.index("<h2>Validation</h2>")


@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium not installed (apt-get install chromium)")
def test_report_renders_in_chromium(tmp_path):
    page = _report(tmp_path)
    shot = tmp_path / "shot.png"
    subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                    "--no-first-run", "--disable-background-networking", "--disable-component-update",
                    "--disable-sync", f"--user-data-dir={tmp_path / 'profile'}",
                    f"--screenshot={shot}", "--window-size=1000,900", page.as_uri()],
                   check=True, capture_output=True, timeout=120)
    from PIL import Image
    img = Image.open(shot).convert("L")
    assert img.size == (1000, 900)
    # a rendered page with text, a table and a plot has many non-white pixels
    dark = sum(1 for p in img.getdata() if p < 200)
    assert dark > 2000, f"only {dark} non-white pixels: the page looks blank"
