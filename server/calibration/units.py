"""Why a campaign's readings or its cell's robot are not in mm and degrees (solver.plausibility),
in a sentence; None when they may be."""

from __future__ import annotations

from robocal.server.formats.cell_json import Cell
from robocal.solver.measurements import Measurements

# How a refusal names the arm when a model's data is evaluated or checked: its calibrated robot
# is the geometry registered on the readings, not the nominal one.
MODEL_ARM = "the model's calibrated arm"


def units_refusal(cell: Cell, meas: Measurements, arm: str = "the nominal arm") -> str | None:
    """Why the readings are not in mm and degrees: their spread is not the one the cell's arm
    gives at the measured joints, or they are its mirror image (solver.mirror); None if they may
    be, or if the cell does not name their SMRs (refused elsewhere). arm names the cell's robot
    in the sentence (a model's calibrated one, when its data is evaluated or checked)."""
    from robocal.solver.plausibility import check_units

    if any(t not in cell.targets for t in meas.target_names):
        return None
    from robocal.solver.mirror import check_mirror

    targets = cell.target_positions(meas.target_names)
    if why := check_units(cell.robot, targets, meas.q, meas.xyz).reason(arm=arm):
        return why
    mirror = check_mirror(cell.robot, targets, meas.q, meas.xyz)
    return mirror.reason(arm) if mirror is not None else None


def radian_refusal(cell: Cell, meas: Measurements) -> str | None:
    """Why the cell's robot's angles look like radians to the readings
    (solver.plausibility.check_cell_angles); None otherwise."""
    from robocal.solver.plausibility import check_cell_angles

    if any(t not in cell.targets for t in meas.target_names):
        return None
    targets = cell.target_positions(meas.target_names)
    check = check_cell_angles(cell.robot, targets, meas.q, meas.xyz)
    return check.reason() if check is not None else None
