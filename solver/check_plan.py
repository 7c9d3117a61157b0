"""The poses of a quick check: those that make a deployed model's likely changes visible.

A check judges each pose by the mean error of its SMRs (one 3-D vector a pose, see drift.py), and
names a change as a rigid motion of every point (the tracker or the base moved), one joint's zero,
or a scale (the arm warmed). The check poses are chosen, out of candidates, to maximise log det of
J'J of those change parameters (D-optimality), J the pose means' motion under each change; a
joint whose zero is itself a rigid motion (joint 1 turns every point about the base's axis) is
left to the rigid motion, which absorbs it; one whose zero hardly moves the SMRs' mean at any pose
(the last joint turns the SMRs about their own centre) is left out as invisible to a check. The
candidates are first kept to the interior of the calibration's design (interior()), where the
model is as good as its held-out error says.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import observability as obs
from .kinematics import Layout, predict

FD_STEP_RAD = 1e-6  # central differences of the prediction in one joint
RIGID_NAMES = ("rx", "ry", "rz", "tx", "ty", "tz")
# A joint's zero column this close (relative residual) to the rigid columns is a rigid motion.
ABSORBED_TOL = 1e-6


@dataclass(frozen=True)
class ChangeDesign:
    """Per pose, the motion of its SMRs' mean (mm) under a unit change of each parameter."""

    J: np.ndarray  # (m, 3, p): rad for rotations and joint zeros, mm, unitless for the scale
    names: tuple[str, ...]  # rx ry rz (rad), tx ty tz (mm), "joint j" (rad), "scale"
    absorbed: tuple[int, ...]  # 1-based joints whose zero the rigid motion absorbs
    invisible: tuple[int, ...]  # 1-based joints whose zero moves no pose's mean enough

    def kinds(self) -> dict[str, np.ndarray]:
        """The change kinds a check names -> their columns: rigid, each joint, scale."""
        out = {"rigid": np.arange(len(RIGID_NAMES))}
        for i, n in enumerate(self.names):
            if n.startswith("joint") or n == "scale":
                out[n] = np.array([i])
        return out


def change_design(
    layout: Layout, x, q, origin, visible_mm_per_rad: float = 0.0, like: ChangeDesign | None = None
) -> ChangeDesign:
    """The change design of poses q (m, N) rad on the model (layout, x); rotations and the scale
    about origin (3,) mm, the robot's base in the tracker frame. A joint whose zero moves no
    pose's SMR mean by visible_mm_per_rad (its largest lever arm, mm) is left out, and one the
    rigid motion absorbs over these poses; given `like`, the joints it kept (a few poses' design
    in the parameters of their candidates')."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    o = np.asarray(origin, dtype=float)
    c = predict(layout, x, q).mean(axis=1) - o  # (m, 3) each pose's SMR mean about the origin
    m, n_j = q.shape
    rigid = np.zeros((m, 3, 6))
    # w x c = [[0, -wz, wy], [wz, 0, -wx], [-wy, wx, 0]] c
    rigid[:, 0, 1], rigid[:, 0, 2] = c[:, 2], -c[:, 1]
    rigid[:, 1, 0], rigid[:, 1, 2] = -c[:, 2], c[:, 0]
    rigid[:, 2, 0], rigid[:, 2, 1] = c[:, 1], -c[:, 0]
    rigid[:, :, 3:] = np.eye(3)
    joints = np.zeros((m, 3, n_j))
    for j in range(n_j):
        step = np.zeros(n_j)
        step[j] = FD_STEP_RAD
        plus = predict(layout, x, q + step).mean(axis=1)
        minus = predict(layout, x, q - step).mean(axis=1)
        joints[:, :, j] = (plus - minus) / (2 * FD_STEP_RAD)
    if like is None:
        keep, absorbed, invisible = _kept_joints(rigid, joints, visible_mm_per_rad)
    else:
        keep = [j for j in range(n_j) if f"joint {j + 1}" in like.names]
        absorbed, invisible = like.absorbed, like.invisible
    J = np.concatenate([rigid, joints[:, :, keep], c[:, :, None]], axis=2)
    names = (*RIGID_NAMES, *(f"joint {j + 1}" for j in keep), "scale")
    return ChangeDesign(J, names, tuple(absorbed), tuple(invisible))


def _kept_joints(rigid, joints, visible_mm_per_rad: float):
    """The joints (0-based) a design keeps, and those (1-based) absorbed and invisible."""
    R = rigid.reshape(-1, 6)
    keep, absorbed, invisible = [], [], []
    for j in range(joints.shape[2]):
        col = joints[:, :, j].ravel()
        coef, *_ = np.linalg.lstsq(R, col, rcond=None)
        size = np.linalg.norm(col)
        if size == 0 or np.linalg.norm(col - R @ coef) <= ABSORBED_TOL * size:
            absorbed.append(j + 1)
        elif np.linalg.norm(joints[:, :, j], axis=1).max() < visible_mm_per_rad:
            invisible.append(j + 1)
        else:
            keep.append(j)
    return keep, absorbed, invisible


def interior(J_id, share: float = 0.5) -> np.ndarray:
    """(m,) bool: the poses whose leverage in the calibration design J_id (per pose, as
    observability takes it) is at most its `share` quantile over the poses.

    A model fitted on poses drawn like these predicts a pose with an error that grows with the
    pose's leverage (sigma^2 h for its parameters; its unmodelled effects extrapolate alike), and
    its held-out error is their average: a check judged against that figure must not measure
    only the poses where the model extrapolates, which D-optimality alone would pick.
    """
    J = obs.unit_columns(J_id)
    J = J.dense() if isinstance(J, obs.PoseJacobians) else np.asarray(J, dtype=float)
    M = np.einsum("nrp,nrq->pq", J, J)
    h = np.einsum("nrp,pq,nrq->n", J, np.linalg.pinv(M), J)
    return h <= np.quantile(h, share)


def choose(design: ChangeDesign, n: int) -> np.ndarray:
    """Sorted indices of the n poses of the design maximising log det J'J (greedy + exchange)."""
    return obs.select_poses(design.J, n, "D")


def standard_errors(J: np.ndarray, sigma_mm: float) -> np.ndarray:
    """(p,) each change parameter's standard error from the poses J (m, 3, p), all fitted at
    once, when each pose mean's coordinates scatter by sigma_mm (inf where not identifiable)."""
    A = np.asarray(J, dtype=float).reshape(-1, J.shape[-1])
    s = np.linalg.svd(A, compute_uv=False)
    if len(s) < A.shape[1] or s[-1] <= s[0] * 1e-12:
        return np.full(A.shape[1], np.inf)
    return sigma_mm * np.sqrt(np.diag(np.linalg.inv(A.T @ A)))


def log_det(J: np.ndarray) -> float:
    """log det J'J of the poses J (m, 3, p), scaled as given (-inf where singular)."""
    return obs.observability_indices(J)["log_det"]
