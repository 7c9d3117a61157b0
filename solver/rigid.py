"""Rigid registration of point sets: in closed form (kabsch), and with a prior on the rotation
(rigid_correction: the acquisition's aim at SMRs a hand's width apart)."""

from __future__ import annotations

import numpy as np

from .finite import finite

GAUSS_NEWTON_STEPS = 3


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The rigid 4x4 transform T minimising sum ||T src - dst||^2 (points as rows)."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    U, _, Vt = np.linalg.svd(
        finite((src - cs).T @ (dst - cd), "the point-set registration's cross-covariance")
    )
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = cd - R @ cs
    return T


def rigid_correction(pred, meas, point_sigma_mm: float, rot_sigma_rad: float) -> np.ndarray:
    """4x4 T (tracker frame) with meas ~ T @ pred: the most probable rigid motion when each
    predicted point is off by point_sigma_mm per axis and the rotation by rot_sigma_rad.

    Three non-collinear points fix a rigid motion, but SMRs a hand's width apart with
    millimetre nominal errors fix its rotation worse than a survey does; the prior keeps the
    rotation where the points cannot tell, while the translation follows the points.
    """
    # here, not at the top: kabsch is on `robocal predict`'s path, which starts without scipy
    from scipy.spatial.transform import Rotation

    pred, meas = np.asarray(pred, dtype=float), np.asarray(meas, dtype=float)
    c = pred.mean(axis=0)
    T = np.eye(4)
    for _ in range(GAUSS_NEWTON_STEPS):
        p = pred @ T[:3, :3].T + T[:3, 3]
        r = (meas - p).ravel() / point_sigma_mm
        v = p - c
        # d(R v) for a small rotation w: w x v = -[v]x w; translation: identity
        J = np.zeros((len(p), 3, 6))
        J[:, 0, 1], J[:, 0, 2] = v[:, 2], -v[:, 1]
        J[:, 1, 0], J[:, 1, 2] = -v[:, 2], v[:, 0]
        J[:, 2, 0], J[:, 2, 1] = v[:, 1], -v[:, 0]
        J[:, :, 3:] = np.eye(3)
        w_now = Rotation.from_matrix(T[:3, :3]).as_rotvec()
        A = np.vstack([J.reshape(-1, 6) / point_sigma_mm, np.hstack([np.eye(3), np.zeros((3, 3))])])
        b = np.concatenate([r, -w_now]) if rot_sigma_rad > 0 else r
        A[-3:] /= rot_sigma_rad
        b[-3:] /= rot_sigma_rad
        step = np.linalg.lstsq(A, b, rcond=None)[0]
        R = Rotation.from_rotvec(step[:3]).as_matrix()
        # the step rotates about the centroid c, then translates
        D = np.eye(4)
        D[:3, :3] = R
        D[:3, 3] = c + step[3:] - R @ c
        T = D @ T
    return T
