"""Joint commands (`joints.csv`, FORMATS.md section 7): one row per pose, `pose`, `q1` ... `qN`
in degrees and, when a compensation wrote it, `predicted_error_mm`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.solver.robot import Robot

from .campaign_csv import _csv_text, joint_deg
from .csv_table import Row, Table
from .files import atomic_write_text
from .limits import COORD_MAX_MM


@dataclass(frozen=True)
class JointCommands:
    """Poses in file order, their joint commands (degrees) and the predicted miss (mm) or None."""

    pose_ids: list[str]
    q_deg: np.ndarray  # (m, n)
    predicted_error_mm: np.ndarray | None  # (m,); NaN where a row left it blank
    lines: list[int]  # each pose's line in the file


def read_joints(path, robot: Robot) -> JointCommands:
    """Read a `joints.csv` for this robot; InputError (file:line:column) on any bad field, a
    repeated pose or a command outside the robot's joint limits."""
    t = Table.read(path)
    columns = [f"q{i}" for i in range(1, robot.n_joints + 1)]
    t.require(["pose", *columns])
    has_error = bool(t.optional(["predicted_error_mm"]))
    t.require_rows()
    ids: list[str] = []
    seen: dict[str, Row] = {}
    q, err = [], []
    for row in t.rows:
        pid = t.text(row, "pose")
        if pid in seen:
            raise t.error(row, "pose", f"pose {pid!r} is already on line {seen[pid].line}")
        seen[pid] = row
        values = [joint_deg(t, row, i, name, robot) for i, name in enumerate(columns)]
        ids.append(pid)
        q.append(values)
        if has_error:
            err.append(t.number(row, "predicted_error_mm", np.nan, (0.0, COORD_MAX_MM), "mm"))
    return JointCommands(
        ids,
        np.array(q, dtype=float).reshape(len(ids), robot.n_joints),
        np.array(err, dtype=float) if has_error else None,
        [r.line for r in t.rows],
    )


def radians_warning(path, cmd: JointCommands, robot: Robot) -> str | None:
    """A warning when every joint command lies within one turn in radians (+-2 pi) while each
    joint's limits span four times that in degrees: degrees in name, radians in fact; None
    otherwise. Not a refusal: poses near home can be so in degrees."""
    q = np.abs(cmd.q_deg)
    span = np.rad2deg(robot.upper - robot.lower)
    # all at home (0 deg) says nothing of the units
    if not q.size or q.max() > 2 * np.pi or q.max() == 0 or not np.all(span > 8 * np.pi):
        return None
    n = robot.n_joints
    return (
        f"{path}: q1..q{n} of all {len(cmd.pose_ids)} poses lie within +-{2 * np.pi:.2f} while "
        f"each joint of {robot.name} spans {span.min():.0f} deg or more: they look like "
        "radians (joints.csv holds degrees)"
    )


def write_joints(path, pose_ids, q_deg, error_mm) -> None:
    """Write `joints.csv`: pose, q1 ... qN (degrees), predicted_error_mm; atomically."""
    q_deg = np.asarray(q_deg, dtype=float)
    n = q_deg.shape[1]
    header = ["pose", *[f"q{i}" for i in range(1, n + 1)], "predicted_error_mm"]
    rows = [
        [str(pid), *[f"{v:.9f}" for v in q], f"{e:.6f}"]
        for pid, q, e in zip(pose_ids, q_deg, error_mm)
    ]
    atomic_write_text(path, _csv_text(header, rows))
