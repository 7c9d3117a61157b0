"""Standard errors are right: the spread of a parameter over repeated campaigns on the same poses
(Monte Carlo) matches the standard error each fit reports."""

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import make_effects
from robocal.solver import identifiability as ident
from robocal.solver.calibrate import calibrate
from robocal.solver.diagnosis_report import parameters
from robocal.solver.effects import Extension, Inputs, joint_basis
from robocal.solver.extended import fit_extended
from robocal.solver.fit_errors import calibration_errors, effect_uncertainty, extended_errors
from robocal.solver.gravity import gravity_basis, gravity_in_base, select_independent
from robocal.solver.identify import register
from robocal.solver.problem import Problem
from robocal.solver.robot import IRB2600
from robocal.solver.uncertainty import Rows, clustered, propagate
from tests.robots import KUKA_LIKE, TARGETS

DRAWS = 40
# With 40 draws the empirical standard deviation is itself uncertain by about 11% (its ratio to
# the truth is sqrt(chi2_39 / 39): 0.68-1.33 holds 99.8%); over ~30 parameters in ~10 tests a
# single ratio may stray that far by chance, so each must lie in 0.65-1.45 and their median,
# much sharper, in 0.85-1.15.
BAND = (0.65, 1.45)
MEDIAN_BAND = (0.85, 1.15)
SCATTER_DEG = 0.004  # per-pose arm error shared by all SMRs of a pose (repeatability)


def base_entries(B0, B):
    """Base B as the six entries of the layout (translation, then z-y-x angles) about B0."""
    D = np.linalg.inv(B0) @ B
    R = D[:3, :3]
    return np.r_[
        D[:3, 3], np.arctan2(R[1, 0], R[0, 0]), -np.arcsin(R[2, 0]), np.arctan2(R[2, 1], R[2, 2])
    ]


def monte_carlo(method, robot=IRB2600, seed=3, poses=40, scatter_deg=0.0, draws=DRAWS):
    """Per identified parameter: empirical sd over draws / RMS reported standard error, for the
    reported (clustered) estimate and the plain one."""
    vc = VirtualCell.random(robot, TARGETS, seed=seed)
    rng = np.random.default_rng(seed)
    q = vc.sample_poses(poses, rng)
    targets = np.array([TARGETS[k] for k in vc.target_names])
    est, se, se_plain, B0 = [], [], [], None
    for _ in range(draws):
        xyz = vc.measure(q, rng)
        # the arm's error at each pose moves all its SMRs alike: added to the joint readings
        q_read = q + np.deg2rad(scatter_deg) * rng.normal(size=q.shape)
        cal = calibrate(Problem(robot, targets, vc.target_names, q_read, xyz), method)
        err = calibration_errors(cal, q_read, xyz)
        B0 = cal.base if B0 is None else B0
        v = cal.x.copy()
        v[cal.layout.base_slice] = base_entries(B0, cal.base)
        est.append(v)
        se.append(err.internal())
        se_plain.append(err.internal(plain_estimate=True))
    est, se, se_plain = map(np.array, (est, se, se_plain))
    ok = np.all(np.isfinite(se), axis=0)
    sd = est[:, ok].std(axis=0, ddof=1)
    held = [n for n, good in zip(err.names, ok) if not good]
    return (
        sd / np.sqrt(np.mean(se[:, ok] ** 2, axis=0)),
        sd / np.sqrt(np.mean(se_plain[:, ok] ** 2, axis=0)),
        held,
        cal,
    )


def assert_honest(ratio):
    assert BAND[0] <= ratio.min() and ratio.max() <= BAND[1], (ratio.min(), ratio.max())
    assert MEDIAN_BAND[0] <= np.median(ratio) <= MEDIAN_BAND[1], np.median(ratio)


@pytest.mark.parametrize("robot,seed", [(IRB2600, 3), (KUKA_LIKE, 11)])
def test_ls_sum_standard_errors_match_the_spread(robot, seed):
    ratio, plain, held, cal = monte_carlo("ls-sum", robot, seed)
    assert_honest(ratio)
    assert_honest(plain)  # independent readings: the plain estimate is right too
    assert len(ratio) >= 25
    assert sorted(held) == sorted(cal.fixed)  # held fixed: no standard error


@pytest.mark.parametrize("method", ["minimax", "ls-pose", "ls-single:B"])
def test_every_method_reports_honest_standard_errors(method):
    ratio, _, held, cal = monte_carlo(method, seed=5)
    assert_honest(ratio)
    # ls-pose's first stage holds some SMR coordinates; its second fits every SMR
    smr = {f"{t}_{c}" for t in TARGETS for c in "xyz"} if method == "ls-pose" else set()
    assert sorted(held) == sorted(set(cal.fixed) - smr)


@pytest.mark.parametrize("method,poses", [("ls-sum", 30), ("ls-sum", 60), ("minimax", 40)])
def test_clustered_errors_stay_honest_with_per_pose_arm_error(method, poses):
    """With an error shared by the SMRs of a pose the plain estimate is too small (its readings are
    not independent); the pose-clustered one still matches the spread."""
    ratio, plain, _, _ = monte_carlo(method, seed=7, poses=poses, scatter_deg=SCATTER_DEG)
    if method == "minimax":
        # its multipliers move from campaign to campaign, which the sandwich holds fixed: at the
        # wrist it errs on the safe side (ratios to 0.6), never on the optimistic one
        assert 0.5 <= ratio.min() and ratio.max() <= BAND[1], (ratio.min(), ratio.max())
        assert MEDIAN_BAND[0] <= np.median(ratio) <= MEDIAN_BAND[1], np.median(ratio)
    else:
        assert_honest(ratio)
    assert np.median(plain) > 1.15 and plain.max() > 1.6, (np.median(plain), plain.max())


