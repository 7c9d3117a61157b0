"""The acquisition's SMR predictor before registration: the most probable base and SMRs given the
first readings and the survey's and drawing's priors, and how far off it says it may be."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.drivers.predictor import SmrPredictor
from robocal.drivers.simulated_cell import surveyed_base
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS


@pytest.mark.parametrize("seed", range(6))
def test_early_predictions_fall_within_the_reach_they_state(seed):
    true = VirtualCell.random(IRB2600, TARGETS, seed=seed)
    rng = np.random.default_rng([seed, 3])
    q = true.sample_poses(6, rng)
    meas = true.measure(q, rng)
    names = list(TARGETS)
    p = SmrPredictor(IRB2600, [TARGETS[n] for n in names], names, surveyed_base(true.base, seed))
    seen = np.isfinite(meas).all(axis=-1)
    wide = p.reach_mm(q[0])
    for i in range(1, 5):
        assert p.update(q[:i], meas[:i]) == "rigid"
        reach = p.reach_mm(q[i])
        err = np.linalg.norm(p.predict(q[i]) - meas[i], axis=-1)[seen[i]]
        assert err.max() <= reach, (i, err, reach)
    # four poses' readings narrow the search well inside the survey's
    assert reach < wide / 3, (reach, wide)
