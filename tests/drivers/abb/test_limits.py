"""Joint limits from the controller (HELLO): a cell wider than the controller is refused at
connect, and every MOVEJ is checked against the tighter of the two before it is written."""

import numpy as np
import pytest

from robocal.drivers.abb import protocol as p
from robocal.drivers.abb.client import ControllerClient, ControllerError, LimitError
from robocal.drivers.abb.sim import SimulatedController, serve_controller
from robocal.solver.robot import IRB2600, Joint, Robot


def with_limits(robot, joint, lo_deg, hi_deg, name="narrow"):
    """`robot` with joint `joint` (0-based) limited to [lo_deg, hi_deg]."""
    joints = list(robot.joints)
    j = joints[joint]
    joints[joint] = Joint(j.a, j.d, j.theta, j.alpha, (np.deg2rad(lo_deg), np.deg2rad(hi_deg)))
    return Robot(name, robot.convention, tuple(joints))


def test_hello_limits_round_trip():
    info = p.HelloInfo("IRB2600-01", 1, 2, ((-180.0, 180.0), (-95.5, 155.0001)))
    fields = p.hello_fields(info)
    assert fields == ("IRB2600-01", "1", "2", "-180", "180", "-95.5", "155.0001")
    assert p.parse_hello(fields) == info
    assert p.parse_hello(("A", "1", "2")).limits_deg is None  # a controller that does not say


def test_a_six_joint_hello_with_a_long_name_fits_a_reply():
    worst = ((-99999.9999, 99999.9999),) * 6
    line = p.encode_reply(p.Reply(99999, p.hello_fields(p.HelloInfo("N" * 32, 1, 6, worst))))
    assert len(line) <= p.MAX_REPLY and p.parse_reply(line).fields[3] == "-99999.9999"


@pytest.mark.parametrize(
    "fields",
    [
        ("A", "1", "2", "-1", "1"),  # one pair for two joints
        ("A", "1", "1", "-1", "1", "2"),
        ("A", "1", "1", "1", "-1"),  # empty range
        ("A", "1", "1", "0", "0"),
        ("A", "1", "1", "-1", "nan"),
    ],
)
def test_bad_hello_limits_refused(fields):
    with pytest.raises(p.ProtocolError):
        p.parse_hello(fields)


def test_a_cell_wider_than_the_controller_is_refused_at_connect(world, clock):
    controller_robot = with_limits(IRB2600, 1, -60.0, 120.0)
    device = SimulatedController(world, controller_robot, clock)
    with serve_controller(device) as server:
        with pytest.raises(ControllerError) as info:
            ControllerClient(server.url, IRB2600, timeout_s=1.0)
    message = str(info.value)
    assert "joint 2" in message and "[-95, 155]" in message and "[-60, 120]" in message
    assert not isinstance(info.value, LimitError)
    assert [line for _, line in device.arrivals if " MOVEJ " in line] == []


def test_moves_are_checked_against_the_tighter_limits(server, device):
    cell_robot = with_limits(IRB2600, 0, -90.0, 90.0)  # the cell is the tighter one here
    with ControllerClient(server.url, cell_robot, timeout_s=1.0) as c:
        lo, hi = c.limits_deg
        assert lo[0] == pytest.approx(-90.0) and hi[1] == pytest.approx(155.0)
        with pytest.raises(LimitError):
            c.move_abs_j([120.0, 0, 0, 0, 0, 0])  # inside the controller's, outside the cell's
        c.move_abs_j([80.0, 0, 0, 0, 0, 0])
    assert [line for _, line in device.arrivals if " MOVEJ " in line] == [
        f"#{device.moves[0][1]} MOVEJ 80.0000 0.0000 0.0000 0.0000 0.0000 0.0000"
    ]


def test_limits_tighten_to_the_controller_within_rounding(server):
    nudged = with_limits(IRB2600, 4, -120.00001, 120.00001)  # beyond, by less than the wire's 1e-4
    with ControllerClient(server.url, nudged, timeout_s=1.0) as c:
        lo, hi = c.limits_deg
        assert (lo[4], hi[4]) == pytest.approx((-120.0, 120.0), abs=1e-9)
        with pytest.raises(LimitError):
            c.move_abs_j([0, 0, 0, 0, 120.00009, 0])
