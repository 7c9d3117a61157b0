"""Newline-framed ASCII lines over pyserial's serial_for_url (serial port, socket://, loop://)."""

from __future__ import annotations

import socket
import time

import serial

from ..line_errors import TransportClosed

MAX_BUFFER = 1024  # a peer that never sends a newline must not grow our buffer forever
# What a port raises once it is gone; closed by another thread (the client's reader may be
# blocked in read() when the connection is closed), pyserial's socket can also raise these.
_PORT_GONE = (serial.SerialException, OSError, AttributeError, TypeError, ValueError)


class LineTransport:
    """One connection; reads whole lines against a monotonic deadline, keeping partial ones.

    pyserial's readline() returns a partial line when its timeout expires; taking that as a line
    would split a reply in two. We keep the bytes read so far and only hand out text up to "\\n".
    """

    def __init__(self, url: str, timeout_s: float, baudrate: int = 9600):
        try:
            self._port = serial.serial_for_url(
                url, timeout=timeout_s, write_timeout=timeout_s, baudrate=baudrate
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise TransportClosed(f"cannot open {url}: {exc}") from exc
        self._buffer = bytearray()
        sock = getattr(self._port, "_socket", None)
        if sock is not None:
            # No Nagle: a STOP written while a request waits for its reply would otherwise sit
            # in our buffer until the controller acknowledges that request (~40 ms delayed ACK).
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    @property
    def is_open(self) -> bool:
        return self._port is not None and self._port.is_open

    def close(self) -> None:
        if self._port is not None:
            try:
                _close_port(self._port)
            except (serial.SerialException, OSError):
                pass  # closing a connection the peer already dropped
            self._port = None

    def discard_input(self) -> None:
        """Forget anything received so far (boot banners, replies nobody waits for)."""
        self._buffer.clear()
        try:
            self._port.reset_input_buffer()
        except _PORT_GONE as exc:
            raise TransportClosed(str(exc)) from exc

    def write_line(self, text: str) -> None:
        try:
            self._port.write(text.encode("ascii") + b"\n")
            self._port.flush()
        except _PORT_GONE as exc:
            raise TransportClosed(str(exc)) from exc

    def read_line(self, deadline: float) -> str | None:
        """The next line without its terminator, or None once time.monotonic() passes deadline."""
        while True:
            end = self._buffer.find(b"\n")
            if end >= 0:
                raw = bytes(self._buffer[:end])
                del self._buffer[: end + 1]
                return raw.rstrip(b"\r").decode("ascii", errors="replace")
            if len(self._buffer) > MAX_BUFFER:
                raw = bytes(self._buffer)
                self._buffer.clear()
                return raw.decode("ascii", errors="replace")  # unparseable: the caller skips it
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            try:
                self._port.timeout = remaining
                chunk = self._port.read(1)  # blocks until a byte arrives or the time is up
                if chunk and self._port.in_waiting:
                    chunk += self._port.read(self._port.in_waiting)
            except _PORT_GONE as exc:
                raise TransportClosed(str(exc)) from exc
            self._buffer += chunk


def _close_port(port) -> None:
    """Close a port; a socket:// one without pyserial's unconditional 0.3 s sleep.

    pyserial sleeps after closing a socket "in case of quick reconnects"; our reconnects need no
    such pause (a new connection waits in the server's listen backlog), and every retry and test
    would pay it.
    """
    sock = getattr(port, "_socket", None)
    if sock is None or not port.is_open:
        port.close()
        return
    try:
        sock.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass  # already reset by the peer
    sock.close()
    port._socket = None
    port.is_open = False
