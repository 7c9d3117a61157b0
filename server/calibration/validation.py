"""The guard between a fit and its use: whether its data supports the model (model.json's
`validation` block, solver.guard), whether it may be deployed (compensate, export), and
whether data it is evaluated on is of its cell."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from robocal.server.calibration.units import units_refusal
from robocal.server.formats.blocks import HeldOut, Validation, ValidationLimits
from robocal.server.formats.cell_json import Cell
from robocal.server.formats.model_json import ModelFile
from robocal.solver import guard
from robocal.solver.effects import Inputs
from robocal.solver.kinematics import predict
from robocal.solver.measurements import Measurements
from robocal.solver.problem import Problem

if TYPE_CHECKING:
    from robocal.solver.metrics import Evaluation
    from robocal.solver.noise import NoiseFloor

HOLDOUT_METHOD = "leave-one-pose-out cross-validation, linearised at the fit"
# Model errors (RMS, mm) on data past which the data cannot be of the model's cell.
ABSURD_MM = 100.0


def noise_floor(cell: Cell, meas: Measurements) -> NoiseFloor:
    """The tracker's noise (3-D RMS per reading, mm) and where it comes from: measured in the
    data (SMR distances with two SMRs or more, else repeated poses), else the cell's tracker
    spec, else the default spec (said so)."""
    from robocal.solver.noise import noise_floor as floor

    return floor(meas.q, meas.xyz, Inputs(meas.q, meas.time_s, meas.temp_c), tracker_spec(cell))


def tracker_spec(cell: Cell) -> dict | None:
    """The cell's tracker spec when its cell.json gave one, None for the default."""
    return cell.tracker if cell.tracker_spec_given else None


def cell_problem(cell: Cell, meas: Measurements) -> Problem:
    """The solver's problem of a campaign in a cell: its arm, SMRs, base guess and tracker spec."""
    targets = cell.target_positions(meas.target_names)
    return Problem.of(cell.robot, targets, meas, cell.base, tracker_spec=tracker_spec(cell))


@dataclass
class NominalErrors:
    """The nominal model's RMS errors (mm a reading) on a campaign, its base and SMRs registered
    on it: on those readings and held out (leave-one-pose-out, as a calibration's); None: no
    figure."""

    fit_rms_mm: float | None
    holdout_rms_mm: float | None


def nominal_errors(cell: Cell, meas: Measurements) -> NominalErrors:
    """The nominal model's errors on the readings: what the calibration is to improve on, held
    out as the calibrated model is (a model worse than it is not deployable)."""
    from robocal.solver.calibrate import calibrate
    from robocal.solver.fit_errors import calibration_figures

    nom = calibrate(cell_problem(cell, meas), "nominal")
    r = np.linalg.norm(predict(nom.layout, nom.x, meas.q) - meas.xyz, axis=-1)
    r = r[np.isfinite(r)]
    fit = json_number(float(np.sqrt(np.mean(r * r)))) if r.size else None
    try:
        held = json_number(calibration_figures(nom, meas.q, meas.xyz)[1].rms())
    except (np.linalg.LinAlgError, ValueError):  # no pose can be held out: no figure
        held = None
    return NominalErrors(fit, held)


def nominal_model_errors(cal, fit_rms_mm: float, holdout) -> NominalErrors | None:
    """A calibration's own errors as the nominal arm's when its method is `nominal` (the
    nominal arm registered: nominal_errors would fit it again); None for any other method."""
    if cal.method != "nominal":
        return None
    return NominalErrors(json_number(fit_rms_mm), json_number(holdout.rms()))


