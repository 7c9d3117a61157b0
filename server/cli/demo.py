"""`robocal demo`: the main job on the embedded defaults."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .common import _diagnose_to_files, _nonnegative_int, _positive_int, _print_diagnosis


def cmd_demo(args) -> None:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from robocal.server.acquisition.acquire import AcquireOptions, acquire
    from robocal.server.calibration import workflow
    from robocal.server.cli import tables
    from robocal.server.cli.tables import console

    from ..formats.model_json import write_model

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    db = out / "robocal.db"
    for f in out.glob("robocal.db*"):  # a fresh campaign each run
        f.unlink()
    cell = workflow.load_cell(None)
    opts = AcquireOptions(
        poses=args.poses + args.holdout, seed=args.seed, name="demo", effects=tuple(args.effect)
    )
    console.print(
        f"acquiring {opts.poses} poses on the simulated IRB 2600 cell (tracker and "
        f"controller on 127.0.0.1, virtual clock; hidden effects: "
        f"{', '.join(args.effect) or 'none'}) into {db}"
    )
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        console=console,
        transient=True,
    ) as progress:
        summary = acquire(db, cell, opts, progress=progress)
    console.print(
        f"campaign done: {summary.readings} readings, simulated campaign time "
        f"{(summary.campaign_s or 0.0) / 60:.1f} min"
    )
    cell, meas = workflow.load_data(db)
    cal_meas = meas.subset(np.arange(args.poses))
    hold = meas.subset(np.arange(args.poses, meas.n_poses))
    rows = workflow.compare(cell, cal_meas)
    console.print(tables.table3(rows, cal_meas.target_names))
    cal, _ = rows["minimax"]
    model = workflow.model_file(cal, cell, cal_meas)
    write_model(out / "model.json", model)
    geo = workflow.evaluate(model, hold)
    report, figures, diagnosis, _ = _diagnose_to_files(
        cell, cal_meas, db, out / "report.json", out / "model-extended.json"
    )
    _print_diagnosis(report)
    from robocal.server.recordings.calibration import record_calibration

    extended = workflow.read_model(out / "model-extended.json")
    record_calibration(  # "after" the final, extended model; the minimax one beside it
        out / "calibration.rrd",
        cell=cell,
        meas=cal_meas,
        calibration=cal,
        nominal=rows["nominal"][0],
        held_out=hold,
        diagnosis=diagnosis,
        extended=extended,
    )
    ext = workflow.evaluate(extended, hold)
    console.print(
        tables.accuracy(
            ext.model, f"extended model on the {args.holdout} held-out poses", hold.target_names
        )
    )
    nominal_rms = geo.nominal.rmse if geo.nominal is not None else float("nan")
    console.print(
        f"held-out RMS: nominal {nominal_rms:.4f} mm, minimax "
        f"{geo.model.rmse:.4f} mm, extended {ext.model.rmse:.4f} mm"
    )
    console.print(
        f"files in {out}: robocal.db (the campaign), model.json (minimax), "
        f"model-extended.json, report.json, calibration.rrd (open with `uv run rerun "
        f"{out / 'calibration.rrd'}`)" + "".join(f", {p.name}" for p in figures)
    )


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    d = sub.add_parser("demo", help="simulate, calibrate with every method, evaluate held-out")
    d.add_argument("--out", default="robocal-demo", help="folder for the demo's files")
    d.add_argument(
        "--poses", type=_positive_int, default=100, help="poses to calibrate on (default 100)"
    )
    d.add_argument(
        "--holdout",
        type=_positive_int,
        default=50,
        help="further poses to evaluate the models on (default 50)",
    )
    d.add_argument("--seed", type=_nonnegative_int, default=1, help="random seed (default 1)")
    d.add_argument(
        "--effect",
        action="append",
        metavar="SPEC",
        help="hidden effects of the simulated arm (default: joint_compliance:2); "
        "see `simulate --help`",
    )
    d.set_defaults(func=cmd_demo)
