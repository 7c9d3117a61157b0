"""What the position-uncertainty coverage suites share: the arms, their SMRs, the number of
calibrations and test positions, and the count of true errors within U."""

from __future__ import annotations

import numpy as np

from robocal.solver.robot import IRB2600
from tests.robots import PUMA_LIKE, UR5

TARGETS = {"A": [60.0, 0.0, 40.0], "B": [-30.0, 52.0, 40.0], "C": [-30.0, -52.0, 40.0]}
ARMS = {"irb2600": IRB2600, "ur5": UR5, "puma": PUMA_LIKE}
SEEDS = 68  # x 3 arms: 204 calibrations
TEST_POSES = 20


def coverage(case, kinds, shrink: float = 1.0) -> tuple[float, dict]:
    """The fraction of true errors within U over every arm and seed (case(robot, seed, kind,
    shrink) -> (error, U), kinds taken in turn), and per kind."""
    within, by_kind = [], {}
    for robot in ARMS.values():
        for seed in range(SEEDS):
            kind = kinds[seed % len(kinds)]
            err, U = case(robot, seed, kind, shrink)
            within.append(err <= U)
            by_kind.setdefault(kind, []).append(float(np.mean(err <= U)))
    return float(np.mean(within)), {k: round(float(np.mean(v)), 3) for k, v in by_kind.items()}