def validation_block(
    v: guard.Validation,
    pose_ids,
    source: str,
    holdout_method: str = HOLDOUT_METHOD,
    *,
    nominal_rms_mm: float | None,
    nominal_holdout_rms_mm: float | None = None,
    warnings: list[str],
) -> Validation:
    """model.json's `validation` block: the verdict, its reasons, the held-out figure (the
    headline) beside the fit's and the nominal arm's (on the readings and held out), the limits applied, the warnings."""
    return Validation(
        deployable=v.deployable,
        reasons=tuple(v.reasons),
        summary=expected_accuracy(v, holdout_method),
        tolerance_mm=json_number(v.tolerance_mm),
        holdout_rms_mm=json_number(v.holdout_rms_mm),
        holdout_max_mm=json_number(v.holdout_max_mm),
        fit_rms_mm=json_number(v.fit_rms_mm),
        holdout=holdout_method,
        condition_number=json_number(v.condition_number),
        equations=v.equations,
        free_parameters=v.free_parameters,
        noise_floor_mm=json_number(v.noise_floor_mm),
        noise_floor_source=source,
        unsupported_poses=[pose_ids[i] for i in v.unsupported_poses],
        limits=ValidationLimits(
            min_equations_per_parameter=guard.MIN_EQUATIONS_PER_PARAMETER,
            noise_floor_fraction=guard.NOISE_FLOOR_FRACTION,
            max_condition_number=guard.MAX_CONDITION,
            max_holdout_ratio=guard.MAX_HOLDOUT_RATIO,
        ),
        nominal_rms_mm=nominal_rms_mm,
        nominal_holdout_rms_mm=nominal_holdout_rms_mm,
        warnings=tuple(warnings),
    )


def late_shift_warning(meas: Measurements, residuals, floor_mm: float | None) -> str | None:
    """The warning the last poses of a campaign give when they miss together, far beyond the
    others (solver.shift_scan.late_shift: too few poses after it for a base shift to be fitted);
    residuals (poses, SMRs, 3): the model's prediction minus every reading, the screened-out
    ones too (a bumped tracker's last poses are gross errors to the screening)."""
    from robocal.solver.motion import visit_order
    from robocal.solver.shift_scan import late_shift

    if residuals is None:
        return None
    order = visit_order(meas.time_s, meas.n_poses)
    late = late_shift(residuals, order, meas.xyz)
    if late is None:
        return order_step_warning(meas, residuals, order, floor_mm)
    k = len(late.poses)
    which = ", ".join(str(meas.pose_ids[i]) for i in late.poses)
    moved = ", ".join(f"{-v:+.3f}" for v in late.shift_mm)
    said = "the last pose" if k == 1 else f"the last {k} poses"
    return (
        f"{said} in time order ({which}) miss{'es' if k == 1 else ''} by {late.miss_mm:.3f} mm "
        f"together (readings off the model by {moved} mm in the tracker frame; one rigid motion "
        f"of them leaves {late.left_mm:.3f} mm), {late.miss_mm / late.rest_mm:.0f}x the other "
        f"poses' {late.rest_mm:.3f} mm: a bumped tracker or moved base? Too few poses after it "
        "to fit a base shift: measure a few poses again, or leave these out, and recalibrate"
    )


def expected_accuracy(v: guard.Validation, holdout_method: str = HOLDOUT_METHOD) -> str:
    """The accuracy to expect on new poses in one sentence (the held-out RMS and max), and how
    it stands against the tolerance; the verdict's reasons are said apart."""
    how = holdout_method.split(" cross-validation")[0]
    if not np.isfinite(v.holdout_rms_mm):
        said = "expected accuracy unknown: no pose could be held out"
    else:
        said = (
            f"expected accuracy on new poses {v.holdout_rms_mm:.3g} mm RMS, max "
            f"{v.holdout_max_mm:.3g} mm (held out: {how})"
        )
    if v.tolerance_mm is None:
        return said + "; no tolerance given (--tolerance-mm, or the cell's tolerance_mm)"
    within = np.isfinite(v.holdout_rms_mm) and v.holdout_rms_mm <= v.tolerance_mm
    if within and v.holdout_max_mm > v.tolerance_mm:  # the RMS is judged; its max said beside
        return said + f"; its RMS within the tolerance {v.tolerance_mm:g} mm, its max beyond"
    return said + f"; {'within' if within else 'beyond'} the tolerance {v.tolerance_mm:g} mm"


def json_number(v) -> float | None:
    """A JSON-safe number: None for NaN and infinity (JSON has neither)."""
    return None if v is None or not np.isfinite(v) else float(v)


