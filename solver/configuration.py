"""An arm's configuration in ABB's confdata terms: cf1, cf4, cf6 and cfx.

cf1, cf4 and cf6 are the quadrants of joints 1, 4 and 6: quadrant k holds the angles in
[90 k, 90 (k + 1)) degrees, so -1 is [-90, 0). cfx numbers the arm configuration 0..7 from three
tests, as ABB's table does: 4 when the wrist centre is behind axis 1, plus 2 when it is behind the
lower arm, plus 1 when joint 5 is negative.

Every test is computed from the kinematics, so it holds for any six-axis DH or modified-DH arm:
the wrist centre is the point of axis 4 nearest to axis 5 (their intersection on a spherical
wrist); "behind axis 1" is the wrist centre on the other side of axis 1 than at the reference
pose, in the plane that turns with joint 1; "behind the lower arm" is the wrist centre on the
other side of the line from axis 2 to axis 3 than at the reference pose, seen along axis 2. The
reference pose is every joint at zero (ABB's calibration pose, configuration 0); where zero puts
the wrist centre on axis 1 or stretches the arm straight (a UR arm), joint 2, then joint 3, at
+90 degrees in turn.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .kinematics import Layout, joint_frames
from .robot import Robot

CF_COLUMNS = ("cf1", "cf4", "cf6", "cfx")
QUADRANT_JOINTS = (0, 3, 5)  # cf1, cf4, cf6: joints 1, 4 and 6 (0-based)
QUADRANT_DEG = 90.0
CFX_MAX = 7
BEHIND_AXIS1, BEHIND_LOWER_ARM, JOINT5_NEGATIVE = 4, 2, 1
# a reference pose whose test is smaller than this (mm, mm^2) leaves the side undecided
DEGENERATE_MM = 1.0
JOINTS = 6


def supports(robot: Robot) -> bool:
    """Whether confdata describes this arm (six joints: a wrist of joints 4, 5 and 6)."""
    return robot.n_joints == JOINTS


def quadrant(q_rad) -> np.ndarray:
    """ABB's quadrant number of joint angles (rad): floor(angle / 90 deg)."""
    return np.floor(np.round(np.degrees(q_rad), 9) / QUADRANT_DEG).astype(int)


def quadrant_range(lower: float, upper: float) -> tuple[int, int]:
    """The quadrants a joint with these limits (rad) can be in."""
    return int(quadrant(lower)), int(quadrant(upper))


@dataclass(frozen=True)
class _Sides:
    """The signs the two geometric tests have at the reference pose."""

    front: float
    lower_arm: float


def _wrist_centre(frames) -> np.ndarray:
    """The point of axis 4 nearest to axis 5 (m, 3)."""
    (R4, o4), (R5, o5) = frames[3], frames[4]
    u, v = R4[:, :, 2], R5[:, :, 2]
    w = o4 - o5
    b = np.einsum("mi,mi->m", u, v)
    d, e = np.einsum("mi,mi->m", u, w), np.einsum("mi,mi->m", v, w)
    den = 1.0 - b * b
    s = np.where(den > 1e-9, (b * e - d) / np.where(den > 1e-9, den, 1.0), 0.0)
    return o4 + s[:, None] * u


def _tests(robot: Robot, q: np.ndarray, forward0: np.ndarray, R1_0: np.ndarray):
    """Per pose, the front test (mm) and the lower-arm test (mm^2), unsigned by the reference."""
    lay = Layout(robot, np.eye(4), ())
    frames = joint_frames(lay, lay.initial(np.zeros((0, 3))), q)
    wc = _wrist_centre(frames)
    (R1, o1), (R2, o2), (_, o3) = frames[0], frames[1], frames[2]
    # the forward direction turns with joint 1 from where it was at the reference pose
    forward = np.einsum("mij,jk,k->mi", R1, R1_0.T, forward0)
    front = np.einsum("mi,mi->m", wc - o1, forward)
    side = np.einsum("mi,mi->m", np.cross(o3 - o2, wc - o3), R2[:, :, 2])
    return front, side / 1000.0


