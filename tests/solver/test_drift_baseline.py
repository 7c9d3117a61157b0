"""The baseline of a check's change (solver.drift) is the model's first checks before any change
was found: two clean checks, then two moved +0.15 mm in x, and the fourth said 0.100 mm from a
baseline that held the third (the mean of 0, 0 and 0.15)."""

from __future__ import annotations

import numpy as np

from robocal.solver import drift

POSES = 6


def test_a_moved_check_does_not_enter_the_baseline():
    rng = np.random.default_rng(4)
    bias = rng.normal(scale=0.05, size=(POSES, 3))
    moved = np.array([0.15, 0.0, 0.0])
    past: list[np.ndarray] = []
    stats: list[tuple[float, float]] = []
    said = []
    for k in range(5):
        now = (
            bias + rng.normal(scale=0.01 / np.sqrt(3.0), size=(POSES, 3)) + (moved if k >= 2 else 0)
        )
        c = drift.since_baseline(now, np.array(past).reshape(-1, POSES, 3), stats, 0.03)
        stats.append((c.z, c.cusum) if c else (0.0, 0.0))
        said.append((c.rms_mm, c.verdict) if c else None)
        past.append(now)
    print(said)
    assert said[2][1] == "recalibrate" and drift.baseline_checks(stats) == 2
    for rms, verdict in said[2:]:
        assert abs(rms - 0.15) < 0.01 and verdict == "recalibrate"


def test_clean_checks_make_a_baseline_of_three():
    assert drift.baseline_checks([(0.0, 0.0), (0.3, 0.0), (1.2, 0.7), (0.1, 0.3)]) == 3
    assert drift.baseline_checks([(0.0, 0.0), (9.0, 8.5)]) == 1
