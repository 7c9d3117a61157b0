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
