"""The diagnosis vocabulary: each effect's class, and backlash's basis from the visit order."""

import numpy as np

from robocal.solver.diagnose import candidates
from robocal.solver.diagnosis_report import evidence, parameters
from robocal.solver.effects import Extension, Inputs, joint_basis
from robocal.solver.kinematics import Layout
from robocal.solver.motion import last_motion
from robocal.solver.robot import IRB2600
from robocal.solver.vocabulary import KINDS
from tests.robots import TARGETS

NAMES = tuple(TARGETS)


def data(seed, m=30):
    rng = np.random.default_rng(seed)
    q = rng.uniform(IRB2600.lower, IRB2600.upper, (m, 6))
    time_s = rng.permutation(m)[:, None] * 20.0 + 2.0 * np.arange(
        len(NAMES)
    )  # visited out of file order
    temp_c = 20.0 + time_s / time_s.max()
    lay = Layout(IRB2600, np.eye(4), NAMES)
    return lay, lay.initial(np.array([TARGETS[n] for n in NAMES])), q, time_s, temp_c


def test_every_kind_proposes_candidates_and_backlash_one_per_joint():
    lay, x, q, time_s, temp_c = data(1)
    cands = candidates(lay, x, Inputs(q, time_s, temp_c))
    assert {c.name for c in cands} == set(KINDS)
    assert (
        "joint_coupling" not in KINDS
    )  # the simulator's wrist coupling stays outside the vocabulary
    assert [c.joint for c in cands if c.name == "joint_backlash"] == list(range(6))
    assert all(c.kind is KINDS[c.name] and c.n_params >= 1 for c in cands)


def test_backlash_basis_is_the_direction_of_the_last_motion_in_time_order():
    lay, x, q, time_s, temp_c = data(2)
    inputs = Inputs(q, time_s, temp_c)
    order = np.argsort(time_s[:, 0])
    visited = np.sign(np.diff(q[order], axis=0))
    for j in range(6):
        B = joint_basis(Extension("joint_backlash", joint=j), lay, x, inputs)
        assert B.shape == (30, 1)
        np.testing.assert_array_equal(B[order[1:], 0], visited[:, j])  # no joint stands still here
        assert B[order[0], 0] == 0.0  # before its first move the direction is unknown
    # a fold's poses keep the directions of the whole campaign, not of their own sequence
    fold = np.arange(0, 30, 3)
    sub = Inputs(q, time_s, temp_c).subset(fold)
    B = joint_basis(Extension("joint_backlash", joint=2), lay, x, sub)
    np.testing.assert_array_equal(B[:, 0], last_motion(q, time_s)[fold, 2])
    # without times, the file order is the visit order
    np.testing.assert_array_equal(Inputs(q).motion[1:], np.sign(np.diff(q, axis=0)))


def test_a_joint_that_moved_one_way_only_is_no_backlash_candidate():
    lay, x, q, time_s, temp_c = data(3)
    q = q[np.argsort(time_s[:, 0])]
    q[:, 4] = np.linspace(-1.0, 1.0, len(q))  # joint 5 only ever moves up: a constant, its offset
    cands = candidates(lay, x, Inputs(q))
    assert [c.joint for c in cands if c.name == "joint_backlash"] == [0, 1, 2, 3, 5]


def test_backlash_reads_as_a_lag_in_degrees():
    ext = Extension("joint_backlash", joint=1, coef=np.array([-np.deg2rad(0.012)]))
    p = parameters(ext, None)
    assert set(p) == {"backlash_deg"} and abs(p["backlash_deg"] - 0.012) < 1e-12
    decision = {"p_value": 0.001, "candidates": 30}
    text = evidence(ext, p, 0.2, 0.02, decision, 100)
    assert "Joint 2" in text and "lags behind" in text and "24.0 mdeg" in text and "0.0200" in text
    ext.coef = -ext.coef
    assert "runs ahead of" in evidence(ext, parameters(ext, None), 0.2, 0.02, decision, 100)


def test_a_gravity_loaded_joint_has_three_compliance_variants_the_middle_one_its_links_masses():
    """Joint 2 of the IRB 2600 (horizontal axis): one stiffness on the nominal mass model, that
    torque with the driven link's masses fitted beside it, and every link's masses; the middle one
    spans the joint's first harmonic (a periodic error or the driven link's moment: one function).
    Joint 1 (vertical axis) has no middle variant: its first harmonic is no gravity torque."""
    lay, x, q, time_s, temp_c = data(4, m=60)
    inputs = Inputs(q, time_s, temp_c)
    comp = [c for c in candidates(lay, x, inputs) if c.name == "joint_compliance"]
    j2 = [c for c in comp if c.joint == 1]
    assert [c.n_params for c in j2][0] == 1 and len(j2) == 3, [c.label() for c in j2]
    one, mid, rich = j2
    assert 1 < mid.n_params < rich.n_params
    assert mid.label() == "joint_compliance(2, its link's masses fitted)"
    B = np.c_[joint_basis(mid, lay, x, inputs), np.ones(len(q))]
    harmonic = np.c_[np.sin(q[:, 1]), np.cos(q[:, 1])]
    coef, *_ = np.linalg.lstsq(B, harmonic, rcond=None)
    assert np.linalg.norm(B @ coef - harmonic) < 1e-6 * np.linalg.norm(harmonic)
    np.testing.assert_allclose(
        joint_basis(mid, lay, x, inputs)[:, 0], joint_basis(one, lay, x, inputs)[:, 0]
    )
    # a base tilted by a degree: joint 1 carries a little gravity torque, but it stays vertical
    tilt = np.eye(4)
    tilt[1:3, 1:3] = [[np.cos(0.017), -np.sin(0.017)], [np.sin(0.017), np.cos(0.017)]]
    tilted = Layout(IRB2600, tilt, NAMES)
    at = tilted.initial(np.array([TARGETS[n] for n in NAMES]))
    j1 = [
        c for c in candidates(tilted, at, inputs) if c.name == "joint_compliance" and c.joint == 0
    ]
    assert j1 and not any(c.masses is not None and c.keep is not None for c in j1), j1
    mid.coef = np.ones(mid.n_params)
    assert parameters(mid, joint_basis(mid, lay, x, inputs))["gravity_terms"] == mid.n_params


def test_which_poses_take_their_approach_from_the_row_order_and_a_sorted_joint():
    """solver.motion: poses without prev_q take their approach from the rows unless every pose
    is timed (the first row has none to take); a joint that only rises or falls over 10+ rows
    says the file was sorted by it."""
    from robocal.solver.motion import ordered_by_rows, sorted_joint

    rng = np.random.default_rng(1)
    q = rng.uniform(-1, 1, (12, 3))
    prev = np.full_like(q, np.nan)
    assert ordered_by_rows(None, None, 12) == 11
    assert ordered_by_rows(np.arange(12.0), None, 12) == 0
    assert ordered_by_rows(np.r_[np.arange(11.0), np.nan], None, 12) == 11  # one pose untimed
    prev[3:] = 0.0
    assert ordered_by_rows(None, prev, 12) == 2  # rows 1 and 2
    assert ordered_by_rows(None, None, 1) == 0
    assert sorted_joint(q) is None
    assert sorted_joint(q[np.argsort(q[:, 1])]) == (1, 1)
    assert sorted_joint(q[np.argsort(-q[:, 2])][:, [0, 2]]) == (1, -1)
    assert sorted_joint(q[np.argsort(q[:, 0])][:9]) is None  # too few rows to tell
