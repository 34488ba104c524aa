"""User-facing messages: error text without tracebacks, and notifications to every open browser tab."""
from __future__ import annotations

import viser

from planner.core.errors import RegraspError


def error_text(exc: Exception) -> str:
    """A user-facing message: a RegraspError as is, anything else with its type."""
    return str(exc) if isinstance(exc, RegraspError) else f"{type(exc).__name__}: {exc}"


def notify_all(server: viser.ViserServer, title: str, body: str, error: bool = False) -> None:
    """A notification in every connected tab (red for errors)."""
    for client in server.get_clients().values():
        client.add_notification(title, body, color="red" if error else "blue", auto_close_seconds=10.0)
