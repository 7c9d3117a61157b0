"""Newline-terminated lines over a TCP socket, with monotonic deadlines; knows no protocol."""

from __future__ import annotations

import select
import socket
import time

from ..line_errors import LineTimeout, TransportClosed

MAX_LINE = 64 * 1024  # longer than any reply: what piles up without a newline is noise


class LineSocket:
    """A connected socket read and written as lines; a line without "\\n" is never returned."""

    def __init__(self, sock: socket.socket):
        self.sock = sock
        self._buf = b""

    @classmethod
    def connect(cls, host: str, port: int, deadline: float) -> LineSocket:
        """Connect by the monotonic deadline; LineTimeout or TransportClosed otherwise."""
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise LineTimeout(f"no time left to connect to {host}:{port}")
        try:
            sock = socket.create_connection((host, port), timeout=remaining)
        except TimeoutError as e:
            raise LineTimeout(f"connecting to {host}:{port} timed out") from e
        except OSError as e:
            raise TransportClosed(f"cannot connect to {host}:{port}: {e}") from e
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # one short line per request
        return cls(sock)

    def close(self) -> None:
        self.sock.close()
        self._buf = b""

    def alive(self) -> bool:
        """Take in what has arrived without waiting; False if the peer has closed."""
        try:
            while select.select([self.sock], [], [], 0)[0]:
                chunk = self.sock.recv(4096)
                if not chunk:
                    return False
                self._take(chunk)
        except (OSError, ValueError):  # ValueError: the socket is already closed
            return False
        return True

    def send_line(self, line: str, deadline: float) -> None:
        data = line.encode("ascii")
        if not data.endswith(b"\n"):
            raise ValueError("a line must end with \\n")
        self.sock.settimeout(max(deadline - time.monotonic(), 1e-3))
        try:
            self.sock.sendall(data)
        except TimeoutError as e:
            raise LineTimeout("send timed out") from e
        except OSError as e:
            raise TransportClosed(f"send failed: {e}") from e

    def read_line(self, deadline: float) -> str:
        """The next complete line, "\\n" included; bytes after it stay buffered for the next call.

        A partial line at the deadline stays buffered too (it is not a reply yet): LineTimeout.
        Bytes that are not ASCII come back as U+FFFD, so the parser can reject the line.
        """
        while True:
            i = self._buf.find(b"\n")
            if i >= 0:
                line, self._buf = self._buf[: i + 1], self._buf[i + 1 :]
                return line.decode("ascii", errors="replace")
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise LineTimeout(f"no complete line by the deadline (partial: {self._buf[:60]!r})")
            self.sock.settimeout(remaining)
            try:
                chunk = self.sock.recv(4096)
            except TimeoutError:
                continue
            except OSError as e:
                raise TransportClosed(f"receive failed: {e}") from e
            if not chunk:
                raise TransportClosed("connection closed by the peer")
            self._take(chunk)

    def _take(self, chunk: bytes) -> None:
        self._buf += chunk
        if len(self._buf) > MAX_LINE and b"\n" not in self._buf:
            self._buf = b"\xff"  # keep a marker so the rest of this line still parses as garbage
