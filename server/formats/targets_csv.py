"""Compensation targets (`targets.csv`) and joint commands (`joints.csv`), FORMATS.md section 7."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.solver import configuration
from robocal.solver.robot import Robot

from .campaign_csv import (
    BOUNDS,
    EXTRAS,
    MEASURED,
    PrevJoints,
    joint_columns,
    joint_deg,
    prev_header,
)
from .csv_table import Row, Table
from .errors import InputError


@dataclass
class Targets:
    """Desired SMR centres per pose (m, K, 3) mm with the SMRs given (m, K), starting guesses
    (m, n) rad (a row of NaN: none), per-reading time and temperature, and each pose's first line."""

    path: str
    pose_ids: list[str]
    names: tuple[str, ...]
    desired: np.ndarray
    mask: np.ndarray
    q0: np.ndarray
    time_s: np.ndarray | None
    temp_c: np.ndarray | None
    lines: list[int]
    # with orientation=True: per pose the tool's rx, ry, rz in the cell frame (m, 3) deg, NaN if none
    orientation: np.ndarray | None = None
    # per pose ABB's confdata cf1, cf4, cf6, cfx (m, 4), NaN where a pose gives none
    cf: np.ndarray | None = None
    # per pose the joints the arm comes from (m, n) rad, NaN where a pose gives none
    prev_q: np.ndarray | None = None


ORIENTATION = ("rx", "ry", "rz")
ANGLE_BOUNDS = ((-360.0, 360.0), "deg")


def read_targets(path, robot: Robot, names, orientation: bool = False) -> Targets:
    """Read `targets.csv` for this robot and these SMR (or TCP) names; InputError on bad input.

    With orientation, optional `rx`, `ry`, `rz` columns give a tool's orientation per pose."""
    t = Table.read(path)
    t.require(["pose", "target", *MEASURED])
    joints = joint_columns(robot)
    have = t.optional(joints)
    if have and len(have) != len(joints):
        missing = next(c for c in joints if c not in have)
        raise _header_error(t, missing, len(joints))
    extras = t.optional(list(EXTRAS))
    angles = t.optional(list(ORIENTATION)) if orientation else []
    if angles and len(angles) != 3:
        missing = next(c for c in ORIENTATION if c not in angles)
        raise InputError(
            t.path,
            t.header_line,
            None,
            f"missing column '{missing}': a tool orientation is rx, ry, rz",
        )
    cfs = _cf_columns(t, robot)
    prev = PrevJoints(t, robot, prev_header(t, robot))
    t.require_rows()
    names = tuple(names)
    turn: dict[int, tuple[Row, list[float]]] = {}
    col = {n: k for k, n in enumerate(names)}
    index: dict[str, int] = {}
    ids: list[str] = []
    first: list[Row] = []
    guesses: list[list[float] | None] = []
    confs: list[list[int] | None] = []
    seen: dict[tuple[int, str], Row] = {}
    readings = []
    for row in t.rows:
        pid = t.text(row, "pose")
        q = _guess(t, row, have, robot)
        k = index.get(pid)
        if k is None:
            k = index[pid] = len(ids)
            ids.append(pid)
            first.append(row)
            guesses.append(q)
            confs.append(_confdata(t, row, cfs, robot))
        elif not _same(conf := _confdata(t, row, cfs, robot), confs[k]):
            raise t.error(
                row,
                _differing(cfs, conf, confs[k]),
                f"the configuration differs from line {first[k].line}, an earlier row of "
                f"pose {pid!r}",
            )
        elif not _same(guesses[k], q):
            name = _differing(have, q, guesses[k]) if have else "pose"
            raise t.error(
                row,
                name,
                f"the starting guess differs from line {first[k].line}, an earlier row of "
                f"pose {pid!r}",
            )
        prev.add(row, k, pid)
        target = t.text(row, "target")
        if target not in col:
            raise t.error(
                row, "target", f"{target!r} is not one of the model's targets ({', '.join(names)})"
            )
        if (k, target) in seen:
            raise t.error(
                row,
                "target",
                f"target {target!r} of pose {pid!r} is already on line {seen[(k, target)].line}",
            )
        seen[(k, target)] = row
        if angles and any(t.raw(row, c) for c in angles):
            r = [t.number(row, c, None, *ANGLE_BOUNDS) for c in angles]
            if k in turn and not _same(turn[k][1], r):
                raise t.error(
                    row,
                    "rx",
                    f"the orientation differs from line {turn[k][0].line} of pose {pid!r}",
                )
            turn[k] = (row, r)
        point = [t.number(row, c, None, *BOUNDS[c]) for c in MEASURED]
        more = [t.number(row, c, np.nan, *BOUNDS[c]) for c in extras]
        readings.append((k, col[target], point, more))
    prev.check_units(guesses)
    m, K, n = len(ids), len(names), robot.n_joints
    desired = np.zeros((m, K, 3))
    mask = np.zeros((m, K), dtype=bool)
    extra = {c: np.full((m, K), np.nan) for c in extras}
    for k, j, p, more in readings:
        desired[k, j], mask[k, j] = p, True
        for c, v in zip(extras, more):
            extra[c][k, j] = v
    q0 = np.full((m, n), np.nan)
    for k, g in enumerate(guesses):
        if g is not None:
            q0[k] = np.deg2rad(g)
    # an SMR a pose does not give still needs a time and temperature for the model's prediction
    for c, a in extra.items():
        have = mask & np.isfinite(a)
        count = have.sum(axis=1, keepdims=True)
        fill = np.where(have, a, 0.0).sum(axis=1, keepdims=True) / np.maximum(count, 1)
        extra[c] = np.where(mask, a, np.where(count > 0, fill, np.nan))
    return Targets(
        str(path),
        ids,
        names,
        desired,
        mask,
        q0,
        extra.get("time_s"),
        extra.get("temp_c"),
        [r.line for r in first],
        _orientations(turn, m) if orientation else None,
        np.array([[np.nan] * 4 if c is None else c for c in confs], dtype=float).reshape(m, 4),
        prev.rad(m),
    )


