"""Readings in a mirrored frame: two columns swapped, or one axis's sign flipped (a left-handed
export). No rigid motion maps the nominal arm's SMR positions onto them, their mirror image does;
calibration then fits a mirrored arm by turning twists and offsets half a turn (the real IRB 120
with x and y swapped: 0.54 mm RMS, d4 -603 mm, alpha4 +180 deg). Likewise one joint's column in
radians among the others' degrees (an export that converted one joint): the file-wide unit check
sees the arm's spread barely change; the nominal arm fits once that joint is read as radians."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kinematics import Layout, predict
from .plausibility import nominal_error_bound
from .rigid import kabsch
from .robot import Robot

# the mirror image fits this many times better than the readings as they are (the IRB 120 swapped:
# 5.3 against 202 mm; as read, its mirror 190x worse than the readings)
MIRROR_RATIO = 5.0


@dataclass(frozen=True)
class MirrorCheck:
    """The nominal arm registered rigidly on the readings and on their mirror image (mm RMS), and
    with one joint read as radians (its 0-based index and fit, -1 and inf: none fits better)."""

    as_read_mm: float
    mirrored_mm: float
    radian_joint: int = -1
    radian_mm: float = float("inf")

    def reason(self, arm: str = "the nominal arm") -> str | None:
        """One sentence when the readings look mirrored or a joint's column looks like radians,
        None otherwise; arm: the geometry registered (a model's, when evaluated or checked)."""
        if self.radian_mm * MIRROR_RATIO < min(self.as_read_mm, self.mirrored_mm):
            j = self.radian_joint + 1
            return (
                f"{arm} fits the readings within {self.radian_mm:.3g} mm RMS with "
                f"q{j} read as radians but only within {self.as_read_mm:.3g} mm as read: q{j} "
                f"looks like radians while the other joints are degrees; give it in degrees"
            )
        if not self.mirrored_mm * MIRROR_RATIO < self.as_read_mm:
            return None
        return (
            f"{arm} at the measured joints fits the readings' mirror image within "
            f"{self.mirrored_mm:.3g} mm RMS but the readings as they are only within "
            f"{self.as_read_mm:.3g} mm: x, y, z look mirrored (two columns swapped, or one "
            "axis's sign flipped: a left-handed frame); give them in the tracker's right-handed "
            "frame"
        )


def _registered(p: np.ndarray, xyz: np.ndarray) -> float:
    T = kabsch(p, xyz)
    r = p @ T[:3, :3].T + T[:3, 3] - xyz
    return float(np.sqrt(np.mean(np.sum(r * r, axis=1))))


def check_mirror(robot: Robot, targets: np.ndarray, q: np.ndarray, xyz: np.ndarray):
    """MirrorCheck of readings xyz (m, K, 3) mm, NaN where missing, of SMRs at targets (K, 3) at
    joints q (m, n) rad; None when the readings are too few, or the arm's own error (its
    nominal_error_bound) explains their misfit as read."""
    mask = np.all(np.isfinite(xyz), axis=-1)
    if mask.sum() < 4:
        return None
    lay = Layout(robot, np.eye(4), tuple(str(k) for k in range(len(targets))))
    p = predict(lay, lay.initial(targets), q)[mask]
    if np.linalg.matrix_rank(p - p.mean(axis=0), tol=1.0) < 3:  # a plane mirrors onto itself
        return None
    pts = xyz[mask]
    as_read = _registered(p, pts)
    if as_read <= nominal_error_bound(robot):
        return None
    mirrored = _registered(p, pts * np.array([-1.0, 1.0, 1.0]))
    best, best_mm = -1, float("inf")
    for j in range(robot.n_joints):
        q_j = q.copy()
        q_j[:, j] = np.rad2deg(q[:, j])  # the values read, taken as radians
        if not np.all((q_j[:, j] >= robot.lower[j] - 1e-6) & (q_j[:, j] <= robot.upper[j] + 1e-6)):
            continue
        fit = _registered(predict(lay, lay.initial(targets), q_j)[mask], pts)
        if fit < best_mm:
            best, best_mm = j, fit
    return MirrorCheck(as_read, mirrored, best, best_mm)
