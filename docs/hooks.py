"""mkdocs hooks: fail the build on a raw Sphinx role left in a rendered page.

mkdocstrings renders ``:func:`simulate``` as literal text; the docstrings use autorefs cross-references
(``[`simulate`][mrpctl.simulation.simulate]``) instead. A page whose HTML still holds a role aborts the build.
"""

from __future__ import annotations

import html
import re
from typing import Any

from mkdocs.exceptions import PluginError

# a role as it appears in rendered HTML: the backticks become <code> or stay literal
RAW_ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|attr|data|exc|obj|ref|doc):(?:`|<code>)")


def on_post_page(output: str, page: Any, config: Any) -> str:
    hits = sorted({m.group(0) for m in RAW_ROLE.finditer(html.unescape(output))})
    if hits:
        raise PluginError(f"{page.file.src_uri}: raw Sphinx role(s) {', '.join(hits)} in the rendered page")
    return output
