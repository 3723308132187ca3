"""Refresh the ``--help`` blocks of docs/cli.md from the CLI itself.

Run after changing a command's options: ``python docs/gen_cli.py``. Text outside the
```` ```text ```` blocks that follow each ``## thermctl NAME`` heading is kept.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

DOC = Path(__file__).with_name("cli.md")
BOX = re.compile(r"[╭╮╰╯│─]")


def help_text(name: str) -> str:
    env = dict(os.environ, COLUMNS="110", TERM="dumb", NO_COLOR="1")
    out = subprocess.run([str(Path(sys.executable).with_name("thermctl")), name, "--help"], env=env,
                         capture_output=True, text=True, check=True).stdout
    lines = [BOX.sub("", ln).rstrip() for ln in out.splitlines()]
    return "\n".join(ln for ln in lines if ln.strip())


def main():
    text = DOC.read_text()

    def repl(m):
        return f"## thermctl {m.group(1)}\n\n```text\n{help_text(m.group(1))}\n```"
    DOC.write_text(re.sub(r"## thermctl (\w+)\n\n```text\n.*?\n```", repl, text, flags=re.S))


if __name__ == "__main__":
    main()