def cell_mismatch(model: ModelFile, cell: Cell) -> str | None:
    """Why data measured on `cell` is not of the model's cell: another robot (name, joint count
    or nominal geometry) or SMRs the model does not have; None if it may be."""
    return data_mismatch(model.nominal or model.robot, list(model.targets), cell)


def data_mismatch(nominal, targets: list[str], cell: Cell) -> str | None:
    """Why data measured on `cell` is not of a robot with this nominal geometry and these SMRs
    (see cell_mismatch); None if it may be."""
    robot = cell.robot
    if robot.name != nominal.name:
        return f"the data is of robot {robot.name!r}, the model of {nominal.name!r}"
    if robot.param_names() != nominal.param_names() or not np.allclose(
        robot.param_vector(), nominal.param_vector(), atol=1e-6
    ):
        return f"the data's robot {robot.name!r} has another nominal geometry than the model's"
    unknown = [t for t in cell.targets if t not in targets]
    if unknown:
        return f"the data's SMR {unknown[0]!r} is not among the model's ({', '.join(targets)})"
    return None


def absurd_errors(result: Evaluation, verdict: Validation | None = None) -> str | None:
    """Why an evaluation's errors say the data is of another cell (a moved tracker, another
    robot), or the model unfit: the model's RMS error past ABSURD_MM; None otherwise."""
    rms = result.model.rmse
    if np.isfinite(rms) and rms <= ABSURD_MM:
        return None
    nominal = result.nominal.rmse if result.nominal is not None else None
    unfit = verdict is not None and not verdict.deployable
    return (
        f"the model's predictions are {rms:.1f} mm RMS from the readings (limit {ABSURD_MM:g} "
        "mm): the data is not of the model's cell (another robot, or the tracker or base moved)"
        + (", or the model is unfit (its validation says not deployable)" if unfit else "")
        + (f"; the nominal robot registered on it errs {nominal:.3f} mm RMS" if nominal else "")
    )


def with_held_out(v: Validation, held: HeldOut) -> None:
    """Give the verdict a separate held-out campaign's (or file's) errors, judged as the
    leave-one-out figure is: measured on poses the fit never saw, they are the stronger word, so
    beyond the tolerance (or, without one, past guard.MAX_FLOOR_RATIO x the noise floor) they make
    the model undeployable even where the leave-one-out estimate passes."""
    v.held_out = held
    rms, floor, tol = held.rms_mm, v.noise_floor_mm, v.tolerance_mm
    if rms is None or held.warning or not v.deployable:  # not of this cell, or already refused
        return
    where = f"campaign {held.campaign_id}" if held.campaign_id is not None else held.file
    said = f"the held-out {where}'s error {rms:.3g} mm RMS (max {held.max_mm:.3g} mm)"
    if tol is not None and rms > tol:
        reason = f"{said} exceeds the tolerance {tol:g} mm"
        v.summary = f"{v.summary}; on held-out {where} {rms:.3g} mm RMS, beyond the tolerance"
    elif tol is None and floor and rms > guard.MAX_FLOOR_RATIO * floor:
        reason = (
            f"{said} is {rms / floor:.3g}x the noise floor {floor:.3f} mm (more than "
            f"{guard.MAX_FLOOR_RATIO:g}x): the model does not hold on poses it was not fitted "
            "on; give the tolerance the application needs (--tolerance-mm, or the cell's "
            "tolerance_mm) to deploy within it"
        )
    else:
        return
    v.deployable = False
    v.reasons = (*v.reasons, reason)


def file_refusal(path) -> str | None:
    """Why a model file must not be deployed (its verdict's reasons, or that it has none), None
    if it may be; InputError, from the model reader, when the file is not a readable model (so a
    bad file is refused in one line before any work)."""
    from robocal.server.formats.model_json import read_model

    return read_model(path).verdict.refusal()


