"""The fleet view: the arms of one robot model, each arm's latest identified parameters against
the fleet's spread, and its jump from its previous calibration."""

from __future__ import annotations

import datetime as dt

import numpy as np
from pydantic import BaseModel, Field

from robocal.solver.fleet import FAMILY_RATE, MIN_ARMS, fleet_spread, jumps

from . import store
from .store.fleet import ArmCalibration, arm_calibrations, model_key


class FleetParameter(BaseModel):
    """One parameter over the fleet's latest calibrations."""

    parameter: str
    unit: str
    centre: float = Field(description="the arms' median, mm or degrees")
    spread: float = Field(description="the arms' robust standard deviation (Qn), same unit")
    arms: int = Field(description="arms with this parameter identified")
    limit: float | None = Field(description="|z| beyond which an arm is flagged; null: too few")


class ArmParameter(BaseModel):
    """One parameter of one arm: its latest value, where it sits in the fleet, its jump."""

    parameter: str
    value: float
    standard_error: float | None
    z: float | None = Field(description="(value - centre) / sqrt(spread^2 + se^2)")
    flagged: bool
    jump: float | None = Field(description="change from the previous calibration; null: none")
    jump_z: float | None = Field(description="jump / sqrt(se_previous^2 + se^2)")
    jump_flagged: bool


class FleetArm(BaseModel):
    """An arm of the fleet and its latest calibration."""

    arm: str
    job_id: int
    campaign_id: int
    calibrated_at: dt.datetime
    method: str
    calibrations: int = Field(description="done calibrations of this arm")
    previous_job_id: int | None
    flagged: bool = Field(description="a parameter beyond the fleet's limit")
    jumped: bool = Field(description="a parameter moved beyond its uncertainty since last time")
    worst: str | None = Field(description="the parameter furthest from the fleet, in |z|")
    parameters: list[ArmParameter]


class Fleet(BaseModel):
    """The fleet view of one robot model."""

    robot_model: str
    family_rate: float = Field(
        description="chance that a fleet of clean arms shows any flag (spread and jumps each)"
    )
    min_arms: int = Field(description="arms needed before the spread is judged")
    jump_limit: float | None = Field(description="|jump_z| beyond which a jump is flagged")
    parameters: list[FleetParameter]
    arms: list[FleetArm]


class FleetModel(BaseModel):
    """A robot model with named, calibrated arms."""

    robot_model: str
    arms: int
    calibrations: int


def fleet_models(db: store.Database) -> list[FleetModel]:
    """The robot models with calibrated named arms, by name."""
    by_model: dict[str, list[ArmCalibration]] = {}
    for c in arm_calibrations(db):
        by_model.setdefault(model_key(c.robot_model), []).append(c)
    return [
        FleetModel(
            robot_model=cs[-1].robot_model, arms=len({c.arm for c in cs}), calibrations=len(cs)
        )
        for _, cs in sorted(by_model.items())
    ]


def fleet_view(db: store.Database, robot_model: str) -> Fleet:
    """The fleet of this robot model; NotFound naming the known models if it has no arm."""
    history = arm_calibrations(db, robot_model=robot_model)
    if not history:
        known = ", ".join(m.robot_model for m in fleet_models(db)) or "none yet"
        raise store.NotFound(
            f"no calibrated arm of robot model {robot_model!r} (models with arms: {known})"
        )
    by_arm: dict[str, list[ArmCalibration]] = {}
    for c in history:
        by_arm.setdefault(c.arm, []).append(c)
    arms = sorted(by_arm)
    latest = [by_arm[a][-1] for a in arms]
    previous = [by_arm[a][-2] if len(by_arm[a]) > 1 else None for a in arms]
    names, units = _columns(latest)
    value, se = _matrix(latest, names)
    before, before_se = _matrix(previous, names)
    spread = fleet_spread(value, se)
    jump = jumps(before, before_se, value, se)
    parameters = [
        FleetParameter(
            parameter=n,
            unit=units[n],
            centre=float(spread.centre[p]),
            spread=float(spread.spread[p]),
            arms=int(spread.arms[p]),
            limit=_num(spread.limit[p]),
        )
        for p, n in enumerate(names)
    ]
    rows = [
        _arm(latest[a], previous[a], len(by_arm[arms[a]]), names, a, value, se, spread, jump)
        for a in range(len(arms))
    ]
    return Fleet(
        robot_model=latest[-1].robot_model,
        family_rate=FAMILY_RATE,
        min_arms=MIN_ARMS,
        jump_limit=_num(jump.limit) if np.isfinite(jump.z).any() else None,
        parameters=parameters,
        arms=rows,
    )


def _columns(latest: list[ArmCalibration]) -> tuple[list[str], dict[str, str]]:
    """Every parameter identified on some arm, in the order first met, and its unit."""
    units: dict[str, str] = {}
    for c in latest:
        for e in c.parameters:
            units.setdefault(e.name, e.unit)
    return list(units), units


def _matrix(calibrations, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(arms, parameters) values and standard errors; nan where not identified (or no
    calibration)."""
    value = np.full((len(calibrations), len(names)), np.nan)
    se = np.full_like(value, np.nan)
    col = {n: i for i, n in enumerate(names)}
    for a, c in enumerate(calibrations):
        for e in c.parameters if c is not None else ():
            if e.name in col:
                value[a, col[e.name]] = e.value
                se[a, col[e.name]] = np.nan if e.standard_error is None else e.standard_error
    return value, se


def _num(v) -> float | None:
    return float(v) if np.isfinite(v) else None


def _arm(c, prev, count, names, a, value, se, spread, jump) -> FleetArm:
    z = spread.z[a]
    known = np.isfinite(z)
    worst = names[int(np.nanargmax(np.abs(z)))] if known.any() else None
    return FleetArm(
        arm=c.arm,
        job_id=c.job_id,
        campaign_id=c.campaign_id,
        calibrated_at=c.calibrated_at,
        method=c.method,
        calibrations=count,
        previous_job_id=None if prev is None else prev.job_id,
        flagged=bool(spread.flagged[a].any()),
        jumped=bool(jump.flagged[a].any()),
        worst=worst,
        parameters=[
            ArmParameter(
                parameter=n,
                value=float(value[a, p]),
                standard_error=_num(se[a, p]),
                z=_num(z[p]),
                flagged=bool(spread.flagged[a, p]),
                jump=_num(jump.delta[a, p]),
                jump_z=_num(jump.z[a, p]),
                jump_flagged=bool(jump.flagged[a, p]),
            )
            for p, n in enumerate(names)
            if np.isfinite(value[a, p])
        ],
    )
