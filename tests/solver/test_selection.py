"""The selection rule in-process: linearised held-out gains, the per-campaign null and its power."""

import numpy as np
import pytest

from robocal.drivers.cell import TrackerSpec, VirtualCell
from robocal.drivers.effects import make_effects
from robocal.solver import identifiability as ident
from robocal.solver.diagnose import Diagnoser, candidates, diagnose
from robocal.solver.effects import Inputs
from robocal.solver.identify import register
from robocal.solver.problem import Problem
from robocal.solver.selection import linear_scores, rmse_gain_interval
from tests.robots import KUKA_LIKE, TARGETS
from tests.sim import default_cell


def campaign(robot, seed, poses, specs=(), noise=1.0):
    vc = VirtualCell.random(robot, TARGETS, seed=seed, tracker=TrackerSpec(10 * noise, 2.5 * noise))
    vc.effects.extend(make_effects(specs, vc, seed))
    return vc.campaign(poses, seed=seed)


def run(robot, meas):
    targets = np.array([TARGETS[t] for t in meas.target_names])
    return diagnose(Problem.of(robot, targets, meas))


def named(d):
    return [(e.name, e.joint) for e in d.report.effects]


def test_linearised_gains_match_the_fitted_cross_validation():
    meas = campaign(default_cell().robot, 4, 60, ["joint_compliance:2"])
    targets = np.array([TARGETS[t] for t in meas.target_names])
    prob, x0 = register(default_cell().robot, targets, meas.target_names, meas.q, meas.xyz)
    st = ident.structural(prob.layout, x0, np.ones(prob.layout.n_params, dtype=bool))
    diag = Diagnoser(prob, x0, st.free, Inputs(meas.q, meas.time_s, meas.temp_c))
    cands = [
        c
        for c in candidates(prob.layout, x0, diag.inputs)
        if c.name in ("joint_compliance", "joint_scale")
    ][:4]
    cv0 = diag.cross_validate([])
    trial, A, r, blocks, rows, scans = diag.linear_system(cv0.fits["all"], [], cands)
    sc = linear_scores(A, r, blocks, rows, diag.folds, len(meas.q), resamples=50)
    assert sc.sse == pytest.approx(cv0.sq.sum(), rel=1e-3)
    for i, c in enumerate(trial):
        fitted = diag.cross_validate([c]).sq.sum()
        assert sc.sse - sc.gain[i] == pytest.approx(fitted, rel=0.02), c.label()
        assert sc.pose_gain[i].sum() == pytest.approx(sc.gain[i], rel=1e-6)


@pytest.mark.parametrize("seed", range(12))
def test_clean_campaigns_name_nothing(seed):
    rng = np.random.default_rng(seed)
    meas = campaign(
        default_cell().robot,
        500 + seed,
        int(rng.choice([30, 40, 60])),
        noise=float(rng.uniform(1, 6)),
    )
    assert named(run(default_cell().robot, meas)) == []


@pytest.mark.parametrize("seed", range(4))
def test_a_gain_on_few_poses_is_found(seed):
    """Joint 1's gear-scale error shows on the poses with large |q1| only: still named."""
    rng = np.random.default_rng(seed)
    ppm = float(rng.uniform(150, 300))
    meas = campaign(KUKA_LIKE, 40 + seed, 100, [f"joint_scale:1={ppm}"])
    d = run(KUKA_LIKE, meas)
    assert ("joint_scale", 1) in named(d)
    assert d.report.final.holdout_rmse_mm < 2.0 * d.report.noise_floor_mm


def test_the_null_scales_with_the_campaign():
    """The threshold comes from the campaign's own resamples: the observed maximum of a pure-noise
    campaign falls below it about 1 - alpha of the time."""
    rng = np.random.default_rng(0)
    m, rows_per = 40, 9
    A = rng.normal(size=(m * rows_per, 12))
    blocks = [rng.normal(size=(m * rows_per, k)) for k in (1, 2, 6)]
    rows = np.repeat(np.arange(m), rows_per)
    folds = [np.arange(m)[i::5] for i in range(5)]
    above = 0
    for s in range(60):
        r = np.random.default_rng(100 + s).normal(size=m * rows_per)
        r -= A @ np.linalg.lstsq(A, r, rcond=None)[0]
        sc = linear_scores(A, r, blocks, rows, folds, m, resamples=400, seed=s)
        above += sc.z.max() > sc.threshold(0.05)
    assert above <= 9  # 5% of 60 is 3; 9 is beyond the binomial's 99.9th percentile


