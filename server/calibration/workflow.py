"""What the commands do, between files and the solver: load, calibrate, predict, compare."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robocal.server.calibration.units import radian_refusal, units_refusal
from robocal.server.calibration.validation import (
    HOLDOUT_METHOD,
    NominalErrors,
    absurd_errors,
    base_guess_warning,
    cell_problem,
    implausible,
    json_number,
    late_shift_warning,
    layout_warnings,
    noise_floor,
    nominal_errors,
    nominal_model_errors,
    repeated_readings_warning,
    validation_block,
)
from robocal.server.formats.blocks import Diagnosis, Fit, HeldOut, Validation
from robocal.server.formats.campaign_csv import read_campaign
from robocal.server.formats.cell_json import Cell, default_cell, read_cell
from robocal.server.formats.model_json import (
    ModelFile,
    extension_errors,
    file_digest,
    joint_range_deg,
    read_model,
    uncertainty_to_json,
)
from robocal.solver.coverage import idle_joints, idle_reason
from robocal.solver.effects import Inputs
from robocal.solver.extended import predict_model
from robocal.solver.finite import require_inputs
from robocal.solver.identifiability import effective_parameters
from robocal.solver.kinematics import predict
from robocal.solver.measurements import Measurements
from robocal.solver.problem import Problem
from robocal.solver.vocabulary import after_campaign, missing_input

# The fit, the screening and the diagnosis pull in scipy (seconds on a busy machine): imported in
# the functions that run them, so `robocal predict` starts with numpy alone.
if TYPE_CHECKING:
    from robocal.server.formats.report_doc import ReportDoc
    from robocal.solver.calibrate import Calibration
    from robocal.solver.diagnose import Diagnosis as SolverDiagnosis
    from robocal.solver.diagnosis_report import EffectFigure
    from robocal.solver.fit_errors import ExtendedErrors
    from robocal.solver.metrics import Accuracy, Evaluation
    from robocal.solver.noise import NoiseFloor
    from robocal.solver.screen import Screening

PAPER_METHODS = ("nominal", "ls-single", "ls-sum", "minimax", "ls-pose")


class DataError(ValueError):
    """Inputs that are well-formed but do not fit together; the message names the file."""


def load_cell(path) -> Cell:
    return default_cell() if path is None else read_cell(path)


def load_campaign(path, cell: Cell, cell_path=None, arm: str = "the nominal arm") -> Measurements:
    """A campaign whose targets the cell (read from cell_path, None for the built-in) describes,
    in the units it implies; arm names the cell's robot in a refusal (a model's own)."""
    meas = read_campaign(path, cell.robot, list(cell.targets))
    try:
        require_inputs(meas.q, meas.xyz)
    except ValueError as e:
        raise DataError(f"{path}: {e}") from None
    refuse_wrong_units(cell_path, path, cell, meas, arm)
    return meas


def refuse_wrong_units(
    cell_path, path, cell: Cell, meas: Measurements, arm: str = "the nominal arm"
) -> None:
    """DataError naming the cell.json whose robot's angles the readings say are radians, or the
    campaign whose readings are not in mm and degrees (server.calibration.units)."""
    # the angles before the units: radians change the arm's spread; a built-in robot's are never
    if cell_path is not None and (why := radian_refusal(cell, meas)):
        raise DataError(f"{cell_path}: {why}")
    if why := units_refusal(cell, meas, arm):
        raise DataError(f"{path}: {why}")


DB_SUFFIXES = (".db", ".sqlite", ".sqlite3")


def is_database(path) -> bool:
    """A store (a URL: sqlite:///..., postgresql+psycopg://...; or a SQLite file), not a CSV."""
    return "://" in str(path) or str(path).lower().endswith(DB_SUFFIXES)


def load_data(path, cell_path=None, campaign_id=None, note=None) -> tuple[Cell, Measurements]:
    """A campaign from a meas.csv, or from the store's database (latest campaign unless given);
    the cell from cell_path, else the database campaign's own, else the built-in default.
    note(text) is told when a database campaign is not done (its measured poses are used)."""
    if not is_database(path):
        cell = load_cell(cell_path)
        return cell, load_campaign(path, cell, cell_path)
    from robocal.server import store
    from robocal.server.formats.cell_json import parse_cell

    if "://" not in str(path) and not Path(path).exists():
        raise FileNotFoundError(2, "no such file", str(path))
    db = store.open_database(path)
    campaigns = store.list_campaigns(db)
    if not campaigns:
        raise DataError(f"{path}: no campaign in the database")
    if campaign_id is None:
        campaign_id = max(c.id for c in campaigns)
    info = next((c for c in campaigns if c.id == campaign_id), None)
    if info is None:
        raise DataError(
            f"{path}: no campaign {campaign_id}; it has "
            + ", ".join(f"{c.id} ({c.name}, {c.status})" for c in campaigns[-10:])
        )
    if info.n_done == 0:
        raise DataError(
            f"{path}: campaign {campaign_id} ({info.name}) has no measured pose yet "
            f"(it is {info.status}): run it with `robocal acquire --db {path} --name {info.name}`"
        )
    if info.status != "done" and note is not None:
        note(
            f"{path}: campaign {campaign_id} ({info.name}) is {info.status}, not done: using its "
            f"{info.n_done} of {info.n_poses} poses measured so far"
        )
    cell = load_cell(cell_path) if cell_path else parse_cell(info.cell_json)
    meas = store.campaign_measurements(db, campaign_id=campaign_id, robot=cell.robot)
    if meas.n_poses == 0:
        raise DataError(
            f"{path}: campaign {campaign_id} ({info.name}) has no reading (all missing)"
        )
    where = f"{path}: campaign {campaign_id}"
    refuse_wrong_units(cell_path or f"{where}'s cell", where, cell, meas)
    return cell, meas


def screen_campaign(cell: Cell, meas: Measurements) -> Screening:
    """The campaign's gross outliers (solver.screen), judged with the cell's nominal model."""
    from robocal.solver.screen import screen_readings

    return screen_readings(cell_problem(cell, meas))


def without_outliers(meas: Measurements, screening: Screening | None) -> Measurements:
    """The campaign with the screened-out readings missing (as a beam break would leave them)."""
    if screening is None or not screening.count:
        return meas
    nan = lambda a: None if a is None else np.where(screening.excluded, np.nan, a)  # noqa: E731
    return Measurements(
        list(meas.pose_ids),
        meas.q,
        meas.target_names,
        screening.apply(meas.xyz),
        nan(meas.time_s),
        nan(meas.temp_c),
        meas.prev_q,
    )


def run_method(
    cell: Cell,
    meas: Measurements,
    method: str,
    qp="primal-dual",
    screening: Screening | bool = True,
    floor: NoiseFloor | None = None,
) -> Calibration:
    """One method on the campaign; screening True screens out gross outliers first, False keeps
    every reading, a Screening reuses one already made (compare screens once for all methods);
    floor: the tracker's noise on the readings used, when measured already (compare's)."""
    from robocal.solver.calibrate import calibrate

    screened = screen_campaign(cell, meas) if screening is True else screening or None
    use = without_outliers(meas, screened)
    floor = floor or noise_floor(cell, use)
    problem = replace(cell_problem(cell, use), noise_floor_mm=floor.mm)
    cal = calibrate(problem, method, qp=qp)
    cal.noise_floor = floor  # the verdict's too (model_file): measured once
    if screened is not None:
        cal.screening = screened
        cal.outliers = screened.report(meas.pose_ids, meas.target_names)
    return cal


def model_file(cal: Calibration, cell: Cell, meas: Measurements, data_path=None) -> ModelFile:
    """The self-contained model file of a calibration."""
    from robocal.server.calibration.identified import identified_block
    from robocal.server.calibration.position_uncertainty import geometric_block
    from robocal.solver import metrics
    from robocal.solver.fit_errors import calibration_figures

    screening = cal.screening
    used = without_outliers(meas, screening)
    pred = predict(cal.layout, cal.x, meas.q)
    acc = metrics.accuracy(pred, used.xyz, meas.target_names, orientation=False)  # positions
    errors, holdout = calibration_figures(cal, meas.q, used.xyz)
    data = {"poses": meas.n_poses, "readings": meas.n_readings, "targets": list(meas.target_names)}
    if data_path is not None and "://" not in str(data_path):  # a server's database: no file
        data.update(file=Path(data_path).name, sha256=file_digest(data_path))
    fit = Fit(
        F_mm2=dict(zip(meas.target_names, np.round(cal.F, 9).tolist())),
        rmse_phi_mm=acc.rmse_phi,
        rmse_mm=acc.rmse,
        ap_max_mm=acc.ap.max,
        condition_number=cal.condition,
        fixed_parameters=cal.fixed,
        iterations=cal.nit,
        seconds=round(cal.seconds, 4),
    )
    if screening is not None:  # the readings the fit left out as gross errors, and why
        fit.readings_used = used.n_readings
        if cal.outliers is not None:
            fit.excluded_readings = [o.to_json() for o in cal.outliers]
        fit.screening = screening.summary()
    model = ModelFile(
        cal.robot,
        cal.base,
        dict(zip(meas.target_names, cal.targets)),
        nominal=cell.robot,
        meta={"method": cal.method, "data": data},
    )
    model.fit = fit
    model.uncertainty = uncertainty = uncertainty_to_json(errors, cal.layout.names())
    if cal.qp is not None:  # minimax
        model.meta["qp"] = cal.qp
    if cal.method != "nominal":  # nothing of the arm identified: no table of it
        model.identified = identified_block(
            model,
            errors,
            fixed=cal.fixed,
            condition=cal.condition,
            nominal_targets={t: cell.targets[t] for t in meas.target_names},
            nominal_base=cell.base,
            shrunk=cal.shrunk,
            prior=cal.prior,
        )
    # the nominal arm, registered, is judged as any calibration: a model without a verdict is
    # never deployable
    floor = cal.noise_floor or noise_floor(cell, used)  # a fit not made by run_method has none
    v = model.validation = validate(
        cal,
        cell,
        used,
        holdout,
        errors,
        acc.rmse,
        floor,
        late_shift_warning(meas, pred - meas.xyz, floor.mm if floor else None),
    )
    if cal.method != "nominal":
        block = geometric_block(
            cal.layout, cal.x, used.q, errors, v.holdout_rms_mm, v.noise_floor_mm
        )
        if block is not None:
            uncertainty.position = block
    return model


def validate(
    cal: Calibration,
    cell: Cell,
    used: Measurements,
    holdout,
    errors,
    fit_rms,
    floor: NoiseFloor,
    late: str | None = None,
) -> Validation:
    """model.json's `validation` block of a calibration on the readings it used (holdout: its
    leave-one-pose-out residuals, solver.guard.Holdout; floor: the tracker's noise on them;
    late: the warning of the campaign's last poses moved together, see verdict)."""
    return verdict(
        cell,
        used,
        cal.robot,
        cal.targets,
        fit_rms_mm=fit_rms,
        holdout=holdout,
        condition=cal.condition,
        free_parameters=effective_parameters(errors.column, cal.shrunk),
        floor=(floor.mm, floor.source),
        layout_condition=cal.layout_condition,
        late=late,
        nominal=nominal_model_errors(cal, fit_rms, holdout),
        base=cal.layout.base(cal.x),
    )


def verdict(
    cell: Cell,
    meas: Measurements,
    robot,
    targets,
    *,
    fit_rms_mm: float,
    holdout,
    condition: float,
    free_parameters: int,
    floor: tuple[float | None, str],
    holdout_method: str = HOLDOUT_METHOD,
    layout_condition: float | None = None,
    extension_reason: str | None = None,
    late: str | None = None,
    explained_share: float | None = None,
    nominal: NominalErrors | None = None,
    base=None,
) -> Validation:
    """The `validation` block of a model fitted on meas, `calibrate`'s and `diagnose`'s alike (one
    model, one verdict): the guard's limits (solver.guard.judge: past MAX_FLOOR_RATIO times the
    noise floor a reason without a tolerance, a warning with one), the physics' (implausible),
    the SMR layout's warnings; layout_condition: the identified parameters' condition number on
    rich poses (solver.identifiability.layout_condition), None: unknown; late: the warning that
    the campaign's last poses moved together (late_shift_warning: a bumped tracker), None;
    explained_share: the strongest covariate's share of a diagnosis's remainder (its
    unexplained block), None; nominal: the nominal arm's errors on meas when known already;
    base: the identified base (4x4), against the cell's guess."""
    from robocal.solver import guard
    from robocal.solver.plausibility import nominal_error_bound

    mm, source = floor
    nominal = nominal or nominal_errors(cell, meas)
    v = guard.judge(
        fit_rms_mm=fit_rms_mm,
        holdout=holdout,
        condition_number=condition,
        equations=3 * int(meas.mask.sum()),
        free_parameters=free_parameters,
        poses=int(np.any(meas.mask, axis=1).sum()),
        noise_floor_mm=mm,
        noise_floor_source=source,
        tolerance_mm=cell.tolerance_mm,
        layout_condition=layout_condition,
        max_fit_mm=nominal_error_bound(cell.robot),
        nominal_holdout_mm=nominal.holdout_rms_mm,
        explained_share=explained_share,
    )
    idle = idle_reason(idle_joints(meas.q[used := np.any(meas.mask, axis=1)]), int(used.sum()))
    v.reasons += implausible(cell, meas, robot) + [r for r in (idle, extension_reason) if r]
    return validation_block(
        v,
        list(meas.pose_ids),
        source,
        holdout_method,
        nominal_rms_mm=nominal.fit_rms_mm,
        nominal_holdout_rms_mm=nominal.holdout_rms_mm,
        warnings=v.warnings
        + layout_warnings(cell, meas, targets)
        + [w for w in (late, repeated_readings_warning(meas), base_guess_warning(cell, base)) if w],
    )


def model_predict(
    model: ModelFile, q, time_s=None, temp_c=None, prev_q=None, pose_ids=None
) -> np.ndarray:
    """SMR centres (m, K, 3) a model file predicts, with its extensions (time and temperature per
    pose (m,) or per reading (m, K)).

    Backlash follows each joint's last motion (Inputs computes it): from the joints the arm came
    from, prev_q (m, n) rad (NaN rows: not given), else the poses as visited in time_s order,
    else in the given order.
    """
    lay, x = model.layout()
    if not model.extensions:
        return predict(lay, x, q)
    m, K = len(q), len(model.targets)

    def per_reading(a):
        if a is None:
            return None
        return np.broadcast_to(np.reshape(np.asarray(a, dtype=float), (m, -1)), (m, K))

    if time_s is None and (later := after_campaign(model.extensions)) is not None:
        time_s = np.full(m, later)
    inputs = Inputs(q, per_reading(time_s), per_reading(temp_c), prev_q=prev_q)
    why = missing_input(model.extensions, inputs, pose_ids)
    if why:
        raise DataError(why)
    return predict_model(model.nominal or model.robot, lay, x, model.extensions, inputs)


def paper_methods(target_names) -> list[str]:
    """The paper's conditions 0-6 for these targets, in Table 3's order."""
    out = ["nominal"] + [f"ls-single:{t}" for t in target_names] + ["ls-sum", "minimax"]
    if len(target_names) >= 3:
        out.append("ls-pose")
    return out


def compare(
    cell: Cell, meas: Measurements, methods=None, qp_solvers=("primal-dual", "exact"), screen=True
) -> dict[str, tuple[Calibration, Accuracy]]:
    """Every method on the same data, screened once for gross outliers (unless screen is False):
    calibrations and their accuracy on the readings they used."""
    from robocal.solver import metrics

    screening = screen_campaign(cell, meas) if screen else None
    used = without_outliers(meas, screening)
    floor = noise_floor(cell, used)  # one data, one floor for every method
    rows = {}
    for method in methods or paper_methods(meas.target_names):
        solvers = qp_solvers if method == "minimax" else (None,)
        for qp in solvers:
            how = qp or "primal-dual"
            cal = run_method(cell, meas, method, how, screening=screening or False, floor=floor)
            label = method if qp is None or qp == qp_solvers[0] else f"{method} ({qp} QP)"
            pred = predict(cal.layout, cal.x, meas.q)
            rows[label] = (cal, metrics.accuracy(pred, used.xyz, meas.target_names))
    return rows


def evaluate(model: ModelFile, meas: Measurements) -> Evaluation:
    """Accuracy of a model on measured data, next to the nominal model fitted to the same data."""
    from robocal.solver import metrics
    from robocal.solver.calibrate import calibrate

    unknown = [t for t in meas.target_names if t not in model.targets]
    if unknown:
        raise DataError(
            f"target {unknown[0]!r} of the data is not in the model ({', '.join(model.targets)})"
        )
    if model.robot.n_joints != meas.q.shape[1]:
        raise DataError("the data's joint count differs from the model's robot")
    require_inputs(meas.q, meas.xyz)  # before any arithmetic on them: no overflow warnings
    names = meas.target_names
    order = [list(model.targets).index(t) for t in names]
    time_s, temp_c = _pose_column(meas.time_s), _pose_column(meas.temp_c)
    pred = model_predict(model, meas.q, time_s, temp_c, meas.prev_q, meas.pose_ids)
    after = metrics.accuracy(pred[:, order], meas.xyz, names)
    if model.nominal is None:
        return metrics.Evaluation(after)
    targets = np.array([model.targets[t] for t in names])
    nom = calibrate(Problem.of(model.nominal, targets, meas), "nominal")
    before = metrics.accuracy(predict(nom.layout, nom.x, meas.q), meas.xyz, names)
    return metrics.Evaluation(after, before, metrics.compare_accuracy(before, after))


def held_out_errors(
    model: ModelFile, meas: Measurements, *, file: str | None = None, campaign_id: int | None = None
) -> HeldOut:
    """A calibration's errors on readings it was not fitted on (mm; RMS and max per reading,
    the nominal model's RMS registered on them), with a warning when they say the data is not
    of the model's cell."""
    result = evaluate(model, meas)
    # only the keys given: a file's figures name no campaign, a campaign's no file
    return HeldOut(
        **({"file": file} if file is not None else {}),
        **({"campaign_id": campaign_id} if campaign_id is not None else {}),
        poses=int(np.any(meas.mask, axis=1).sum()),
        readings=int(meas.mask.sum()),
        rms_mm=json_number(result.model.rmse),
        max_mm=json_number(result.model.ap.max),
        nominal_rms_mm=json_number(result.nominal.rmse) if result.nominal is not None else None,
        warning=absurd_errors(result, model.verdict),
    )


def _pose_column(a):
    """Per-pose value of a per-reading column (the first measured reading of each pose)."""
    if a is None:
        return None
    first = np.argmax(np.isfinite(a), axis=1)
    return a[np.arange(len(a)), first]


@dataclass
class Diagnosed:
    """A diagnosis as the server holds it: its report typed once (formats.report_doc) and the
    solver's result (the final model, the figures' data, the standard errors)."""

    report: ReportDoc
    result: SolverDiagnosis
    # the geometry as ls-sum finds it on the same readings (judged beside the final model)
    geometric: Calibration | None = None

    @property
    def extensions(self) -> list:
        return self.result.extensions

    @property
    def figures(self) -> list[EffectFigure]:
        return self.result.figures

    @property
    def errors(self) -> ExtendedErrors | None:
        return self.result.errors


def diagnose(cell: Cell, meas: Measurements, log=None, screen=True) -> tuple[Diagnosed, ModelFile]:
    """The diagnosis of a campaign (solver.diagnose) and its final model as a model file."""
    from robocal.server.formats.report_doc import (
        ReportDoc,  # not loaded for the commands that never diagnose
    )
    from robocal.solver.diagnose import diagnose as run_diagnosis

    solved = run_diagnosis(cell_problem(cell, meas), log=log, screen_outliers=screen)
    lay, x = solved.layout, solved.x
    robot = lay.robot.with_params(x[: lay.n_geo])
    model = ModelFile(
        robot,
        lay.base(x),
        dict(zip(meas.target_names, lay.targets(x))),
        nominal=cell.robot,
        extensions=solved.extensions,
        parameters=solved.parameters,
        meta={"method": "ls-sum+extensions"},
    )
    # the solver's report as report.json has it, typed once: what the model keeps of it
    d = Diagnosed(ReportDoc.of(solved), solved)
    report = d.report
    model.diagnosis = Diagnosis(
        final=report.final,
        noise_floor_mm=report.noise_floor_mm,
        noise_floor_source=report.noise_floor_source,
        joint_range_deg=joint_range_deg(meas.q),
        **(
            {"outliers": [o.to_json() for o in report.outliers]}
            if report.outliers is not None
            else {}
        ),
    )
    if d.errors is not None:
        model.uncertainty = uncertainty_to_json(d.errors.parameters, lay.names())
        model.extension_errors = extension_errors(d.errors)
        d.geometric = _judge_diagnosis(d.report, d.errors, cell, meas, model, solved.geometric)
        _position_block(d.report, d.errors, cell, meas, model)
    return d, model


def _position_block(
    report: ReportDoc, errors: ExtendedErrors, cell: Cell, meas: Measurements, model: ModelFile
) -> None:
    """An extended model's `uncertainty.position` block: its geometry's and its coefficients'
    covariance, the joint scatter fitted to the diagnosis's final held-out RMS."""
    from robocal.server.calibration.position_uncertainty import extended_block

    if model.uncertainty is None:
        return
    inputs = cell_problem(cell, meas).inputs()
    final, floor = report.final.holdout_rmse_mm, report.noise_floor_mm
    block = extended_block(model, inputs, errors.parameters, final, floor)
    if block is not None:
        model.uncertainty.position = block


def _judge_diagnosis(
    report: ReportDoc,
    errors: ExtendedErrors,
    cell: Cell,
    meas: Measurements,
    model: ModelFile,
    geometric: Calibration | None = None,
) -> Calibration:
    """The `identified` and `validation` blocks of a diagnosis's final model, as a calibration's:
    the held-fixed and the shrunk parameters, the prior and the condition number of the geometry
    the diagnosis fitted under (`geometric`, its ls-sum; else ls-sum's on these readings),
    that geometry returned."""
    from robocal.server.calibration.identified import identified_block
    from robocal.solver.calibrate import calibrate

    if geometric is None:
        problem = replace(cell_problem(cell, meas), noise_floor_mm=report.noise_floor_mm)
        geometric = calibrate(problem, "ls-sum")
    model.identified = identified_block(
        model,
        errors.parameters,
        fixed=geometric.fixed,
        condition=geometric.condition,
        nominal_targets={t: cell.targets[t] for t in meas.target_names},
        nominal_base=cell.base,
        shrunk=geometric.shrunk,
        prior=geometric.prior,
    )
    model.validation = validate_diagnosis(report, errors, cell, meas, model, geometric)
    return geometric


def validate_diagnosis(
    report: ReportDoc,
    errors: ExtendedErrors,
    cell: Cell,
    meas: Measurements,
    model: ModelFile,
    geometric: Calibration,
) -> Validation:
    """model.json's `validation` block of a diagnosis's final model, by the calibration's rule
    (verdict): its own cross-validated held-out figures against its fit, with the geometry's
    condition number (and its layout's) and shrunk parameters (each counted as the share of it
    the data gives, as the diagnosis fits them under its prior) and the report's noise floor."""
    from robocal.solver import guard
    from robocal.solver.diagnose import FOLDS
    from robocal.solver.plausibility import implausible_extensions

    pred = model_predict(model, meas.q, meas.time_s, meas.temp_c, meas.prev_q, meas.pose_ids)
    r = np.linalg.norm(pred - meas.xyz, axis=-1)
    r = r[np.isfinite(r)]
    final, left = report.final, report.unexplained
    v = verdict(
        cell,
        meas,
        model.robot,
        [model.targets[t] for t in meas.target_names],
        fit_rms_mm=float(np.sqrt(np.mean(r * r))),
        holdout=guard.CrossValidated(final.holdout_rmse_mm, final.holdout_max_mm),
        condition=geometric.condition,
        free_parameters=effective_parameters(errors.parameters.column, geometric.shrunk),
        # the solver's report always says where its floor comes from; one read from a file may not
        floor=(report.noise_floor_mm, report.noise_floor_source or "unstated"),
        holdout_method=f"{FOLDS}-fold cross-validation of the diagnosis",
        layout_condition=geometric.layout_condition,
        extension_reason=implausible_extensions(*model.layout(), model.extensions, meas.q),
        late=late_shift_warning(meas, pred - meas.xyz, report.noise_floor_mm),
        base=model.base,
        explained_share=max((c.strength for c in left.covariates), default=None) if left else None,
    )
    # a small campaign's resamples: the cause taken from them, or their doubt, said here too
    st = report.stability
    said = (
        tuple(s for s in (st.agreed, st.half_way, *(st.held or ()), st.doubt) if s)
        if st is not None
        else ()
    )
    return v.model_copy(update={"warnings": (*v.warnings, *said)}) if said else v


def write_diagnosis(
    d: Diagnosed,
    model: ModelFile,
    report_path: Path,
    data: dict,
    model_path=None,
    list_figures=False,
) -> tuple[ReportDoc, list[Path]]:
    """Write the report (each effect naming its figure; with list_figures, every figure in
    `figures`), its figures beside it and the model. Returns (report, figure paths)."""
    from robocal.server.figures.diagnosis import write_figures
    from robocal.server.formats.model_json import write_json_atomic, write_model

    report = d.report
    exts = _report_order(report, d.extensions)
    # One numbering everywhere: effect N is the report's effects[N - 1], its figure
    # REPORT_N_*.png, and `diagnose` prints it as "effect N" (the order the report ranks them
    # in, not found in).
    rank = {x.label(): k for k, x in enumerate(exts)}
    ranked = sorted(d.figures, key=lambda f: rank.get(f.label, len(rank)))
    figures = write_figures(ranked, report_path)
    by_label = {f.label: path.name for f, path in zip(ranked, figures)}
    for e, ext in zip(report.effects, exts):
        e.figure = by_label.get(ext.label())
    if list_figures:
        report.figures = [p.name for p in figures]
    # the final model's table and verdict, in the report too
    if model.identified is not None:
        report.identified = model.identified
    if model.validation is not None:
        report.validation = model.validation
    model.meta["data"] = data
    write_json_atomic(report_path, report.to_json())
    if model_path:
        write_model(model_path, model)
    return report, figures


def _report_order(report: ReportDoc, exts) -> list:
    """The extensions in the report's order (most important first)."""
    index = {(x.name, None if x.joint is None else x.joint + 1, x.harmonic): x for x in exts}
    return [index[e.key()] for e in report.effects]


__all__ = [
    "DataError",
    "load_cell",
    "load_campaign",
    "run_method",
    "model_file",
    "model_predict",
    "compare",
    "evaluate",
    "read_model",
    "paper_methods",
    "screen_campaign",
    "without_outliers",
]
