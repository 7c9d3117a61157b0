"""Checks of the store's arguments before any database work; ValueError says what is wrong."""

from __future__ import annotations

import json
import math

import numpy as np

from robocal.server.formats.campaign_csv import LIMIT_TOL_DEG
from robocal.server.formats.cell_json import TARGET_NAME, Cell, parse_cell
from robocal.solver.robot import Robot

from .errors import Conflict


def cell_text(cell_json) -> tuple[Cell, str]:
    """The parsed cell and its text, from cell.json text or its JSON object; InputError if bad."""
    text = cell_json if isinstance(cell_json, str) else json.dumps(cell_json)
    return parse_cell(text), text


def matching_robot(robot: Robot | None, cell: Cell) -> Robot:
    """The robot to use: the one given if its joint count fits the cell's, else the cell's."""
    if robot is None:
        return cell.robot
    if robot.n_joints != cell.robot.n_joints:
        raise ValueError(
            f"robot {robot.name} has {robot.n_joints} joints, the cell's "
            f"{cell.robot.name} has {cell.robot.n_joints}"
        )
    return robot


def plan_deg(poses_deg, robot: Robot) -> np.ndarray:
    """The plan as an (n >= 1, N) array of finite joint angles within the robot's limits, deg."""
    q = np.asarray(poses_deg, dtype=float)
    if q.ndim != 2 or q.shape[0] == 0 or q.shape[1] != robot.n_joints:
        raise ValueError(
            f"poses_deg must be (n >= 1, {robot.n_joints}) for {robot.name}, not {q.shape}"
        )
    if not np.all(np.isfinite(q)):
        raise ValueError("poses_deg must be finite")
    lo, hi = np.rad2deg(robot.lower), np.rad2deg(robot.upper)
    bad = np.argwhere((q < lo - LIMIT_TOL_DEG) | (q > hi + LIMIT_TOL_DEG))
    if len(bad):
        i, j = bad[0]
        raise ValueError(
            f"pose {i}: joint {j + 1} at {q[i, j]:g} deg is outside [{lo[j]:g}, {hi[j]:g}] deg"
        )
    return q


def pose_labels(labels, n: int) -> list[str]:
    """n distinct labels; "1" ... "n" (as `robocal simulate` numbers poses) when none are given."""
    if labels is None:
        return [str(i) for i in range(1, n + 1)]
    labels = [str(v) for v in labels]
    if len(labels) != n or len(set(labels)) != n or any(not v or v != v.strip() for v in labels):
        raise ValueError(f"labels must be {n} distinct non-blank strings without outer spaces")
    return labels


def target_name(target) -> str:
    """A target name as cell.json allows it (it becomes a CSV value and a parameter name)."""
    if not isinstance(target, str) or not TARGET_NAME.fullmatch(target):
        raise ValueError(
            f"target {target!r} is not a target name (a letter, then up to 15 "
            "letters, digits or '_')"
        )
    return target


def one_of(value: str, allowed, what: str) -> str:
    """The value, if it is one of `allowed`."""
    if value not in allowed:
        raise ValueError(f"{what} must be one of {', '.join(allowed)}, not {value!r}")
    return value


def floats(values, what: str) -> tuple[float, ...]:
    """A vector of finite numbers as plain floats."""
    a = np.asarray(values, dtype=float)
    if a.ndim != 1 or not np.all(np.isfinite(a)):
        raise ValueError(f"{what} must be a vector of finite numbers")
    return tuple(float(v) for v in a)


def vector3(values, what: str, minimum: float | None = None) -> tuple[float, float, float]:
    """Three finite numbers, each at least `minimum` if given."""
    v = floats(values, what)
    if len(v) != 3 or (minimum is not None and min(v) < minimum):
        at_least = "" if minimum is None else f" >= {minimum:g}"
        raise ValueError(f"{what} must be 3 finite numbers{at_least}")
    return v


def optional(value) -> float | None:
    """A float, or None for a value not recorded (None or NaN: NULL in the database)."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def samples(value) -> int | None:
    """A sample count (>= 1), or None."""
    if value is None:
        return None
    if isinstance(value, bool) or int(value) != value or value < 1:
        raise ValueError(f"samples must be a whole number >= 1, not {value!r}")
    return int(value)


def outcome_agrees(state: str, ok: int, missing: int, pose_index: int) -> None:
    """Conflict unless the pose's readings fit the state, so a resumed run can trust outcomes."""
    wrong = {
        "measured": missing or not ok,
        "missing-target": not missing,
        "skipped": ok or missing,
    }[state]
    if wrong:
        raise Conflict(
            f"pose {pose_index} cannot be {state}: it has {ok} reading(s) and "
            f"{missing} target(s) recorded missing"
        )


ARM_MAX = 64  # characters of an arm's serial number


def arm_name(arm) -> str | None:
    """An arm's serial number, stripped: printable, 1 to ARM_MAX characters; None: unnamed."""
    if arm is None:
        return None
    if not isinstance(arm, str) or not arm.strip():
        raise ValueError("an arm's serial number must be a non-empty text")
    arm = arm.strip()
    if len(arm) > ARM_MAX or not arm.isprintable():
        raise ValueError(f"arm {arm[:ARM_MAX]!r}: at most {ARM_MAX} printable characters")
    return arm
