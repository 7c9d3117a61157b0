"""The configuration-split suite's cases (issue 21): training and test poses in the two
configurations of the drawn split, on each of the three arms, measured at exactly those poses."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.server.bench import split_suite as ss
from robocal.solver import configuration
from robocal.solver.problem import Problem


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


def test_a_backlash_fitted_on_40_poses_of_one_configuration_holds_in_the_other():
    """A joint-6 backlash on the IRB 2600 with two SMRs, 40 training poses: a region fold trained
    on 20 of them extrapolates geometry worse beside it (in the geometric span only), which alone
    refused it; accepted, it removes at least 80% of geometry's excess in the other elbow
    configuration, what the effect known exactly would remove."""
    case = ss.draw_split_case(33, "joint_backlash")
    assert case.arm == "irb2600" and case.n_train == 40 and len(case.targets) == 2
    r = ss.run_split_case(case)
    assert r["named"] == [["joint_backlash", 6, None]], r["named"]
    assert r["ratio"] <= ss.MAX_RATIO and r["removed"] >= ss.REMOVED_MIN, r
    assert r["geometric_without_effects_test_mm"] < r["geometric_test_mm"]
    assert r["removable"] == pytest.approx(r["removed"], abs=0.05)
    # the report says which fold was worse, and why it did not refuse the backlash
    from robocal.solver.diagnose import diagnose

    vc = case.cell()
    q_train, _, _ = ss.split_poses(case, vc)
    train = vc.campaign(case.n_train, case.cell_seed, poses=q_train, **case.options)
    nominal = np.array([case.targets[t] for t in train.target_names])
    d = diagnose(
        Problem(case.robot, nominal, train.target_names, train.q, train.xyz, time_s=train.time_s)
    )
    folds = d.report.extrapolation.folds
    exempt = [f for f in folds if f.worse_only_in_geometric_span]
    assert exempt and d.report.extrapolation.refused == [], folds
    assert all(f.final_rmse_mm > ss.MAX_RATIO * f.geometric_rmse_mm for f in exempt)


def test_a_clean_case_has_no_removable_share():
    r = ss.run_split_case(ss.draw_split_case(5, "clean"))
    # nothing named: the diagnosis's geometry is ls-sum's, fitted under the same prior (before,
    # its shrunk parameters held at nominal tested 0.9988x it), equal to the solvers' tolerance
    assert (
        r["named"] == [] and r["removable"] is None and r["ratio"] == pytest.approx(1.0, abs=1e-4)
    )


def test_a_periodic_error_seen_by_one_smr_holds_in_the_other_wrist_configuration():
    """A joint-4 periodic error on the KUKA-like arm with one SMR, 60 training poses: on a region
    fold trained on 30 of them the extended model moves geometry's part by more than geometry
    misses there, but less than that and what it gained outside; accepted, it removes at least
    80% of geometry's excess on the other wrist configuration."""
    case = ss.draw_split_case(112, "joint_periodic")
    assert case.arm == "kuka-like" and len(case.targets) == 1
    r = ss.run_split_case(case)
    assert r["named"] == [["joint_periodic", 4, 1]], r["named"]
    assert r["ratio"] <= ss.MAX_RATIO and r["removed"] >= ss.REMOVED_MIN, r


def test_a_ur_like_arm_is_drawn_when_asked_and_its_compliance_holds_in_the_other_configuration():
    """The UR-like arms (offset wrist, parallel axes 2-3-4) the bench adds: one SMR, joint-2
    compliance under a mass model the program does not know, fitted in one wrist configuration:
    named, and at least 80% of geometry's excess removed in the other."""
    assert ss.split_suite([1], arm="ur") == [(1, "joint_compliance", "ur")]
    case = ss.draw_split_case(1, "joint_compliance", "ur")
    assert case.arm == "ur" and case.robot.name == "ur-1" and len(case.targets) == 1
    vc = case.cell()
    q_train, q_test, split = ss.split_poses(case, vc)
    bit = ss.SPLITS[split]
    train_side = (configuration.cfx(case.robot, q_train) & bit) > 0
    test_side = (configuration.cfx(case.robot, q_test) & bit) > 0
    assert set(train_side) == {case.train_side} and set(test_side) == {not case.train_side}
    r = ss.run_split_case(case)
    assert r["named"] == [["joint_compliance", 2, None]], r["named"]
    assert r["ratio"] <= ss.MAX_RATIO and r["removed"] >= ss.REMOVED_MIN, r
    assert ss.summarize_split([r])["per_arm"]["ur"]["hurt"] == 0


def test_a_compliance_with_a_periodic_error_of_its_joint_holds_in_the_other_elbow_configuration():
    """Seed 29: joint-2 compliance under an unknown mass model and a joint-2 first-harmonic
    periodic error, a random arm, 60 training poses in one elbow configuration. Every link's
    masses fitted win on random folds and absorb the periodic term (it lies in the driven link's
    columns) but fit the training configuration's quirks: 0.78 of geometry's excess removed in the
    other configuration. Judged on the grouped folds, the compliance with only its driven link's
    masses fitted is taken and removes at least 80% (the periodic term, inside its span, is the
    same function under another name, not another cause it stands in for)."""
    case = ss.draw_split_case(29, "compliance_periodic")
    assert case.arm == "random" and case.n_train == 60
    r = ss.run_split_case(case)
    assert r["named"][0] == ["joint_compliance", 2, None], r["named"]
    assert r["ratio"] <= ss.MAX_RATIO and r["removed"] >= ss.REMOVED_MIN, r
