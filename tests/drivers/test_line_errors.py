"""Both devices fail in one vocabulary: a bad line, a closed link, a timeout are the same errors."""

from __future__ import annotations

import socket
import time

import pytest

from robocal.drivers.abb import protocol as abb
from robocal.drivers.abb.transport import LineTransport
from robocal.drivers.line_errors import LineTimeout, ProtocolError, TransportClosed
from robocal.drivers.tracker import protocol as tracker
from robocal.drivers.tracker.transport import LineSocket


@pytest.mark.parametrize(
    "parse, line",
    [(abb.parse_request, "#12 FLY 1 2 3"), (tracker.parse_request, "#12 FLY\n")],
    ids=["controller", "tracker"],
)
def test_a_bad_line_is_one_protocol_error_with_its_request_id(parse, line):
    with pytest.raises(ProtocolError) as info:
        parse(line)
    assert info.value.request_id == 12


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_refused_connection_is_transport_closed_on_both_devices():
    port = _closed_port()
    with pytest.raises(TransportClosed):
        LineSocket.connect("127.0.0.1", port, time.monotonic() + 5)
    with pytest.raises(TransportClosed):
        LineTransport(f"socket://127.0.0.1:{port}", timeout_s=1.0)


def test_a_silent_peer_is_a_line_timeout():
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        line = LineSocket.connect("127.0.0.1", server.getsockname()[1], time.monotonic() + 5)
        try:
            with pytest.raises(LineTimeout):
                line.read_line(time.monotonic() + 0.05)
        finally:
            line.close()
