"""mkdocs hook: render the Sphinx roles of numpydoc docstrings on the API page.

mkdocstrings renders docstrings as Markdown, so ``:func:`fit``` and ``.. math::`` would
show as written. This turns them into code and into arithmatex math (typeset by MathJax,
see ``javascripts/mathjax.js``) after the page is converted to HTML.
"""

from __future__ import annotations

import re

_ROLE = re.compile(r":(?:py:)?(?:func|meth|class|attr|mod|data|exc|obj|const|ref):<code>(~?)\.?([^<]*)</code>")
_MATH_ROLE = re.compile(r":math:<code>([^<]*)</code>")
_MATH_BLOCK = re.compile(r"<p>\.\. math::</p>\s*<pre><code>(.*?)</code></pre>", re.S)
_MATH_BLOCK_INLINE = re.compile(r"<p>\.\. math::\s*(.*?)</p>", re.S)


def _role(m: re.Match) -> str:
    # Sphinx shows "~pkg.mod.Name" as "Name"; ".problem.X" (relative) as written minus the dot
    tilde, text = m.groups()
    return f"<code>{text.rsplit('.', 1)[-1] if tilde else text}</code>"


def on_page_content(html, page, config, files):
    html = _MATH_BLOCK.sub(lambda m: f'<div class="arithmatex">\\[{m.group(1)}\\]</div>', html)
    html = _MATH_BLOCK_INLINE.sub(lambda m: f'<div class="arithmatex">\\[{m.group(1)}\\]</div>', html)
    html = _MATH_ROLE.sub(lambda m: f'<span class="arithmatex">\\({m.group(1)}\\)</span>', html)
    return _ROLE.sub(_role, html)
