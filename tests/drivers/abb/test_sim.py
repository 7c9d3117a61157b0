"""The simulated controller's device logic, driven line by line on a VirtualClock."""

import numpy as np
import pytest

from robocal.drivers.abb import protocol as p
from robocal.drivers.world import ACCEL_S
from robocal.solver.robot import IRB2600

LO, HI = np.rad2deg(IRB2600.lower), np.rad2deg(IRB2600.upper)


def ask(device, line):
    return p.parse_reply(device.handle_line(line))


def movej(q_deg, request_id=10):
    return p.encode_request(p.Request(request_id, "MOVEJ", tuple(q_deg)))


def status(device):
    return p.parse_status(ask(device, "#1 STATUS").fields)


def test_hello_and_idle(device):
    limits = tuple(zip(LO.round(4).tolist(), HI.round(4).tolist(), strict=True))
    assert p.parse_hello(ask(device, "#1 HELLO").fields) == p.HelloInfo("IRB2600-SIM", 1, 6, limits)
    assert status(device) == p.Status("IDLE", 0)
    assert device.received == ["#1 HELLO", "#1 STATUS"]


@pytest.mark.parametrize(
    "q_deg, slowest_s",
    [
        ([87.5, 0, 0, 0, 0, 0], 87.5 / 175),  # main axes at 175 deg/s
        ([0, 0, 0, 0, 0, 180], 180 / 360),  # wrist axes at 360 deg/s
        ([-35, 70, -17.5, 90, 0, 0], 70 / 175),  # the slowest joint sets the duration
        ([0, 0, 0, 0, 0, 0], 0.0),  # no travel still ramps
    ],
)
def test_move_duration_follows_joint_speeds(device, world, q_deg, slowest_s):
    expected = world.move_duration(np.deg2rad(q_deg))
    reply = ask(device, movej(q_deg))
    assert isinstance(reply, p.Reply)
    assert p.parse_duration(reply.fields) == pytest.approx(expected, abs=1e-3)
    assert expected == pytest.approx(slowest_s + ACCEL_S)


def test_moving_then_inpos_after_the_duration(device, clock):
    target = [10.0, -20.5, 30.0, 0.0, 45.0, 90.0]
    duration = p.parse_duration(ask(device, movej(target, 7)).fields)
    clock.sleep(duration / 2)
    assert status(device) == p.Status("MOVING", 7)
    halfway = np.array(p.parse_joints(ask(device, "#2 JOINTS").fields, 6))
    assert 0 < halfway[5] < 90
    clock.sleep(duration / 2 - 1e-3)
    assert status(device).state == "MOVING"
    clock.sleep(2e-3)
    assert status(device) == p.Status("INPOS", 7)
    assert p.parse_joints(ask(device, "#3 JOINTS").fields, 6) == pytest.approx(target, abs=1e-4)


@pytest.mark.parametrize("joint", range(6))
@pytest.mark.parametrize("side", ["low", "high"])
def test_limits_refused(device, world, joint, side):
    q = np.zeros(6)
    q[joint] = LO[joint] - 0.001 if side == "low" else HI[joint] + 0.001
    reply = ask(device, movej(q, 4))
    assert isinstance(reply, p.ErrorReply) and reply.code == "LIMIT"
    assert reply.message.startswith(f"joint {joint + 1} ")
    assert not world.moving() and status(device) == p.Status("IDLE", 0)
    assert device.moves == []


def test_limits_are_inclusive(device):
    assert isinstance(ask(device, movej(HI)), p.Reply)


def test_busy_while_moving(device, clock):
    ask(device, movej([90, 0, 0, 0, 0, 0], 5))
    reply = ask(device, movej([0, 0, 0, 0, 0, 0], 6))
    assert reply == p.ErrorReply(6, "BUSY", "executing move 5")
    assert status(device).move_id == 5


def test_stop_halts_where_the_arm_is(device, world, clock):
    duration = p.parse_duration(ask(device, movej([90, 0, 0, 0, 0, 0], 5)).fields)
    clock.sleep(duration / 2)
    assert ask(device, "#2 STOP") == p.Reply(2)
    assert status(device) == p.Status("STOPPED", 5)
    q_stop = p.parse_joints(ask(device, "#3 JOINTS").fields, 6)[0]
    clock.sleep(duration)
    assert p.parse_joints(ask(device, "#4 JOINTS").fields, 6)[0] == q_stop
    assert 0 < q_stop < 90 and not world.moving()
    assert ask(device, "#5 STOP") == p.Reply(5)  # STOP when still: harmless, state unchanged
    assert status(device).state == "STOPPED"


def test_fault_until_reset_not_hello(device, clock):
    ask(device, movej([90, 0, 0, 0, 0, 0], 5))
    clock.sleep(0.3)
    device.fault(50204)
    assert status(device) == p.Status("FAULT", 5, 50204)
    assert ask(device, movej([0] * 6, 6)) == p.ErrorReply(6, "FAULT", "50204")
    assert isinstance(ask(device, "#7 HELLO"), p.Reply)
    assert status(device).state == "FAULT"
    assert isinstance(ask(device, "#8 JOINTS"), p.Reply)  # reading still works
    assert ask(device, "#9 RESET") == p.Reply(9)
    assert status(device) == p.Status("STOPPED", 5)  # the fault interrupted move 5
    assert isinstance(ask(device, movej([0] * 6, 10)), p.Reply)


@pytest.mark.parametrize(
    "line, expected",
    [
        ("garbage", "#0 ERR BAD_REQUEST"),
        ("#5 FLY", "#5 ERR BAD_REQUEST"),
        ("#5 MOVEJ 1 2 3", "#5 ERR BAD_REQUEST MOVEJ needs 6 values, got 3"),
        ("#5 MOVEJ 1 2 3 nan 5 6", "#5 ERR BAD_REQUEST"),
        ("#5 MOVEJ 1 2 3 1e999 5 6", "#5 ERR BAD_REQUEST"),
    ],
)
def test_bad_requests(device, world, line, expected):
    assert device.handle_line(line).startswith(expected)
    assert not world.moving() and device.received == [line]