def test_gain_interval_brackets_the_gain():
    rng = np.random.default_rng(1)
    n = np.full(50, 3.0)
    before = rng.uniform(0.5, 1.5, 50) * 3 * 0.04
    after = before * 0.25
    lo, hi = rmse_gain_interval(before, after, n)
    gain = np.sqrt(before.sum() / n.sum()) - np.sqrt(after.sum() / n.sum())
    assert lo < gain < hi and lo > 0


def test_two_effects_at_once():
    meas = campaign(
        default_cell().robot, 9, 100, ["joint_compliance:2", "joint_periodic:4:2=0.015"]
    )
    d = run(default_cell().robot, meas)
    assert set(named(d)) == {("joint_compliance", 2), ("joint_periodic", 4)}
    for e in d.report.effects:
        lo, hi = e.holdout_gain_interval_mm
        assert 0 < lo <= e.holdout_rmse_before_mm - e.holdout_rmse_after_mm <= hi
        assert e.significance.p_value < 0.005


@pytest.mark.parametrize("seed", range(8))
def test_a_gain_on_few_poses_is_found_on_a_small_campaign(seed):
    """30 poses at 3x the tracker noise: a scale error seen on the poses of large |q1| is named."""
    rng = np.random.default_rng(seed)
    ppm = float(rng.uniform(120, 180))
    meas = campaign(KUKA_LIKE, 60 + seed, 30, [f"joint_scale:1={ppm}"], noise=3.0)
    d = run(KUKA_LIKE, meas)
    assert ("joint_scale", 1) in named(d)


def test_how_rich_a_compliance_is_judged_on_the_grouped_folds_where_the_campaign_has_them():
    """Three variants of one compliance (one stiffness, its driven link's masses, every link's):
    on random folds every link's masses clearly beat the driven link's, which clearly beat one
    stiffness; on the folds grouped by region and configuration every link's masses lose to the
    driven link's. Those folds decide how rich the model is; without them the random ones."""
    from robocal.solver.diagnose import simplest_variant
    from robocal.solver.selection import Scores
    from robocal.solver.vocabulary import Extension

    keep = lambda k: np.arange(20) < k  # noqa: E731
    trial = [
        Extension("joint_compliance", joint=1, masses=np.ones(20)),
        Extension("joint_compliance", joint=1, masses=np.ones(20), keep=keep(2)),
        Extension("joint_compliance", joint=1, keep=keep(10)),
        Extension("joint_periodic", joint=1, harmonic=1),
    ]
    assert [e.n_params for e in trial] == [1, 3, 10, 2]
    rng = np.random.default_rng(0)
    m = 40

    def scores(per_pose_gain):  # per pose: squared error 1 before, minus each candidate's gain
        g = np.array([v + rng.normal(scale=0.02, size=m) for v in per_pose_gain])
        return Scores(float(m), np.ones(m), g.sum(axis=1), g, np.zeros(4), np.zeros(1))

    random = scores([0.3, 0.5, 0.7, 0.4])
    grouped = scores([0.3, 0.6, 0.4, 0.2])
    ok = [0, 1, 2, 3]
    assert trial[simplest_variant(trial, ok, 2, random)].n_params == 10
    assert trial[simplest_variant(trial, ok, 2, random, grouped)].n_params == 3
    # a richer variant no better on the grouped folds than one stiffness: one stiffness
    flat = scores([0.3, 0.3, 0.3, 0.2])
    assert trial[simplest_variant(trial, ok, 2, random, flat)].n_params == 1
    # only the variants the null let through compete: without the middle one, every link's
    # masses beat one stiffness on both kinds of folds
    assert trial[simplest_variant(trial, [0, 2, 3], 2, random, grouped)].n_params == 10
