"""Text from a file, a task, a session, a result or an error, made safe to put into markdown or HTML.

viser renders markdown with raw HTML allowed and does not sanitise it, and the suite report is HTML: such text must
never become markup there. `plain` turns every ASCII punctuation character into a numeric character reference, which
HTML and markdown both show as the character itself and never read as markup (no tag, emphasis, link, table cell or
autolink can start), and line breaks and other control characters into spaces (a text stays on its line: in a table
cell, in a heading). Notifications, labels and dropdown options are plain text already: they need no `plain`.
"""
from __future__ import annotations

import string
import unicodedata

_PUNCTUATION = frozenset(string.punctuation)


def _safe(c: str) -> str:
    if c in _PUNCTUATION:
        return f"&#{ord(c)};"
    return " " if unicodedata.category(c)[0] in "CZ" and c != " " else c


def plain(value: object) -> str:
    """`str(value)` shown literally by markdown and by HTML (text or a quoted attribute value)."""
    return "".join(map(_safe, str(value)))
