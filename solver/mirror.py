"""Readings in a mirrored frame: two columns swapped, or one axis's sign flipped (a left-handed
export). No rigid motion maps the nominal arm's SMR positions onto them, their mirror image does;
calibration then fits a mirrored arm by turning twists and offsets half a turn (the real IRB 120
with x and y swapped: 0.54 mm RMS, d4 -603 mm, alpha4 +180 deg)."""

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
    """The nominal arm registered rigidly on the readings and on their mirror image (mm RMS)."""

    as_read_mm: float
    mirrored_mm: float

    def reason(self) -> str | None:
        """One sentence when the readings look mirrored, None otherwise."""
        if not self.mirrored_mm * MIRROR_RATIO < self.as_read_mm:
            return None
        return (
            f"the nominal arm at the measured joints fits the readings' mirror image within "
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
    return MirrorCheck(as_read, _registered(p, pts * np.array([-1.0, 1.0, 1.0])))
