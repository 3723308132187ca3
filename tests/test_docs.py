"""The documentation builds (mkdocs --strict: broken links and bad docstrings fail)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MKDOCS = shutil.which("mkdocs", path=str(Path(sys.executable).parent)) or shutil.which("mkdocs")


@pytest.mark.skipif(MKDOCS is None, reason="mkdocs not installed (pip install -e '.[docs]')")
def test_docs_build_strict(tmp_path):
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    res = subprocess.run([MKDOCS, "build", "--strict", "--site-dir", str(tmp_path / "site")],
                         cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert (tmp_path / "site" / "api" / "index.html").exists()


def test_cli_reference_lists_every_command():
    from typer.main import get_command

    from thermctl.cli import app
    text = (ROOT / "docs" / "cli.md").read_text()
    for name in get_command(app).commands:
        assert f"## thermctl {name}" in text, f"docs/cli.md lacks `thermctl {name}`"
