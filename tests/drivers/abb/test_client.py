"""ControllerClient over real 127.0.0.1 sockets against the simulated controller, with faults."""

import math
import time

import numpy as np
import pytest

from robocal.drivers.abb import protocol as p
from robocal.drivers.abb.client import (
    BusyError,
    ControllerClient,
    ControllerConnectionError,
    ControllerError,
    ControllerTimeout,
    FaultError,
    LimitError,
    MoveStopped,
    check_target,
)
from robocal.solver.robot import IRB2600, Joint, Robot

LO, HI = np.rad2deg(IRB2600.lower), np.rad2deg(IRB2600.upper)
TARGET = [10.0, -20.5, 30.0, 0.0, 45.0, 90.0]
SHORT = 0.05  # s: the reply timeout where a test provokes timeouts (silence)


@pytest.fixture
def client(server):
    with ControllerClient(server.url, IRB2600, timeout_s=1.0) as c:
        yield c


@pytest.fixture
def quick(server):
    """A client that gives up on a reply after SHORT seconds."""
    with ControllerClient(server.url, IRB2600, timeout_s=SHORT) as c:
        yield c


def sent_moves(device):
    """Every MOVEJ that reached the controller, as parsed requests."""
    return [p.parse_request(line) for line in device.received if " MOVEJ " in line]


def within_limits(values) -> bool:
    return bool(IRB2600.within_limits(np.deg2rad(np.array(values)))[0])


def test_move_poll_joints_cycle(client, device, clock):
    wall = time.monotonic()
    limits = tuple(zip(LO.round(4).tolist(), HI.round(4).tolist(), strict=True))
    assert client.info == p.HelloInfo("IRB2600-SIM", 1, 6, limits)
    assert client.status().state == "IDLE"
    duration = client.move_abs_j(TARGET)
    assert duration == pytest.approx(0.6 + 90 / 360, abs=1e-3)
    final = client.wait_in_position(clock, poll_s=0.2)
    assert final == p.Status("INPOS", client.last_move.id)
    assert duration <= clock.now() < duration + 0.2 + 1e-9  # simulated time, polled every 0.2 s
    np.testing.assert_allclose(client.joints(), TARGET, atol=1e-4)
    assert time.monotonic() - wall < 1.0
    assert [m.values for m in sent_moves(device)] == [tuple(TARGET)]


@pytest.mark.parametrize(
    "q",
    [
        [0, 200, 0, 0, 0, 0],
        [0, 0, 0, 0, 0, 400.001],
        [-180.0001, 0, 0, 0, 0, 0],
        [0, 155.00006, 0, 0, 0, 0],  # 155.0001 on the wire: the check is on what is sent
        [0, 0, 0, math.nan, 0, 0],
        [0, 0, 0, 0, math.inf, 0],
        [0, 0, 0, 0, 0],
        [0] * 7,
        [[0] * 6],
        "fast",
    ],
)
def test_limit_error_raised_locally_and_nothing_sent(client, device, q):
    before = list(device.received)
    with pytest.raises(LimitError):
        client.move_abs_j(q)
    assert device.received == before
    assert client.status().state == "IDLE"


def test_no_out_of_limit_movej_ever_reaches_the_controller(client, device, clock):
    rng = np.random.default_rng(3)
    span = HI - LO
    for q in LO + rng.uniform(-0.2, 1.2, size=(40, 6)) * span:
        try:
            client.move_abs_j(q)
            client.wait_in_position(clock)
        except LimitError:
            pass
    client.move_abs_j(LO)  # the limits themselves are allowed
    moves = sent_moves(device)
    assert 0 < len(moves) < 40
    assert all(within_limits(m.values) for m in moves)


def test_value_rounding_onto_the_limit_is_allowed():
    assert check_target([0, 155.00004, 0, 0, 0, 0], IRB2600.lower, IRB2600.upper)[1] == 155.0


def test_the_check_guards_the_wire_itself(client, device):
    before = list(device.received)
    with pytest.raises(LimitError):
        client._roundtrip(p.Request(4242, "MOVEJ", (0.0, 200.0, 0.0, 0.0, 0.0, 0.0)))
    assert device.received == before


def test_a_controller_without_limits_is_refused_unless_the_robot_is_built_in(server, device):
    device.report_limits = False  # a controller that does not say its limits at HELLO
    wide = Robot(
        "wide", "dh", tuple(Joint(j.a, j.d, j.theta, j.alpha, (-7.0, 7.0)) for j in IRB2600.joints)
    )
    with pytest.raises(ControllerError, match="does not report its joint limits"):
        ControllerClient(server.url, wide, timeout_s=1.0)
    # a built-in robot: its own limits stand in for the controller's
    with ControllerClient(server.url, IRB2600, timeout_s=1.0) as c:
        with pytest.raises(LimitError, match="outside"):
            c.move_abs_j([0, 200, 0, 0, 0, 0])
    assert device.moves == []


