"""Lines over a socket: partial lines at a deadline, several lines per chunk, peer hang-up."""

import socket
import threading
import time

import pytest

from robocal.drivers.line_errors import LineTimeout
from robocal.drivers.tracker.transport import MAX_LINE, LineSocket


@pytest.fixture
def pair():
    a, b = socket.socketpair()
    yield a, LineSocket(b)
    a.close()
    b.close()


def soon(s: float = 0.02) -> float:
    return time.monotonic() + s


def test_partial_line_at_the_deadline_is_not_a_line(pair):
    peer, line = pair
    peer.sendall(b"#1 OK par")
    with pytest.raises(LineTimeout, match="partial"):
        line.read_line(soon())
    peer.sendall(b"tial\n#2 OK")
    assert line.read_line(soon()) == "#1 OK partial\n"
    with pytest.raises(LineTimeout):
        line.read_line(soon())


def test_several_lines_in_one_chunk(pair):
    peer, line = pair
    peer.sendall(b"#1 OK A\n#2 OK B\n")
    assert [line.read_line(soon()), line.read_line(soon())] == ["#1 OK A\n", "#2 OK B\n"]


def test_non_ascii_bytes_come_back_replaced(pair):
    peer, line = pair
    peer.sendall(b"\x00\xff#1\n")
    assert line.read_line(soon()) == "\x00\ufffd#1\n"


def test_overlong_noise_is_cut_to_one_garbage_line(pair):
    peer, line = pair
    sender = threading.Thread(target=peer.sendall, args=(b"x" * (MAX_LINE + 5000),))
    sender.start()  # more than a socket buffer may hold: send while the line reads
    with pytest.raises(LineTimeout):
        line.read_line(soon(0.1))
    sender.join(5.0)
    peer.sendall(b"yy\n#1 OK LOCKED\n")
    assert line.read_line(soon()).startswith("\ufffd")
    assert line.read_line(soon()) == "#1 OK LOCKED\n"


def test_peer_hang_up(pair):
    peer, line = pair
    assert line.alive()
    peer.sendall(b"#1 OK LOCKED\n")
    peer.close()
    assert not line.alive()
    assert line.read_line(soon()) == "#1 OK LOCKED\n"  # what arrived before the hang-up is kept
    with pytest.raises(ConnectionError):
        line.read_line(soon())


def test_send_line_needs_a_newline(pair):
    peer, line = pair
    with pytest.raises(ValueError):
        line.send_line("#1 ID", soon())
    line.send_line("#1 ID\n", soon())
    assert peer.recv(100) == b"#1 ID\n"
