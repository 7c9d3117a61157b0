"""What goes wrong on a device's line, in one set of words for the tracker and the controller.

Both devices speak newline-framed ASCII over a port; their transports and parsers fail the same
three ways, and callers (the campaign engine, the acquisition) handle each the same way whichever
device it came from: retry after a timeout, reconnect after a closed link, skip a bad line.
"""

from __future__ import annotations


class LineTimeout(TimeoutError):
    """No complete line arrived (or could be sent) before the deadline."""


class TransportClosed(ConnectionError):
    """The port could not be opened, or the peer went away (socket closed or reset, port gone)."""


class ProtocolError(ValueError):
    """A line not following the device's protocol; `request_id` set when the id was readable."""

    def __init__(self, message: str, request_id: int | None = None):
        super().__init__(message)
        self.request_id = request_id
