"""Small campaigns: the effects named on resamples of the campaign, and the doubt said when no
majority of them names the final model's cause, or they name another (issue 21, point 3)."""

from __future__ import annotations

import numpy as np

from robocal.solver.stability import RESAMPLES, Stability, key_label, leave_out

C2 = ("joint_compliance", 1, None)
P2 = ("joint_periodic", 1, 2)


def test_each_resample_leaves_out_its_own_share_of_the_poses():
    subsets = leave_out(36)
    assert len(subsets) == RESAMPLES
    left = [np.setdiff1d(np.arange(36), s) for s in subsets]
    assert np.array_equal(np.sort(np.concatenate(left)), np.arange(36))  # each pose left out once
    assert all(len(s) in (28, 29) for s in subsets)


def test_a_majority_of_resamples_naming_the_cause_raises_no_doubt():
    s = Stability(29, (C2,), ((C2,), (C2,), (C2,), (), (P2,)))
    assert s.count(C2) == 3 and s.count(P2) == 1 and s.agreeing() == 3 and s.doubt() is None
    rep = s.to_report().to_json()  # as report.json has it
    assert rep["effects"] == [
        {"effect": "joint_compliance(2)", "named_in": 3, "in_final": True},
        {"effect": "joint_periodic(2, harmonic 2)", "named_in": 1, "in_final": False},
    ]
    assert rep["doubt"] is None and rep["resamples"] == RESAMPLES and rep["named_nothing"] == 1
    assert rep["agreeing"] == 3
    # a resample naming the final model's second cause agrees with it too
    assert Stability(29, (C2, P2), ((C2,), (P2,), (P2,), (), ())).doubt() is None


def test_resamples_naming_nothing_count_against_the_cause():
    """The real IRB 120's 30-pose folds named joint-2 compliance on 1 of 5 resamples, nothing on
    the others: a cause a few poses decide, said in doubt (a majority, 3 of 5, is needed)."""
    s = Stability(29, (C2,), ((C2,), (), (), (), ()))
    doubt = s.doubt()
    assert doubt is not None and s.agreeing() == 1
    assert "joint_compliance(2) named on 1 of 5; nothing on 4 of 5" in doubt, doubt
    two = Stability(29, (C2,), ((C2,), (C2,), (), (), (P2,)))
    assert two.doubt() is not None and "nothing on 2 of 5" in two.doubt()


def test_another_cause_named_on_two_resamples_puts_the_answer_in_doubt():
    rival = Stability(29, (C2,), ((C2,), (C2,), (P2,), (P2,), ()))
    doubt = rival.doubt()
    assert doubt is not None and doubt.startswith("the cause is in doubt: on 5 resamples")
    assert "joint_compliance(2) named on 2 of 5" in doubt
    assert "joint_periodic(2, harmonic 2) named on 2 of 5" in doubt
    assert [e.in_final for e in rival.to_report().effects] == [True, False]
    assert key_label(("thermal_drift", None, None)) == "thermal_drift"


S2 = ("joint_scale", 1, None)


def test_a_cause_a_majority_of_resamples_name_in_the_final_models_place_is_the_rival():
    """The bench's 30-pose compliance-and-periodic case (seed 7) named joint 2's scale on the
    whole campaign, its compliance on 4 of 5 resamples: the resamples agree on the compliance."""
    s = Stability(24, (S2,), ((C2,), (C2,), (S2,), (C2,), (C2,)))
    assert s.rival() == C2 and s.agreed() is None
    # a majority is needed, and the final model's causes on one resample at most each
    assert Stability(24, (S2,), ((C2,), (C2,), (S2,), (), ())).rival() is None
    assert Stability(24, (S2, P2), ((C2,), (C2,), (C2,), (P2,), (S2,))).rival() == C2
    assert Stability(24, (S2, P2), ((C2,), (C2,), (C2,), (P2,), (P2,))).rival() is None
    # the real QKM half (train q5 > 8.3 deg): joint 2's compliance on 2, joint 3's on 3
    assert Stability(24, (S2,), ((C2,), (C2,), (C2,), (S2,), (S2,))).rival() is None
    assert Stability(24, (S2,), ((C2,), (C2,), (C2,), (), ())).rival() == C2
    taken = Stability(24, (C2,), s.named, replaced=(S2,), agreed_on=C2)
    said = taken.agreed()
    assert said is not None and "first choice, joint_scale(2) (on 1 of 5): " in said, said
    assert said.endswith("joint_compliance(2) (named on 4 of 5); the model takes it instead")
    rep = taken.to_report().to_json()
    assert rep["replaced"] == ["joint_scale(2)"] and rep["agreed"] == said
    assert rep["doubt"] is None  # 4 of 5 agree with the model it deploys
    assert s.to_report().to_json()["replaced"] is None
    # refused on all the poses: the geometric model, the effects suspected, no doubt beside it
    none = Stability(24, (), s.named, replaced=(S2,), agreed_on=C2)
    said = none.agreed()
    assert said is not None and "the model is the geometric one" in said, said
    assert none.doubt() is None and none.to_report().to_json()["agreed"] == said