def order_step_warning(meas: Measurements, residuals, order, floor_mm) -> str | None:
    """The warning the poses after a split in the visit order give when they are off the model
    together against the ones before (solver.order_step: a tracker bumped mid-campaign, which the
    diagnosis fits as a base shift only against time_s), None when none is."""
    from robocal.solver.order_step import order_step

    step = order_step(residuals, order, floor_mm)
    if step is None:
        return None
    by = "time order" if meas.time_s is not None else "the file's order (no time_s)"
    moved = ", ".join(f"{-v:+.3f}" for v in step.shift_mm)
    return (
        f"the {step.after} poses from {meas.pose_ids[step.first_after]!r} on in {by} are off "
        f"the model by {np.linalg.norm(step.shift_mm):.3f} mm together against the "
        f"{step.before} before (readings moved {moved} mm in the tracker frame; beyond every one "
        f"of {round(1 / step.p_value) - 1} random reorderings of the poses): a tracker bumped or "
        "a base moved mid-campaign? Calibrate the two parts apart, or give time_s so that "
        "diagnose can fit a base shift"
    )


def repeated_readings_warning(meas: Measurements) -> str | None:
    """The warning poses whose every reading repeats another pose's to the last digit give (a
    row block copied: no tracker reads a point twice alike), None when none does: each copy
    counts as a pose of its own, and a held-out copy is predicted by its twin."""
    flat = np.where(np.isfinite(meas.xyz), meas.xyz, np.inf).reshape(meas.n_poses, -1)
    _, first, inverse, counts = np.unique(
        flat, axis=0, return_index=True, return_inverse=True, return_counts=True
    )
    copies = [
        (int(first[g]), k)
        for k, g in enumerate(np.asarray(inverse).reshape(-1))
        if counts[g] > 1 and k != first[g]
    ]
    if not copies:
        return None
    a, b = copies[0]
    more = f" ({len(copies) - 1} more poses repeat another so)" if len(copies) > 1 else ""
    return (
        f"pose {meas.pose_ids[b]!r} repeats every reading of pose {meas.pose_ids[a]!r} to the "
        f"last digit{more}: a copied block of rows? Each copy counts as a pose of its own, and "
        "the held-out figures predict it from its twin; remove the copies"
    )


# A quick survey of the cell puts the base some 10 mm and half a degree off; past these, the
# cell's base describes another setup (a wall or ceiling mount the data does not show, metres)
BASE_GUESS_MM, BASE_GUESS_DEG = 100.0, 10.0


def base_guess_warning(cell: Cell, base) -> str | None:
    """The warning a base identified far from the cell's `base` guess gives (the fit holds: the
    base is found from the data), None when it is near or the cell gives none."""
    if cell.base is None or base is None:
        return None
    guess, found = np.asarray(cell.base, dtype=float), np.asarray(base, dtype=float)
    moved = float(np.linalg.norm(found[:3, 3] - guess[:3, 3]))
    cos = (np.trace(guess[:3, :3].T @ found[:3, :3]) - 1.0) / 2.0
    turned = float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    if moved <= BASE_GUESS_MM and turned <= BASE_GUESS_DEG:
        return None
    return (
        f"the base identified lies {moved:.0f} mm and {turned:.1f} deg from the cell's base "
        f"(more than {BASE_GUESS_MM:g} mm or {BASE_GUESS_DEG:g} deg, past a survey's error): the "
        "data places the arm elsewhere than the cell says (another mount, the tracker moved, "
        "metres); the fit takes the data's, check the cell's base before planning with it"
    )


def implausible(cell: Cell, meas: Measurements, robot) -> list[str]:
    """The verdict's reasons against a model physics rules out (solver.plausibility): readings
    in other units than the cell's nominal arm implies, or an identified geometry changed from
    the nominal beyond what an arm of its size can have."""
    from robocal.solver.plausibility import implausible_changes

    units = units_refusal(cell, meas)
    changes = implausible_changes(cell.robot, robot).reason()
    return [why for why in (units, changes) if why]


def layout_warnings(cell: Cell, meas: Measurements, targets) -> list[str]:
    """The verdict's warnings: SMRs (targets (K, 3), the readings' order) identified far from
    where the cell puts them. The fit holds (the SMR positions are free), so the model stays
    deployable, but the cell's layout or its flange frame is not what the user thinks."""
    from robocal.solver.plausibility import check_layout

    names = meas.target_names
    nominal = cell.target_positions(names)
    why = check_layout(names, nominal, np.asarray(targets, dtype=float)).reason()
    return [why] if why else []
