"""`robocal evaluate`: a model's accuracy on measured data."""

from __future__ import annotations

import sys

import numpy as np

from .common import _campaign_only_with_database, _note, _positive_int


def cmd_evaluate(args) -> None:
    from robocal.server.calibration import workflow
    from robocal.server.cli import tables
    from robocal.server.cli.tables import console

    from ..formats.model_json import write_json_atomic

    model = workflow.read_model(args.model)
    _campaign_only_with_database(args)
    if workflow.is_database(args.meas):
        # The model's own robot reads the joints: the campaign's cell may differ in its targets.
        _, meas = workflow.load_data(args.meas, None, args.campaign, note=_note)
    else:
        from ..calibration.units import MODEL_ARM
        from ..formats.cell_json import Cell

        cell = Cell(model.robot, model.targets, None, {}, None)
        meas = workflow.load_campaign(args.meas, cell, arm=MODEL_ARM)
    try:
        res = workflow.evaluate(model, meas)
    except workflow.DataError as e:
        raise workflow.DataError(f"{args.meas}: {e}") from None
    from robocal.server.calibration.validation import absurd_errors

    why = absurd_errors(res, model.verdict)
    if why and not args.force:
        raise workflow.DataError(f"{args.meas}: {why}; --force to evaluate anyway")
    if why:
        print(f"robocal: warning: {args.meas}: {why}", file=sys.stderr)
    from robocal.server.formats.model_json import approach_unknown

    if unknown := approach_unknown(model, meas.q, meas.time_s, meas.prev_q, meas.pose_ids):
        print(f"robocal: warning: {args.meas}: {unknown}", file=sys.stderr)
    if res.nominal is not None:
        console.print(
            tables.accuracy(res.nominal, "Nominal model (base and SMRs fitted)", meas.target_names)
        )
    console.print(tables.accuracy(res.model, f"Model {args.model}", meas.target_names))
    if res.improvement_pct is not None:
        console.print(
            "improvement over nominal: "
            + ", ".join(
                f"{k} {v:.1f}%" for k, v in res.improvement_pct.to_json().items() if np.isfinite(v)
            )
        )
    _verdict_lines(args.model, model.verdict, res.model.ap.rms)
    if args.json:
        write_json_atomic(args.json, res.to_json())


def _verdict_lines(path, verdict, rms_mm: float) -> None:
    """The model's own verdict beside its accuracy here: the tolerance it was validated against,
    met or not on this data, and a warning if it is not deployable (evaluate printed a model 0.87
    mm RMS off beside nothing, its tolerance 0.05 mm and its 'not deployable' unsaid)."""
    from robocal.server.cli.tables import console

    tol = verdict.tolerance_mm
    if tol is not None and np.isfinite(rms_mm):
        side = "within" if rms_mm <= tol else "BEYOND"
        console.print(
            f"{rms_mm:.4g} mm RMS on this data: {side} the tolerance {tol:g} mm the model was "
            "validated against"
        )
    if not verdict.deployable:
        print(f"robocal: warning: {path}: {verdict.refusal()}", file=sys.stderr)


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    e = sub.add_parser("evaluate", help="accuracy of a model on measured data")
    e.add_argument("model", help="model.json (robocal calibrate)")
    e.add_argument("meas", help="meas.csv, or a campaign database (.db file or URL)")
    e.add_argument(
        "--campaign",
        type=_positive_int,
        help="campaign id when MEAS is a database (default: latest)",
    )
    e.add_argument("--json", help="also write the figures as JSON")
    e.add_argument(
        "--force", action="store_true", help="evaluate data whose errors say another cell"
    )
    e.set_defaults(func=cmd_evaluate)
