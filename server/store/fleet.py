"""The calibrations of named arms: per done calibration job on a campaign naming its arm, the
robot model (the cell's robot name) and the arm's identified joint parameters."""

from __future__ import annotations

import datetime as dt
import json
import re
from dataclasses import dataclass

from sqlalchemy import select

from .db import Database
from .models import Campaign, Job


@dataclass(frozen=True)
class ParameterEstimate:
    """One identified parameter of an arm: its value and standard error, mm or degrees."""

    name: str
    unit: str
    value: float
    standard_error: float | None


@dataclass(frozen=True)
class ArmCalibration:
    """A done calibration of a named arm."""

    arm: str
    robot_model: str  # the cell's robot name as written
    job_id: int
    campaign_id: int
    calibrated_at: dt.datetime
    method: str
    parameters: tuple[ParameterEstimate, ...]


def model_key(name: str) -> str:
    """A robot model's name compared without case, blanks or dashes ("IRB 2600" = "irb2600")."""
    return re.sub(r"[^a-z0-9]", "", name.lower())


def robot_model_of(cell_json: str) -> str:
    """The robot model a stored cell names: a built-in's name or an inline robot's `name`."""
    robot = json.loads(cell_json).get("robot")
    return robot.strip() if isinstance(robot, str) else str((robot or {}).get("name", "custom"))


def arm_calibrations(db: Database, *, robot_model: str | None = None) -> list[ArmCalibration]:
    """Done calibrations of named arms (of this robot model, if given) whose job stored some of
    the arm's parameters, oldest first."""
    query = (
        select(Job, Campaign)
        .join(Campaign, Job.campaign_id == Campaign.id)
        .where(Job.kind == "calibration", Job.state == "done", Campaign.arm.is_not(None))
        .order_by(Job.finished_at, Job.id)
    )
    want = None if robot_model is None else model_key(robot_model)
    out = []
    with db.session() as s:
        for job, campaign in s.execute(query):
            model = robot_model_of(campaign.cell_json)
            rows = (job.results or {}).get("parameters")
            # a fit that identified none of the arm's parameters (the `nominal` method) says
            # nothing of the arm: taken as its latest, it would hide the arm's calibration
            if not rows or (want is not None and model_key(model) != want):
                continue
            out.append(
                ArmCalibration(
                    str(campaign.arm),
                    model,
                    job.id,
                    campaign.id,
                    job.finished_at or job.created_at,
                    job.method,
                    tuple(_estimate(r) for r in rows),
                )
            )
    return out


def _estimate(row: dict) -> ParameterEstimate:
    se = row.get("standard_error")
    return ParameterEstimate(
        str(row["parameter"]),
        str(row.get("unit", "")),
        float(row["calibrated"]),
        None if se is None else float(se),
    )