def test_reconnect_after_drop(client, server, device, clock):
    client.move_abs_j(TARGET)
    server.drop_connections()
    assert client.status().state == "MOVING"
    client.wait_in_position(clock)
    server.drop_connections()
    np.testing.assert_allclose(client.joints(), TARGET, atol=1e-4)
    assert sum(1 for line in device.received if line.endswith(" HELLO")) == 3


def test_movej_lost_before_the_controller_is_sent_again_once(client, server, device, clock):
    server.drop_next(execute=False)
    duration = client.move_abs_j(TARGET)
    assert duration == pytest.approx(0.85, abs=1e-3)
    client.wait_in_position(clock)
    assert len(sent_moves(device)) == 1


def test_movej_reply_lost_is_not_resent(quick, server, device, clock):
    server.silence()  # the controller executes the MOVEJ but its reply never arrives
    duration = quick.move_abs_j(TARGET)
    assert quick.last_move.duration_s is None and duration == quick.max_move_s
    assert quick.wait_in_position(clock).state == "INPOS"
    assert len(sent_moves(device)) == 1


def test_movej_reply_lost_until_after_arrival(client, server, device, clock, monkeypatch):
    handle_line = device.handle_line

    def slow_network(line):  # the reply is lost, and the arm arrives before we ask STATUS
        reply = handle_line(line)
        if " MOVEJ " in line:
            clock.sleep(5.0)
        return reply

    monkeypatch.setattr(device, "handle_line", slow_network)
    server.drop_next(execute=True)
    assert client.move_abs_j(TARGET) == 0.0
    assert client.wait_in_position(clock).state == "INPOS"
    assert len(sent_moves(device)) == 1


def test_garbage_on_connect_tolerated(server, device):
    server.garbage(on_connect=True)
    with ControllerClient(server.url, IRB2600, timeout_s=1.0) as c:
        assert c.info.name == "IRB2600-SIM"
        assert c.status().state == "IDLE"
        server.garbage(b"\x00\xffnoise without newline ")
        assert c.status().state == "IDLE"


def test_reply_to_another_request_is_ignored(client, server):
    server.garbage(b"#1 OK FAULT 50204 3\n")  # well formed, but not our id
    assert client.status().state == "IDLE"


def test_silence_once_is_retried(quick, server):
    server.silence()
    assert quick.status().state == "IDLE"  # the first STATUS timed out; the retry answered


def test_timeout_when_silent(quick, server):
    server.silence(10)
    wall = time.monotonic()
    with pytest.raises(ControllerTimeout):
        quick.status()
    # 1 + 2 retries, each SHORT: none of them is answered, so a client waiting for a reply would
    # wait for ever (the margin is for a loaded machine)
    assert time.monotonic() - wall < 3 * SHORT + 2.0


def test_connection_refused(server):
    url = server.url
    server.close()
    with pytest.raises(ControllerConnectionError):
        ControllerClient(url, IRB2600, timeout_s=SHORT, retries=1)


def test_fault_stops_the_wait_and_only_reset_clears_it(client, server, clock):
    client.move_abs_j([90, 0, 0, 0, 0, 0])
    clock.sleep(0.3)
    server.fault(50204)
    with pytest.raises(FaultError) as info:
        client.wait_in_position(clock)
    assert info.value.code == 50204
    with pytest.raises(FaultError):
        client.move_abs_j(TARGET)
    client.connect()  # a reconnect (HELLO) acknowledges nothing
    assert client.status().state == "FAULT"
    client.reset()
    assert client.status().state == "STOPPED"


def test_stop_ends_the_wait(client, clock):
    client.move_abs_j([90, 0, 0, 0, 0, 0])
    clock.sleep(0.3)
    client.stop()
    with pytest.raises(MoveStopped):
        client.wait_in_position(clock)


def test_busy(client):
    client.move_abs_j([90, 0, 0, 0, 0, 0])
    with pytest.raises(BusyError):
        client.move_abs_j(TARGET)


def test_wait_times_out_on_the_given_clock(client, clock):
    wall = time.monotonic()
    client.move_abs_j([170, 0, 0, 0, 0, 0])  # 1.57 s
    with pytest.raises(ControllerTimeout):
        client.wait_in_position(clock, poll_s=0.1, timeout_s=1.0)
    assert 1.0 <= clock.now() < 1.2 and time.monotonic() - wall < 1.0


def test_another_client_moving_the_arm_is_noticed(client, server, clock):
    client.move_abs_j([10, 0, 0, 0, 0, 0])
    client.wait_in_position(clock)
    with ControllerClient(server.url, IRB2600, timeout_s=1.0) as other:
        other.move_abs_j(TARGET)
    with pytest.raises(ControllerError, match="reports move"):
        client.wait_in_position(clock)


def test_joint_count_mismatch_refused(server):
    five = Robot("five", "dh", IRB2600.joints[:5])
    with pytest.raises(ControllerError, match="6 joints"):
        ControllerClient(server.url, five, timeout_s=1.0)
