"""Physical plausibility: readings in the wrong units and geometry changes no arm can have are
told apart from real campaigns, of any arm size, however close their poses (issue 21, point 5)."""

import re

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.solver.measurements import Measurements
from robocal.solver.plausibility import (
    TARGET_MOVE_MM,
    check_cell_angles,
    check_layout,
    check_units,
    implausible_changes,
)
from robocal.solver.robot import IRB2600, KUKA_LIKE, Joint, Robot
from tests.robots import IIWA_LIKE, PUMA_LIKE, TARGETS, UR5

ROBOTS = [IRB2600, KUKA_LIKE, PUMA_LIKE, UR5, IIWA_LIKE]


def campaign(robot, n=40, seed=1):
    """A simulated campaign of the robot with the shared SMR ring, and its SMRs (K, 3)."""
    meas = VirtualCell.random(robot, TARGETS, seed=seed).campaign(n, seed=seed)
    return meas, np.array([TARGETS[t] for t in meas.target_names])


@pytest.mark.parametrize("robot", ROBOTS, ids=lambda r: r.name)
def test_wrong_units_named_right_ones_pass(robot):
    meas, targets = campaign(robot)
    right = check_units(robot, targets, meas.q, meas.xyz)
    print(f"{robot.name}: spread ratio {right.ratio:.4f}")
    assert right.plausible and abs(np.log(right.ratio)) < 0.01
    for unit, scale in (("metres", 1000.0), ("inches", 25.4), ("centimetres", 10.0)):
        c = check_units(robot, targets, meas.q, meas.xyz / scale)
        assert c.likely == (unit, "degrees"), (unit, c)
        assert f"x, y, z look like {unit}; give them in mm" in c.reason()
    c = check_units(robot, targets, np.deg2rad(meas.q), meas.xyz)
    assert c.likely == ("mm", "radians"), c
    assert c.reason().endswith(f"q1..q{robot.n_joints} look like radians; give them in degrees")
    c = check_units(robot, targets, np.deg2rad(meas.q), meas.xyz / 1000.0)
    assert c.likely == ("metres", "radians"), c


@pytest.mark.parametrize("robot", ROBOTS, ids=lambda r: r.name)
def test_cell_angles_in_radians_named(robot):
    """A cell.json whose theta and alpha were written in radians (read as degrees)."""
    meas, targets = campaign(robot)
    assert check_cell_angles(robot, targets, meas.q, meas.xyz) is None  # twists of 90 deg
    as_written = Robot(
        robot.name,
        robot.convention,
        tuple(
            Joint(j.a, j.d, np.deg2rad(j.theta), np.deg2rad(j.alpha), j.limits)
            for j in robot.joints
        ),
    )
    check = check_cell_angles(as_written, targets, meas.q, meas.xyz)
    print(f"{robot.name}: {check.degrees_rms_mm:.1f} mm as degrees, {check.radians_rms_mm:.2f}")
    assert check.reason().endswith("read as radians: give the robot's angles in degrees")


@pytest.mark.parametrize("sd_deg", [0.1, 1.0, 5.0])
@pytest.mark.parametrize("robot", ROBOTS, ids=lambda r: r.name)
def test_poses_close_together_are_no_unit_mistake(robot, sd_deg):
    vc = VirtualCell.random(robot, TARGETS, seed=5)
    rng = np.random.default_rng(0)
    q = vc.campaign(1, seed=5).q + np.deg2rad(sd_deg) * rng.normal(size=(30, robot.n_joints))
    xyz = vc.true_points(q) + rng.normal(scale=0.01, size=(30, 3, 3))
    meas = Measurements([str(i) for i in range(30)], q, tuple(TARGETS), xyz)
    targets = np.array([TARGETS[t] for t in meas.target_names])
    assert check_units(robot, targets, meas.q, meas.xyz).plausible


def changed(robot, **by):
    """The robot with named parameters changed (mm, degrees for angles)."""
    names = robot.param_names()
    p = robot.param_vector()
    for name, v in by.items():
        p[names.index(name)] += v if name[0] in "ad" and name[:5] != "alpha" else np.deg2rad(v)
    return robot.with_params(p)


def test_implausible_changes_named_with_their_limits():
    limit = 0.005 * IRB2600.reach_mm
    ok = changed(IRB2600, a2=limit * 0.9, d4=-limit * 0.9, theta4=4.9, alpha3=1.9, beta2=-1.9)
    assert implausible_changes(IRB2600, ok).changes == []
    assert implausible_changes(IRB2600, ok).reason() is None
    bad = changed(IRB2600, a2=-899.1, theta4=6.0, alpha3=2.5, d4=limit * 1.1)
    check = implausible_changes(IRB2600, bad)
    assert [c.name for c in check.changes] == ["a2", "alpha3", "theta4", "d4"]
    assert check.reason().startswith(
        f"a2 changed by -899.1 mm from nominal (more than {limit:.3g} mm for an arm of 2,658 mm "
        "reach), alpha3 by +2.50 deg, theta4 by +6.00 deg, d4 by"
    )
    assert check.reason().endswith("check the units of the data and the nominal geometry")


