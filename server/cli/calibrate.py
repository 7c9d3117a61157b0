"""`robocal calibrate`: identify a model from a campaign."""

from __future__ import annotations

import sys
from pathlib import Path

from .common import (
    _campaign_only_with_database,
    _data_arguments,
    _note,
    _outlier_argument,
    _print_screening,
    _recording_arguments,
    _tolerance_argument,
    _with_tolerance,
)


def _held_out_data(args, cell):
    """The --held-out readings (None without it); DataError if they are not of the cell."""
    from robocal.server.calibration import workflow
    from robocal.server.calibration.validation import data_mismatch

    if args.held_out is None:
        if args.held_out_campaign is not None:
            raise workflow.DataError(
                "--held-out-campaign picks a campaign of --held-out's database"
            )
        return None
    if args.held_out_campaign is not None and not workflow.is_database(args.held_out):
        raise workflow.DataError(
            f"{args.held_out}: --held-out-campaign picks a campaign of a database (.db), "
            "not of a CSV file"
        )
    same_file = Path(args.held_out).resolve() == Path(args.meas).resolve()
    if same_file and args.held_out_campaign == args.campaign:
        raise workflow.DataError(f"{args.held_out}: the held-out readings are the fitted ones")
    held_cell, hold = workflow.load_data(args.held_out, args.cell, args.held_out_campaign)
    why = data_mismatch(cell.robot, list(cell.targets), held_cell)
    if why:
        raise workflow.DataError(f"{args.held_out}: {why}")
    return hold


def _warn_undeployable(verdict, path) -> None:
    """One line on stderr when a model's verdict says it is not to be deployed."""
    why = verdict.refusal()
    if why:
        print(f"robocal: warning: {path}: {why}", file=sys.stderr)


def cmd_calibrate(args) -> None:
    from robocal.server.calibration import workflow
    from robocal.server.cli import tables
    from robocal.server.cli.tables import console
    from robocal.solver.calibrate import MethodDataError, parse_method

    from ..formats.model_json import write_model

    _campaign_only_with_database(args)
    if args.recording:  # refused now, not after the calibration
        from ..formats.files import check_writable

        check_writable(args.recording)
    cell, meas = workflow.load_data(args.meas, args.cell, args.campaign, note=_note)
    cell = _with_tolerance(cell, args)
    hold = _held_out_data(args, cell)
    try:
        parse_method(args.method, meas.target_names)
    except MethodDataError as e:  # the data's fault: named by its file
        raise workflow.DataError(f"{args.meas}: {e}") from None
    cal = workflow.run_method(cell, meas, args.method, qp=args.qp, screening=not args.keep_outliers)
    model = workflow.model_file(cal, cell, meas, data_path=args.meas)
    if hold is not None:  # the separate validation figure beside the leave-one-out one
        from robocal.server.calibration.validation import with_held_out
        from robocal.server.calibration.workflow import held_out_errors

        held_out = held_out_errors(
            model, hold, file=Path(args.held_out).name, campaign_id=args.held_out_campaign or None
        )
        if model.validation is not None:
            with_held_out(model.validation, held_out)
    write_model(args.out, model)
    if args.recording:
        from robocal.server.recordings.calibration import record_calibration

        record_calibration(
            args.recording,
            cell=cell,
            meas=meas,
            calibration=cal,
            held_out=hold,
            viewer_url=args.rerun_viewer,
        )
    fit, validation, identified, uncertainty = (
        model.fit,
        model.validation,
        model.identified,
        model.uncertainty,
    )
    # model_file writes these three for every method
    assert fit is not None and validation is not None and uncertainty is not None
    console.print(
        f"{args.method} on {meas.n_poses} poses, {meas.n_readings} readings "
        f"in {cal.seconds * 1000:.0f} ms"
    )
    _print_screening(cal)
    if validation.held_out is not None:  # the held-out figure is the headline
        console.print(tables.held_out_line(validation.held_out))
    for line in tables.validation_lines(model.verdict):
        console.print(line)
    console.print("held fixed: " + tables.fixed_parameters(cal.fixed))
    if cal.shrunk:
        console.print("shrunk toward nominal: " + tables.shrunk_parameters(cal.shrunk))
    console.print(tables.identified_geometry(cal.robot, cell.robot, uncertainty))
    if identified is not None:
        console.print(tables.frames_table(identified))
        console.print(tables.correlations(identified))
    else:
        console.print(tables.frame_errors(uncertainty, meas.target_names))
    console.print(
        f"condition number {cal.condition:.3g}; "
        + ", ".join(f"F_{k} {v:.4f} mm^2" for k, v in (fit.F_mm2 or {}).items())
        + f"; RMSE(phi) {fit.rmse_phi_mm:.4f} mm; RMS {fit.rmse_mm:.4f} mm"
    )
    if cal.history is not None:  # minimax
        console.print(
            f"SQP ({cal.qp} QP): {cal.nit} iterations, "
            f"{cal.qp_iterations} QP iterations, max F_i "
            f"{cal.history[0]:.5f} -> {cal.history[-1]:.5f} mm^2 ({cal.message})"
        )
    console.print(
        f"model written to {args.out}"
        + (f", rerun recording to {args.recording}" if args.recording else "")
    )
    _warn_undeployable(model.verdict, args.out)


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    c = sub.add_parser("calibrate", help="identify a model from a campaign")
    _data_arguments(c)
    c.add_argument(
        "--method",
        default="minimax",
        help="minimax (default), ls-sum, ls-single:TARGET (one SMR, default the first), ls-pose",
    )
    c.add_argument(
        "--qp",
        choices=("primal-dual", "exact"),
        default="primal-dual",
        help="minimax's QP subsolver: the paper's primal-dual method or Clarabel",
    )
    c.add_argument("--out", default="model.json", help="model.json to write (default model.json)")
    c.add_argument(
        "--held-out",
        metavar="MEAS",
        help="readings of the same cell not to fit on (meas.csv or database): the model's error "
        "on them is printed first and kept in model.json; the recording shows them apart",
    )
    c.add_argument(
        "--held-out-campaign",
        type=int,
        metavar="N",
        help="the campaign of --held-out's database (default its latest)",
    )
    _outlier_argument(c)
    _tolerance_argument(c)
    _recording_arguments(c, "the calibration")
    c.set_defaults(func=cmd_calibrate)
