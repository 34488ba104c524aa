"""The port the workbench serves on, checked before the server starts: viser would move on to the next free port (and
print its banner for it), while a person who asked for a port wants that one or a clear error."""
from __future__ import annotations

import contextlib
import errno
import io
import os
import socket

import viser

from planner.core.errors import RegraspError


def port_in_use(host: str, port: int) -> str:
    """The error of a port another server holds."""
    return f"port {port} on {host} is in use (another workbench?): stop it, or choose another with --port"


def check_port(host: str, port: int) -> None:
    """A RegraspError (one line) unless a server could listen on `host`:`port` now (0: any free port will do)."""
    if not port:
        return
    try:
        family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
    except socket.gaierror as exc:
        raise RegraspError(f"--host {host}: not an address this machine knows ({exc.strerror})") from exc
    with socket.socket(family, kind, proto) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server binds: a port in TIME_WAIT is free
        try:
            probe.bind(address)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise RegraspError(port_in_use(host, port)) from exc
            raise RegraspError(f"cannot serve on {host} port {port}: {os.strerror(exc.errno) if exc.errno else exc}") from exc


def start_server(host: str, port: int) -> viser.ViserServer:
    """The workbench's viser server on `host`:`port` (0: any free port); a RegraspError (one line, no banner of viser's)
    when the port is taken, also when it was taken between the check and the start."""
    check_port(host, port)
    server = viser.ViserServer(host, port, label="regrasp", verbose=False)
    if port and server.get_port() != port:  # viser moved on to the next free port
        with contextlib.redirect_stdout(io.StringIO()):
            server.stop()
        raise RegraspError(port_in_use(host, port))
    return server
