"""`robocal compare`: every method side by side (the paper's Table 3)."""

from __future__ import annotations

from .common import (
    _campaign_only_with_database,
    _data_arguments,
    _note,
    _outlier_argument,
    _print_screening,
)


def cmd_compare(args) -> None:
    from robocal.server.calibration import workflow
    from robocal.server.cli import tables
    from robocal.server.cli.tables import console

    from ..formats.model_json import write_json_atomic

    _campaign_only_with_database(args)
    cell, meas = workflow.load_data(args.meas, args.cell, args.campaign, note=_note)
    rows = workflow.compare(cell, meas, screen=not args.keep_outliers)
    _print_screening(next(iter(rows.values()))[0])
    console.print(tables.table3(rows, meas.target_names))
    for label, (cal, _) in rows.items():
        if cal.history is not None:  # minimax
            console.print(
                f"{label}: {cal.nit} SQP iterations, {cal.qp_iterations} QP "
                f"iterations, {cal.sqp_seconds * 1000:.1f} ms, final max F_i "
                f"{cal.F.max():.6f} mm^2"
            )
    worst = {k: max(acc.F.values()) for k, (_, acc) in rows.items()}
    best = [k for k, v in worst.items() if v <= min(worst.values()) * (1 + 1e-9)]
    console.print(f"smallest max F_i: {', '.join(best)}")
    if args.json:
        write_json_atomic(
            args.json,
            {
                k: {
                    "F": acc.F,
                    "rmse_phi": acc.rmse_phi,
                    "accuracy": acc.to_json(),
                    "seconds": cal.seconds,
                }
                for k, (cal, acc) in rows.items()
            },
        )


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    co = sub.add_parser("compare", help="every method side by side (the paper's Table 3)")
    _data_arguments(co)
    co.add_argument("--json", help="also write the figures as JSON")
    _outlier_argument(co)
    co.set_defaults(func=cmd_compare)
