"""Robot geometries and SMR rings shared by the tests."""

from solver.robot import robot_from_degrees

TARGETS = {"A": [60.0, 0.0, 35.0], "B": [-30.0, 52.0, 35.0], "C": [-30.0, -52.0, 35.0]}

# Standard DH, KUKA KR 16-like proportions; axes 2 and 3 parallel.
KUKA_LIKE = robot_from_degrees("kuka-like", "dh", [
    (260.0, 675.0, 0.0, -90.0, (-185.0, 185.0)),
    (680.0, 0.0, -90.0, 0.0, (-65.0, 140.0)),
    (35.0, 0.0, 0.0, -90.0, (-210.0, 66.0)),
    (0.0, 670.0, 0.0, 90.0, (-350.0, 350.0)),
    (0.0, 0.0, 0.0, -90.0, (-130.0, 130.0)),
    (0.0, 158.0, 0.0, 0.0, (-350.0, 350.0)),
])

# Craig's modified DH, PUMA-like on a pedestal; axes 2 and 3 parallel.
PUMA_LIKE = robot_from_degrees("puma-like", "mdh", [
    (0.0, 660.0, 0.0, 0.0, (-160.0, 160.0)),
    (0.0, 0.0, 0.0, -90.0, (-225.0, 45.0)),
    (432.0, 150.0, 0.0, 0.0, (-45.0, 225.0)),
    (20.0, 432.0, 0.0, -90.0, (-110.0, 170.0)),
    (0.0, 0.0, 0.0, 90.0, (-100.0, 100.0)),
    (0.0, 100.0, 0.0, -90.0, (-266.0, 266.0)),
])
