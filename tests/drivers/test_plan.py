"""A campaign's plan listed without any device: its messages, their order, resume and bad input."""

import dataclasses

import numpy as np
import pytest

from robocal.drivers.plan import Aim, Checkpoint, Measure, Move, Save, Settle, campaign_plan

POSES = np.array([[0, 10, 20, 0, 30, 0], [5, 15, 25, 0, 35, 0], [10, 20, 30, 0, 40, 0]], float)


def test_a_plan_is_move_settle_aim_measure_save_per_pose_after_a_checkpoint():
    plan = list(campaign_plan(POSES, ("a", "b")))
    first = [
        Checkpoint(0),
        Move(0, (0.0, 10.0, 20.0, 0.0, 30.0, 0.0)),
        Settle(0),
        Aim(0, "a"),
        Measure(0, "a"),
        Aim(0, "b"),
        Measure(0, "b"),
        Save(0),
    ]
    assert plan[:8] == first
    assert len(plan) == 3 * 8
    assert [m.pose for m in plan] == [i for i in range(3) for _ in range(8)]
    assert [type(m) for m in plan[8:16]] == [type(m) for m in first]


def test_a_resumed_plan_skips_measured_poses_and_the_cut_off_pose_s_stored_targets():
    plan = list(campaign_plan(POSES, ("a", "b"), start=1, partial={"a": np.zeros(3)}))
    assert plan[:6] == [
        Checkpoint(1),
        Move(1, tuple(POSES[1])),
        Settle(1),
        Aim(1, "b"),
        Measure(1, "b"),
        Save(1),
    ]
    # the partial readings are pose 1's only: pose 2 measures every target
    assert [m for m in plan if isinstance(m, Measure)] == [
        Measure(1, "b"),
        Measure(2, "a"),
        Measure(2, "b"),
    ]
    assert list(campaign_plan(POSES, ("a",), start=3)) == []


def test_an_order_sets_each_pose_s_targets_and_the_one_its_move_leads_with():
    asked = []

    def order(q_deg):  # pose 1 reversed
        asked.append(float(q_deg[0]))
        return ("c", "b", "a") if q_deg[0] == 5 else ("a", "b", "c")

    plan = list(campaign_plan(POSES, ("a", "b", "c"), start=1, partial={"c": 1}, order=order))
    assert asked == [5.0, 10.0]
    moves = [m for m in plan if isinstance(m, Move)]
    # pose 1's c is stored: its readings begin with b
    assert [m.first for m in moves] == ["b", "a"]
    assert [(m.pose, m.target) for m in plan if isinstance(m, Aim)] == [
        (1, "b"),
        (1, "a"),
        (2, "a"),
        (2, "b"),
        (2, "c"),
    ]
    with pytest.raises(ValueError, match="not an order of"):
        list(campaign_plan(POSES, ("a", "b"), order=lambda q: ("a", "a")))


def test_messages_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        Move(0, (1.0,)).pose = 2


@pytest.mark.parametrize(
    "kwargs, says",
    [
        (dict(start=4), "start 4 is outside 0..3"),
        (dict(start=-1), "start -1 is outside 0..3"),
        (dict(partial={"z": (0, 0, 0)}), "unknown targets: z"),
    ],
)
def test_bad_plans_are_refused_before_any_message(kwargs, says):
    with pytest.raises(ValueError, match=says):
        campaign_plan(POSES, ("a", "b"), **kwargs)


def test_poses_must_be_a_table():
    with pytest.raises(ValueError, match="poses_deg must be a"):
        campaign_plan(np.zeros(6), ("a",))


def test_a_growing_plan_asks_for_each_batch_after_the_last_save_and_numbers_on():
    from robocal.drivers.plan import growing_plan

    batches = [np.zeros((2, 6)), np.ones((1, 6))]
    asked = []
    msgs = []

    def next_batch():
        asked.append(len(msgs))
        return batches.pop(0) if batches else None

    for msg in growing_plan(next_batch, ("A", "B"), start=3, partial={"A": 1}):
        msgs.append(msg)
    # asked first, then after pose 4's Save, then after pose 5's
    assert [type(msgs[i - 1]).__name__ for i in asked[1:]] == ["Save", "Save"]
    assert [m.pose for m in msgs if isinstance(m, Move)] == [3, 4, 5]
    # the partial reading is skipped at the first pose only
    aims = [(m.pose, m.target) for m in msgs if isinstance(m, Aim)]
    assert aims == [(3, "B"), (4, "A"), (4, "B"), (5, "A"), (5, "B")]
    assert [m.q_deg for m in msgs if isinstance(m, Move)][2] == (1.0,) * 6