def compliance(layout, x0, q):
    g = gravity_in_base(layout, x0)
    keep = select_independent(gravity_basis(layout, x0, q, 1, g))
    return Extension("joint_compliance", joint=1, keep=keep, gravity=g)


@pytest.mark.parametrize(
    "spec,make,keys",
    [
        ("joint_compliance:2", compliance, {"deflection_rms_deg", "deflection_range_deg"}),
        (
            "joint_periodic:3:1",
            lambda *_: Extension("joint_periodic", joint=2, harmonic=1),
            {"amplitude_deg", "phase_deg"},
        ),
    ],
)
def test_effect_parameters_standard_errors_match_the_spread(spec, make, keys):
    """An effect's coefficients and its parameters in degrees, over repeated campaigns."""
    seed = 21
    vc = VirtualCell.random(IRB2600, TARGETS, seed=seed)
    vc.effects.extend(make_effects([spec], vc, seed))
    rng = np.random.default_rng(seed)
    q = vc.sample_poses(60, rng)
    targets = np.array([TARGETS[k] for k in vc.target_names])
    ext = None
    values, ses = [], []
    for _ in range(DRAWS):
        xyz = vc.measure(q, rng)
        prob, x0 = register(IRB2600, targets, vc.target_names, q, xyz)
        if ext is None:  # one extension (its gravity terms) for every draw
            free = ident.structural(prob.layout, x0, np.ones(prob.layout.n_params, bool)).free
            ext = make(prob.layout, x0, q)
        inputs = Inputs(q)
        x, ee, _ = fit_extended(prob, inputs, x0, free, [ext])
        err = extended_errors(prob, inputs, x0, free, x, ee)
        basis = joint_basis(ee[0], prob.layout, x0, inputs)
        p = parameters(ee[0], basis)
        u = effect_uncertainty(err, ee, 0, basis, parameters)
        assert set(u) == keys  # not the term count or the harmonic
        coef_se = np.sqrt(
            np.diag(err.block([f"{ee[0].label()}[{i}]" for i in range(ext.n_params)]))
        )
        values.append([p[k] for k in sorted(keys)] + list(ee[0].coef))
        ses.append([u[k] for k in sorted(keys)] + list(coef_se))
    values, ses = np.array(values), np.array(ses)
    ratio = values.std(axis=0, ddof=1) / np.sqrt(np.mean(ses**2, axis=0))
    assert_honest(ratio)


def test_propagation_matches_the_analytic_one_and_wraps_phases():
    c = np.array([-1e-3, 1e-6])  # phase near 180 degrees: the central difference crosses it
    cov = np.array([[4e-10, 1e-10], [1e-10, 9e-10]])

    def values(v):
        return {
            "amplitude_deg": float(np.degrees(np.hypot(*v))),
            "phase_deg": float(np.degrees(np.arctan2(v[1], v[0]))),
            "harmonic": 1,
            "variable": "time_s",
            "shift_mm": [v[0], 2 * v[1]],
            "rounded_mm": float(np.round(v[0], 5)),
        }  # rounded far below its error

    out = propagate(values, c, cov)
    assert set(out) == {"amplitude_deg", "phase_deg", "shift_mm", "rounded_mm"}
    assert 0.5 < out["rounded_mm"] / 2e-5 < 2.0
    g_amp = np.degrees(c / np.hypot(*c))
    g_phase = np.degrees(np.array([-c[1], c[0]]) / (c @ c))
    assert out["amplitude_deg"] == pytest.approx(np.sqrt(g_amp @ cov @ g_amp), rel=1e-5)
    assert out["phase_deg"] == pytest.approx(np.sqrt(g_phase @ cov @ g_phase), rel=1e-5)
    assert out["shift_mm"] == pytest.approx([2e-5, 6e-5], rel=1e-6)


def test_held_parameters_have_no_standard_error_and_angles_are_in_degrees():
    vc = VirtualCell.random(IRB2600, TARGETS, seed=1)
    meas = vc.campaign(40, seed=1)
    targets = np.array([TARGETS[k] for k in vc.target_names])
    cal = calibrate(Problem(IRB2600, targets, vc.target_names, meas.q, meas.xyz), "ls-sum")
    err = calibration_errors(cal, meas.q, meas.xyz)
    se = err.standard_errors()
    assert [n for n, v in se.items() if v is None] == list(cal.fixed)
    i = err.names.index("alpha2")
    assert se["alpha2"] == pytest.approx(np.degrees(err.internal()[i]))
    assert se["a2"] == pytest.approx(err.internal()[err.names.index("a2")])


def test_clustered_estimate_is_unbiased_on_a_linear_model_with_uneven_poses():
    """CR2's defining property: with independent errors of one variance its mean is the exact
    covariance, however few the poses per parameter and whatever their reading counts."""
    rng = np.random.default_rng(0)
    sizes = rng.choice([3, 6, 9], size=14)  # poses missing readings
    pose = np.repeat(np.arange(len(sizes)), sizes)
    J = rng.normal(size=(len(pose), 10)) * rng.uniform(0.1, 10.0, size=10)
    exact = np.linalg.inv(J.T @ J)
    H = J @ exact @ J.T
    mean = np.zeros(10)
    draws = 3000
    for _ in range(draws):
        r = (np.eye(len(pose)) - H) @ rng.normal(size=len(pose))
        mean += np.diag(clustered(Rows(J, J, r, pose, np.zeros(len(pose), int)))) / draws
    assert mean == pytest.approx(np.diag(exact), rel=0.1)
