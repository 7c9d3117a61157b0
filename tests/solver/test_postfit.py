"""The post-fit figures taken a block of poses at a time (solver.postfit) are the ones they
replace: standard errors equal the dense sandwich over the whole hat matrix, leave-one-pose-out
residuals equal explicit refits without each pose, for every method and blocks of any size."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.solver import fit_errors
from robocal.solver.calibrate import calibrate
from robocal.solver.fit_errors import (
    calibration_blocks,
    calibration_figures,
    calibration_rows,
    plain_sums,
    point_errors,
    point_rows,
    prior_terms,
)
from robocal.solver.kinematics import predict
from robocal.solver.postfit import post_fit, sums
from robocal.solver.problem import Problem
from robocal.solver.robot import IRB2600
from robocal.solver.uncertainty import ABSORBED, inverse_root_times
from tests.robots import TARGETS

POSES = 14


def campaign(seed=5, poses=POSES, missing=True):
    """A small simulated campaign, some readings missing (poses of unequal row counts)."""
    vc = VirtualCell.random(IRB2600, TARGETS, seed=seed)
    meas = vc.campaign(poses, seed=seed)
    xyz = meas.xyz.copy()
    if missing:
        xyz[2, 1] = np.nan
        xyz[7, 0] = np.nan
    targets = np.array([TARGETS[k] for k in vc.target_names])
    return vc.target_names, targets, meas.q, xyz


def fit(method, seed=5):
    names, targets, q, xyz = campaign(seed)
    return calibrate(Problem(IRB2600, targets, names, q, xyz), method), q, xyz


def inv_sqrt(M):
    """M^-1/2 of a symmetric block, absorbed eigenvalues dropped (as the CR2 estimate does)."""
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    return V @ np.diag(np.where(w > ABSORBED, 1 / np.sqrt(np.clip(w, ABSORBED, None)), 0)) @ V.T


def dense(rows):
    """The textbook figures from the whole hat matrix H = J A^-1 G' (N x N) at once: CR2
    clustered and plain covariances, and each pose's PRESS residuals (I - H_pp)^-1 r_p."""
    J, G, r = rows.J, rows.G, rows.r
    Ai = np.linalg.inv(G.T @ J)
    R = np.eye(len(r)) - J @ Ai @ G.T
    M = R @ R.T
    meat = np.zeros_like(Ai)
    held = np.full(len(r), np.nan)
    for p in np.unique(rows.pose):
        at = np.flatnonzero(rows.pose == p)
        score = G[at].T @ inv_sqrt(M[np.ix_(at, at)]) @ r[at]
        meat += np.outer(score, score)
        held[at] = np.linalg.solve(R[np.ix_(at, at)], r[at])
    plain = np.zeros_like(Ai)
    for s in np.unique(rows.stage):
        on = rows.stage == s
        used = int(np.count_nonzero(np.any(G[on] != 0, axis=0)))
        plain += r[on] @ r[on] / (on.sum() - used) * G[on].T @ G[on]
    return Ai @ meat @ Ai.T, Ai @ plain @ Ai.T, held


@pytest.mark.parametrize("method", ["ls-sum", "ls-single:B", "minimax", "ls-pose"])
@pytest.mark.parametrize("block", [1, 3, POSES])
def test_blocked_figures_equal_the_dense_ones(method, block):
    cal, q, xyz = fit(method)
    rows, _ = calibration_rows(cal, q, xyz)
    clustered, plain, held = dense(rows)
    blocks, _ = calibration_blocks(cal, q, xyz, block)
    got = post_fit(blocks, lambda r: point_errors(cal, r))
    np.testing.assert_allclose(
        got.clustered, clustered, rtol=1e-7, atol=1e-12 * abs(clustered).max()
    )
    np.testing.assert_allclose(got.plain, plain, rtol=1e-7, atol=1e-12 * abs(plain).max())
    want = held[point_errors(cal, rows)].reshape(-1, 3)
    np.testing.assert_allclose(got.holdout.residuals, want, rtol=1e-7, atol=1e-12)
    assert got.poses == len(np.unique(rows.pose))


