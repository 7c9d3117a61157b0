"""The fleet: the robot models with calibrated named arms, and one model's arms against the
fleet's spread with each arm's jump from its previous calibration."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path

from robocal.server.fleet import Fleet, FleetModel, fleet_models, fleet_view

from .deps import DbDep

router = APIRouter(prefix="/fleet", tags=["fleet"])
RobotModel = Annotated[
    str, Path(min_length=1, max_length=100, description="a robot model as cells name it")
]


@router.get("")
def list_fleet(db: DbDep) -> list[FleetModel]:
    """The robot models with calibrated arms (campaigns naming their `arm`), by name."""
    return fleet_models(db)


@router.get("/{robot_model}")
def get_fleet(robot_model: RobotModel, db: DbDep) -> Fleet:
    """One robot model's arms: each arm's latest identified parameters (mm, degrees) against the
    fleet's median and robust spread, z = deviation / sqrt(spread^2 + se^2), flagged beyond a
    limit set for 1% false alarms over the whole fleet; and each arm's change since its previous
    calibration, flagged beyond its uncertainty (404: no arm of this model)."""
    return fleet_view(db, robot_model)
