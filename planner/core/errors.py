"""Errors a user can act on: each names the file, the field and what was expected."""
from __future__ import annotations

from pathlib import Path


class RegraspError(Exception):
    """Base class of every error regrasp reports to a user instead of a traceback."""


class InputError(RegraspError):
    """Bad input: a file, a field in it, and what was expected there."""

    def __init__(self, source: str | Path, field: str | None, message: str):
        self.source = str(source)
        self.field = field
        self.detail = message
        where = f"{self.source}" + (f", field '{field}'" if field else "")
        super().__init__(f"{where}: {message}")