@pytest.mark.parametrize("method", ["ls-sum", "nominal", "ls-single:B", "minimax", "ls-pose"])
def test_a_plain_fit_has_its_first_pass_without_rows(method, monkeypatch):
    """ls-sum's and nominal's normal matrices, assembled from twists in blocks of 3 poses, are
    the rows' (their rows are then built once); the weighted and staged fits' are not had so."""
    cal, q, xyz = fit(method)
    blocks, column = calibration_blocks(cal, q, xyz)
    monkeypatch.setattr(fit_errors, "TWIST_BLOCK_ENTRIES", 18 * (int((column >= 0).sum()) + 1))
    got = plain_sums(cal, q, xyz, column)
    if method not in ("ls-sum", "nominal"):
        assert got is None
        return
    assert got is not None
    want = sums(blocks)
    scale = abs(want.A).max()
    np.testing.assert_allclose(got.A, want.A, rtol=1e-10, atol=1e-13 * scale)
    np.testing.assert_allclose(got.B, want.B, rtol=1e-10, atol=1e-13 * scale)
    (s,) = want.stages.values()
    (g,) = got.stages.values()
    assert g.rr == pytest.approx(s.rr, rel=1e-10) and g.count == s.count
    np.testing.assert_array_equal(g.used, s.used)
    # and the figures with it are those of the rows' own first pass (the fit's prior in both)
    rows_pass = post_fit(blocks, lambda r: point_errors(cal, r), prior=prior_terms(cal, column))
    errors, holdout = calibration_figures(cal, q, xyz)
    clustered, plain = rows_pass.clustered, rows_pass.plain
    np.testing.assert_allclose(errors.cov, clustered, rtol=1e-7, atol=1e-12 * abs(clustered).max())
    np.testing.assert_allclose(errors.plain_cov, plain, rtol=1e-7, atol=1e-12 * abs(plain).max())
    np.testing.assert_allclose(
        holdout.residuals, rows_pass.holdout.residuals, rtol=1e-7, atol=1e-12
    )


def refit_without(cal, q, xyz, p, iterations=8):
    """The ls-sum fit refitted without pose p (Gauss-Newton from the fit over the same free
    parameters, to convergence, with the fit's prior rows): its point errors at pose p."""
    lay, x = cal.layout, np.array(cal.x, dtype=float)
    rows, column = calibration_rows(cal, q, xyz)
    cols = np.flatnonzero(column >= 0)[np.argsort(column[column >= 0])]
    keep = np.arange(len(q)) != p
    mask = np.all(np.isfinite(xyz[keep]), axis=-1)
    for _ in range(iterations):
        r = point_rows(lay, x, q[keep], xyz[keep], mask, cols, np.ones(len(cols), bool))
        J = np.vstack([r.J, np.diag(np.sqrt(cal.prior.weight[cols]))])
        x[cols] -= np.linalg.lstsq(J, np.r_[r.r, cal.prior.rows(x, cols)], rcond=None)[0]
    e = predict(lay, x, q[p : p + 1])[0] - xyz[p]
    return e[np.all(np.isfinite(xyz[p]), axis=-1)]


def test_leave_one_pose_out_equals_explicit_refits():
    cal, q, xyz = fit("ls-sum")
    rows, _ = calibration_rows(cal, q, xyz)
    errors, holdout = calibration_figures(cal, q, xyz)
    reading_pose = rows.pose[::3]
    fitted = rows.r.reshape(-1, 3)
    for p in range(POSES):
        want = refit_without(cal, q, xyz, p)
        got = holdout.residuals[reading_pose == p]
        moved = np.abs(got - fitted[reading_pose == p]).max()  # what holding the pose out does
        assert moved > 1e-4
        # linearised at the fit: exact up to the model's curvature over one pose's pull
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-3 * moved)
    assert np.isfinite(errors.internal()).sum() == int((errors.column >= 0).sum())


def test_inverse_root_series_and_eigensolver_agree():
    rng = np.random.default_rng(0)
    for scale in (1e-3, 0.2, 0.6):  # the series, its limit, the eigensolver
        X = rng.normal(size=(50, 6, 6))
        E = X + X.transpose(0, 2, 1)
        E *= scale / np.sqrt(np.einsum("bij,bij->b", E, E))[:, None, None]
        r = rng.normal(size=(50, 6))
        want = np.stack([inv_sqrt(np.eye(6) - e) @ v for e, v in zip(E, r)])
        np.testing.assert_allclose(inverse_root_times(E, r), want, rtol=1e-12, atol=1e-13)
