"""`robocal check --plan N`: a model's check poses, chosen once and reused by every check.

Candidates are random poses within the limits that the tracker sees (drivers.planning, on the
model's arm and base), drawn from a fixed seed so that the same model plans the same poses, and
kept to those where the model is as good as its held-out error (not extrapolating); the N that
make the check's change kinds most visible are chosen (solver.check_plan) and ordered for a
short path from the arm's home.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from robocal.server.formats.campaign_csv import read_poses, write_poses
from robocal.server.formats.model_json import ModelFile
from robocal.solver import check_plan as cp
from robocal.solver.drift import REPEATABILITY_MM

DEFAULT_POSES = 6
MIN_POSES = 2  # a check compares at least two poses with its baseline (drift.since_baseline)
MAX_POSES = 100
CANDIDATES = 1000
# The candidates kept: those of leverage in the calibration design at most the median's, poses
# where the model predicts at least as well as on a typical pose (solver.check_plan.interior).
INTERIOR_SHARE = 0.5
PLAN_SEED = 0x23C4  # fixed: a model's plan is the same every time it is made
# The smallest zero slip a check is asked to see (a gear or encoder change, issue 23): a joint
# whose slip of this size moves no candidate pose's SMR mean by the arm's repeatability (per
# coordinate) cannot be seen by a check, whatever its poses (the last joint turns the SMRs about
# their own centre); the plan leaves it out rather than spend poses on it.
SLIP_RAD = np.deg2rad(0.005)
VISIBLE_MM_PER_RAD = REPEATABILITY_MM / np.sqrt(3.0) / SLIP_RAD


@dataclass(frozen=True)
class CheckPlan:
    """The check poses in visit order and how well they show each change kind."""

    pose_ids: list[str]
    q: np.ndarray  # (n, N) rad
    move_s: float  # the path's move time from home, s (the simulated controller's speeds)
    names: tuple[str, ...]  # the change parameters designed for
    absorbed: tuple[int, ...]  # joints whose zero the rigid motion absorbs
    invisible: tuple[int, ...]  # joints whose zero no pose's SMR mean shows
    log_det: float  # of the chosen poses' J'J, columns scaled over the candidates
    log_det_random: float  # of n random candidates, the same scaling
    # one check's standard errors, every change fitted at once, at the arm's repeatability:
    # the rigid translation's largest (mm), each joint's zero (mdeg), the scale (ppm)
    rigid_mm: float
    joint_zero_mdeg: dict[int, float]
    scale_ppm: float


def plan_check(model: ModelFile, n: int = DEFAULT_POSES) -> CheckPlan:
    """The n check poses of the model (ValueError outside MIN_POSES..MAX_POSES)."""
    from robocal.drivers.planning import (
        candidate_jacobians,
        order_poses,
        plan_poses,
        total_move_time,
    )

    if not MIN_POSES <= n <= MAX_POSES:
        raise ValueError(f"--plan: {n} poses; a check plans {MIN_POSES} to {MAX_POSES}")
    from robocal.drivers.cell import AXIS_CLEARANCE_MM

    origin = float(np.linalg.norm(np.asarray(model.base)[:3, 3]))
    if origin < AXIS_CLEARANCE_MM:
        # the planner puts the tracker at its frame's origin, and keeps it 1 m from every SMR
        raise ValueError(
            f"--plan: the model's frame has its origin {origin:.1f} mm from the robot's base, "
            "where no tracker stands: its readings were registered to the robot, so where the "
            "tracker is (which poses face it, at what range) is unknown; measure poses of your "
            "choice as the check, the same every time, or calibrate in the tracker's own frame"
        )
    rng = np.random.default_rng(PLAN_SEED)
    cand = plan_poses(model.robot, model.base, model.targets, CANDIDATES, rng)
    lay, x = model.layout()
    design = cp.change_design(lay, x, cand, np.asarray(model.base)[:3, 3], VISIBLE_MM_PER_RAD)
    # the calibration's poses were drawn like these: choose among those where the model is as
    # good as its held-out error, which the check's level is judged against
    ident = candidate_jacobians(model.robot, model.base, model.targets, cand)
    inside = np.flatnonzero(cp.interior(ident, INTERIOR_SHARE))
    chosen = inside[cp.choose(replace(design, J=design.J[inside]), n)]
    home = np.zeros(model.robot.n_joints)
    idx = chosen[order_poses(cand[chosen], start=home)]
    unit = design.J / np.linalg.norm(design.J, axis=(0, 1))  # mm and rad comparable
    return CheckPlan(
        [f"check{i + 1}" for i in range(n)],
        cand[idx],
        total_move_time(cand[idx], start=home),
        design.names,
        design.absorbed,
        design.invisible,
        cp.log_det(unit[idx]),
        cp.log_det(unit[:n]),  # candidates are i.i.d. random: any n of them are a random set
        *standard_errors(design.J[idx], design.names),
    )


def standard_errors(J: np.ndarray, names) -> tuple[float, dict[int, float], float]:
    """One check's standard errors of poses J: the rigid translation's largest (mm), each
    joint's zero (mdeg), the scale (ppm); every change fitted at once, at the repeatability."""
    se = cp.standard_errors(J, REPEATABILITY_MM / np.sqrt(3.0))
    names = list(names)
    joints = {
        int(n.split()[1]): float(np.degrees(se[i]) * 1000.0)
        for i, n in enumerate(names)
        if n.startswith("joint")
    }
    rigid = float(max(se[names.index(t)] for t in ("tx", "ty", "tz")))
    return rigid, joints, float(se[names.index("scale")] * 1e6)


def write_plan(path, plan: CheckPlan) -> None:
    """The plan as a poses.csv (FORMATS section 4): `pose,q1..qN`, degrees, in visit order."""
    write_poses(path, plan.pose_ids, plan.q)


def check_poses(model: ModelFile, path=None, n: int = DEFAULT_POSES):
    """The check's (pose ids, q rad): read from a poses.csv (a `check --plan` file; joints
    refused outside the limits with file, line and column), else planned."""
    if path is not None:
        ids, q, *_ = read_poses(path, model.robot)
        return [str(i) for i in ids], q
    plan = plan_check(model, n)
    return plan.pose_ids, plan.q
