"""MkDocs hook: a pipe escaped inside inline code in a table row (``\\|``), as GitHub's Markdown needs it,
reads as a plain ``|`` on the site too (Python-Markdown keeps the backslash inside code, and does not split
cells at a pipe inside code in the first place)."""

from __future__ import annotations

import re

INLINE_CODE = re.compile(r"`[^`\n]*`")


def unescape_table_code(markdown: str) -> str:
    """``markdown`` with ``\\|`` inside the inline code of table rows (lines starting with ``|``) as ``|``."""
    lines = markdown.split("\n")
    for i, line in enumerate(lines):
        if line.lstrip().startswith("|"):
            lines[i] = INLINE_CODE.sub(lambda code: code.group(0).replace("\\|", "|"), line)
    return "\n".join(lines)


def on_page_markdown(markdown: str, **_kwargs) -> str:
    return unescape_table_code(markdown)
