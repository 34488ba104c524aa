"""The workbench's WebSocket trusts no client: pages of foreign origins are refused, and a GUI change is acted on only
when a person could have made it in the page (a listed option, an enabled control, a value of the control's type and
range); the rest is logged in one line and dropped before viser applies it. An upload larger than the workbench takes
is refused by its declared size before any of its bytes is kept, and a part beyond the declared size is dropped.

viser 1.1 has no option for either, so the guard sits in front of its WebSocket server's dispatch of incoming
messages (every GUI change passes there before it reaches a handle) and checks each connection's handshake request
when it opens, before any message of it is read.
"""
from __future__ import annotations

import ipaddress
import logging
import math
import socket
from collections.abc import Callable, Coroutine
from typing import Any
from urllib.parse import urlsplit

import viser
from viser import _messages
from viser.infra import WebsockClientConnection

from .mesh_upload import too_large

log = logging.getLogger("regrasp.workbench")

MAX_TEXT = 4096  # characters a text field takes from a client
REFUSED = (_messages.ShareUrlRequest, _messages.ShareUrlDisconnect)  # the workbench offers no public share link
LOOPBACK = {"localhost", "127.0.0.1", "::1"}
ANY_INTERFACE = {"0.0.0.0", "::", ""}
MIN_PART_BYTES = 1024  # an upload's parts average at least this (viser's page sends 512 KiB parts): caps the part count
Dispatch = Callable[[int, _messages.Message], Coroutine[Any, Any, None]]


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def origin_allowed(origin: str | None, host_header: str | None, bound: str) -> bool:
    """Whether a WebSocket handshake's Origin is the workbench's own page: none (not a browser), or the address the
    request went to (its Host) when that names this machine: a loopback name, the bound host, or, served on every
    interface, an IP address or this machine's name (a DNS name of someone else's pointing here is refused)."""
    if origin is None:
        return True
    parts = urlsplit(origin)
    if parts.scheme not in ("http", "https") or not host_header or parts.netloc.lower() != host_header.lower():
        return False
    name = (parts.hostname or "").lower()
    if name in LOOPBACK or name == bound.lower():
        return True
    return bound in ANY_INTERFACE and (_is_ip(name) or name in {socket.gethostname().lower(), socket.getfqdn().lower()})


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def change_problem(handle: Any, updates: dict[str, Any]) -> str | None:
    """Why a client's change of a GUI control must be dropped (None: a person could have made it)."""
    if not isinstance(updates, dict) or set(updates) != {"value"}:
        return f"only a control's value may change, not {updates!r:.80}"
    if getattr(handle, "disabled", False):
        return "the control is disabled"
    value, current = updates["value"], handle.value
    if isinstance(handle, viser.GuiButtonHandle):
        ok = value is True
    elif isinstance(handle, (viser.GuiDropdownHandle, viser.GuiButtonGroupHandle)):
        ok = isinstance(value, str) and value in handle.options
    elif isinstance(current, bool):
        ok = isinstance(value, bool)
    elif isinstance(current, str):
        ok = isinstance(value, str) and len(value) <= MAX_TEXT
    elif _number(current):
        low, high = getattr(handle, "min", None), getattr(handle, "max", None)
        slack = getattr(handle, "step", None) or 0.0  # the page rounds to its step, maybe just past a limit
        ok = _number(value) and (low is None or value >= low - slack) and (high is None or value <= high + slack)
    else:  # vectors and colours: as many numbers as now
        ok = isinstance(value, (list, tuple)) and len(value) == len(current) and all(map(_number, value))
    return None if ok else f"{value!r:.80} is not a value the control offers"


class ClientGuard:
    """Installed on a viser server: refuses foreign origins and drops the changes `change_problem` names."""

    def __init__(self, server: viser.ViserServer, bound: str):
        self.bound = bound
        self._server = server
        self._uploads: dict[str, list[int]] = {}  # transfer id -> [client id, declared bytes, bytes received]
        self._inputs: dict[str, Any] = server.gui._gui_input_handle_from_uuid  # viser's own uuid -> handle map
        self._refused: set[int] = set()
        websock = server._websock_server
        self._live = websock._live_connections  # client id -> its connection (set before the connect callbacks run)
        self._dispatch: Dispatch = websock._handle_incoming_message
        websock._handle_incoming_message = self._guarded  # every message of every client passes here first
        websock.on_client_connect(self._check_origin)
        websock.on_client_disconnect(self._forget)

    def _forget(self, conn: WebsockClientConnection) -> None:
        self._refused.discard(conn.client_id)
        for transfer in [t for t, (owner, _, _) in self._uploads.items() if owner == conn.client_id]:
            del self._uploads[transfer]

    async def _check_origin(self, conn: WebsockClientConnection) -> None:
        connection = self._live.get(conn.client_id)
        headers = connection.request.headers if connection is not None and connection.request is not None else {}
        origin = headers.get("Origin")
        if not origin_allowed(origin, headers.get("Host"), self.bound):
            self._refused.add(conn.client_id)
            log.warning("workbench: refused a connection from the page at %r (not this workbench's page)", origin)
            if connection is not None:
                await connection.close(1008, "foreign origin")

    async def _guarded(self, client_id: int, message: _messages.Message) -> None:
        if client_id in self._refused:
            return
        if isinstance(message, REFUSED):
            log.warning("workbench: ignored a %s from client %d (sharing is off)", type(message).__name__, client_id)
            return
        if isinstance(message, _messages.GuiUpdateMessage) and (handle := self._inputs.get(str(message.uuid))) is not None:
            problem = change_problem(handle, message.updates)
            if problem is not None:
                log.warning("workbench: ignored a change of %r from client %d: %s", handle.label, client_id, problem)
                return
        if isinstance(message, (_messages.FileTransferStartUpload, _messages.FileTransferPart)) and \
                not self._upload_allowed(client_id, message):
            return
        await self._dispatch(client_id, message)

    def _upload_allowed(self, client_id: int, message: _messages.FileTransferStartUpload | _messages.FileTransferPart) -> bool:
        """An upload's start within the size limit (else the tab is told why), and its parts within the declared size."""
        if isinstance(message, _messages.FileTransferStartUpload):
            size, parts = message.size_bytes, message.part_count
            problem = too_large(size) if isinstance(size, int) and size >= 0 else f"declares {size!r:.40} bytes"
            if problem is None and not (isinstance(parts, int) and 0 <= parts <= 1 + size // MIN_PART_BYTES):
                problem = f"declares {parts!r:.40} parts for {size} bytes"
            if problem is not None:
                log.warning("workbench: refused the upload of %r from client %d: %s", str(message.filename)[:80], client_id, problem)
                client = self._server.get_clients().get(client_id)
                if client is not None:
                    client.add_notification("Upload refused", f"{str(message.filename)[:80]} {problem}", color="red",
                                            auto_close_seconds=10.0)
                return False
            if size > 0:
                self._uploads[message.transfer_uuid] = [client_id, size, 0]
            return True
        state = self._uploads.get(message.transfer_uuid)
        if state is None or state[0] != client_id:
            return False
        state[2] += len(message.content)
        if state[2] >= state[1]:
            del self._uploads[message.transfer_uuid]
        return state[2] <= state[1]
