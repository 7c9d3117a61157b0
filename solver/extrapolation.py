"""Whether the model's extensions hold beyond the poses they were fitted on.

Random folds test a model on poses among its training poses; a user's later poses lie elsewhere:
in another elbow or wrist configuration, another part of the joint space. Region folds split the
campaign at the median of a gravity-loaded joint (train on one side, test on the other), so an
effect that only fitted the quirks of one region shows up as a worse test than geometry's there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .effects import gravity_in_base
from .kinematics import Layout, joint_frames

# A joint is gravity-loaded when its axis is on average this far from vertical (|cos| below).
HORIZONTAL_AXIS = 0.7
# Joints that move less than this (rad) over the campaign give no region to extrapolate to.
MIN_SPAN_RAD = np.radians(10.0)
# An extension is refused when a region fold's held-out RMS exceeds geometry's by this factor.
MAX_RATIO = 1.02


@dataclass(frozen=True)
class RegionFold:
    """Test poses on one side of a joint's median, the training poses on the other."""

    joint: int  # 0-based
    at_rad: float
    above: bool  # the test poses are those at or above the split
    test: np.ndarray  # pose indices
    beyond_rad: float  # how far the test poses reach past the training poses' range

    def label(self) -> str:
        side = ">=" if self.above else "<"
        return f"q{self.joint + 1} {side} {np.degrees(self.at_rad):.1f} deg"


@dataclass(frozen=True)
class FoldCheck:
    """One region fold: the geometric and the extended model's held-out RMS (mm) there."""

    fold: RegionFold
    geometric_rms: float
    extended_rms: float

    @property
    def worse(self) -> bool:
        return self.extended_rms > MAX_RATIO * self.geometric_rms


def gravity_loaded(layout: Layout, x, q: np.ndarray) -> list[int]:
    """Joints whose axes lie mostly horizontal over the campaign (the levelled tracker's z up)."""
    frames = joint_frames(Layout(layout.robot, np.eye(4), layout.target_names), x, q)
    g = gravity_in_base(layout, x)
    return [
        j
        for j, (R, _) in enumerate(frames[: layout.robot.n_joints])
        if float(np.mean(np.abs(R[:, :, 2] @ g))) < HORIZONTAL_AXIS
    ]


def region_folds(layout: Layout, x, q: np.ndarray, min_poses: int) -> list[RegionFold]:
    """Both sides of the median of each gravity-loaded joint that moves, each side with at least
    min_poses poses (fewer leave the training side unable to fit the model)."""
    out = []
    for j in gravity_loaded(layout, x, q):
        qj = q[:, j]
        if np.ptp(qj) < MIN_SPAN_RAD:
            continue
        at = float(np.median(qj))
        hi = qj >= at
        if min(hi.sum(), (~hi).sum()) < min_poses:
            continue
        for above in (False, True):
            test = np.flatnonzero(hi == above)
            train = qj[hi != above]
            beyond = (qj[test].max() - train.max()) if above else (train.min() - qj[test].min())
            out.append(RegionFold(j, at, above, test, float(max(beyond, 0.0))))
    return out


def joint_ranges(q: np.ndarray) -> np.ndarray:
    """(n, 2) the joint-space box the campaign covers, rad: where the model may be trusted."""
    return np.stack([q.min(axis=0), q.max(axis=0)], axis=1)
