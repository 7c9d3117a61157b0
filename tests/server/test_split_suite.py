"""The configuration-split suite's cases (issue 21): training and test poses in the two
configurations of the drawn split, on each of the three arms, measured at exactly those poses."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.server.bench import split_suite as ss
from robocal.solver import configuration


@pytest.mark.parametrize("seed", [0, 5, 10])  # clean cases (no aiming): one per arm
def test_training_and_test_poses_lie_in_the_two_configurations(seed):
    kind = ss.split_suite([seed])[0][1]
    case = ss.draw_split_case(seed, kind)
    assert kind == "clean" and case.arm == ss.ARMS[seed % 3]
    vc = case.cell()
    q_train, q_test, split = ss.split_poses(case, vc)
    assert len(q_train) == case.n_train and len(q_test) == ss.TEST_POSES
    bit = ss.SPLITS[split]
    train_side = (configuration.cfx(case.robot, q_train) & bit) > 0
    test_side = (configuration.cfx(case.robot, q_test) & bit) > 0
    assert set(train_side) == {case.train_side} and set(test_side) == {not case.train_side}
    meas = vc.campaign(len(q_test), 1, poses=q_test)
    assert np.array_equal(meas.q, q_test) and meas.xyz.shape == (len(q_test), len(case.targets), 3)


def test_the_summary_counts_cases_that_extrapolate_worse_than_geometry():
    def result(kind, arm, ratio, removed, removable=None):
        geo = 0.3
        return {
            "case": {"kind": kind, "arm": arm},
            "named": [],
            "hidden": [] if kind == "clean" else [["joint_compliance", 2, None]],
            "detected": [] if kind == "clean" else [removed is not None and removed > 0.5],
            "false_alarm": False,
            "floor_mm": 0.05,
            "geometric_test_mm": geo,
            "diagnosed_test_mm": geo * ratio,
            "ratio": ratio,
            "test_over_floor": geo * ratio / 0.05,
            "removed": removed,
            "removable": removable,
        }

    s = ss.summarize_split(
        [
            result("joint_compliance", "irb2600", 0.3, 0.95, 0.97),
            result("joint_periodic", "kuka-like", 1.05, -0.1, 0.9),
            result("joint_backlash", "kuka-like", 0.9, 0.3, 0.4),
            result("clean", "random", 1.0, None),
        ]
    )
    assert s["hurt"] == 1 and s["worst_ratio"] == 1.05
    assert s["removed"] == {
        "median": pytest.approx(0.3),
        "at_least_0.8": 1,
        "of": 3,
        # the backlash: even the effects known exactly would remove only 40%
        "removable_below_0.8": 1,
        "at_least_0.8_where_removable": 1,
        "removable_of": 2,
    }
    assert s["per_arm"]["kuka-like"]["hurt"] == 1 and s["per_arm"]["irb2600"]["hurt"] == 0
    assert s["false_alarms"]["clean_campaigns"] == 1 and s["detection_rate"] == pytest.approx(1 / 3)
