"""MkDocs hook: the generated result pages' unit brackets stay text.

``docs/RESULTS.md`` and ``docs/results/*/report.md`` are written by ``scpformer report`` and
``scpformer experiment run``; their table cells put a unit in brackets after a bracketed range
(``x in [30, 40] [%]``), which Markdown would read as a reference link named ``%``. On those
pages the second bracket is escaped before rendering; the files themselves are not changed.
"""

from __future__ import annotations

import re

_BRACKET_PAIR = re.compile(r"\] \[")


def on_page_markdown(markdown: str, page, config, files) -> str:  # MkDocs calls hooks by keyword
    """Escape ``] [`` on the generated result pages; other pages pass through."""
    uri = page.file.src_uri
    if uri == "RESULTS.md" or uri.startswith("results/"):
        return _BRACKET_PAIR.sub(r"] \\[", markdown)
    return markdown
