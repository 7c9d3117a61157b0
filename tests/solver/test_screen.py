"""Gross-outlier screening (solver.screen): seeded campaigns with readings displaced at random."""

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell, displace
from robocal.solver.diagnose import noise_floor
from robocal.solver.effects import Inputs
from robocal.solver.screen import screen_readings
from tests.sim import default_cell

CELL = default_cell()


def campaign(seed, poses, one_smr=False, beam_break_rate=0.0):
    vc = VirtualCell.random(CELL.robot, CELL.targets, seed=seed)
    meas = vc.campaign(poses, seed=seed, beam_break_rate=beam_break_rate)
    if one_smr:  # one SMR a pose, which one drawn from the seed
        keep = np.random.default_rng([9, seed]).integers(0, 3, poses)
        drop = np.ones(meas.xyz.shape[:2], dtype=bool)
        drop[np.arange(poses), keep] = False
        meas.xyz[drop] = np.nan
    return vc, meas


def screen(meas, xyz):
    return screen_readings(CELL.problem(meas).with_meas(xyz))


@pytest.mark.parametrize(
    "poses, one_smr, breaks",
    [(40, False, 0.0), (60, False, 0.1), (100, False, 0.0), (40, True, 0.0)],
)
def test_every_gross_outlier_is_found(poses, one_smr, breaks):
    """Every reading moved by 0.3 mm or more is excluded, over 12 seeds of 1-3% outliers."""
    found = total = false = 0
    for seed in range(12):
        _, meas = campaign(seed, poses, one_smr, breaks)
        rate = np.random.default_rng(seed).uniform(0.01, 0.03)
        xyz, moved = displace(meas.xyz, seed, rate)
        s = screen(meas, xyz)
        found += int((s.excluded & moved).sum())
        total += int(moved.sum())
        false += int((s.excluded & ~moved).sum())
    assert found == total
    assert false <= 1  # the clean-campaign rate below, over these 12 campaigns


def test_false_flags_on_clean_campaigns_are_rare():
    """Measured over 150 clean campaigns of 30-100 poses: about 1-2% have any reading excluded."""
    flagged = 0
    for seed in range(150):
        _, meas = campaign(1000 + seed, (30, 40, 60, 100)[seed % 4])
        flagged += screen(meas, meas.xyz).count > 0
    assert flagged / 150 <= 0.04, flagged


def test_noise_floor_is_not_inflated_by_outliers():
    """With 3% gross outliers the floor from SMR distances stays within 30% of the truth."""
    for seed in range(8):
        vc, meas = campaign(seed, 40)
        xyz, _ = displace(meas.xyz, seed, 0.03)
        inputs = Inputs(meas.q, meas.time_s, meas.temp_c)
        truth = vc.noise_floor_mm(meas.q)
        assert noise_floor(xyz, inputs) > 3 * truth  # what the outliers do unscreened
        assert abs(noise_floor(screen(meas, xyz).apply(xyz), inputs) / truth - 1) < 0.3


def test_two_readings_of_one_pose_or_two_smrs_a_pose():
    """Two moved readings at one pose, and a pose of two SMRs, are told apart by the geometry."""
    _, meas = campaign(3, 40)
    xyz = meas.xyz.copy()
    xyz[5, 0] += [0.5, -0.3, 0.2]
    xyz[5, 1] += [0.4, -0.2, 0.3]  # nearly the same move: the distances alone cannot tell
    xyz[9, 2] = np.nan
    xyz[9, 1] += [0.0, 0.0, 0.6]
    s = screen(meas, xyz)
    assert {(p, k) for p, k, *_ in s.listing()} == {(5, 0), (5, 1), (9, 1)}


def test_beyond_its_breakdown_it_excludes_no_clean_reading():
    """With 10-50% of the readings moved the scale grows with them: fewer found, none wrongly."""
    _, meas = campaign(2, 40)
    for rate in (0.1, 0.2, 0.5):
        xyz, moved = displace(meas.xyz, 2, rate)
        assert not (screen(meas, xyz).excluded & ~moved).any()


def test_too_few_poses_for_the_geometry_are_left_unscreened():
    """Two poses cannot fit the geometry: nothing judged, the reason kept (nominal still runs)."""
    _, meas = campaign(4, 40)
    few = meas.subset(np.arange(2))
    s = screen(few, few.xyz)
    assert s.count == 0 and "poses" in s.skipped


@pytest.mark.parametrize("targets", [3, 1])
def test_leverage_from_row_blocks_equals_the_dense_hat_matrix(targets):
    """The leverage from J's row blocks (R, then U = J V / s) equals the diagonal blocks of the
    dense hat matrix from J's SVD, rank-deficient J included (one SMR: redundant parameters)."""
    from robocal.solver.calibrate import calibrate
    from robocal.solver.identifiability import jacobian_rows
    from robocal.solver.problem import Problem
    from robocal.solver.screen import leverage

    cell = default_cell()
    names = list(cell.targets)[:targets]
    vc = VirtualCell.random(cell.robot, {n: cell.targets[n] for n in names}, seed=7)
    meas = vc.campaign(300, seed=8)
    nominal = np.array([cell.targets[n] for n in names])
    cal = calibrate(Problem(cell.robot, nominal, names, meas.q, meas.xyz), "ls-sum")
    J = jacobian_rows(cal.layout, cal.x, meas.q, np.ones(meas.xyz.shape[:2], bool))
    Js = J / np.linalg.norm(J, axis=0)
    U, sv, _ = np.linalg.svd(Js, full_matrices=False)
    U = U[:, sv > sv[0] * 1e-9]
    hat = np.einsum("ip,jp->ij", U, U)
    dense = np.diagonal(hat).reshape(-1, 3).mean(axis=1)
    blocks = leverage(lambda: (J[i : i + 250] for i in range(0, len(J), 250)))
    assert np.allclose(blocks, dense, rtol=0, atol=1e-12)
    assert blocks.sum() == pytest.approx(U.shape[1] / 3)  # the rank, a third a coordinate
