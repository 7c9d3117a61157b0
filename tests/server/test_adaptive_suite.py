"""The adaptive campaign against fixed and random ones on the simulated cell (3 arms, 2 seeds
each, through the devices and the store; `robocal bench acquire` runs 20 seeds of each): the
issue's criteria on a sample, each able to fail."""

import numpy as np
import pytest

from robocal.server.bench.adaptive import (
    ARMS,
    FIXED_POSES,
    POSE_SHARE,
    PREDICTION_TOL,
    TIME_SHARE,
    run_adaptive_suite,
    run_arm,
)


@pytest.fixture(scope="module")
def suite():
    return run_adaptive_suite(seeds=2, factors=(2.0,))


def test_every_stopped_campaign_reaches_its_target_on_independent_poses(suite):
    s = suite["summary"]["2"]
    assert s["runs"] == 2 * len(ARMS)
    assert s["reached_share"] == 1.0, s["missed"]  # >= 95 % of 6 runs: every one
    for run in suite["runs"]:
        t = run["targets"]["2"]
        assert t["target_mm"] == pytest.approx(2.0 * run["floor_mm"])
        assert t["stopped"] == "target" and t["predicted_mm"] <= t["target_mm"]
        assert t["named"] == [] and t["effects"] == []  # no effect named on a clean cell


def test_with_half_the_poses_and_half_the_time_of_a_fixed_80_pose_campaign(suite):
    s = suite["summary"]["2"]
    assert all(r["fixed"]["poses"] == FIXED_POSES for r in suite["runs"])
    assert s["pose_share_of_fixed"] <= POSE_SHARE
    assert s["time_share_of_fixed"] <= TIME_SHARE


def test_no_worse_than_random_poses_of_the_same_number(suite):
    s = suite["summary"]["2"]
    assert s["heldout_mean_mm"] <= s["random_heldout_mean_mm"]
    assert s["heldout_over_random_mean"] <= 1.0


def test_the_prediction_at_the_stop_is_within_20_percent_of_the_measured_accuracy(suite):
    # on average over the runs (the 20-seed bench reports the share of runs within it too)
    s = suite["summary"]["2"]
    err = [abs(r["targets"]["2"]["prediction_error"]) for r in suite["runs"]]
    assert s["prediction_error_mean"] == pytest.approx(np.mean(err))
    assert s["prediction_error_mean"] <= PREDICTION_TOL


def test_a_hidden_periodic_error_is_named_fitted_and_the_2x_target_reached():
    # joint 2's cyclic error (0.002 deg) puts the geometric fit's floor near 2x the tracker's:
    # the fixed 80-pose campaign's geometric fit misses the 2x target, the adaptive campaign's
    # checkpoint diagnosis names the error, fits it with the geometry and reaches the target on
    # independent poses, its prediction within 20 % of what they measure
    run = run_arm("irb2600", 1, (2.0,), ("joint_periodic:2=0.002",))
    t = run["targets"]["2"]
    assert run["fixed"]["heldout_mm"] > t["target_mm"]
    assert [e.split(",")[0] for e in t["effects"]] == ["joint_periodic(2"]
    assert t["stopped"] == "target" and t["reached"], t
    assert abs(t["prediction_error"]) <= PREDICTION_TOL
    assert t["poses"] <= POSE_SHARE * FIXED_POSES
    # as many random poses fitted with the same effect do no better
    assert t["heldout_mm"] <= t["random_heldout_mm"] * 1.05
