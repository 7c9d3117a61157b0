"""The calibrated chain as fixed transforms between joint axes, and their roll-pitch-yaw angles."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robocal.solver.kinematics import Op, joint_ops, rot, translation
from robocal.solver.robot import Robot


@dataclass(frozen=True)
class Segment:
    """From the previous joint's moving frame (or the base) to this joint's frame, which then
    turns about its local `axis` (0, 1, 2: x, y, z) by the joint reading."""

    origin: np.ndarray  # 4x4, mm
    axis: int


def op_matrix(op: Op, amount: float) -> np.ndarray:
    """The 4x4 transform of one elementary motion of the chain."""
    if op.kind == "r":
        return rot(op.axis, amount)
    v = [0.0, 0.0, 0.0]
    v[op.axis] = amount
    return translation(*v)


def segments(robot: Robot) -> tuple[list[Segment], np.ndarray]:
    """Per joint, its Segment, and the fixed transform from the last joint's frame to the flange.

    Built from the solver's own elementary motions (kinematics.joint_ops), so a DH or MDH chain
    with beta is reproduced motion for motion: each joint's zero offset theta is the fixed part
    of its rotation, folded into its origin.
    """
    x = robot.param_vector()
    out, acc = [], np.eye(4)
    for op in joint_ops(robot):
        acc = acc @ op_matrix(op, x[op.param])
        if op.joint >= 0:
            out.append(Segment(acc, op.axis))
            acc = np.eye(4)
    return out, acc


def rpy_from_matrix(R: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw), rad, with R = Rz(yaw) Ry(pitch) Rx(roll) (URDF's `rpy`).

    Yaw is taken first and the rest from Rz(-yaw) R, so that near pitch = +-90 degrees (where
    roll and yaw are each ill-conditioned but only their difference or sum matters) the three
    still rebuild R to rounding.
    """
    # the nearest rotation: a matrix read from a file rounded to a few digits is not quite one
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=float)[:3, :3])
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    yaw = math.atan2(R[1, 0], R[0, 0]) if math.hypot(R[0, 0], R[1, 0]) > 1e-12 else 0.0
    M = rot(2, -yaw)[:3, :3] @ R[:3, :3]  # = Ry(pitch) Rx(roll)
    pitch = math.atan2(-M[2, 0], M[0, 0])
    roll = math.atan2(-M[1, 2], M[1, 1])
    return roll, pitch, yaw


def matrix_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """The 4x4 rotation Rz(yaw) Ry(pitch) Rx(roll)."""
    return rot(2, yaw) @ rot(1, pitch) @ rot(0, roll)