def _cf_columns(t: Table, robot: Robot) -> list[str]:
    """The confdata columns present: all four or none, and only for a six-axis arm."""
    have = t.optional(list(configuration.CF_COLUMNS))
    if not have:
        return []
    if len(have) != len(configuration.CF_COLUMNS):
        missing = next(c for c in configuration.CF_COLUMNS if c not in have)
        raise InputError(
            t.path,
            t.header_line,
            None,
            f"missing column '{missing}': a configuration gives cf1, cf4, cf6 and cfx",
        )
    if not configuration.supports(robot):
        raise InputError(
            t.path,
            t.header_line,
            None,
            f"column '{have[0]}': cf1, cf4, cf6, cfx describe a six-axis arm's configuration; "
            f"{robot.name} has {robot.n_joints} joints: give starting joints q1 to "
            f"q{robot.n_joints} instead",
        )
    return have


def _confdata(t: Table, row: Row, cfs, robot: Robot) -> list[int] | None:
    """The row's confdata, or None when its cf fields are all blank; refused unless each is an
    integer its joint's limits allow (cfx 0 to 7)."""
    if not cfs or not any(t.raw(row, c) for c in cfs):
        return None
    out = []
    for c, name in enumerate(configuration.CF_COLUMNS):
        if c < len(configuration.QUADRANT_JOINTS):
            j = configuration.QUADRANT_JOINTS[c]
            lo, hi = configuration.quadrant_range(robot.lower[j], robot.upper[j])
            what = f"a quadrant of joint {j + 1} within its limits ({lo} to {hi})"
        else:
            lo, hi, what = 0, configuration.CFX_MAX, "an arm configuration number, 0 to 7"
        v = t.number(row, name)
        if v != round(v) or not lo <= v <= hi:
            raise t.error(row, name, f"{t.raw(row, name)} is not {what}")
        out.append(int(v))
    return out


def _orientations(turn, m: int) -> np.ndarray:
    out = np.full((m, 3), np.nan)
    for k, (_, r) in turn.items():
        out[k] = r
    return out


def _header_error(t: Table, missing: str, n: int):
    return InputError(
        t.path,
        t.header_line,
        None,
        f"missing column '{missing}': a starting guess gives every joint, q1 to q{n}",
    )


def _guess(t: Table, row: Row, have, robot) -> list[float] | None:
    """The row's starting guess in degrees, or None when its joint fields are all blank."""
    if not have or not any(t.raw(row, c) for c in have):
        return None
    return [joint_deg(t, row, i, name, robot) for i, name in enumerate(have)]


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return all(abs(u - v) <= 1e-6 for u, v in zip(a, b))


def _differing(columns, a, b, tol: float = 1e-6) -> str:
    """The column of a row's values a that differs from an earlier row's b (the first column
    where one row gives none): the field a refusal names."""
    if a is None or b is None:
        return columns[0]
    return next((c for c, u, v in zip(columns, a, b) if abs(u - v) > tol), columns[0])
