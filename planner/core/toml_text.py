"""TOML text of data as tomllib reads it (tasks written by the suite's generator and by the workbench's task editor).

The one TOML writer, beside the one reader (`planner.core.tomlread`): every string is escaped so that any text (a
description typed in a browser included) reads back as it was written and never as more TOML.
"""
from __future__ import annotations

import math
import re
from typing import Any

# what a TOML basic string may not hold as itself: the quote, the backslash, and control characters (TOML 1.0)
_ESCAPED = re.compile(r'["\\\x00-\x1f\x7f]')
_SHORT = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}
_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _string(text: str) -> str:
    """A TOML basic string holding `text`; a lone surrogate (no Unicode character, no UTF-8) is refused."""
    if any("\ud800" <= c <= "\udfff" for c in text):
        raise ValueError(f"TOML text holds Unicode characters only, got a lone surrogate in {text[:40]!r}")
    return '"' + _ESCAPED.sub(lambda m: _SHORT.get(m.group(), f"\\u{ord(m.group()):04x}"), text) + '"'


def _value(value: Any) -> str:
    """One TOML value: a string, a number, a boolean, an array or an inline table."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return _string(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"TOML task files hold finite numbers only, got {value}")
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + " }" if value else "{}"
    raise TypeError(f"no TOML form for {type(value).__name__}")


def _key(key: str) -> str:
    return key if _BARE_KEY.fullmatch(key) else _string(key)


def toml_text(data: dict[str, Any]) -> str:
    """Top-level values first, then each table (its sub-tables inline), then each array of tables."""
    lines = [f"{_key(k)} = {_value(v)}" for k, v in data.items() if not isinstance(v, dict) and not _tables(v)]
    for key, value in data.items():
        if isinstance(value, dict):
            lines += ["", f"[{_key(key)}]", *(f"{_key(k)} = {_value(v)}" for k, v in value.items())]
    for key, value in data.items():
        if _tables(value):
            for table in value:
                lines += ["", f"[[{_key(key)}]]", *(f"{_key(k)} = {_value(v)}" for k, v in table.items())]
    return "\n".join(lines) + "\n"


def _tables(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)
