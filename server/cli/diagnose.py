"""`robocal diagnose`: what the geometric model misses, named and modelled."""

from __future__ import annotations

from .common import (
    _campaign_only_with_database,
    _data_arguments,
    _diagnose_to_files,
    _note,
    _outlier_argument,
    _print_diagnosis,
    _tolerance_argument,
    _with_tolerance,
)


def cmd_diagnose(args) -> None:
    from robocal.server.calibration import workflow
    from robocal.server.cli.tables import console

    _campaign_only_with_database(args)
    cell, meas = workflow.load_data(args.meas, args.cell, args.campaign, note=_note)
    cell = _with_tolerance(cell, args)
    report, figures, _ = _diagnose_to_files(
        cell, meas, args.meas, args.out, args.model_out, screen=not args.keep_outliers
    )
    _print_diagnosis(report)
    console.print(
        f"report written to {args.out}"
        + (f", model to {args.model_out}" if args.model_out else "")
        + "".join(f", figure {p}" for p in figures)
    )


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    dg = sub.add_parser("diagnose", help="what the geometric model misses, named and modelled")
    _data_arguments(dg)
    dg.add_argument("--out", default="report.json", help="report (figures are written beside it)")
    dg.add_argument("--model-out", help="the final, extended model.json")
    _outlier_argument(dg)
    _tolerance_argument(dg)
    dg.set_defaults(func=cmd_diagnose)