def test_limits_scale_with_the_arm():
    small = implausible_changes(UR5, changed(UR5, a2=8.0)).changes
    large = implausible_changes(IRB2600, changed(IRB2600, a2=8.0)).changes
    assert [c.name for c in small] == ["a2"] and large == []


def test_smrs_found_far_from_the_cell_are_named_with_the_motion_that_explains_them():
    """A layout placed in another flange frame (turned about the flange axis, or tilted) is told
    as that motion; one mistyped SMR as a position to check; a drawing's few mm is nothing."""
    from scipy.spatial.transform import Rotation

    names = ("A", "B", "C", "D")
    nominal = np.array([[60.0, 0, 35], [-30, 52, 35], [-30, -52, 35], [0, 0, 80]])
    rng = np.random.default_rng(3)
    drawn = nominal + rng.normal(scale=1.0, size=nominal.shape)  # a drawing's error
    assert check_layout(names, nominal, drawn).reason() is None

    for angle, axis, about, moved in (
        (180.0, [0, 0, 1], "the flange axis (z)", "A, B, C"),
        (90.0, [0, 0, -1], "the flange axis (z)", "A, B, C"),
        (30.0, [1, 0, 0], "an axis ", "B, C, D"),
    ):
        R = Rotation.from_rotvec(np.deg2rad(angle) * np.array(axis, float)).as_matrix()
        found = drawn @ R.T + [0.5, 0, 0]
        why = check_layout(names, nominal, found).reason()
        turned = re.search(r"turned (\d+) deg about ", why)
        assert turned and abs(int(turned[1]) - angle) <= 2, why
        assert why[turned.end() :].startswith(about), why
        assert why.startswith(f"SMR {moved} identified up to"), why

    typo = drawn.copy()
    typo[1, 0] += 40.0  # one SMR's x mistyped
    why = check_layout(names, nominal, typo).reason()
    assert why.startswith("SMR B identified up to 3") and "check the cell's SMR positions" in why
    assert "turned" not in why
    one = check_layout(("A",), nominal[:1], nominal[:1] + [0, 0, 2 * TARGET_MOVE_MM])
    assert one.reason().startswith("SMR A identified up to 50") and "turned" not in one.reason()


# SMRs on a large fixture, 300 mm from the flange's axis (a UR10's nest plate, a welding gun)
FAR = {"A": [300.0, 0.0, 100.0], "B": [-150.0, 260.0, 100.0], "C": [-150.0, -260.0, 100.0]}


@pytest.mark.parametrize("n", [6, 10, 30])
@pytest.mark.parametrize("robot", ROBOTS, ids=lambda r: r.name)
def test_radians_named_with_smrs_far_from_the_flange(robot, n):
    """Joints in radians on a UR10-like arm with its SMRs 300 mm off the flange passed the unit
    check (spread ratio 2.40 on 6 poses, 2.47 on 10, inside the band of 2.5): the spread of the
    whole ring, which no joint value changes, hid how little the arm moved; `check` then said
    'recalibrate' (exit 3) and `evaluate` 'the data is not of the model's cell'. Each SMR's own
    spread is what the joints move."""
    vc = VirtualCell.random(robot, FAR, seed=2)
    meas = vc.campaign(n, seed=2)
    targets = np.array([FAR[t] for t in meas.target_names])
    right = check_units(robot, targets, meas.q, meas.xyz)
    assert right.plausible and abs(np.log(right.ratio)) < 0.05, right
    c = check_units(robot, targets, np.deg2rad(meas.q), meas.xyz)
    print(f"{robot.name} {n} poses: ratio {right.ratio:.3f}, radians {c.ratio:.2f}")
    assert c.likely == ("mm", "radians"), c
    for unit, scale in (("metres", 1000.0), ("inches", 25.4)):
        assert check_units(robot, targets, meas.q, meas.xyz / scale).likely == (unit, "degrees")
    # one pose of the ring: no SMR moves, the ring's own spread still tells a length unit
    one = check_units(robot, targets, meas.q[:1], meas.xyz[:1] / 1000.0)
    assert one.likely == ("metres", "degrees"), one
    assert "(RMS from their centroid)" in one.reason(), one.reason()
