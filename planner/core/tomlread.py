"""Typed reading of TOML tables, so every bad field is reported by file and dotted field name."""
from __future__ import annotations

import math
import re
import sys
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from planner.core.errors import InputError
from planner.core.results import MAX_DEPTH, MAX_INT_DIGITS, check_nesting


def load_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file (the one TOML reader: tasks, suites, robot specs), turning a missing file, a syntax error,
    nesting deeper than MAX_DEPTH or an integer longer than MAX_INT_DIGITS into an InputError naming the file (and the field)."""
    if not path.is_file():
        raise InputError(path, None, "file not found")
    try:
        with path.open("rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(path, None, f"not valid TOML ({exc})") from exc
    except UnicodeDecodeError as exc:
        raise InputError(path, None, "not a UTF-8 text file") from exc
    except RecursionError as exc:
        raise InputError(path, None, f"nested deeper than Python can parse; expected at most {MAX_DEPTH} levels") from exc
    except ValueError as exc:  # an integer of more than 4300 digits, which Python refuses to convert
        raise InputError(path, _long_integer(path.read_text()), f"an integer of more than {sys.get_int_max_str_digits()} "
                                                                 f"digits; expected at most {MAX_INT_DIGITS} digits") from exc
    check_nesting(data, path)
    return data


def _long_integer(text: str) -> str | None:
    """The key (and line) of the first integer of more than MAX_INT_DIGITS digits in TOML text, if any."""
    found = re.search(rf"\d[\d_]{{{MAX_INT_DIGITS},}}", text)
    if found is None:
        return None
    start = text.rfind("\n", 0, found.start()) + 1
    line = text.count("\n", 0, found.start()) + 1
    key, sep, _ = text[start:found.start()].partition("=")
    return f"{key.strip()} (line {line})" if sep and key.strip() else f"line {line}"


class Table:
    """A TOML table with its file and its dotted path, for precise error messages."""

    def __init__(self, data: dict[str, Any], source: str | Path, path: str = ""):
        self.data = data
        self.source = source
        self.path = path

    def field(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def error(self, key: str | None, message: str) -> InputError:
        return InputError(self.source, self.field(key) if key else (self.path or None), message)

    def check_keys(self, allowed: set[str]) -> None:
        """Reject unknown keys: a typo must not silently fall back to a default."""
        for key in self.data:
            if key not in allowed:
                raise self.error(key, f"unknown field (expected one of: {', '.join(sorted(allowed))})")

    def has(self, key: str) -> bool:
        return key in self.data

    def _get(self, key: str, default: Any) -> Any:
        if key not in self.data:
            if default is _REQUIRED:
                raise self.error(key, "missing required field")
            return default
        return self.data[key]

    def table(self, key: str, default: Any = None) -> "Table":
        value = self._get(key, _REQUIRED if default is None else default)
        if not isinstance(value, dict):
            raise self.error(key, f"expected a table, got {type(value).__name__}")
        return Table(value, self.source, self.field(key))

    def tables(self, key: str) -> list["Table"]:
        value = self._get(key, _REQUIRED)
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(key, "expected an array of tables ([[...]])")
        return [Table(v, self.source, f"{self.field(key)}[{i}]") for i, v in enumerate(value)]

    def str(self, key: str, default: str | None = None) -> str:
        value = self._get(key, _REQUIRED if default is None else default)
        if not isinstance(value, str) or not value:
            raise self.error(key, "expected a non-empty string")
        return value

    def float(self, key: str, default: float | None = None, positive: bool = False) -> float:
        value = self._get(key, _REQUIRED if default is None else default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.error(key, f"expected a finite number, got {value!r}")
        if positive and value <= 0:
            raise self.error(key, f"expected a positive number, got {value!r}")
        return float(value)

    def bool(self, key: str, default: bool | None = None) -> bool:
        value = self._get(key, _REQUIRED if default is None else default)
        if not isinstance(value, bool):
            raise self.error(key, f"expected true or false, got {value!r}")
        return value

    def str_list(self, key: str, default: list[str] | None = None) -> list[str]:
        value = self._get(key, _REQUIRED if default is None else default)
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise self.error(key, "expected a list of names (strings)")
        return list(value)

    def name_pairs(self, key: str) -> list[tuple[str, str]]:
        """A list of two-name lists, e.g. [["a", "b"], ["c", "d"]] (empty when absent)."""
        value = self._get(key, [])
        if not isinstance(value, list) or not all(
                isinstance(v, list) and len(v) == 2 and all(isinstance(n, str) and n for n in v) for v in value):
            raise self.error(key, 'expected a list of name pairs, e.g. [["link_a", "link_b"]]')
        return [(a, b) for a, b in value]

    def vector(self, key: str, length: int | None = None, default: Any = None) -> np.ndarray:
        value = self._get(key, _REQUIRED if default is None else default)
        ok = isinstance(value, list) and all(
            not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) for v in value
        )
        if not ok:
            raise self.error(key, "expected a list of finite numbers")
        if length is not None and len(value) != length:
            raise self.error(key, f"expected {length} numbers, got {len(value)}")
        return np.asarray(value, dtype=float)

    def number_map(self, key: str, default: dict | None = None) -> dict[str, float]:
        tab = self.table(key, default)
        return {name: tab.float(name) for name in tab.data}


_REQUIRED = object()
