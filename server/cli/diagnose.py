"""`robocal diagnose`: what the geometric model misses, named and modelled."""

from __future__ import annotations

from .common import (
    _campaign_only_with_database,
    _data_arguments,
    _diagnose_to_files,
    _note,
    _outlier_argument,
    _print_diagnosis,
    _recording_arguments,
    _tolerance_argument,
    _with_tolerance,
)


def cmd_diagnose(args) -> None:
    from robocal.server.calibration import workflow
    from robocal.server.cli.tables import console

    _campaign_only_with_database(args)
    if args.recording:  # refused now, not after the diagnosis
        from ..formats.files import check_writable

        check_writable(args.recording)
    cell, meas = workflow.load_data(args.meas, args.cell, args.campaign, note=_note)
    cell = _with_tolerance(cell, args)
    report, figures, diagnosed, model = _diagnose_to_files(
        cell, meas, args.meas, args.out, args.model_out, screen=not args.keep_outliers
    )
    if args.recording:
        from robocal.server.recordings.calibration import record_diagnosis

        record_diagnosis(
            args.recording,
            cell=cell,
            meas=meas,
            diagnosed=diagnosed,
            model=model,
            viewer_url=args.rerun_viewer,
        )
    _print_diagnosis(report)
    from ..formats.model_json import diagnosis_order

    if why := diagnosis_order(model, meas.q, meas.time_s, meas.prev_q):
        import sys

        print(f"robocal: warning: {args.meas}: {why}", file=sys.stderr)
    console.print(
        f"report written to {args.out}"
        + (f", model to {args.model_out}" if args.model_out else "")
        + "".join(f", figure {p}" for p in figures)
        + (f", rerun recording to {args.recording}" if args.recording else "")
    )


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    dg = sub.add_parser("diagnose", help="what the geometric model misses, named and modelled")
    _data_arguments(dg)
    dg.add_argument("--out", default="report.json", help="report (figures are written beside it)")
    dg.add_argument("--model-out", help="the final, extended model.json")
    _outlier_argument(dg)
    _tolerance_argument(dg)
    _recording_arguments(dg, "the diagnosis: after, its final model; the geometry beside it")
    dg.set_defaults(func=cmd_diagnose)
