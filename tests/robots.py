"""Robot geometries and SMR rings shared by the tests."""

from robocal.solver.robot import KUKA_LIKE, robot_from_degrees  # noqa: F401 (KUKA_LIKE: shared)

TARGETS = {"A": [60.0, 0.0, 35.0], "B": [-30.0, 52.0, 35.0], "C": [-30.0, -52.0, 35.0]}

# Craig's modified DH, PUMA-like on a pedestal; axes 2 and 3 parallel.
PUMA_LIKE = robot_from_degrees(
    "puma-like",
    "mdh",
    [
        (0.0, 660.0, 0.0, 0.0, (-160.0, 160.0)),
        (0.0, 0.0, 0.0, -90.0, (-225.0, 45.0)),
        (432.0, 150.0, 0.0, 0.0, (-45.0, 225.0)),
        (20.0, 432.0, 0.0, -90.0, (-110.0, 170.0)),
        (0.0, 0.0, 0.0, 90.0, (-100.0, 100.0)),
        (0.0, 100.0, 0.0, -90.0, (-266.0, 266.0)),
    ],
)

# UR5's DH table (a, d, theta, alpha): no parallel-axis Hayati beta, a wrist offset at joint 4
UR5 = robot_from_degrees(
    "ur5",
    "dh",
    [
        (0.0, 89.159, 0.0, 90.0, (-360.0, 360.0)),
        (-425.0, 0.0, 0.0, 0.0, (-180.0, 0.0)),
        (-392.25, 0.0, 0.0, 0.0, (-160.0, 160.0)),
        (0.0, 109.15, 0.0, 90.0, (-360.0, 360.0)),
        (0.0, 94.65, 0.0, -90.0, (-360.0, 360.0)),
        (0.0, 82.3, 0.0, 0.0, (-360.0, 360.0)),
    ],
)
# A 7-axis arm (KUKA LBR iiwa 14-like, standard DH)
IIWA_LIKE = robot_from_degrees(
    "iiwa-like",
    "dh",
    [
        (0.0, 360.0, 0.0, -90.0, (-170.0, 170.0)),
        (0.0, 0.0, 0.0, 90.0, (-120.0, 120.0)),
        (0.0, 420.0, 0.0, 90.0, (-170.0, 170.0)),
        (0.0, 0.0, 0.0, -90.0, (-120.0, 120.0)),
        (0.0, 400.0, 0.0, -90.0, (-170.0, 170.0)),
        (0.0, 0.0, 0.0, 90.0, (-120.0, 120.0)),
        (0.0, 126.0, 0.0, 0.0, (-175.0, 175.0)),
    ],
)