@lru_cache(maxsize=16)
def _reference(robot: Robot) -> tuple[_Sides, np.ndarray, np.ndarray]:
    """The reference signs of the two tests, joint 1's forward direction and its frame at zero."""
    lay = Layout(robot, np.eye(4), ())
    x = lay.initial(np.zeros((0, 3)))
    candidates = [np.zeros(JOINTS)]
    for j in (1, 2):
        c = np.zeros(JOINTS)
        c[j] = np.pi / 2
        candidates.append(c)
    q = np.array(candidates)
    frames = joint_frames(lay, x, q)
    R1, o1 = frames[0]
    z1 = R1[0, :, 2]
    wc = _wrist_centre(frames)
    flat = (wc - o1) - np.outer((wc - o1) @ z1, z1)
    # joint 1's zero frame: every candidate shares it only if joint 1 is at zero, which it is
    reach = np.linalg.norm(flat, axis=1)
    k = int(np.argmax(reach > DEGENERATE_MM))
    forward0 = flat[k] / max(reach[k], 1e-12)
    R1_0 = R1[0]
    front, side = _tests(robot, q, forward0, R1_0)
    k_side = int(np.argmax(np.abs(side) > DEGENERATE_MM))
    sides = _Sides(float(np.sign(front[k]) or 1.0), float(np.sign(side[k_side]) or 1.0))
    return sides, forward0, R1_0


def cfx(robot: Robot, q) -> np.ndarray:
    """ABB's arm configuration number 0..7 of joint angles q (m, 6) rad."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    sides, forward0, R1_0 = _reference(robot)
    front, side = _tests(robot, q, forward0, R1_0)
    behind_axis1 = front * sides.front < 0
    behind_lower = side * sides.lower_arm < 0
    negative5 = np.round(np.degrees(q[:, 4]), 9) < 0
    return (
        BEHIND_AXIS1 * behind_axis1 + BEHIND_LOWER_ARM * behind_lower + JOINT5_NEGATIVE * negative5
    ).astype(int)


def confdata(robot: Robot, q) -> np.ndarray:
    """(m, 4) integers cf1, cf4, cf6, cfx of joint angles q (m, 6) rad."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    quads = quadrant(q[:, list(QUADRANT_JOINTS)])
    return np.column_stack([quads, cfx(robot, q)])


def bounds(robot: Robot, cf) -> tuple[np.ndarray, np.ndarray]:
    """Per pose (m, 6) rad, the joint ranges confdata cf (m, 4) allows within the limits: joints
    1, 4, 6 in their quadrants, joint 5 on its side of zero (the cfx bits of the wrist centre's
    sides are judged on the solution)."""
    cf = np.atleast_2d(np.asarray(cf, dtype=int))
    m = cf.shape[0]
    lo = np.repeat(robot.lower[None], m, axis=0)
    hi = np.repeat(robot.upper[None], m, axis=0)
    step = np.deg2rad(QUADRANT_DEG)
    edge = np.deg2rad(1e-7)  # the quadrant's upper end is not in it
    for c, j in enumerate(QUADRANT_JOINTS):
        lo[:, j] = np.maximum(lo[:, j], cf[:, c] * step)
        hi[:, j] = np.minimum(hi[:, j], (cf[:, c] + 1) * step - edge)
    negative = (cf[:, 3] & JOINT5_NEGATIVE) > 0
    hi[:, 4] = np.where(negative, np.minimum(hi[:, 4], -edge), hi[:, 4])
    lo[:, 4] = np.where(negative, lo[:, 4], np.maximum(lo[:, 4], 0.0))
    return lo, hi


def open_turns(robot: Robot) -> list[int]:
    """Joints (0-based) whose turn confdata leaves open within the limits: joints 2 and 3 with more
    than a full turn between their limits, joint 5 with more than one on a side of zero (its sign
    is cfx's bit). ABB's arms have none; a UR-like arm's +-360 deg joints have all three."""
    turn = 2.0 * np.pi + np.deg2rad(1e-7)
    lo, hi = robot.lower, robot.upper
    out = [j for j in (1, 2) if hi[j] - lo[j] > turn]
    if max(hi[4], 0.0) > turn or -min(lo[4], 0.0) > turn:
        out.append(4)
    return sorted(out)


def describe(cf) -> str:
    """confdata as ABB writes it: [cf1,cf4,cf6,cfx]."""
    return "[" + ",".join(str(int(v)) for v in cf) + "]"
