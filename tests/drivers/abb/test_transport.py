"""LineTransport over pyserial's loop:// (the port echoes what is written)."""

import time

import pytest

from robocal.drivers.abb.client import ControllerClient, ControllerTimeout
from robocal.drivers.abb.transport import LineTransport
from robocal.drivers.line_errors import TransportClosed
from robocal.solver.robot import IRB2600


@pytest.fixture
def loop():
    t = LineTransport("loop://", timeout_s=0.05)
    yield t
    t.close()


def test_line_round_trip(loop):
    loop.write_line("#1 HELLO")
    assert loop.read_line(time.monotonic() + 0.5) == "#1 HELLO"


def test_partial_line_is_kept_across_a_timeout(loop):
    loop._port.write(b"#5 OK 3.")  # half a reply, then the deadline passes
    assert loop.read_line(time.monotonic() + 0.02) is None
    loop._port.write(b"42\r\n#6 OK\n")
    deadline = time.monotonic() + 0.5
    assert loop.read_line(deadline) == "#5 OK 3.42"
    assert loop.read_line(deadline) == "#6 OK"


def test_discard_input(loop):
    loop._port.write(b"boot banner\n#3 OK")
    loop.discard_input()
    assert loop.read_line(time.monotonic() + 0.02) is None


def test_closed_transport_raises(loop):
    loop.close()
    with pytest.raises(TransportClosed):
        loop.write_line("#1 STATUS")
    with pytest.raises(TransportClosed):
        loop.read_line(time.monotonic() + 0.02)


def test_bad_url():
    with pytest.raises(TransportClosed):
        LineTransport("nosuch://x", timeout_s=0.05)


def test_client_over_loop_hears_only_its_own_echo():
    # The echo of a request is not a reply: skipped like noise, so the handshake times out.
    with pytest.raises(ControllerTimeout):
        ControllerClient("loop://", IRB2600, timeout_s=0.05, retries=0)
