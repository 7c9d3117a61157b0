"""The noise floor and its source: SMR distances, repeated poses, the tracker's spec or the default."""

import numpy as np
import pytest

from robocal.solver.effects import Inputs
from robocal.solver.noise import from_repeats, from_spec, noise_floor

SIGMA = 0.01  # mm a coordinate


def readings(poses, repeats, smrs, seed=0):
    """Joints and readings (tracker noise SIGMA a coordinate) of `poses` poses measured `repeats`
    times each, with `smrs` SMRs 100 mm apart about 2 m away."""
    rng = np.random.default_rng(seed)
    q = np.repeat(rng.uniform(-1, 1, size=(poses, 6)), repeats, axis=0)
    centre = rng.uniform(-300, 300, size=(poses, 1, 3)) + [2000.0, 0.0, 0.0]
    true = np.repeat(centre + 100.0 * np.eye(3)[:smrs][None], repeats, axis=0)
    return q, true + rng.normal(scale=SIGMA, size=true.shape)


def test_repeated_poses_measure_the_floor_of_one_smr():
    q, meas = readings(20, 3, 1)
    f = noise_floor(q, meas, Inputs(q))
    assert f.source == "repeated readings of the same pose in the data"
    assert f.mm == pytest.approx(np.sqrt(3) * SIGMA, rel=0.2)


def test_too_few_repeats_leave_the_spec_and_the_default_is_said():
    q, meas = readings(4, 2, 1)  # 4 degrees of freedom
    assert from_repeats(q, meas) is None
    f = noise_floor(q, meas, Inputs(q))
    assert f.source.startswith("tracker specification (default MPE 10 um + 2.5 um/m")
    # MPE/2 a coordinate at ~2 m: 0.5 x (10 + 2.5 x 2) um
    assert f.mm == pytest.approx(np.sqrt(3) * 0.5e-3 * 15.0, rel=0.05)
    given = noise_floor(q, meas, Inputs(q), {"mpe_um": 20.0, "mpe_um_per_m": 0.0})
    assert given.source.startswith("tracker specification (MPE 20 um + 0 um/m")
    assert given.mm == pytest.approx(np.sqrt(3) * 0.01)


def test_smr_distances_come_first():
    q, meas = readings(20, 1, 3)
    f = noise_floor(q, meas, Inputs(q), {"mpe_um": 100.0})
    assert f.source == "SMR-to-SMR distances in the data"
    assert f.mm == pytest.approx(np.sqrt(3) * SIGMA, rel=0.25)


def test_the_spec_floor_of_no_reading_is_zero_not_nan():
    assert from_spec(np.full((2, 1, 3), np.nan), None).mm == 0.0
