"""Every identification method on clean simulated campaigns: held-out accuracy at the noise floor, minimax smallest max F_i."""

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.solver.calibrate import calibrate
from robocal.solver.identifiability import NotIdentifiable
from robocal.solver.kinematics import predict
from robocal.solver.problem import Problem
from robocal.solver.robot import IRB2600
from tests.robots import KUKA_LIKE, PUMA_LIKE, TARGETS

NAMES = ("A", "B", "C")
METHODS = ["ls-sum", "ls-single:A", "ls-single:C", "ls-pose", "minimax"]
ROBOTS = {"irb2600": IRB2600, "kuka-like": KUKA_LIKE, "puma-like": PUMA_LIKE}


def campaign(robot, seed, n_cal=100, n_hold=50):
    cell = VirtualCell.random(robot, TARGETS, seed=seed)
    meas = cell.campaign(n_cal + n_hold, seed=seed + 1000)
    return cell, meas.subset(np.arange(n_cal)), meas.subset(np.arange(n_cal, n_cal + n_hold))


def fit(robot, meas, method, **kw):
    targets = np.array([TARGETS[t] for t in NAMES])
    return calibrate(Problem(robot, targets, NAMES, meas.q, meas.xyz), method, **kw)


def noise_floor(cell, meas, rows=slice(None)):
    """RMS error a perfect model would show on these readings: the tracker noise drawn for them."""
    noise = meas.xyz[:, rows] - cell.true_points(meas.q)[:, rows]
    return np.sqrt(np.nanmean(np.sum(noise**2, axis=-1)))


def fitted_rows(method):
    return [NAMES.index(method.split(":")[1])] if method.startswith("ls-single") else [0, 1, 2]


@pytest.fixture(
    scope="module", params=[("irb2600", 1), ("kuka-like", 2), ("puma-like", 3)], ids=lambda p: p[0]
)
def fits(request):
    name, seed = request.param
    robot = ROBOTS[name]
    cell, cal, hold = campaign(robot, seed)
    out = {m: fit(robot, cal, m) for m in METHODS}
    out["minimax-exact"] = fit(robot, cal, "minimax", qp="exact")
    return cell, cal, hold, out


@pytest.mark.parametrize("method", METHODS + ["minimax-exact"])
def test_heldout_error_at_the_noise_floor(fits, method):
    cell, cal, hold, out = fits
    c = out[method]
    rows = fitted_rows(method)
    err = predict(c.layout, c.x, hold.q)[:, rows] - hold.xyz[:, rows]
    rms = np.sqrt(np.nanmean(np.sum(err**2, axis=-1)))
    floor = noise_floor(cell, hold, rows)
    assert rms <= 1.1 * floor, f"{method}: held-out RMS {rms:.4f} mm vs noise floor {floor:.4f} mm"


def test_minimax_has_the_smallest_max_F(fits):
    _, _, _, out = fits
    worst = {m: c.F.max() for m, c in out.items()}
    assert worst["minimax"] <= min(worst.values()) * (1 + 1e-6), worst
    assert worst["minimax"] < worst["ls-sum"]


def test_both_qp_subsolvers_reach_the_same_minimax(fits):
    _, _, _, out = fits
    a, b = out["minimax"].F.max(), out["minimax-exact"].F.max()
    assert abs(a - b) <= 1e-6 * b
    assert out["minimax"].success and out["minimax"].status == 0, out["minimax"].message
    assert out["minimax"].qp_converged and out["minimax-exact"].qp_converged


def test_minimax_respects_distance_invariance(fits):
    _, _, _, out = fits
    assert np.all(np.array(out["minimax"].constraints) <= 1e-9)


def test_redundant_parameters_are_named():
    _, cal, _ = campaign(IRB2600, 5)
    c = fit(IRB2600, cal, "ls-sum")
    # base takes joint 1's offset and height; SMRs take the last joint's frame; beta replaces d2
    assert set(c.fixed) == {"theta1", "d1", "d2", "theta6", "d6", "a6", "alpha6"}
    assert "base_rz" in c.fixed["theta1"] and "base_z" in c.fixed["d1"]
    assert np.isfinite(c.condition) and c.condition < 1e4


def test_too_few_poses_are_refused():
    _, cal, _ = campaign(IRB2600, 6)
    with pytest.raises(NotIdentifiable, match="poses"):
        fit(IRB2600, cal.subset(np.arange(2)), "ls-sum")


def test_too_similar_poses_shrink_what_they_cannot_separate_by_name():
    """Only joint 1 moves: the geometry it does not separate is shrunk toward nominal (almost
    nothing of it from the data), named with the parameters it moves with."""
    cell, cal, _ = campaign(IRB2600, 7)
    q = np.repeat(cal.q[:1], 30, axis=0)
    q[:, 0] += np.linspace(-0.5, 0.5, 30)  # only joint 1 moves
    xyz = cell.measure(q, np.random.default_rng(0))
    targets = np.array([TARGETS[t] for t in NAMES])
    c = calibrate(Problem(IRB2600, targets, NAMES, q, xyz), "ls-sum")
    for p in ("theta2", "a2", "theta3", "d4", "theta5"):
        assert "only together with" in c.shrunk[p].why and c.shrunk[p].share < 0.1, c.shrunk[p]
    assert np.isfinite(c.condition) and c.condition < 1e4


def test_missing_readings_are_tolerated():
    cell = VirtualCell.random(IRB2600, TARGETS, seed=8)
    meas = cell.campaign(150, seed=9, beam_break_rate=0.1)
    cal, hold = meas.subset(np.arange(100)), meas.subset(np.arange(100, 150))
    c = fit(IRB2600, cal, "minimax")
    err = predict(c.layout, c.x, hold.q) - hold.xyz
    rms = np.sqrt(np.nanmean(np.sum(err**2, axis=-1)))
    assert rms <= 1.1 * noise_floor(cell, hold)
