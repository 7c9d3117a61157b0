"""The fleet's numerics: clean fleets rarely flag, one bent arm cannot hide, jumps beyond the
standard errors are flagged and those within are not."""

from __future__ import annotations

import numpy as np

from robocal.solver.fleet import FAMILY_RATE, MIN_ARMS, fleet_spread, jumps


def clean_fleet(rng, arms=12, parameters=21):
    """Values of unit spread around random centres, each with a standard error a tenth of it."""
    centre = rng.normal(scale=100.0, size=parameters)
    se = np.full((arms, parameters), 0.1)
    return centre + rng.standard_normal((arms, parameters)), se


def test_clean_fleets_flag_about_as_often_as_the_family_rate():
    rng = np.random.default_rng(7)
    flagged = [fleet_spread(*clean_fleet(rng)).flagged.any() for _ in range(1000)]
    # 1% expected; 2.5% is 4.8 binomial standard deviations above it
    assert np.mean(flagged) <= 2.5 * FAMILY_RATE


def test_one_bent_arm_is_flagged_and_no_other():
    rng = np.random.default_rng(8)
    values, se = clean_fleet(rng, arms=10)
    values[3, 5] += 15.0  # fifteen spreads off
    spread = fleet_spread(values, se)
    assert spread.flagged[3, 5] and spread.flagged.sum() == 1
    assert abs(spread.spread[5] - 1.0) < 0.6  # the bent arm does not widen the spread much


def test_too_few_arms_are_not_judged():
    values, se = clean_fleet(np.random.default_rng(9), arms=MIN_ARMS - 1)
    values[0, 0] += 100.0
    spread = fleet_spread(values, se)
    assert np.isnan(spread.limit).all() and not spread.flagged.any()


def test_a_parameter_missing_on_an_arm_is_left_out():
    values, se = clean_fleet(np.random.default_rng(10))
    values[2, 4] = se[2, 4] = np.nan
    spread = fleet_spread(values, se)
    assert spread.arms[4] == len(values) - 1 and np.isnan(spread.z[2, 4])
    assert not spread.flagged[2, 4]


def test_jumps_beyond_their_uncertainty_are_flagged():
    rng = np.random.default_rng(11)
    before = rng.normal(size=(12, 21))
    se = np.full_like(before, 0.01)
    after = before + 0.01 * np.sqrt(2) * rng.standard_normal(before.shape)
    after[5, 2] += 0.2  # twenty standard errors
    before[7] = np.nan  # an arm calibrated once
    j = jumps(before, se, after, se)
    assert j.flagged[5, 2] and j.flagged.sum() == 1
    assert np.isnan(j.z[7]).all() and 4.0 < j.limit < 4.5


def test_shapes_must_agree():
    try:
        fleet_spread(np.zeros((10, 3)), np.zeros((10, 2)))
    except ValueError as e:
        assert "(arms, parameters)" in str(e)
    else:
        raise AssertionError("mismatched shapes accepted")
